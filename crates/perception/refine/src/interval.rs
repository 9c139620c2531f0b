//! From the depths under one mask to the interval of depths it keeps.

use voxpan_kde::{BandwidthFallback, Density, Kde, KdeError};

use crate::Rule;

/// The default rule separates clusters where the density is below this fraction of the
/// uniform density `1 / range`: "almost no samples here". The choice hardly matters within two
/// decades (the sweep: docs/design/refinement.md, Constants).
const GAP_FRACTION: f64 = 1e-2;

/// Under the default rule a stuff mask keeps every depth cluster holding at least this share of
/// its weight (and everything between them): walls and floors are large and spread over
/// metres, so a detached group holding a fifth of the mask is part of the surface, a small one
/// is foreign (furniture in front, a door behind). Sweep: docs/design/refinement.md.
const STUFF_SHARE: f64 = 0.2;

/// Default of [`crate::RefineConfig::far_limit`] (metres). No RGB-D, time-of-flight or stereo
/// camera a robot carries measures past a few tens of metres, so a depth beyond this is a
/// renderer's sky or garbage.
pub const FAR_LIMIT_M: f64 = 100.0;

/// The paper's absolute cut-off density.
const PAPER_CUTOFF: f64 = 1e-6;

/// The depths a mask keeps, and how they were found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthInterval {
    /// Smallest kept depth (metres, inclusive).
    pub low: f64,
    /// Largest kept depth (metres, inclusive).
    pub high: f64,
    /// Kernel bandwidth in metres.
    pub bandwidth: f64,
    /// Set when the ISJ root search failed and a documented fallback bandwidth was used.
    pub bandwidth_fallback: Option<BandwidthFallback>,
}

impl DepthInterval {
    #[inline]
    pub fn contains(&self, depth: f32) -> bool {
        let d = depth as f64;
        self.low <= d && d <= self.high
    }

    /// The smallest and the largest float32 in the interval: for any float32 `d`,
    /// `contains(d)` exactly when `low <= d && d <= high`, compared without conversion.
    pub fn float32_bounds(&self) -> (f32, f32) {
        let mut low = self.low as f32;
        if (low as f64) < self.low {
            low = next_up(low);
        }
        let mut high = self.high as f32;
        if (high as f64) > self.high {
            high = -next_up(-high);
        }
        (low, high)
    }
}

/// The least float32 above `x` (`f32::next_up`, which needs Rust 1.86).
fn next_up(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        x
    } else if x == 0.0 {
        f32::from_bits(1)
    } else if x > 0.0 {
        f32::from_bits(x.to_bits() + 1)
    } else {
        f32::from_bits(x.to_bits() - 1)
    }
}

/// Which side of the peak.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    Near,
    Far,
}

/// Why a mask was kept unchanged.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "reason")]
pub enum KeptReason {
    /// Fewer valid-depth pixels than the configured minimum.
    TooFewPixels { valid: usize, min: usize },
    /// All valid depths are equal: nothing to separate.
    ConstantDepth,
    /// Depths too extreme for a density grid (only with corrupt data).
    DepthOutOfRange,
    /// The density's maximum lies on the grid's first or last point (the original code finds
    /// no peak there).
    PeakAtGridEdge,
    /// The density never falls below the cut-off on this side of the peak.
    NoCrossing { side: Side },
    /// The segment is stuff and `--things-only` is set.
    NotAThing,
    /// Every depth under the mask lies beyond the far limit (the default rule's "no surface").
    AllBeyondFarLimit,
    /// `--things-only` and the segment list does not say whether it is a thing.
    UnknownKind,
    /// Refinement is off (rule `none`).
    NoRule,
}

impl std::fmt::Display for KeptReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TooFewPixels { valid, min } => {
                write!(
                    f,
                    "too few pixels with depth ({valid}, at least {min} needed)"
                )
            }
            Self::ConstantDepth => write!(f, "every depth under the mask is the same"),
            Self::DepthOutOfRange => write!(f, "depths too extreme for a density grid"),
            Self::PeakAtGridEdge => write!(f, "the density peaks at the edge of its grid"),
            Self::NoCrossing { side } => write!(
                f,
                "the density never falls below the cut-off on the {} side",
                match side {
                    Side::Near => "near",
                    Side::Far => "far",
                }
            ),
            Self::NotAThing => write!(f, "stuff, and only things are refined"),
            Self::AllBeyondFarLimit => write!(f, "every depth lies beyond the far limit"),
            Self::UnknownKind => write!(f, "not known to be a thing, and only things are refined"),
            Self::NoRule => write!(f, "refinement is off"),
        }
    }
}

/// What the density says about one mask.
pub(crate) enum Judgement {
    Decided(DepthInterval),
    /// The default rule found several depth clusters; which to keep depends on each
    /// cluster's weight (see [`ClusterChoice`]).
    Undecided(ClusterChoice),
}

/// Chooses the interval for `depths` (valid depths, metres) under `rule`, or, under the
/// default rule with several depth clusters, says what the choice needs. `values` is a
/// buffer reused between calls by the published rules (the default rule hands the depths to
/// the KDE as they are).
pub(crate) fn depth_interval(
    kde: &mut Kde,
    rule: Rule,
    depths: &[f32],
    far_limit: f64,
    values: &mut Vec<f64>,
    is_thing: Option<bool>,
) -> Result<Judgement, KeptReason> {
    values.clear();
    if rule == Rule::None {
        return Err(KeptReason::NoRule);
    }
    // The released code normalises in float32 (NumPy on the float32 depth image); so do we,
    // so that its KDE sees the same values.
    let (offset, scale) = match rule {
        Rule::Release => {
            let (min, max) = depths
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &d| {
                    (a.min(d), b.max(d))
                });
            let range = max - min;
            if range <= 0.0 {
                return Err(KeptReason::ConstantDepth);
            }
            values.extend(depths.iter().map(|&d| ((d - min) / range) as f64));
            (min as f64, range as f64)
        }
        Rule::Paper | Rule::None => {
            values.extend(depths.iter().map(|&d| d as f64));
            (0.0, 1.0)
        }
        Rule::Default => (0.0, 1.0),
    };
    let density = if rule == Rule::Default {
        // Depths beyond the far limit are no surface: they stay out of the density (one
        // would stretch its grid over kilometres and blur every near surface into one
        // cluster) and so fall outside the kept interval.
        match kde.estimate_f32_up_to(depths, far_limit) {
            // `depths` holds valid depths: none is left only when all lie beyond.
            Err(KdeError::Empty) if !depths.is_empty() => {
                return Err(KeptReason::AllBeyondFarLimit);
            }
            density => density,
        }
    } else {
        kde.estimate(values)
    };
    let density = density.map_err(|e| match e {
        KdeError::Empty => KeptReason::TooFewPixels { valid: 0, min: 1 },
        KdeError::Constant { .. } => KeptReason::ConstantDepth,
        KdeError::RangeOverflow { .. } => KeptReason::DepthOutOfRange,
    })?;
    let (left, right) = match rule {
        Rule::Default => {
            let (min, max) = density.data_range;
            let found = clusters(&density.values, GAP_FRACTION / (max - min));
            let stuff_share = (is_thing == Some(false)).then_some(STUFF_SHARE);
            let choice = ClusterChoice::new(density, found, stuff_share, far_limit)?;
            if choice.clusters.len() > 1 {
                return Ok(Judgement::Undecided(choice));
            }
            return Ok(Judgement::Decided(choice.choose(&[1.0])?));
        }
        Rule::Paper | Rule::None => walk_from_peak(&density, |_, _| PAPER_CUTOFF)?,
        Rule::Release => walk_from_peak(&density, |y, peak| {
            y[..peak].iter().cloned().fold(f64::NEG_INFINITY, f64::max) / 20.0
        })?,
    };
    Ok(Judgement::Decided(DepthInterval {
        low: density.x(left) * scale + offset,
        high: density.x(right) * scale + offset,
        bandwidth: density.bandwidth.value * scale,
        bandwidth_fallback: density.bandwidth.fallback,
    }))
}

/// Runs of grid points where the density is at least `cutoff`: `(start, end)`, inclusive.
fn clusters(y: &[f64], cutoff: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < y.len() {
        if y[i] < cutoff {
            i += 1;
            continue;
        }
        let start = i;
        while i < y.len() && y[i] >= cutoff {
            i += 1;
        }
        out.push((start, i - 1));
    }
    out
}

/// The default rule's choice among a mask's depth clusters. The depths split into clusters
/// wherever the density falls below [`GAP_FRACTION`] of the uniform level `1 / range` (a
/// stretch of depth with almost no samples, several bandwidths wide). Each cluster has a
/// weight: the sum over its pixels of their depth inside the mask (plus one), or, without the
/// image, its share of the density. A mask's over-coverage is a band along its outline (it
/// bleeds across the silhouette onto what lies behind), so the object owns the mask's interior
/// and the bleed only its rim; weighing by interior depth picks the object even when the bleed
/// has more pixels. A thing keeps its heaviest cluster; stuff keeps everything between its
/// first and last cluster holding at least [`STUFF_SHARE`] of the weight (walls and floors are
/// large and spread; only small detached groups, like furniture in front, are foreign). The
/// bounds are, like the published rules', the first grid points below the cut-off on each side.
pub(crate) struct ClusterChoice {
    density: Density,
    /// Grid index ranges (inclusive) of the clusters, near to far.
    clusters: Vec<(usize, usize)>,
    /// Cluster owning each grid point (`u32::MAX` in gaps).
    owner: Vec<u32>,
    stuff_share: Option<f64>,
    far_limit: f64,
    /// First grid point and `1 / grid step`, for placing depths on the grid.
    x0: f64,
    per_step: f64,
}

impl ClusterChoice {
    fn new(
        density: Density,
        clusters: Vec<(usize, usize)>,
        stuff_share: Option<f64>,
        far_limit: f64,
    ) -> Result<Self, KeptReason> {
        if clusters.is_empty() || density.values.len() < 2 {
            return Err(KeptReason::PeakAtGridEdge);
        }
        let mut owner = vec![u32::MAX; density.values.len()];
        for (k, c) in clusters.iter().enumerate() {
            owner[c.0..=c.1].fill(k as u32);
        }
        let (x0, per_step) = (density.x(0), 1.0 / (density.x(1) - density.x(0)));
        Ok(Self {
            density,
            clusters,
            owner,
            stuff_share,
            far_limit,
            x0,
            per_step,
        })
    }

    pub(crate) fn len(&self) -> usize {
        self.clusters.len()
    }

    /// The cluster a depth falls in: the owner of its nearest grid point (none in a gap or
    /// beyond the far limit).
    #[inline]
    pub(crate) fn cluster_of(&self, depth: f32) -> Option<usize> {
        let d = depth as f64;
        if d > self.far_limit {
            return None;
        }
        // `as` saturates: depths left of the grid land on its first point.
        let i = (((d - self.x0) * self.per_step + 0.5) as usize).min(self.owner.len() - 1);
        let k = self.owner[i];
        (k != u32::MAX).then_some(k as usize)
    }

    /// Each cluster's share of the density: its share of the pixels, all weighing the same.
    pub(crate) fn density_weights(&self) -> Vec<f64> {
        let y = &self.density.values;
        self.clusters
            .iter()
            .map(|c| y[c.0..=c.1].iter().sum())
            .collect()
    }

    /// The interval kept, given each cluster's weight.
    pub(crate) fn choose(&self, weight: &[f64]) -> Result<DepthInterval, KeptReason> {
        let n = self.clusters.len();
        let total: f64 = weight.iter().sum();
        let (first, last) = match self.stuff_share {
            None => (0..n)
                .max_by(|&a, &b| weight[a].total_cmp(&weight[b]))
                .map(|k| (k, k)),
            Some(share) => {
                let heavy = |k: &usize| weight[*k] >= share * total;
                (0..n).find(heavy).zip((0..n).rfind(heavy))
            }
        }
        .ok_or(KeptReason::PeakAtGridEdge)?;
        let end = self.density.values.len() - 1;
        let (left, right) = (
            self.clusters[first].0.saturating_sub(1),
            (self.clusters[last].1 + 1).min(end),
        );
        Ok(DepthInterval {
            low: self.density.x(left),
            high: self.density.x(right),
            bandwidth: self.density.bandwidth.value,
            bandwidth_fallback: self.density.bandwidth.fallback,
        })
    }
}

/// Densities within this fraction of the maximum count as the maximum when locating the peak.
/// Both published rules take SciPy's `find_peaks(y, height=max(y))[0]`, which makes a run of
/// equal values one peak at its middle. The released rule meets such ties: a mask's nearest
/// (or farthest) depth normalises to 0 (or 1), exactly halfway between two points of KDEpy's
/// grid, and a narrow kernel gives both the same density. SciPy's direct convolution rounds
/// them equal; our FFT leaves them an ulp apart (the golden comb mask), which moved the peak
/// one point right and so raised the cut-off twentyfold. 1e-12 is thousands of ulps, yet far
/// below the difference between neighbours at any peak the grid resolves.
const PEAK_TIE: f64 = 1e-12;

/// The peak the original code walks from: SciPy's first `find_peaks` peak at the maximum
/// height. That is the first run of (tied) maximal values that touches neither end of the grid
/// (SciPy finds no peak on an edge), taken at its middle, the left of the two middles on an
/// even run (SciPy's `(left + right) // 2`).
fn original_peak(y: &[f64]) -> Option<usize> {
    let max = y.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let at_max = |i: usize| y[i] >= max - PEAK_TIE * max.abs();
    let mut i = 0;
    while i < y.len() {
        if !at_max(i) {
            i += 1;
            continue;
        }
        let start = i;
        while i + 1 < y.len() && at_max(i + 1) {
            i += 1;
        }
        if start > 0 && i + 1 < y.len() {
            return Some((start + i) / 2);
        }
        i += 1;
    }
    None
}

/// Grid indices of the interval's ends: the first point on each side of the peak whose density
/// is below the cut-off.
/// `cutoff(density, peak)` gives the rule's cut-off density.
fn walk_from_peak(
    density: &Density,
    cutoff: impl Fn(&[f64], usize) -> f64,
) -> Result<(usize, usize), KeptReason> {
    let y = &density.values;
    let peak = original_peak(y).ok_or(KeptReason::PeakAtGridEdge)?;
    let cutoff = cutoff(y, peak);
    let left = (0..peak)
        .rev()
        .find(|&i| y[i] < cutoff)
        .ok_or(KeptReason::NoCrossing { side: Side::Near })?;
    let right = (peak..y.len())
        .find(|&i| y[i] < cutoff)
        .ok_or(KeptReason::NoCrossing { side: Side::Far })?;
    Ok((left, right))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn next_up_steps_to_the_adjacent_float_at_the_special_values() {
        let tiny = f32::from_bits(1);
        assert_eq!(next_up(f32::NEG_INFINITY), f32::MIN);
        assert_eq!(next_up(f32::MIN), f32::from_bits(f32::MIN.to_bits() - 1));
        assert_eq!(next_up(-tiny), -0.0);
        assert_eq!(next_up(-0.0), tiny);
        assert_eq!(next_up(0.0), tiny);
        assert_eq!(next_up(1.0), 1.0 + f32::EPSILON);
        assert_eq!(next_up(f32::MAX), f32::INFINITY);
        assert_eq!(next_up(f32::INFINITY), f32::INFINITY);
        assert!(next_up(f32::NAN).is_nan());
    }

    proptest! {
        /// The float32 bounds admit exactly the float32 depths the f64 interval contains,
        /// probed at the bounds' neighbours, where rounding could go either way.
        #[test]
        fn float32_bounds_agree_with_the_interval(
            low in -1e3f64..1e3,
            width in 0.0f64..10.0,
            step in prop::sample::select(vec![0.0, 1e-12, 1e-7, 1e-3]),
        ) {
            let interval = DepthInterval {
                low,
                high: low + width + step,
                bandwidth: 1.0,
                bandwidth_fallback: None,
            };
            let (lo, hi) = interval.float32_bounds();
            for edge in [interval.low, interval.high] {
                let near = edge as f32;
                let down = |x: f32| -next_up(-x);
                for d in [down(down(near)), down(near), near, next_up(near), next_up(next_up(near))] {
                    prop_assert_eq!(interval.contains(d), lo <= d && d <= hi, "depth {}", d);
                }
            }
        }
    }

    #[test]
    fn the_peak_is_scipys_first_maximal_run_at_its_middle() {
        // A single maximum, runs of two and three (SciPy takes the left middle of an even run).
        assert_eq!(original_peak(&[0.0, 1.0, 3.0, 1.0, 0.0]), Some(2));
        assert_eq!(original_peak(&[0.0, 3.0, 3.0, 1.0, 3.0, 0.0]), Some(1));
        assert_eq!(original_peak(&[0.0, 3.0, 3.0, 3.0, 0.0]), Some(2));
        // Values an ulp apart are a tie, as SciPy's rounding makes them on the comb mask.
        let above = f64::from_bits(413.789_500_988_410_4_f64.to_bits() + 1);
        assert_eq!(
            original_peak(&[0.0, 413.789_500_988_410_4, above, 6.8]),
            Some(1)
        );
        // A run on an edge is no peak; a later one is.
        assert_eq!(original_peak(&[3.0, 3.0, 1.0, 3.0, 0.0]), Some(3));
        assert_eq!(original_peak(&[3.0, 1.0, 2.0, 3.0]), None);
    }
}
