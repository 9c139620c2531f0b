//! Thing masks trimmed off the frame's stuff planes.
//!
//! A network's thing masks bleed onto what lies behind and beside the thing. Depth refinement
//! removes the bleed at other depths; bleed onto the floor a thing stands on, or onto the wall
//! it stands against, has the thing's own depths and stays. Floors, walls and ceilings are
//! planes, and the frame's stuff segments show where they are: each stuff segment is fitted
//! with planes by least median of squares (no threshold to tune: the noise scale comes from the
//! fit), and a thing's pixels that lie on one of those planes are given to that stuff segment
//! (unlike refinement, which makes pixels void: here the plane says what they are). A thing
//! nearly all of whose pixels (weighed by depth inside the mask: the core counts more than
//! the rim) lie on a stuff plane is flat on it (a picture, a rug, a door) and
//! keeps its mask.
//!
//! Planes are fitted in inverse depth: a plane in space is an affine function of the pixel
//! coordinates in 1/z, and a triangulating depth camera's noise is about constant in 1/z (its
//! depth noise grows with z²), so one noise scale holds for a plane at every distance.

use voxpan_core::{DepthImage, LabelImage, Segment, is_valid_depth, run_end, widest};

use crate::frame::ShapeMismatch;
use crate::interior::interior_depth;

/// Stuff pixels sampled on a grid of this step (the tracker's step: a plane is found from a
/// 16th of its pixels).
const STRIDE: usize = 4;
/// A plane needs this many samples to be fitted and as many inliers to be kept (512 pixels at
/// the stride: below that a wall patch says little about where the wall goes).
const MIN_SAMPLES: usize = 32;
/// Planes per stuff segment: a wall segment spans a room's corner (2), a floor segment rarely
/// more than one; 4 leaves room for steps and alcoves.
const MAX_PLANES: usize = 4;
/// Random triples tried per plane: with half the samples on the plane, all 64 miss it with
/// probability (7/8)^64 ≈ 2e-4.
const TRIALS: usize = 64;
/// Samples that score a trial plane (its median residual): more adds time, not accuracy.
const SCORED: usize = 256;
/// Inliers lie within this many robust standard deviations (Rousseeuw and Leroy's cut-off for
/// reweighted least squares after least median of squares).
const CUTOFF: f64 = 2.5;
/// A plane is at most this thick relative to its depth (tolerance / (1/z) = Δz / z to first
/// order): consumer RGB-D cameras measure planes to 1-2 % of the depth (σ), 2.5 σ of that.
/// Thicker "planes" are what a sequential fit leaves of clutter.
const MAX_THICKNESS: f64 = 0.05;
/// A plane whose scatter exceeds the frame's best-supported plane's this many times is no plane
/// (see `trim`). A triangulating camera's scatter in 1/z varies less than that across a room:
/// with σ = 1 mm + 2 mm·z², from 0.006 at 0.5 m to 0.002 far away.
const SCATTER_RATIO: f64 = 3.0;
/// A thing with this share of its weight on stuff planes lies flat on them (a picture, a rug)
/// and keeps its mask; each pixel weighs its depth inside the mask plus one, as in the default
/// rule, so a thin thing's wide bleed (its rim) does not outweigh the thing (its core).
/// Gaussian noise puts 1.2 % of a plane's own pixels beyond `CUTOFF`; a tenth leaves room for
/// jitter at the rim. Not a half: a thin thing (a chair's legs and back) with the widest bleed
/// has more bleed than thing.
const FLAT_ON_PLANE: f64 = 0.9;

#[derive(Clone, Copy, Debug)]
struct Sample {
    u: f64,
    v: f64,
    /// Inverse depth, 1/m.
    w: f64,
}

impl Sample {
    /// How far the sample lies from plane `w = abc[0]·u + abc[1]·v + abc[2]`, in 1/m.
    fn residual(&self, abc: &[f64; 3]) -> f64 {
        self.w - (abc[0] * self.u + abc[1] * self.v + abc[2])
    }
}

/// A plane found in one stuff segment: inverse depth `w = a·u + b·v + c` over pixel
/// coordinates, and how far from it a pixel still lies on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StuffPlane {
    /// The stuff segment it was fitted to.
    pub segment: u16,
    pub a: f64,
    pub b: f64,
    pub c: f64,
    /// In 1/m: `CUTOFF` times the inliers' residual standard deviation.
    pub tolerance: f64,
    /// Samples (one per `STRIDE`² pixels) within the tolerance.
    pub inliers: usize,
}

impl StuffPlane {
    fn residual(&self, u: f64, v: f64, w: f64) -> f64 {
        w - (self.a * u + self.b * v + self.c)
    }

    /// Whether pixel `(u, v)` with depth `depth` lies on the plane.
    pub fn holds(&self, u: f64, v: f64, depth: f32) -> bool {
        self.residual(u, v, 1.0 / depth as f64).abs() <= self.tolerance
    }
}

/// What trimming did to one thing segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct TrimReport {
    pub id: u16,
    /// Pixels with depth before trimming.
    pub pixels: usize,
    /// Of those, on a stuff plane.
    pub on_stuff: usize,
    /// Pixels given to the stuff segments: `on_stuff`, or 0 when the thing lies flat on a plane
    /// and keeps them.
    pub removed: usize,
}

/// Trims thing masks off stuff planes; keeps its buffers between frames.
#[derive(Default)]
pub struct PlaneTrimmer {
    planes: Vec<StuffPlane>,
    /// Thing pixels on a plane: index, thing slot, and the stuff segment whose plane it is.
    on_plane: Vec<(u32, u16, u16)>,
    thing_slot: Vec<u16>,
    /// Each pixel's distance inside its mask (see [`interior_depth`]).
    interior: Vec<u16>,
}

impl PlaneTrimmer {
    pub fn new() -> Self {
        Self::default()
    }

    /// The planes found in the last frame trimmed.
    pub fn planes(&self) -> &[StuffPlane] {
        &self.planes
    }

    /// Fits planes to the stuff segments of `labels` and trims its thing segments off them.
    /// Segments whose kind is unknown are neither. One report per thing segment (none when
    /// the frame has no stuff plane).
    pub fn trim(
        &mut self,
        depth: &DepthImage,
        labels: &mut LabelImage,
        segments: &[Segment],
    ) -> Result<Vec<TrimReport>, ShapeMismatch> {
        ShapeMismatch::check(depth, labels)?;
        // The pass over the things' pixels vectorises twice as wide with AVX2.
        Ok(widest!(self.trim_checked(depth, labels, segments)))
    }

    #[inline(always)]
    fn trim_checked(
        &mut self,
        depth: &DepthImage,
        labels: &mut LabelImage,
        segments: &[Segment],
    ) -> Vec<TrimReport> {
        let mut kinds: Vec<(u16, bool)> = segments
            .iter()
            .filter_map(|s| s.is_thing.map(|t| (s.id, t)))
            .collect();
        kinds.sort_unstable();
        kinds.dedup_by_key(|k| k.0);
        let stuff: Vec<u16> = kinds.iter().filter(|k| !k.1).map(|k| k.0).collect();
        let things: Vec<u16> = kinds.iter().filter(|k| k.1).map(|k| k.0).collect();
        self.planes.clear();
        if stuff.is_empty() || things.is_empty() {
            return Vec::new();
        }
        let (width, height) = depth.dims();

        // Samples of each stuff segment, on the grid.
        let mut samples: Vec<Vec<Sample>> = vec![Vec::new(); stuff.len()];
        for y in (0..height).step_by(STRIDE) {
            let (depth_row, label_row) = (depth.row(y), labels.row(y));
            for x in (0..width).step_by(STRIDE) {
                let (l, z) = (label_row[x], depth_row[x]);
                if l == 0 || !is_valid_depth(z) {
                    continue;
                }
                if let Ok(k) = stuff.binary_search(&l) {
                    samples[k].push(Sample {
                        u: x as f64,
                        v: y as f64,
                        w: 1.0 / z as f64,
                    });
                }
            }
        }
        for (k, mut remaining) in samples.into_iter().enumerate() {
            let mut rng = SplitMix(0x9e37_79b9_7f4a_7c15 ^ stuff[k] as u64);
            for _ in 0..MAX_PLANES {
                let Some(plane) = fit_plane(stuff[k], &mut remaining, &mut rng) else {
                    break;
                };
                self.planes.push(plane);
            }
        }
        // Sequential fits end on what is left of a segment, which may be no plane at all (a
        // curtain, a cluttered shelf): its scatter then exceeds the sensor's. The plane with
        // the most inliers shows the sensor's scatter in this frame.
        let Some(reference) = self
            .planes
            .iter()
            .max_by_key(|p| p.inliers)
            .map(|p| p.tolerance)
        else {
            return Vec::new();
        };
        self.planes
            .retain(|p| p.tolerance <= SCATTER_RATIO * reference);

        // Thing pixels on a plane, counted per thing; then the masks not flat on the planes
        // give those pixels to the plane's stuff (the first plane that holds the pixel: where
        // planes meet, either is right).
        let mut reports: Vec<TrimReport> = things
            .iter()
            .map(|&id| TrimReport {
                id,
                pixels: 0,
                on_stuff: 0,
                removed: 0,
            })
            .collect();
        // Thing index + 1 by segment id (0: not a thing): a table, not a search per pixel.
        self.thing_slot.clear();
        self.thing_slot
            .resize(things.last().map_or(0, |&id| id as usize + 1), 0);
        for (t, &id) in things.iter().enumerate() {
            self.thing_slot[id as usize] = t as u16 + 1;
        }
        self.on_plane.clear();
        interior_depth(labels, &mut self.interior);
        // Per thing: the weight of its pixels and of those on a plane, each pixel weighing its
        // depth inside the mask plus one (the rule's weights: the bleed is a rim).
        let mut weights = vec![(0u64, 0u64); things.len()];
        // Per row, each plane is `w = a·x + offset`.
        let slopes: Vec<f64> = self.planes.iter().map(|p| p.a).collect();
        let tolerances: Vec<f64> = self.planes.iter().map(|p| p.tolerance).collect();
        let mut offsets = vec![0.0; self.planes.len()];
        for y in 0..height {
            let (depth_row, label_row) = (depth.row(y), labels.row(y));
            for (offset, p) in offsets.iter_mut().zip(&self.planes) {
                *offset = p.b * y as f64 + p.c;
            }
            // A run of one label at a time: most runs are stuff or void and are skipped whole.
            let mut start = 0;
            while start < width {
                let l = label_row[start];
                let end = run_end(label_row, start);
                let slot = self.thing_slot.get(l as usize).copied().unwrap_or(0);
                if slot != 0 {
                    let report = &mut reports[slot as usize - 1];
                    let weight = &mut weights[slot as usize - 1];
                    for (x, &z) in depth_row.iter().enumerate().take(end).skip(start) {
                        if !is_valid_depth(z) {
                            continue;
                        }
                        let inside = self.interior[y * width + x] as u64 + 1;
                        weight.0 += inside;
                        report.pixels += 1;
                        let (u, w) = (x as f64, 1.0 / z as f64);
                        let hit = slopes.iter().zip(&offsets).zip(&tolerances).position(
                            |((&a, &offset), &tolerance)| (w - (a * u + offset)).abs() <= tolerance,
                        );
                        if let Some(k) = hit {
                            weight.1 += inside;
                            report.on_stuff += 1;
                            self.on_plane.push((
                                (y * width + x) as u32,
                                slot,
                                self.planes[k].segment,
                            ));
                        }
                    }
                }
                start = end;
            }
        }
        let trimmed: Vec<bool> = reports
            .iter_mut()
            .zip(&weights)
            .map(|(r, &(all, on))| {
                let trim = (on as f64) < FLAT_ON_PLANE * all as f64;
                if trim {
                    r.removed = r.on_stuff;
                }
                trim && r.on_stuff > 0
            })
            .collect();
        let pixels = labels.pixels_mut();
        for &(i, slot, stuff) in &self.on_plane {
            if trimmed[slot as usize - 1] {
                pixels[i as usize] = stuff;
            }
        }
        reports
    }
}

/// One plane of `samples` by least median of squares, refined by least squares on its inliers,
/// which are removed from `samples`. `None` when too few samples remain or lie on it.
fn fit_plane(segment: u16, samples: &mut Vec<Sample>, rng: &mut SplitMix) -> Option<StuffPlane> {
    let n = samples.len();
    if n < MIN_SAMPLES {
        return None;
    }
    let scored: Vec<Sample> = if n > SCORED {
        (0..SCORED).map(|i| samples[i * n / SCORED]).collect()
    } else {
        samples.clone()
    };
    let mut squares = vec![0.0; scored.len()];
    let middle = scored.len() / 2;
    let scale = |median: f64| 1.4826 * (1.0 + 5.0 / (scored.len() as f64 - 3.0)) * median.sqrt();
    let mut best: Option<([f64; 3], f64)> = None;
    for _ in 0..TRIALS {
        let picks = [rng.below(n), rng.below(n), rng.below(n)];
        let Some(abc) = plane_through(picks.map(|i| samples[i])) else {
            continue;
        };
        let mut below_best = 0;
        let best_median = best.map_or(f64::INFINITY, |(_, m)| m);
        for (sq, s) in squares.iter_mut().zip(&scored) {
            let r = s.residual(&abc);
            *sq = r * r;
            below_best += usize::from(*sq < best_median);
        }
        // The median beats the best one only if more than half the residuals do: most trials
        // end here, without selecting their median.
        if below_best <= middle {
            continue;
        }
        let median = *squares.select_nth_unstable_by(middle, f64::total_cmp).1;
        best = Some((abc, median));
    }
    let (abc, median) = best?;
    // Rousseeuw and Leroy's scale estimate from the median squared residual (3 parameters).
    let p = 3.0;
    let sigma = scale(median);
    let on = |s: &Sample, abc: &[f64; 3], limit: f64| s.residual(abc).abs() <= limit;
    let inliers: Vec<Sample> = samples
        .iter()
        .filter(|s| on(s, &abc, CUTOFF * sigma))
        .copied()
        .collect();
    if inliers.len() < MIN_SAMPLES {
        return None;
    }
    let abc = least_squares(&inliers)?;
    let dof = inliers.len() as f64 - p;
    let variance = inliers
        .iter()
        .map(|s| s.residual(&abc).powi(2))
        .sum::<f64>()
        / dof;
    let mean_w = inliers.iter().map(|s| s.w).sum::<f64>() / inliers.len() as f64;
    // Exact depths (rendered, or a wall facing the camera at one quantised value) scatter by
    // their float32 rounding only, which the sum may not show: never below one unit of it.
    let tolerance = CUTOFF * variance.sqrt().max(f32::EPSILON as f64 * mean_w);
    if tolerance > MAX_THICKNESS * mean_w {
        return None; // a slab this thick is clutter, not a surface the sensor measured
    }
    let before = samples.len();
    samples.retain(|s| !on(s, &abc, tolerance));
    let count = before - samples.len();
    if count < MIN_SAMPLES {
        return None;
    }
    Some(StuffPlane {
        segment,
        a: abc[0],
        b: abc[1],
        c: abc[2],
        tolerance,
        inliers: count,
    })
}

/// The plane through three samples; `None` when their pixels are (nearly) collinear.
fn plane_through(s: [Sample; 3]) -> Option<[f64; 3]> {
    let (du1, dv1, dw1) = (s[1].u - s[0].u, s[1].v - s[0].v, s[1].w - s[0].w);
    let (du2, dv2, dw2) = (s[2].u - s[0].u, s[2].v - s[0].v, s[2].w - s[0].w);
    let det = du1 * dv2 - du2 * dv1;
    // Twice the triangle's area in pixels²: below a few pixels the slope is noise.
    if det.abs() < 8.0 {
        return None;
    }
    let a = (dw1 * dv2 - dw2 * dv1) / det;
    let b = (du1 * dw2 - du2 * dw1) / det;
    Some([a, b, s[0].w - a * s[0].u - b * s[0].v])
}

/// Least-squares plane through `samples` (coordinates centred for conditioning).
fn least_squares(samples: &[Sample]) -> Option<[f64; 3]> {
    let n = samples.len() as f64;
    let (su, sv, sw) = samples
        .iter()
        .fold((0.0, 0.0, 0.0), |(u, v, w), s| (u + s.u, v + s.v, w + s.w));
    let (mu, mv, mw) = (su / n, sv / n, sw / n);
    let (mut uu, mut uv, mut vv, mut uw, mut vw) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for s in samples {
        let (u, v, w) = (s.u - mu, s.v - mv, s.w - mw);
        uu += u * u;
        uv += u * v;
        vv += v * v;
        uw += u * w;
        vw += v * w;
    }
    let det = uu * vv - uv * uv;
    if det <= 0.0 || !det.is_finite() {
        return None;
    }
    let a = (uw * vv - vw * uv) / det;
    let b = (vw * uu - uw * uv) / det;
    Some([a, b, mw - a * mu - b * mv])
}

/// A small deterministic generator (SplitMix64): the same frame trims the same way every run.
struct SplitMix(u64);

impl SplitMix {
    fn below(&mut self, n: usize) -> usize {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 / (1u64 << 53) as f64 * n as f64) as usize
    }
}
