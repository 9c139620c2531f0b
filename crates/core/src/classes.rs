use std::collections::BTreeMap;

/// What one id of a label table means.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClassInfo {
    /// Semantic class (for ground truth: `ClassID`; for a network: the category itself).
    pub class_id: u32,
    pub is_thing: bool,
    pub name: String,
    pub color: [u8; 3],
}

/// `id → ClassInfo`: a network's categories or a dataset's ground-truth instances.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClassTable {
    pub entries: BTreeMap<u32, ClassInfo>,
}

impl ClassTable {
    pub fn get(&self, id: u32) -> Option<&ClassInfo> {
        self.entries.get(&id)
    }

    /// Every id's name.
    pub fn names(&self) -> BTreeMap<u32, String> {
        self.entries
            .iter()
            .map(|(&id, c)| (id, c.name.clone()))
            .collect()
    }

    /// The name of `id`, or `None` if the table does not list it.
    pub fn name(&self, id: u32) -> Option<&str> {
        self.get(id).map(|c| c.name.as_str())
    }
}
