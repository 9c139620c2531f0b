use std::collections::BTreeMap;
use std::path::Path;

use crate::DatasetError;

/// One row of a label table.
#[derive(Clone, Debug, PartialEq)]
pub struct ClassInfo {
    /// Semantic class (for ground truth: `ClassID`; for the network: the category itself).
    pub class_id: u32,
    pub is_thing: bool,
    pub name: String,
    pub color: [u8; 3],
}

/// `InstanceID → ClassInfo`, from `groundtruth_labels.csv` or `detectron_labels.csv`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClassTable {
    pub entries: BTreeMap<u32, ClassInfo>,
}

impl ClassTable {
    /// Reads a panoptic_mapping label CSV: a header naming at least `InstanceID`, `ClassID`,
    /// `PanopticID` (1 = thing), `R`, `G`, `B`, `Name`.
    pub fn read_csv(path: &Path) -> Result<Self, DatasetError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| DatasetError::invalid(path, format!("cannot read: {e}")))?;
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let header: Vec<&str> = lines
            .next()
            .ok_or_else(|| DatasetError::invalid(path, "empty file"))?
            .split(',')
            .map(str::trim)
            .collect();
        let column = |name: &str| {
            header
                .iter()
                .position(|h| *h == name)
                .ok_or_else(|| DatasetError::invalid(path, format!("no {name} column")))
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
            let bad =
                || DatasetError::invalid(path, format!("line {}: malformed row {line:?}", n + 2));
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
        Ok(Self { entries })
    }

    /// Writes the table in the ground-truth CSV layout (MeshID and InfraredID repeat the id).
    pub fn write_csv(&self, path: &Path) -> Result<(), DatasetError> {
        let mut out =
            String::from("InstanceID,ClassID,PanopticID,MeshID,InfraredID,R,G,B,Name,Size\n");
        for (id, c) in &self.entries {
            out += &format!(
                "{id},{},{},{id},{id},{},{},{},{},M\n",
                c.class_id, c.is_thing as u8, c.color[0], c.color[1], c.color[2], c.name
            );
        }
        std::fs::write(path, out)
            .map_err(|e| DatasetError::invalid(path, format!("cannot write: {e}")))
    }

    pub fn get(&self, id: u32) -> Option<&ClassInfo> {
        self.entries.get(&id)
    }
}
