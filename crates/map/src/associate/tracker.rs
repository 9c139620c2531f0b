//! Instance tracking: per-frame segment ids mean nothing across frames, so each frame's
//! segments are matched to the map's instances, panoptic_mapping-style.
//!
//! The rule: render the map's instance labels into the current camera (surface voxels, with a
//! z-buffer), compute the IoU of every frame segment with every rendered instance, and accept
//! matches greedily from the highest IoU down while IoU ≥ `min_iou` (0.2), each instance at
//! most once. Unmatched segments of at least `min_pixels` (100) become new instances; smaller
//! ones are not integrated. Each instance keeps class votes; its class is the most voted.

use std::collections::BTreeMap;

use voxpan_core::{LabelImage, Segment};

use crate::TrackingConfig;

/// What the map knows about an instance.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct InstanceInfo {
    /// Votes per class id.
    pub class_votes: BTreeMap<u32, u32>,
    /// Votes for "thing" and "stuff".
    pub thing_votes: [u32; 2],
    /// Frames in which a segment was assigned to the instance.
    pub frames_seen: u32,
}

impl InstanceInfo {
    /// The most voted class (ties: the smallest id).
    pub fn class(&self) -> Option<u32> {
        self.class_votes
            .iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            .map(|(c, _)| *c)
    }

    pub fn is_thing(&self) -> bool {
        self.thing_votes[0] >= self.thing_votes[1] && self.thing_votes[0] > 0
    }
}

/// What one frame's association did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct AssociationStats {
    /// Segments matched to an existing instance.
    pub matched: usize,
    /// Segments that founded a new instance.
    pub created: usize,
    /// Segments left out (too small to found an instance, or no instance id left).
    pub unassigned: usize,
}

/// The frame's segments as map instances.
pub(crate) struct Assignment {
    /// Map instance per pixel (0 where nothing is integrated), at the labels' resolution.
    pub instances: LabelImage,
    pub stats: AssociationStats,
}

/// Keeps map instances and assigns frame segments to them.
#[derive(Clone, Debug, Default)]
pub(crate) struct InstanceTracker {
    pub config: TrackingConfig,
    pub instances: BTreeMap<u16, InstanceInfo>,
    next_id: u16,
}

impl InstanceTracker {
    pub fn new(config: TrackingConfig) -> Self {
        Self {
            config,
            instances: BTreeMap::new(),
            next_id: 1,
        }
    }

    /// A tracker that continues numbering after the highest of `instances`.
    pub fn with_instances(config: TrackingConfig, instances: BTreeMap<u16, InstanceInfo>) -> Self {
        let next_id = instances.keys().max().map_or(1, |&m| m.saturating_add(1));
        Self {
            config,
            instances,
            next_id,
        }
    }

    /// Takes the frame's segment ids as map instance ids (segments that already identify
    /// objects across frames): records their classes, and returns the instance image (ids
    /// without a segment entry become 0).
    pub fn identified(&mut self, labels: &LabelImage, segments: &[Segment]) -> Assignment {
        let mut listed = vec![false; u16::MAX as usize + 1];
        let mut stats = AssociationStats::default();
        for segment in segments {
            listed[segment.id as usize] = true;
            let info = self.instances.entry(segment.id).or_default();
            if info.frames_seen == 0 {
                stats.created += 1;
            } else {
                stats.matched += 1;
            }
            info.frames_seen += 1;
            if let Some(class) = segment.class_id {
                *info.class_votes.entry(class).or_default() += 1;
            }
            match segment.is_thing {
                Some(true) => info.thing_votes[0] += 1,
                Some(false) => info.thing_votes[1] += 1,
                None => {}
            }
            self.next_id = self.next_id.max(segment.id.saturating_add(1));
        }
        Assignment {
            instances: labels.map(|&l| if listed[l as usize] { l } else { 0 }),
            stats,
        }
    }

    /// Maps the frame's `segments` (ids in `labels`) to map instances, given the map's
    /// instances rendered into this camera (`rendered`, 0 = none; it may be a downscaled
    /// rendering, see [`downscaled`](super::downscaled)).
    pub fn assign(
        &mut self,
        labels: &LabelImage,
        segments: &[Segment],
        rendered: &LabelImage,
    ) -> Assignment {
        // Full-resolution segment sizes decide which segments may found instances; the IoU is
        // counted on the rendered image's grid (it may be coarser than the frame).
        let mut full_area: BTreeMap<u16, usize> = BTreeMap::new();
        for &s in labels.pixels() {
            if s != 0 {
                *full_area.entry(s).or_default() += 1;
            }
        }
        let (lw, lh) = labels.dims();
        let (rw, rh) = rendered.dims();
        let mut seg_area: BTreeMap<u16, usize> = BTreeMap::new();
        let mut inst_area: BTreeMap<u16, usize> = BTreeMap::new();
        let mut pairs: BTreeMap<(u16, u16), usize> = BTreeMap::new();
        for y in 0..rh {
            let ly = (y * lh / rh.max(1)).min(lh.saturating_sub(1));
            for x in 0..rw {
                let lx = (x * lw / rw.max(1)).min(lw.saturating_sub(1));
                let (s, r) = (*labels.get(lx, ly), *rendered.get(x, y));
                if s != 0 {
                    *seg_area.entry(s).or_default() += 1;
                }
                if r != 0 {
                    *inst_area.entry(r).or_default() += 1;
                }
                if s != 0 && r != 0 {
                    *pairs.entry((s, r)).or_default() += 1;
                }
            }
        }
        let mut candidates: Vec<(f64, u16, u16)> = pairs
            .iter()
            .map(|(&(s, r), &inter)| {
                (
                    inter as f64 / (seg_area[&s] + inst_area[&r] - inter) as f64,
                    s,
                    r,
                )
            })
            .filter(|c| c.0 >= self.config.min_iou)
            .collect();
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut to_instance: BTreeMap<u16, u16> = BTreeMap::new();
        let mut taken = std::collections::BTreeSet::new();
        let mut stats = AssociationStats::default();
        for (_, s, r) in candidates {
            if !to_instance.contains_key(&s) && !taken.contains(&r) {
                to_instance.insert(s, r);
                taken.insert(r);
                stats.matched += 1;
            }
        }
        for (&s, &area) in &full_area {
            if to_instance.contains_key(&s) {
                continue;
            }
            if area >= self.config.min_pixels && self.next_id < u16::MAX {
                to_instance.insert(s, self.next_id);
                self.next_id += 1;
                stats.created += 1;
            } else {
                stats.unassigned += 1;
            }
        }
        for segment in segments {
            if let Some(&instance) = to_instance.get(&segment.id) {
                let info = self.instances.entry(instance).or_default();
                if let Some(class) = segment.class_id {
                    *info.class_votes.entry(class).or_default() += 1;
                }
                match segment.is_thing {
                    Some(true) => info.thing_votes[0] += 1,
                    Some(false) => info.thing_votes[1] += 1,
                    None => {}
                }
            }
        }
        for instance in to_instance.values() {
            self.instances.entry(*instance).or_default().frames_seen += 1;
        }
        Assignment {
            instances: labels.map(|s| to_instance.get(s).copied().unwrap_or(0)),
            stats,
        }
    }
}
