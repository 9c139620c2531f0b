//! Depth hole filling (step 1 of the pipeline, the paper's Eq. 1).
//!
//! Each invalid pixel (0, negative or non-finite) becomes the Gaussian-weighted average of the
//! valid pixels in its `k × k` neighbourhood,
//! `d(p) = Σ_q w(p - q) v(q) d(q) / Σ_q w(p - q) v(q)` with `w(x, y) = exp(-(x² + y²) / 2σ²)`
//! and `v` the validity mask; it stays 0 when no neighbour is valid. Valid pixels are never
//! changed, and filled values are not used to fill other holes (one pass, no propagation).
//!
//! The Gaussian window is separable, so the two sums are computed as a horizontal pass (only
//! where the vertical pass will read it) and a vertical pass (only at holes). The work is
//! proportional to the holes, `O(k)` per needed pixel; inside clustered holes (a dark surface,
//! out-of-range regions) neighbouring holes share the horizontal sums, so the cost per hole
//! falls from `O(k²)` towards `O(k)`.
//!
//! ```
//! use voxpan_core::Image;
//! use voxpan_fill::{fill_holes, FillParams};
//!
//! // A flat surface 2 m away with one missing pixel.
//! let mut depth = Image::filled(9, 9, 2.0f32);
//! *depth.get_mut(4, 4) = 0.0;
//! let stats = fill_holes(&mut depth, &FillParams::default());
//! assert_eq!((stats.holes, stats.filled), (1, 1));
//! assert!((depth.get(4, 4) - 2.0).abs() < 1e-6);
//! ```

use voxpan_core::{DepthImage, is_valid_depth};

/// Window size and Gaussian width.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FillParams {
    /// Side of the square window in pixels; odd (an even value is rounded up). Default 5.
    pub kernel_size: usize,
    /// Gaussian standard deviation in pixels. Default `kernel_size / 4` (1.25 for k = 5), so
    /// the window edge still weighs about a quarter of the centre along each axis.
    pub sigma: f32,
}

impl Default for FillParams {
    fn default() -> Self {
        Self::with_kernel_size(5)
    }
}

impl FillParams {
    /// A `k × k` window with the default `σ = k / 4`.
    pub fn with_kernel_size(k: usize) -> Self {
        let k = k.max(1) | 1;
        Self {
            kernel_size: k,
            sigma: k as f32 / 4.0,
        }
    }

    fn radius(&self) -> usize {
        (self.kernel_size.max(1) | 1) / 2
    }

    fn weights(&self) -> Vec<f32> {
        let r = self.radius() as isize;
        let two_sigma_sq = 2.0 * self.sigma.max(1e-3).powi(2);
        (-r..=r)
            .map(|d| (-((d * d) as f32) / two_sigma_sq).exp())
            .collect()
    }
}

/// Hole filling as configured (the `[fill]` section of voxpan's configuration file).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FillConfig {
    /// Fill holes before integration (default true).
    pub enabled: bool,
    /// Side of the square window in pixels, odd (default 5, the paper's).
    pub kernel_size: usize,
    /// Gaussian standard deviation in pixels (default: a quarter of the window).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<f32>,
}

impl Default for FillConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            kernel_size: 5,
            sigma: None,
        }
    }
}

impl FillConfig {
    /// The filter these settings describe.
    pub fn params(&self) -> FillParams {
        let mut params = FillParams::with_kernel_size(self.kernel_size);
        if let Some(sigma) = self.sigma {
            params.sigma = sigma;
        }
        params
    }

    /// Checks the window and width; the error names the key.
    pub fn validate(&self) -> Result<(), String> {
        // Wider than 63 pixels the filter bridges whole objects (and costs O(k) per hole).
        if !(1..=63).contains(&self.kernel_size) {
            return Err(format!(
                "fill.kernel_size = {}: expected 1 to 63",
                self.kernel_size
            ));
        }
        if let Some(s) = self.sigma
            && !(s.is_finite() && s > 0.0 && s <= 64.0)
        {
            return Err(format!("fill.sigma = {s}: expected a number in (0, 64]"));
        }
        Ok(())
    }
}

/// What a fill did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FillStats {
    /// Invalid pixels found.
    pub holes: usize,
    /// Of those, the ones that got a value.
    pub filled: usize,
}

/// Fills holes in place; returns how many were found and filled. For a stream of frames, keep
/// a [`HoleFiller`] instead: it reuses its buffers.
pub fn fill_holes(depth: &mut DepthImage, params: &FillParams) -> FillStats {
    HoleFiller::new(*params).fill(depth)
}

/// Hole filling with buffers kept between frames (no per-frame allocation or clearing).
pub struct HoleFiller {
    params: FillParams,
    weights: Vec<f32>,
    holes: Vec<usize>,
    /// Horizontal sums Σ w·v·d and Σ w·v, valid where `stamp == generation`.
    num: Vec<f32>,
    den: Vec<f32>,
    stamp: Vec<u32>,
    generation: u32,
}

impl HoleFiller {
    pub fn new(params: FillParams) -> Self {
        Self {
            weights: params.weights(),
            params,
            holes: Vec::new(),
            num: Vec::new(),
            den: Vec::new(),
            stamp: Vec::new(),
            generation: 0,
        }
    }

    pub fn params(&self) -> &FillParams {
        &self.params
    }

    /// Fills `depth`'s holes in place.
    pub fn fill(&mut self, depth: &mut DepthImage) -> FillStats {
        let (w, h) = depth.dims();
        self.holes.clear();
        self.holes.extend(
            depth
                .pixels()
                .iter()
                .enumerate()
                .filter(|&(_, &d)| !is_valid_depth(d))
                .map(|(i, _)| i),
        );
        let mut stats = FillStats {
            holes: self.holes.len(),
            filled: 0,
        };
        if self.holes.is_empty() {
            return stats;
        }
        if self.stamp.len() < w * h {
            self.num.resize(w * h, 0.0);
            self.den.resize(w * h, 0.0);
            self.stamp.resize(w * h, 0);
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // Wrapped: old stamps could collide with the new generation.
            self.stamp.fill(0);
            self.generation = 1;
        }
        let r = self.params.radius();
        let weights = &self.weights;
        let src = depth.pixels();

        // Horizontal sums where the vertical pass will read them: each hole's column, r rows
        // up and down. The work follows the holes, never the frame size; inside clustered holes
        // (dark surfaces, out-of-range regions) neighbours share the sums, so the cost per
        // hole falls from O(k²) towards O(k).
        for &i in &self.holes {
            let (x, y) = (i % w, i / w);
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                let j = yy * w + x;
                if self.stamp[j] == self.generation {
                    continue;
                }
                self.stamp[j] = self.generation;
                let row = &src[yy * w..(yy + 1) * w];
                let (lo, hi) = (x.saturating_sub(r), (x + r).min(w - 1));
                let (mut n, mut d) = (0f32, 0f32);
                for (q, &v) in row[lo..=hi].iter().enumerate() {
                    if is_valid_depth(v) {
                        let wt = weights[lo + q + r - x];
                        n += wt * v;
                        d += wt;
                    }
                }
                self.num[j] = n;
                self.den[j] = d;
            }
        }

        // Vertical pass at the holes.
        let out = depth.pixels_mut();
        for &i in &self.holes {
            let (x, y) = (i % w, i / w);
            let (lo, hi) = (y.saturating_sub(r), (y + r).min(h - 1));
            let (mut n, mut d) = (0f32, 0f32);
            for yy in lo..=hi {
                let wt = weights[yy + r - y];
                n += wt * self.num[yy * w + x];
                d += wt * self.den[yy * w + x];
            }
            out[i] = if d > 0.0 {
                stats.filled += 1;
                n / d
            } else {
                0.0
            };
        }
        stats
    }
}

/// The definition, evaluated directly (`O(k²)` per hole); the reference for tests and benches.
pub fn fill_holes_naive(depth: &mut DepthImage, params: &FillParams) -> FillStats {
    let (w, h) = depth.dims();
    let r = params.radius() as isize;
    let weights = params.weights();
    let src = depth.clone();
    let mut stats = FillStats::default();
    for y in 0..h {
        for x in 0..w {
            if is_valid_depth(*src.get(x, y)) {
                continue;
            }
            stats.holes += 1;
            let (mut n, mut d) = (0f32, 0f32);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                        continue;
                    }
                    let v = *src.get(xx as usize, yy as usize);
                    if is_valid_depth(v) {
                        let wt = weights[(dx + r) as usize] * weights[(dy + r) as usize];
                        n += wt * v;
                        d += wt;
                    }
                }
            }
            *depth.get_mut(x, y) = if d > 0.0 {
                stats.filled += 1;
                n / d
            } else {
                0.0
            };
        }
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn plane_holes_get_the_plane_value() {
        // A linear ramp: a symmetric window averages back to the centre value.
        let mut depth = DepthImage::from_fn(20, 10, |x, y| 1.0 + 0.01 * x as f32 + 0.02 * y as f32);
        *depth.get_mut(8, 5) = 0.0;
        let stats = fill_holes(&mut depth, &FillParams::default());
        assert_eq!(
            stats,
            FillStats {
                holes: 1,
                filled: 1
            }
        );
        assert!((depth.get(8, 5) - (1.0 + 0.08 + 0.10)).abs() < 1e-5);
    }

    #[test]
    fn isolated_large_hole_stays_zero_inside() {
        let mut depth = DepthImage::filled(30, 30, 2.0);
        for y in 5..25 {
            for x in 5..25 {
                *depth.get_mut(x, y) = f32::NAN;
            }
        }
        let stats = fill_holes(&mut depth, &FillParams::default());
        assert_eq!(*depth.get(15, 15), 0.0);
        assert_eq!(*depth.get(5, 5), 2.0);
        // With k = 5 the two outer rings of the 20×20 hole reach valid pixels.
        assert_eq!(stats.filled, 400 - 16 * 16);
    }

    #[test]
    fn all_invalid_stays_zero() {
        let mut depth = DepthImage::filled(4, 4, 0.0);
        let stats = fill_holes(&mut depth, &FillParams::default());
        assert_eq!(
            stats,
            FillStats {
                holes: 16,
                filled: 0
            }
        );
        assert!(depth.pixels().iter().all(|&d| d == 0.0));
    }

    #[test]
    fn a_reused_filler_gives_the_same_result() {
        let mut filler = HoleFiller::new(FillParams::default());
        for k in 0..3 {
            let depth = DepthImage::from_fn(30, 20, |x, y| {
                if (x * 7 + y * 3 + k) % 5 == 0 {
                    0.0
                } else {
                    1.0 + x as f32 * 0.1
                }
            });
            let (mut a, mut b) = (depth.clone(), depth);
            assert_eq!(
                filler.fill(&mut a),
                fill_holes_naive(&mut b, &FillParams::default())
            );
            for (p, q) in a.pixels().iter().zip(b.pixels()) {
                assert!((p - q).abs() <= 1e-5 * q.abs(), "{p} vs {q}");
            }
        }
    }

    proptest! {
        #[test]
        fn separable_equals_definition(
            w in 1usize..24, h in 1usize..24, k in 1usize..12, seed in any::<u64>(), hole_rate in 0.0f64..1.0
        ) {
            let mut state = seed | 1;
            let mut next = move || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state };
            let depth = DepthImage::from_fn(w, h, |_, _| {
                let u = (next() % 10_000) as f64 / 10_000.0;
                if u < hole_rate { 0.0 } else { 0.5 + (next() % 1000) as f32 / 200.0 }
            });
            let params = FillParams::with_kernel_size(k);
            let (mut fast, mut slow) = (depth.clone(), depth.clone());
            let a = fill_holes(&mut fast, &params);
            let b = fill_holes_naive(&mut slow, &params);
            prop_assert_eq!(a, b);
            for (p, q) in fast.pixels().iter().zip(slow.pixels()) {
                prop_assert!((p - q).abs() <= 1e-4 * q.abs().max(1.0), "{} vs {}", p, q);
            }
            // Valid pixels are untouched.
            for (p, q) in fast.pixels().iter().zip(depth.pixels()) {
                if is_valid_depth(*q) { prop_assert_eq!(p, q); }
            }
        }
    }
}
