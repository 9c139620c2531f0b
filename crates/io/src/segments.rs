use std::path::Path;

use serde::{Deserialize, Serialize};
use voxpan_core::Segment;

use crate::IoError;

/// One entry of a panoptic_mapping `NNNNNN_labels.json`.
#[derive(Deserialize, Serialize)]
struct Entry {
    id: u32,
    #[serde(default)]
    isthing: Option<bool>,
    #[serde(default)]
    category_id: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    score: Option<f32>,
}

/// Reads a segment list in the panoptic_mapping format:
/// `[{"id", "isthing", "category_id", "score"?, ...}, ...]`.
pub fn read_segments_json(path: &Path) -> Result<Vec<Segment>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::io(path, e))?;
    parse_segments_json(&text, path)
}

/// [`read_segments_json`] on a file's text; `path` names it in errors.
pub fn parse_segments_json(text: &str, path: &Path) -> Result<Vec<Segment>, IoError> {
    let entries: Vec<Entry> = serde_json::from_str(text)
        .map_err(|e| IoError::format(path, format!("not a segment list: {e}")))?;
    entries
        .into_iter()
        .map(|e| {
            let id = u16::try_from(e.id)
                .ok()
                .filter(|&id| id != 0)
                .ok_or_else(|| {
                    IoError::format(path, format!("segment id {} is not in 1..=65535", e.id))
                })?;
            Ok(Segment {
                id,
                class_id: e.category_id,
                is_thing: e.isthing,
                score: e.score,
            })
        })
        .collect()
}

/// Writes a segment list in the same format.
pub fn write_segments_json(path: &Path, segments: &[Segment]) -> Result<(), IoError> {
    std::fs::write(path, segments_json(segments)).map_err(|e| IoError::io(path, e))
}

/// A segment list in the same format, as text (what [`parse_segments_json`] reads back).
pub fn segments_json(segments: &[Segment]) -> String {
    let entries: Vec<Entry> = segments
        .iter()
        .map(|s| Entry {
            id: s.id as u32,
            isthing: s.is_thing,
            category_id: s.class_id,
            score: s.score,
        })
        .collect();
    serde_json::to_string(&entries).expect("plain data serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_flat_labels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("labels.json");
        std::fs::write(
            &path,
            r#"[{"id": 1, "isthing": false, "category_id": 8, "area": 36421},
                {"id": 3, "isthing": true, "category_id": 62, "score": 0.93, "instance_id": 0}]"#,
        )
        .unwrap();
        let s = read_segments_json(&path).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(
            (s[1].id, s[1].is_thing, s[1].class_id),
            (3, Some(true), Some(62))
        );
        assert_eq!(s[1].score, Some(0.93));
        assert_eq!(s[0].score, None);
    }

    #[test]
    fn rejects_void_id_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.json");
        std::fs::write(&path, r#"[{"id": 0}]"#).unwrap();
        let err = read_segments_json(&path).unwrap_err().to_string();
        assert!(
            err.contains("bad.json") && err.contains("segment id 0"),
            "{err}"
        );
    }
}
