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
    // One bit per id (8 KB, not a 64 KB flag table to clear and scan), set once per run of
    // equal labels: masks are runs, so most pixels repeat their left neighbour.
    let mut seen = vec![0u64; (u16::MAX as usize + 1) / 64];
    let mut previous = None;
    for &l in labels.pixels() {
        if previous != Some(l) {
            seen[l as usize / 64] |= 1 << (l % 64);
            previous = Some(l);
        }
    }
    seen[0] &= !1; // void
    let mut ids = Vec::new();
    for (word, &bits) in seen.iter().enumerate() {
        let mut bits = bits;
        while bits != 0 {
            ids.push((word * 64) as u16 + bits.trailing_zeros() as u16);
            bits &= bits - 1;
        }
    }
    ids
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Image;

    #[test]
    fn ids_exclude_void_and_are_sorted() {
        let labels = Image::from_vec(3, 2, vec![0, 7, 7, 2, 0, 300]).unwrap();
        assert_eq!(segment_ids(&labels), vec![2, 7, 300]);
        // Both ends of the id range and of a 64-id word, repeated and alternating.
        let pixels = vec![65535, 65535, 63, 64, 1, 0, 64, 63, 65535, 0, 127, 128];
        let labels = Image::from_vec(4, 3, pixels).unwrap();
        assert_eq!(segment_ids(&labels), vec![1, 63, 64, 127, 128, 65535]);
        assert!(segment_ids(&Image::filled(5, 5, 0)).is_empty());
    }

    #[test]
    fn ids_are_the_distinct_non_void_labels() {
        // Runs of random length and id (xorshift), against a plain set.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..50 {
            let mut pixels = Vec::new();
            while pixels.len() < 900 {
                let id = match next() % 4 {
                    0 => 0,
                    1 => (next() % 8) as u16,
                    _ => next() as u16,
                };
                pixels.extend(std::iter::repeat_n(id, (next() % 40) as usize + 1));
            }
            pixels.truncate(900);
            let expected: std::collections::BTreeSet<u16> =
                pixels.iter().copied().filter(|&l| l != 0).collect();
            let labels = Image::from_vec(30, 30, pixels).unwrap();
            assert_eq!(segment_ids(&labels), expected.into_iter().collect::<Vec<_>>());
        }
    }
}
