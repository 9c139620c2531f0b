//! From the depths under one mask to the interval of depths it keeps.

use voxpan_kde::{BandwidthFallback, Density, Kde, KdeError};

use crate::Rule;

/// Below this density ratio to the peak the default rule stops: `exp(-9/2)`, the height of a
/// Gaussian at 3σ.
const DEFAULT_RELATIVE_CUTOFF: f64 = 0.011_108_996_538_242_306;

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
    /// `--things-only` and the segment is stuff.
    NotAThing,
    /// `--things-only` and the segment list does not say whether it is a thing.
    UnknownKind,
}

/// Chooses the interval for `depths` (valid depths, metres) under `rule`.
/// `scratch` is reused between calls.
pub(crate) fn depth_interval(
    kde: &mut Kde,
    rule: Rule,
    depths: &[f32],
    scratch: &mut Vec<f64>,
) -> Result<DepthInterval, KeptReason> {
    scratch.clear();
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
            scratch.extend(depths.iter().map(|&d| ((d - min) / range) as f64));
            (min as f64, range as f64)
        }
        Rule::Paper | Rule::Default => {
            scratch.extend(depths.iter().map(|&d| d as f64));
            (0.0, 1.0)
        }
    };
    let density = kde.estimate(scratch).map_err(|e| match e {
        KdeError::Empty => KeptReason::TooFewPixels { valid: 0, min: 1 },
        KdeError::Constant { .. } => KeptReason::ConstantDepth,
        KdeError::RangeOverflow { .. } => KeptReason::DepthOutOfRange,
    })?;
    let (left, right) = walk_from_peak(&density, rule)?;
    Ok(DepthInterval {
        low: density.x(left) * scale + offset,
        high: density.x(right) * scale + offset,
        bandwidth: density.bandwidth.value * scale,
        bandwidth_fallback: density.bandwidth.fallback,
    })
}

/// Grid indices of the interval's ends: the first point on each side of the peak whose density
/// is below the cut-off.
fn walk_from_peak(density: &Density, rule: Rule) -> Result<(usize, usize), KeptReason> {
    let y = &density.values;
    let peak = density.peak_index();
    if peak == 0 || peak + 1 == y.len() {
        return Err(KeptReason::PeakAtGridEdge);
    }
    let cutoff = match rule {
        Rule::Paper => PAPER_CUTOFF,
        Rule::Release => y[..peak].iter().cloned().fold(f64::NEG_INFINITY, f64::max) / 20.0,
        Rule::Default => DEFAULT_RELATIVE_CUTOFF * y[peak],
    };
    let left = (0..peak)
        .rev()
        .find(|&i| y[i] < cutoff)
        .ok_or(KeptReason::NoCrossing { side: Side::Near })?;
    let right = (peak..y.len())
        .find(|&i| y[i] < cutoff)
        .ok_or(KeptReason::NoCrossing { side: Side::Far })?;
    Ok((left, right))
}
