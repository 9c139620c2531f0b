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

/// The end of the run of equal labels starting at `start`.
#[inline(always)]
pub fn run_end(labels: &[u16], start: usize) -> usize {
    let l = labels[start];
    let mut end = start + 1;
    // Masks run for dozens to hundreds of pixels: 16 labels are compared at once (an OR of
    // XORs compiles to a vector compare) while all match, then one at a time.
    while let Some(chunk) = labels.get(end..end + 16) {
        if chunk.iter().fold(0, |differ, &x| differ | (x ^ l)) != 0 {
            break;
        }
        end += 16;
    }
    labels[end..]
        .iter()
        .position(|&x| x != l)
        .map_or(labels.len(), |n| end + n)
}

/// The runs of equal labels of an image, in pixel order (a run may continue on the next row):
/// a segment's pixels are handled a run at a time, its slot looked up once per run. Pass one
/// row to keep runs within it.
#[inline(always)]
pub fn label_runs(labels: &[u16]) -> impl Iterator<Item = (u16, std::ops::Range<usize>)> + '_ {
    let mut start = 0;
    std::iter::from_fn(move || {
        let l = *labels.get(start)?;
        let run = start..run_end(labels, start);
        start = run.end;
        Some((l, run))
    })
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

    #[test]
    fn label_runs_split_where_labels_change() {
        // Runs of 1 to 70 labels (under, at and over the 16-label stride), a run ending on
        // the last label, and one-label images.
        let lengths = [1, 15, 16, 17, 31, 32, 33, 70, 2, 1, 48];
        let labels: Vec<u16> = lengths
            .iter()
            .enumerate()
            .flat_map(|(i, &n)| std::iter::repeat_n((i % 3) as u16, n))
            .collect();
        let mut expected = Vec::new();
        let mut start = 0;
        for (i, &n) in lengths.iter().enumerate() {
            expected.push(((i % 3) as u16, start..start + n));
            start += n;
        }
        assert_eq!(label_runs(&labels).collect::<Vec<_>>(), expected);
        assert_eq!(label_runs(&[7]).collect::<Vec<_>>(), [(7, 0..1)]);
        assert_eq!(label_runs(&[]).count(), 0);
    }
}
