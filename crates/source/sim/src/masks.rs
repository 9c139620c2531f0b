//! Predicted masks with the errors a lightweight instance-segmentation network makes.

use std::collections::BTreeMap;

use voxpan_core::{DepthImage, LabelImage, Segment};

use crate::{Rand, Scene};

/// The error model. `strength` scales every error (0 = perfect masks, 1 = a typical
/// lightweight CNN, 2 = a poor one); each kind can be switched off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskErrors {
    pub strength: f64,
    /// Things bleed `strength × 3..15` px onto the background behind and beside them.
    pub over_cover: bool,
    /// Boundary pixels flip to a neighbouring segment.
    pub jitter: bool,
    /// Small spurious blobs of a random thing class.
    pub fragments: bool,
    /// Two touching things predicted as one.
    pub merges: bool,
    /// Small things (< 400 px) missed.
    pub misses: bool,
}

impl MaskErrors {
    pub fn new(strength: f64) -> Self {
        Self {
            strength: strength.max(0.0),
            over_cover: true,
            jitter: true,
            fragments: true,
            merges: true,
            misses: true,
        }
    }

    /// Only over-coverage (for measuring refinement on exactly the error it targets).
    pub fn over_cover_only(strength: f64) -> Self {
        Self {
            jitter: false,
            fragments: false,
            merges: false,
            misses: false,
            ..Self::new(strength)
        }
    }

    /// The largest bleed in pixels.
    pub fn max_bleed(&self) -> usize {
        (15.0 * self.strength).round() as usize
    }

    /// A network's label image and segment list for a frame whose true instances are
    /// `truth` (ids of `scene`) and true depth `depth`. Segment ids are shuffled per frame.
    pub fn predict(
        &self,
        truth: &LabelImage,
        depth: &DepthImage,
        scene: &Scene,
        rng: &mut Rand,
    ) -> (LabelImage, Vec<Segment>) {
        let (labels, segments, _) = self.predict_traced(truth, depth, scene, rng);
        (labels, segments)
    }

    /// Like [`MaskErrors::predict`], also returning, per segment, the true instance it was
    /// predicted from (`None` for spurious fragments).
    pub fn predict_traced(
        &self,
        truth: &LabelImage,
        depth: &DepthImage,
        scene: &Scene,
        rng: &mut Rand,
    ) -> (LabelImage, Vec<Segment>, Vec<Option<u16>>) {
        let (w, h) = truth.dims();
        let s = self.strength;
        let object_of: BTreeMap<u16, usize> = scene
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| (o.instance_id, i))
            .collect();

        // Visible instances, their pixels and median depth.
        let mut pixels: BTreeMap<u16, Vec<usize>> = BTreeMap::new();
        for (i, &id) in truth.pixels().iter().enumerate() {
            if id != 0 {
                pixels.entry(id).or_default().push(i);
            }
        }
        // owner[i]: index into `segments` (class, thing, score), or usize::MAX for void.
        let mut owner = vec![usize::MAX; w * h];
        let mut segments: Vec<(u32, bool, Option<f32>)> = Vec::new();
        let mut sources: Vec<Option<u16>> = Vec::new();
        let mut things: Vec<(usize, f32, u16)> = Vec::new();
        for (&id, list) in &pixels {
            let Some(&o) = object_of.get(&id) else {
                continue;
            };
            let object = &scene.objects[o];
            if object.is_thing && self.misses && list.len() < 400 && rng.chance((0.5 * s).min(1.0))
            {
                continue; // missed: void
            }
            let seg = segments.len();
            let score = object.is_thing.then(|| rng.range(0.55, 0.99) as f32);
            segments.push((object.class_id, object.is_thing, score));
            sources.push(Some(id));
            for &i in list {
                owner[i] = seg;
            }
            if object.is_thing {
                let mut d: Vec<f32> = list.iter().map(|&i| depth.pixels()[i]).collect();
                d.sort_by(f32::total_cmp);
                things.push((seg, d[d.len() / 2], id));
            }
        }

        if self.over_cover && s > 0.0 {
            // Far things first, so that a nearer thing's bleed wins where two overlap.
            things.sort_by(|a, b| b.1.total_cmp(&a.1));
            for &(seg, median, id) in &things {
                let r = (s * rng.range(3.0, 15.0)).round() as i64;
                let list = &pixels[&id];
                let mut grown = Vec::new();
                for &i in list {
                    let (x, y) = ((i % w) as i64, (i / w) as i64);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let (nx, ny) = (x + dx, y + dy);
                            if nx < 0
                                || ny < 0
                                || nx >= w as i64
                                || ny >= h as i64
                                || dx * dx + dy * dy > r * r
                            {
                                continue;
                            }
                            let j = ny as usize * w + nx as usize;
                            // Only the background: other surfaces behind the object's middle.
                            if truth.pixels()[j] != id && depth.pixels()[j] > median {
                                grown.push(j);
                            }
                        }
                    }
                }
                for j in grown {
                    owner[j] = seg;
                }
            }
        }

        if self.jitter && s > 0.0 {
            let before = owner.clone();
            for y in 1..h.saturating_sub(1) {
                for x in 1..w.saturating_sub(1) {
                    let i = y * w + x;
                    let neighbours = [i - 1, i + 1, i - w, i + w];
                    if let Some(&n) = neighbours.iter().find(|&&n| before[n] != before[i]) {
                        if rng.chance(0.2 * s) {
                            owner[i] = before[n];
                        }
                    }
                }
            }
        }

        if self.merges && s > 0.0 && rng.chance((0.3 * s).min(1.0)) {
            // Merge the first pair of touching things found.
            let thing_seg = |seg: usize| seg != usize::MAX && segments[seg].1;
            'search: for y in 0..h {
                for x in 0..w.saturating_sub(1) {
                    let (a, b) = (owner[y * w + x], owner[y * w + x + 1]);
                    if a != b && thing_seg(a) && thing_seg(b) {
                        for o in owner.iter_mut().filter(|o| **o == b) {
                            *o = a;
                        }
                        break 'search;
                    }
                }
            }
        }

        if self.fragments && s > 0.0 {
            let count = (2.0 * s + rng.uniform()).floor() as usize;
            for _ in 0..count {
                let (cx, cy) = (rng.index(0, w) as i64, rng.index(0, h) as i64);
                let r = rng.range(4.0, 12.0) * (w as f64 / 640.0).max(0.25);
                let class = rng.index(3, 11) as u32;
                let seg = segments.len();
                segments.push((class, true, Some(rng.range(0.3, 0.6) as f32)));
                sources.push(None);
                let ri = r.ceil() as i64;
                for dy in -ri..=ri {
                    for dx in -ri..=ri {
                        let (x, y) = (cx + dx, cy + dy);
                        if x >= 0
                            && y >= 0
                            && x < w as i64
                            && y < h as i64
                            && ((dx * dx + dy * dy) as f64) <= r * r
                        {
                            owner[y as usize * w + x as usize] = seg;
                        }
                    }
                }
            }
        }

        // Per-frame random ids for the segments that survived.
        let mut present = vec![false; segments.len()];
        for &o in &owner {
            if o != usize::MAX {
                present[o] = true;
            }
        }
        let survivors: Vec<usize> = (0..segments.len()).filter(|&i| present[i]).collect();
        let mut ids: Vec<u16> = (1..=survivors.len() as u16).collect();
        for i in (1..ids.len()).rev() {
            ids.swap(i, rng.index(0, i + 1));
        }
        let mut id_of = vec![0u16; segments.len()];
        for (k, &seg) in survivors.iter().enumerate() {
            id_of[seg] = ids[k];
        }
        let labels = LabelImage::from_vec(
            w,
            h,
            owner
                .iter()
                .map(|&o| if o == usize::MAX { 0 } else { id_of[o] })
                .collect(),
        )
        .expect("w*h pixels");
        let mut list: Vec<(Segment, Option<u16>)> = survivors
            .iter()
            .map(|&seg| {
                let segment = Segment {
                    id: id_of[seg],
                    class_id: Some(segments[seg].0),
                    is_thing: Some(segments[seg].1),
                    score: segments[seg].2,
                };
                (segment, sources[seg])
            })
            .collect();
        list.sort_by_key(|(s, _)| s.id);
        let (list, sources) = list.into_iter().unzip();
        (labels, list, sources)
    }
}
