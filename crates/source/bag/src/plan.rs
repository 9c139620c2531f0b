//! Opening a bag as a dataset, in the order a reader checks it: the topics asked for exist
//! with the right types ([`check_topics`]); one pass indexes the images and decodes the small
//! messages ([`scan`]); the camera and world frames are named ([`frames_of_reference`]); each
//! depth image becomes a frame with its colour image, pose, intrinsics and labels, or is
//! skipped with the reason ([`plan_frames`]).

use std::path::Path;

use voxpan_core::Segment;

use crate::container::{Connection, Container};
use crate::{
    BagError, BagOptions, Indexed, Planned, fmt_time, intrinsics_of, msgs, nearest,
    parse_segment_list, tf, topics_of, within,
};

const IMAGE: &str = "sensor_msgs/Image";
const INFO: &str = "sensor_msgs/CameraInfo";
const TF: [&str; 2] = ["tf2_msgs/TFMessage", "tf/tfMessage"];
const POSE: [&str; 2] = [
    "geometry_msgs/PoseStamped",
    "geometry_msgs/TransformStamped",
];

/// Depth images that make no frame: frame id and why.
pub(crate) type Skipped = Vec<(String, String)>;

/// The optional inputs a bag holds and will be read.
pub(crate) struct Inputs {
    pub labels: bool,
    pub segments: bool,
    pub tf_static: bool,
}

/// Checks that each topic voxpan reads exists with the right type and CDR or ROS 1 encoding;
/// says which optional ones are there.
pub(crate) fn check_topics(
    file: &Path,
    connections: &[Connection],
    options: &BagOptions,
) -> Result<Inputs, BagError> {
    let err = |m: String| BagError::new(file, m);
    let present = |topic: &str| connections.iter().any(|c| c.topic == topic);
    let check = |topic: &str, option: &str, types: &[&str]| -> Result<(), BagError> {
        let found: Vec<&Connection> = connections.iter().filter(|c| c.topic == topic).collect();
        if found.is_empty() {
            return Err(err(format!(
                "no topic {topic} ({option}); {} topics in the bag: {}",
                types[0],
                topics_of(connections, types[0])
            )));
        }
        for c in found {
            if !types.contains(&c.msg_type.as_str()) {
                return Err(err(format!(
                    "{topic} is {}, expected {}",
                    c.msg_type,
                    types.join(" or ")
                )));
            }
            if c.wire.is_none() {
                return Err(err(format!(
                    "{topic}: messages are not CDR (ROS 2) encoded"
                )));
            }
        }
        Ok(())
    };
    check(&options.color_topic, "--color-topic", &[IMAGE])?;
    check(&options.depth_topic, "--depth-topic", &[IMAGE])?;
    if !present(&options.info_topic) {
        return Err(err(format!(
            "no camera_info: topic {} (--info-topic) is not in the bag, and voxpan never \
             guesses intrinsics; CameraInfo topics in the bag: {}",
            options.info_topic,
            topics_of(connections, INFO)
        )));
    }
    check(&options.info_topic, "--info-topic", &[INFO])?;
    match &options.pose_topic {
        Some(topic) => check(topic, "--pose-topic", &POSE)?,
        None => check(&options.tf_topic, "/tf", &TF)?,
    }
    let labels = options.require_labels || present(&options.labels_topic);
    if labels {
        check(&options.labels_topic, "--labels-topic", &[IMAGE])?;
    }
    let segments = labels && present(&options.segments_topic);
    if segments {
        check(
            &options.segments_topic,
            "--segments-topic",
            &["std_msgs/String"],
        )?;
    }
    let tf_static = options.pose_topic.is_none() && present(&options.tf_static_topic);
    if tf_static {
        check(&options.tf_static_topic, "/tf_static", &TF)?;
    }
    Ok(Inputs {
        labels,
        segments,
        tf_static,
    })
}

/// What one pass over the bag found, each list sorted by stamp.
pub(crate) struct Scanned {
    pub color: Vec<(i64, Indexed)>,
    pub depth: Vec<(i64, Indexed)>,
    pub labels: Vec<(i64, Indexed)>,
    pub infos: Vec<(i64, msgs::CameraInfoMsg)>,
    pub segment_lists: Vec<(i64, Vec<Segment>)>,
    pub tree: tf::TfTree,
    pub pose_track: tf::Track,
    /// The first colour image's `header.frame_id`.
    pub color_frame: Option<String>,
}

/// Indexes the images (their stamps and where they lie) and decodes the camera_info, pose,
/// transform and segment-list messages, in one pass; fails on the first message that does
/// not decode, and when depth, colour or camera_info have no message at all.
pub(crate) fn scan(
    bag: &Container,
    file: &Path,
    connections: &[Connection],
    options: &BagOptions,
    inputs: &Inputs,
) -> Result<Scanned, BagError> {
    let err = |m: String| BagError::new(file, m);
    let mut s = Scanned {
        color: Vec::new(),
        depth: Vec::new(),
        labels: Vec::new(),
        infos: Vec::new(),
        segment_lists: Vec::new(),
        tree: tf::TfTree::new(&options.tf_topic),
        pose_track: tf::Track::default(),
        color_frame: None,
    };
    bag.scan(&mut |m| {
        let c = &connections[m.connection];
        let Some(wire) = c.wire else { return Ok(()) };
        let topic = c.topic.as_str();
        let at_time = |e: String| {
            err(format!(
                "{topic} message recorded at {} s: {e}",
                fmt_time(m.log_time as i64)
            ))
        };
        let image_list = if topic == options.color_topic {
            Some(&mut s.color)
        } else if topic == options.depth_topic {
            Some(&mut s.depth)
        } else if inputs.labels && topic == options.labels_topic {
            Some(&mut s.labels)
        } else {
            None
        };
        if let Some(list) = image_list {
            let image = msgs::image(wire, m.data).map_err(at_time)?;
            if topic == options.color_topic && s.color_frame.is_none() {
                s.color_frame = Some(image.header.frame_id.clone());
            }
            let stamp = image.header.stamp_ns;
            list.push((
                stamp,
                Indexed {
                    stamp,
                    at: m.at,
                    wire,
                },
            ));
        } else if topic == options.info_topic {
            let info = msgs::camera_info(wire, m.data).map_err(at_time)?;
            s.infos.push((info.header.stamp_ns, info));
        } else if options.pose_topic.as_deref() == Some(topic) {
            let t = if c.msg_type == POSE[0] {
                msgs::pose_stamped(wire, m.data)
            } else {
                msgs::transform_stamped(wire, m.data)
            }
            .map_err(at_time)?;
            s.pose_track
                .push(t.header.stamp_ns, tf::pose_of(&t).map_err(at_time)?);
        } else if options.pose_topic.is_none()
            && (topic == options.tf_topic || (inputs.tf_static && topic == options.tf_static_topic))
        {
            let is_static = topic == options.tf_static_topic;
            for t in msgs::tf_message(wire, m.data).map_err(at_time)? {
                s.tree.add(&t, is_static).map_err(at_time)?;
            }
        } else if inputs.segments && topic == options.segments_topic {
            let text = msgs::string(wire, m.data).map_err(at_time)?;
            let (stamp, list) = parse_segment_list(&text, file).map_err(at_time)?;
            s.segment_lists.push((stamp, list));
        }
        Ok(())
    })?;
    for list in [&mut s.color, &mut s.depth, &mut s.labels] {
        list.sort_by_key(|(t, _)| *t);
    }
    s.infos.sort_by_key(|(t, _)| *t);
    s.segment_lists.sort_by_key(|(t, _)| *t);

    if s.depth.is_empty() {
        return Err(err(format!(
            "no message on {} (--depth-topic)",
            options.depth_topic
        )));
    }
    if s.color.is_empty() {
        return Err(err(format!(
            "no message on {} (--color-topic)",
            options.color_topic
        )));
    }
    if s.infos.is_empty() {
        return Err(err(format!(
            "no camera_info message on {} (--info-topic): intrinsics unknown",
            options.info_topic
        )));
    }
    Ok(s)
}

/// The camera frame (as asked, else the colour images') and the world frame (as asked, else
/// the root of the camera's transform tree; none with a pose topic).
pub(crate) fn frames_of_reference(
    file: &Path,
    scanned: &Scanned,
    options: &BagOptions,
) -> Result<(String, String), BagError> {
    let err = |m: String| BagError::new(file, m);
    let camera = match (&options.camera_frame, &scanned.color_frame) {
        (Some(f), _) => f.clone(),
        (None, Some(f)) if !f.is_empty() => f.clone(),
        _ => {
            return Err(err(format!(
                "{} images have no header.frame_id: name the camera frame",
                options.color_topic
            )));
        }
    };
    let world = match (&options.world_frame, &options.pose_topic) {
        (Some(f), _) => f.clone(),
        (None, Some(_)) => String::new(),
        (None, None) => {
            if scanned.tree.is_empty() {
                return Err(err(format!(
                    "no transform on {} or {}: no poses (or name a --pose-topic)",
                    options.tf_topic, options.tf_static_topic
                )));
            }
            scanned.tree.root(&camera).map_err(err)?
        }
    };
    if options.pose_topic.is_some() && scanned.pose_track.is_empty() {
        return Err(err(format!(
            "no message on {} (--pose-topic)",
            options.pose_topic.as_deref().unwrap_or_default()
        )));
    }
    Ok((camera, world))
}

/// One frame per depth image, in stamp order: its colour image within the sync tolerance,
/// its pose from the pose topic or the transform tree, the nearest camera_info's intrinsics,
/// and its label image and segment list where the bag has them. A depth image without one of
/// these is skipped, with the reason; unusable intrinsics fail the whole bag.
pub(crate) fn plan_frames(
    file: &Path,
    scanned: &Scanned,
    options: &BagOptions,
    inputs: &Inputs,
    (camera, world): (&str, &str),
) -> Result<(Vec<Planned>, Skipped), BagError> {
    let err = |m: String| BagError::new(file, m);
    let secs = |s: f64| (s * 1e9).round() as i64;
    let tolerance = secs(options.sync_tolerance_s);
    let max_gap = secs(options.max_tf_gap_s);
    let depth = &scanned.depth;
    let mut frames = Vec::new();
    let mut skipped = Vec::new();
    for (k, (t, d)) in depth.iter().enumerate() {
        let id = format!("{k:06}");
        let when = fmt_time(*t);
        // Sorted by stamp: a repeated stamp follows its first. Which images and which
        // transform at that stamp belong to which frame cannot be told.
        if k > 0 && depth[k - 1].0 == *t {
            skipped.push((
                id,
                format!(
                    "its depth stamp {when} s is frame {:06}'s too: which images and pose \
                     belong to which is ambiguous",
                    k - 1
                ),
            ));
            continue;
        }
        let Some((_, c)) = within(&scanned.color, *t, tolerance) else {
            skipped.push((
                id,
                format!(
                    "no {} image within {:.0} ms of the depth stamp {when} s",
                    options.color_topic,
                    options.sync_tolerance_s * 1e3
                ),
            ));
            continue;
        };
        let pose = match &options.pose_topic {
            Some(topic) => scanned
                .pose_track
                .at(*t, max_gap, tolerance)
                .map_err(|e| format!("{topic} has no pose at {when} s: {e}")),
            None => scanned.tree.lookup(world, camera, *t, max_gap, tolerance),
        };
        let pose = match pose {
            Ok(p) => p,
            Err(e) => {
                skipped.push((id, e));
                continue;
            }
        };
        let (_, info) = nearest(&scanned.infos, c.stamp).expect("at least one camera_info");
        let intrinsics = intrinsics_of(info);
        if let Err(e) = intrinsics.check() {
            return Err(err(format!(
                "{} at {} s: unusable intrinsics: {e}",
                options.info_topic,
                fmt_time(info.header.stamp_ns)
            )));
        }
        let mut frame_labels = None;
        if inputs.labels {
            let Some((lt, l)) = within(&scanned.labels, c.stamp, tolerance) else {
                skipped.push((
                    id,
                    format!(
                        "no {} label image within {:.0} ms of the colour stamp {} s",
                        options.labels_topic,
                        options.sync_tolerance_s * 1e3,
                        fmt_time(c.stamp)
                    ),
                ));
                continue;
            };
            let list = if inputs.segments {
                match within(&scanned.segment_lists, *lt, tolerance) {
                    Some((_, list)) => Some(list.clone()),
                    None => {
                        skipped.push((
                            id,
                            format!(
                                "no {} segment list for the label image at {} s",
                                options.segments_topic,
                                fmt_time(*lt)
                            ),
                        ));
                        continue;
                    }
                }
            } else {
                None
            };
            frame_labels = Some((*l, list));
        }
        frames.push(Planned {
            id,
            stamp: *t,
            color: *c,
            depth: *d,
            labels: frame_labels,
            pose,
            intrinsics,
        });
    }
    Ok((frames, skipped))
}

/// The first distorted camera_info's warning (said once).
pub(crate) fn distortion_warning(scanned: &Scanned, options: &BagOptions) -> Vec<String> {
    scanned
        .infos
        .iter()
        .find_map(|(t, info)| {
            let why = info.distortion_warning()?;
            Some(format!("{} at {}: {why}", options.info_topic, fmt_time(*t)))
        })
        .into_iter()
        .collect()
}
