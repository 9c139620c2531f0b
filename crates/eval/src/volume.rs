//! Panoptic quality over voxels: a map's instances against a reference map's.
//!
//! Both maps fuse the same depth, so their surface voxels coincide; each labelled surface voxel
//! (|distance| < one voxel) belongs to the instance its label evidence favours. Instances are
//! matched when their voxel IoU exceeds 0.5 (a match is then unique), and
//! PQ = SQ × RQ as for images.

use std::collections::BTreeMap;

use voxpan_map::{PanopticMap, VoxelIndex};

/// Voxel panoptic quality, in percent.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct VoxelPq {
    pub pq: f64,
    pub sq: f64,
    pub rq: f64,
    pub tp: usize,
    pub fp: usize,
    pub fn_: usize,
}

/// The map's labelled surface voxels.
pub fn surface_labels(map: &PanopticMap) -> BTreeMap<VoxelIndex, u16> {
    map.surface_voxels()
        .filter(|v| v.instance != 0)
        .map(|v| (v.index, v.instance))
        .collect()
}

/// Scores labelled voxels `predicted` against `truth` (voxel → instance).
pub fn voxel_pq_of(
    predicted: &BTreeMap<VoxelIndex, u16>,
    truth: &BTreeMap<VoxelIndex, u16>,
) -> VoxelPq {
    let mut p_size: BTreeMap<u16, usize> = BTreeMap::new();
    let mut t_size: BTreeMap<u16, usize> = BTreeMap::new();
    let mut both: BTreeMap<(u16, u16), usize> = BTreeMap::new();
    for (key, &a) in predicted {
        *p_size.entry(a).or_default() += 1;
        if let Some(&b) = truth.get(key) {
            *both.entry((a, b)).or_default() += 1;
        }
    }
    for &b in truth.values() {
        *t_size.entry(b).or_default() += 1;
    }
    let mut tp_iou = Vec::new();
    for (&(a, b), &inter) in &both {
        let iou = inter as f64 / (p_size[&a] + t_size[&b] - inter) as f64;
        if iou > 0.5 {
            tp_iou.push(iou);
        }
    }
    let tp = tp_iou.len();
    let (fp, fn_) = (p_size.len() - tp, t_size.len() - tp);
    let sq = if tp == 0 {
        0.0
    } else {
        100.0 * tp_iou.iter().sum::<f64>() / tp as f64
    };
    let denominator = tp as f64 + fp as f64 / 2.0 + fn_ as f64 / 2.0;
    let rq = if denominator == 0.0 {
        0.0
    } else {
        100.0 * tp as f64 / denominator
    };
    VoxelPq {
        pq: sq * rq / 100.0,
        sq,
        rq,
        tp,
        fp,
        fn_,
    }
}

/// Scores the instances of `predicted` against those of `truth`.
pub fn voxel_pq(predicted: &PanopticMap, truth: &PanopticMap) -> VoxelPq {
    voxel_pq_of(&surface_labels(predicted), &surface_labels(truth))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 100 voxels in a row labelled by `label(i)`.
    fn labels(label: impl Fn(usize) -> u16) -> BTreeMap<VoxelIndex, u16> {
        (0..100).map(|i| ([i as i32, 0, 0], label(i))).collect()
    }

    #[test]
    fn identical_maps_score_100_and_renumbering_does_not_matter() {
        let truth = labels(|i| if i < 60 { 1 } else { 2 });
        let pred = labels(|i| if i < 60 { 7 } else { 9 });
        let s = voxel_pq_of(&pred, &truth);
        assert_eq!((s.tp, s.fp, s.fn_), (2, 0, 0));
        assert!((s.pq - 100.0).abs() < 1e-12);
    }

    #[test]
    fn a_merged_instance_counts_once() {
        // Truth: 70 + 30 voxels; prediction merges them: IoU 0.7 with the first, 0.3 with the
        // second. TP = 1 (SQ 70), FN = 1: RQ = 1 / 1.5.
        let truth = labels(|i| if i < 70 { 1 } else { 2 });
        let pred = labels(|_| 5);
        let s = voxel_pq_of(&pred, &truth);
        assert_eq!((s.tp, s.fp, s.fn_), (1, 0, 1));
        assert!((s.sq - 70.0).abs() < 1e-9 && (s.rq - 200.0 / 3.0).abs() < 1e-9);
    }
}
