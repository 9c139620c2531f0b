//! panoptic_mapping label tables (`groundtruth_labels.csv`, `detectron_labels.csv`).

use std::collections::BTreeMap;
use std::path::Path;

use voxpan_core::{ClassInfo, ClassTable};

use crate::IoError;

/// Reads a panoptic_mapping label CSV: a header naming at least `InstanceID`, `ClassID`,
/// `PanopticID` (1 = thing), `R`, `G`, `B`, `Name`.
pub fn read_class_csv(path: &Path) -> Result<ClassTable, IoError> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::io(path, e))?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| IoError::format(path, "empty file"))?
        .split(',')
        .map(str::trim)
        .collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| IoError::format(path, format!("no {name} column")))
    };
    let (c_id, c_class, c_pan) = (
        column("InstanceID")?,
        column("ClassID")?,
        column("PanopticID")?,
    );
    let (c_r, c_g, c_b, c_name) = (column("R")?, column("G")?, column("B")?, column("Name")?);
    let mut entries = BTreeMap::new();
    for (n, line) in lines.enumerate() {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let bad = || IoError::format(path, format!("line {}: malformed row {line:?}", n + 2));
        let num = |i: usize| f.get(i).and_then(|v| v.parse::<u32>().ok()).ok_or_else(bad);
        let byte = |i: usize| f.get(i).and_then(|v| v.parse::<u8>().ok()).ok_or_else(bad);
        entries.insert(
            num(c_id)?,
            ClassInfo {
                class_id: num(c_class)?,
                is_thing: num(c_pan)? == 1,
                name: f.get(c_name).ok_or_else(bad)?.to_string(),
                color: [byte(c_r)?, byte(c_g)?, byte(c_b)?],
            },
        );
    }
    Ok(ClassTable { entries })
}

/// Writes the table in the ground-truth CSV layout (MeshID and InfraredID repeat the id).
pub fn write_class_csv(table: &ClassTable, path: &Path) -> Result<(), IoError> {
    let mut out = String::from("InstanceID,ClassID,PanopticID,MeshID,InfraredID,R,G,B,Name,Size\n");
    for (id, c) in &table.entries {
        out += &format!(
            "{id},{},{},{id},{id},{},{},{},{},M\n",
            c.class_id, c.is_thing as u8, c.color[0], c.color[1], c.color[2], c.name
        );
    }
    std::fs::write(path, out).map_err(|e| IoError::io(path, e))
}
