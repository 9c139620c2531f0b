use serde::{Deserialize, Serialize};

use crate::LabelImage;

/// One predicted segment of a frame, as a panoptic network reports it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// The segment's id in the frame's label image (never 0, which is void).
    pub id: u16,
    /// Class index into the network's label table, when known.
    pub class_id: Option<u32>,
    /// `true` for countable objects ("things"), `false` for walls, floors, ... ("stuff").
    /// `None` when the network did not say.
    pub is_thing: Option<bool>,
    /// Detection confidence in `[0, 1]`, when known.
    pub score: Option<f32>,
}

impl Segment {
    /// A segment known only by its id.
    pub fn bare(id: u16) -> Self {
        Self {
            id,
            class_id: None,
            is_thing: None,
            score: None,
        }
    }
}

/// The sorted non-void ids present in a label image.
pub fn segment_ids(labels: &LabelImage) -> Vec<u16> {
    let mut seen = vec![false; u16::MAX as usize + 1];
    for &l in labels.pixels() {
        seen[l as usize] = true;
    }
    (1..=u16::MAX).filter(|&id| seen[id as usize]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Image;

    #[test]
    fn ids_exclude_void_and_are_sorted() {
        let labels = Image::from_vec(3, 2, vec![0, 7, 7, 2, 0, 300]).unwrap();
        assert_eq!(segment_ids(&labels), vec![2, 7, 300]);
    }
}
