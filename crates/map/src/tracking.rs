//! Instance tracking: per-frame segment ids mean nothing across frames, so each frame's
//! segments are matched to the map's instances, panoptic_mapping-style.
//!
//! The rule: render the map's instance labels into the current camera (surface voxels, with a
//! z-buffer), compute the IoU of every frame segment with every rendered instance, and accept
//! matches greedily from the highest IoU down while IoU ≥ `min_iou` (0.2), each instance at
//! most once. Unmatched segments of at least `min_pixels` (100) become new instances; smaller
//! ones are not integrated. Each instance keeps class votes; its class is the most voted.

use std::collections::BTreeMap;

use voxpan_core::{Intrinsics, LabelImage, Pose, Segment};

use crate::{Block, Layer, VOXELS_PER_BLOCK};

/// Matching thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackingConfig {
    pub min_iou: f64,
    pub min_pixels: usize,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            min_iou: 0.2,
            min_pixels: 100,
        }
    }
}

/// What the map knows about an instance.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstanceInfo {
    /// Votes per class id.
    pub class_votes: BTreeMap<u32, u32>,
    /// Votes for "thing" and "stuff".
    pub thing_votes: [u32; 2],
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

/// Keeps map instances and assigns frame segments to them.
#[derive(Clone, Debug, Default)]
pub struct InstanceTracker {
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

    /// Maps the frame's `segments` (ids in `labels`) to map instances, given the map's
    /// instances rendered into this camera (`rendered`, 0 = none; it may be a downscaled
    /// rendering, see [`downscaled`]). Returns the frame's map-instance image at the labels'
    /// resolution (0 where nothing is integrated).
    pub fn assign(
        &mut self,
        labels: &LabelImage,
        segments: &[Segment],
        rendered: &LabelImage,
    ) -> LabelImage {
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
        for (_, s, r) in candidates {
            if !to_instance.contains_key(&s) && !taken.contains(&r) {
                to_instance.insert(s, r);
                taken.insert(r);
            }
        }
        for (&s, &area) in &full_area {
            if !to_instance.contains_key(&s)
                && area >= self.config.min_pixels
                && self.next_id < u16::MAX
            {
                to_instance.insert(s, self.next_id);
                self.next_id += 1;
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
            self.instances.entry(*instance).or_default();
        }
        labels.map(|s| to_instance.get(s).copied().unwrap_or(0))
    }
}

/// Intrinsics of the same camera with `factor` times fewer pixels per axis (pixel centres stay
/// at integer coordinates). Tracking renders at a quarter resolution: IoU barely changes, the
/// rendering costs a sixteenth.
pub fn downscaled(k: &Intrinsics, factor: usize) -> Intrinsics {
    let f = factor.max(1) as f64;
    Intrinsics {
        width: k.width.div_ceil(factor.max(1)),
        height: k.height.div_ceil(factor.max(1)),
        fx: k.fx / f,
        fy: k.fy / f,
        cx: (k.cx + 0.5) / f - 0.5,
        cy: (k.cy + 0.5) / f - 0.5,
    }
}

/// The map's instances as seen from `pose`: every labelled surface voxel (|distance| < one
/// voxel) splatted over its projected footprint, nearest first.
pub fn render_instances(layer: &Layer, pose: &Pose, k: &Intrinsics) -> LabelImage {
    let (w, h) = (k.width, k.height);
    let mut depth = vec![f32::INFINITY; w * h];
    let mut out = LabelImage::filled(w, h, 0);
    let world_to_camera = pose.inverse();
    let voxel = layer.voxel_size();
    for (&index, block) in &layer.blocks {
        // Skip blocks behind the camera or outside the image (a block fits in a sphere of
        // radius block size around its centre).
        let centre = world_to_camera * Block::voxel_center(index, VOXELS_PER_BLOCK / 2, voxel);
        let reach = layer.block_size();
        if centre.z < -reach {
            continue;
        }
        if centre.z > reach {
            let (u, v) = (
                k.fx * centre.x / centre.z + k.cx,
                k.fy * centre.y / centre.z + k.cy,
            );
            let r = k.fx.max(k.fy) * reach / (centre.z - reach).max(1e-6);
            if u < -r || v < -r || u > w as f64 + r || v > h as f64 + r {
                continue;
            }
        }
        for i in block.surface_voxels() {
            let id = block.labels[i].instance();
            let p = world_to_camera * Block::voxel_center(index, i, voxel);
            let Some((u, vv)) = k.project(&p) else {
                continue;
            };
            let radius = (0.5 * k.fx * voxel / p.z).ceil().max(1.0) as i64;
            let (u, vv) = (u.round() as i64, vv.round() as i64);
            for y in (vv - radius).max(0)..(vv + radius).min(h as i64) {
                for x in (u - radius).max(0)..(u + radius).min(w as i64) {
                    let j = y as usize * w + x as usize;
                    if (p.z as f32) < depth[j] {
                        depth[j] = p.z as f32;
                        out.pixels_mut()[j] = id;
                    }
                }
            }
        }
    }
    out
}
