//! The perception node's segment lists as the mapping node reads them: the bag reader's
//! format plus `null` segments (no masks), the arrival time for latency, the label table, and
//! (between keyframes) the settings the map's masks are refined with.

use std::path::Path;

use voxpan_bag::live::Wire;
use voxpan_core::Segment;

/// One frame's segment list.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentList {
    pub stamp_ns: i64,
    /// `None`: the frame has no masks.
    pub segments: Option<Vec<Segment>>,
    /// When the perception node received the frame's depth image (0 if not said).
    pub received_unix_ns: i64,
    /// The segmenter's label table, when the perception node sent it (id -> name).
    pub class_names: Option<std::collections::BTreeMap<u32, String>>,
    /// A frame between keyframes: its depth is as measured, and its masks are the map's,
    /// refined and filled with the perception node's `[refine]` and `[fill]` (the rest of
    /// the configuration at its defaults).
    pub carry: Option<voxpan_perception::PerceptionConfig>,
}

/// Decodes a std_msgs/String segment list (ROS 1 serialised body or CDR).
pub fn segment_list(wire: Wire, data: &[u8]) -> Result<SegmentList, String> {
    let text = voxpan_bag::live::string(wire, data)?;
    let doc: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("segment list is not JSON: {e}"))?;
    let stamp = &doc["header"]["stamp"];
    let (Some(sec), Some(nsec)) = (stamp["sec"].as_i64(), stamp["nanosec"].as_i64()) else {
        return Err("segment list has no header.stamp {sec, nanosec}".into());
    };
    let segments = match doc.get("segments") {
        None => return Err("segment list has no \"segments\"".into()),
        Some(serde_json::Value::Null) => None,
        Some(list) => Some(
            voxpan_io::parse_segments_json(&list.to_string(), Path::new("segment list"))
                .map_err(|e| e.to_string())?,
        ),
    };
    let class_names = match doc.get("class_names") {
        None => None,
        Some(serde_json::Value::Object(names)) => Some(
            names
                .iter()
                .map(|(id, name)| match (id.parse::<u32>(), name.as_str()) {
                    (Ok(id), Some(name)) => Ok((id, name.to_owned())),
                    _ => Err(format!(
                        "class_names: {id:?}: {name} is not a class id and name"
                    )),
                })
                .collect::<Result<_, _>>()?,
        ),
        Some(other) => return Err(format!("class_names is not an object: {other}")),
    };
    let carry = match doc.get("carry") {
        None => None,
        Some(settings) => {
            let config: voxpan_perception::PerceptionConfig =
                serde_json::from_value(settings.clone()).map_err(|e| format!("carry: {e}"))?;
            config.validate().map_err(|e| format!("carry: {e}"))?;
            Some(config)
        }
    };
    if carry.is_some() && segments.is_some() {
        return Err("a segment list with \"carry\" has masks: expected \"segments\": null".into());
    }
    Ok(SegmentList {
        stamp_ns: voxpan_bag::json_stamp_ns(sec, nsec)
            .ok_or_else(|| format!("segment list stamp {sec} s {nsec} ns is out of range"))?,
        segments,
        received_unix_ns: doc["received_unix_ns"].as_i64().unwrap_or(0),
        class_names,
        carry,
    })
}
