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

/// A map instance and the reference object it matched: voxel IoU above 0.5, so each is the
/// other's only match.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct VoxelMatch {
    pub instance: u16,
    pub object: u16,
    /// Voxel IoU, 0.5 < iou ≤ 1.
    pub iou: f64,
}

/// The instances of `predicted` matched to objects of `truth` (voxel → instance), by
/// instance id: the true positives [`voxel_pq_of`] counts.
pub fn voxel_matches_of(
    predicted: &BTreeMap<VoxelIndex, u16>,
    truth: &BTreeMap<VoxelIndex, u16>,
) -> Vec<VoxelMatch> {
    Overlaps::new(predicted, truth).matches()
}

/// A reference object no instance matched, and where its surface voxels are in the map.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ObjectCover {
    pub object: u16,
    /// Its labelled surface voxels in the reference.
    pub voxels: usize,
    /// The instances holding most of them, with how many each holds (largest first, at most
    /// [`HOLDERS`]).
    pub holders: Vec<(u16, usize)>,
    /// Of its voxels, those no shown instance leads in the map: never labelled, or led by an
    /// instance still hidden (unconfirmed, or under `tracking.min_voxels`).
    pub unlabelled: usize,
}

/// Holders listed per missed object.
pub const HOLDERS: usize = 3;

/// Instance sizes and their overlaps with objects, over labelled voxels.
struct Overlaps {
    p_size: BTreeMap<u16, usize>,
    t_size: BTreeMap<u16, usize>,
    both: BTreeMap<(u16, u16), usize>,
}

impl Overlaps {
    fn new(predicted: &BTreeMap<VoxelIndex, u16>, truth: &BTreeMap<VoxelIndex, u16>) -> Self {
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
        Self {
            p_size,
            t_size,
            both,
        }
    }

    /// Pairs with IoU > 0.5, in instance order.
    fn matches(&self) -> Vec<VoxelMatch> {
        self.both
            .iter()
            .filter_map(|(&(a, b), &inter)| {
                let iou = inter as f64 / (self.p_size[&a] + self.t_size[&b] - inter) as f64;
                (iou > 0.5).then_some(VoxelMatch {
                    instance: a,
                    object: b,
                    iou,
                })
            })
            .collect()
    }

    /// The objects none of `matches` is, and the instances holding their voxels.
    fn unmatched(&self, matches: &[VoxelMatch]) -> Vec<ObjectCover> {
        let mut holders: BTreeMap<u16, Vec<(u16, usize)>> = BTreeMap::new();
        for (&(a, b), &n) in &self.both {
            holders.entry(b).or_default().push((a, n));
        }
        self.t_size
            .iter()
            .filter(|(object, _)| !matches.iter().any(|m| m.object == **object))
            .map(|(&object, &voxels)| {
                let mut held = holders.remove(&object).unwrap_or_default();
                let labelled: usize = held.iter().map(|(_, n)| n).sum();
                held.sort_by(|x, y| y.1.cmp(&x.1).then(x.0.cmp(&y.0)));
                held.truncate(HOLDERS);
                ObjectCover {
                    object,
                    voxels,
                    holders: held,
                    unlabelled: voxels - labelled,
                }
            })
            .collect()
    }

    fn pq(&self) -> VoxelPq {
        let tp_iou: Vec<f64> = self.matches().iter().map(|m| m.iou).collect();
        let tp = tp_iou.len();
        let (fp, fn_) = (self.p_size.len() - tp, self.t_size.len() - tp);
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
}

/// Scores labelled voxels `predicted` against `truth` (voxel → instance).
pub fn voxel_pq_of(
    predicted: &BTreeMap<VoxelIndex, u16>,
    truth: &BTreeMap<VoxelIndex, u16>,
) -> VoxelPq {
    Overlaps::new(predicted, truth).pq()
}

/// Scores the instances of `predicted` against those of `truth`.
pub fn voxel_pq(predicted: &PanopticMap, truth: &PanopticMap) -> VoxelPq {
    voxel_pq_of(&surface_labels(predicted), &surface_labels(truth))
}

/// A map's instances against a reference's objects: panoptic quality over all instances,
/// things only and stuff only, and how the instances split and merge the objects.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PanopticScores {
    pub all: VoxelPq,
    pub things: VoxelPq,
    pub stuff: VoxelPq,
    /// Map instances with labelled surface voxels.
    pub instances: usize,
    /// Of those, instances of fewer than 100 voxels (a few centimetres of surface).
    pub small_instances: usize,
    /// Reference objects with labelled surface voxels.
    pub objects: usize,
    /// Objects split over several instances: an object that is where most voxels of two or
    /// more instances lie.
    pub over_segmented: usize,
    /// Instances spanning several objects: an instance that holds the largest share of two or
    /// more objects.
    pub under_segmenting: usize,
}

/// Voxels below which an instance is counted as small: 100 voxels is 4 cm × 4 cm of surface at
/// 2 cm — fragments no object is made of.
const SMALL_INSTANCE: usize = 100;

/// Scores `map` against `reference`; instance kinds (thing or stuff) come from each map's
/// instance table.
pub fn panoptic_scores(map: &PanopticMap, reference: &PanopticMap) -> PanopticScores {
    panoptic_comparison(map, reference).scores
}

/// A map against a reference: the scores, the matches, and the objects left unmatched.
#[derive(Clone, Debug, Default)]
pub struct PanopticComparison {
    pub scores: PanopticScores,
    /// Which reference object each matched instance is (the true positives of `all`).
    pub matches: Vec<VoxelMatch>,
    /// The reference objects no instance matched (the false negatives of `all`), in object
    /// order, with where their voxels are.
    pub unmatched: Vec<ObjectCover>,
}

/// [`panoptic_scores`], with the matched instances and the unmatched objects.
pub fn panoptic_comparison(map: &PanopticMap, reference: &PanopticMap) -> PanopticComparison {
    let (predicted, truth) = (surface_labels(map), surface_labels(reference));
    let kinds = |m: &PanopticMap| -> BTreeMap<u16, bool> {
        m.instances().iter().map(|i| (i.id, i.is_thing)).collect()
    };
    let (p_kind, t_kind) = (kinds(map), kinds(reference));
    let only = |labels: &BTreeMap<VoxelIndex, u16>, kind: &BTreeMap<u16, bool>, thing: bool| {
        labels
            .iter()
            .filter(|(_, id)| kind.get(id).copied().unwrap_or(false) == thing)
            .map(|(k, &v)| (*k, v))
            .collect::<BTreeMap<_, _>>()
    };
    let all = Overlaps::new(&predicted, &truth);
    let (overlap, sizes) = (&all.both, &all.p_size);
    let objects: std::collections::BTreeSet<u16> = truth.values().copied().collect();
    // Each instance's main object, and each object's main instance.
    let mut main_object: BTreeMap<u16, (usize, u16)> = BTreeMap::new();
    let mut main_instance: BTreeMap<u16, (usize, u16)> = BTreeMap::new();
    for (&(a, b), &n) in overlap {
        let e = main_object.entry(a).or_insert((0, 0));
        if n > e.0 {
            *e = (n, b);
        }
        let e = main_instance.entry(b).or_insert((0, 0));
        if n > e.0 {
            *e = (n, a);
        }
    }
    let count_repeats = |values: Vec<u16>| {
        let mut counts: BTreeMap<u16, usize> = BTreeMap::new();
        for v in values {
            *counts.entry(v).or_default() += 1;
        }
        counts.values().filter(|&&n| n >= 2).count()
    };
    let scores = PanopticScores {
        all: all.pq(),
        things: voxel_pq_of(
            &only(&predicted, &p_kind, true),
            &only(&truth, &t_kind, true),
        ),
        stuff: voxel_pq_of(
            &only(&predicted, &p_kind, false),
            &only(&truth, &t_kind, false),
        ),
        instances: sizes.len(),
        small_instances: sizes.values().filter(|&&n| n < SMALL_INSTANCE).count(),
        objects: objects.len(),
        over_segmented: count_repeats(main_object.values().map(|v| v.1).collect()),
        under_segmenting: count_repeats(main_instance.values().map(|v| v.1).collect()),
    };
    let matches = all.matches();
    let unmatched = all.unmatched(&matches);
    PanopticComparison {
        scores,
        matches,
        unmatched,
    }
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
    fn unmatched_objects_list_who_holds_their_voxels() {
        // Objects 1 (0..50), 2 (50..80), 3 (80..100). Instances 7 and 10 match 1 and 3;
        // object 2 is split between instances 8 (10 voxels) and 9 (5), and 15 of its voxels
        // carry no instance.
        let truth = labels(|i| match i {
            0..50 => 1,
            50..80 => 2,
            _ => 3,
        });
        let pred: BTreeMap<VoxelIndex, u16> = (0..100)
            .filter_map(|i| {
                let id = match i {
                    0..50 => 7,
                    50..60 => 8,
                    60..65 => 9,
                    65..80 => return None,
                    _ => 10,
                };
                Some(([i, 0, 0], id))
            })
            .collect();
        let all = Overlaps::new(&pred, &truth);
        let matches = all.matches();
        assert_eq!(matches.len(), 2);
        assert_eq!(
            all.unmatched(&matches),
            vec![ObjectCover {
                object: 2,
                voxels: 30,
                holders: vec![(8, 10), (9, 5)],
                unlabelled: 15,
            }]
        );
        // At most HOLDERS instances are listed, the largest first; the rest count as
        // labelled all the same.
        let pieces: BTreeMap<VoxelIndex, u16> = (0..100)
            .map(|i| ([i, 0, 0], 20 + (i / 10) as u16))
            .collect();
        let one = labels(|_| 1);
        let all = Overlaps::new(&pieces, &one);
        let cover = &all.unmatched(&all.matches())[0];
        assert_eq!(cover.holders.len(), HOLDERS);
        assert_eq!(cover.holders[0], (20, 10));
        assert_eq!(cover.unlabelled, 0);
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
        // The matched pair is the one true positive, with its IoU.
        let m = voxel_matches_of(&pred, &truth);
        assert_eq!(m.len(), 1);
        assert_eq!((m[0].instance, m[0].object), (5, 1));
        assert!((m[0].iou - 0.7).abs() < 1e-12);
    }

    #[test]
    fn matches_are_the_pairs_above_half_iou() {
        // Truth: 50 + 50. Instance 3 covers 0..40 (IoU 0.8 with object 1); instance 4 covers
        // 40..100 (IoU 50/60 with object 2, 10/100 with object 1); no match at exactly 0.5.
        let truth = labels(|i| if i < 50 { 1 } else { 2 });
        let pred = labels(|i| if i < 40 { 3 } else { 4 });
        let m = voxel_matches_of(&pred, &truth);
        let pairs: Vec<(u16, u16)> = m.iter().map(|m| (m.instance, m.object)).collect();
        assert_eq!(pairs, [(3, 1), (4, 2)]);
        assert!((m[1].iou - 50.0 / 60.0).abs() < 1e-12);
        assert_eq!(voxel_pq_of(&pred, &truth).tp, m.len());
        let half = labels(|i| if i < 50 { 1 } else { 2 });
        let halves = labels(|_| 9);
        assert!(
            voxel_matches_of(&halves, &half).is_empty(),
            "IoU 0.5 is not a match"
        );
    }
}
