//! The pieces of KDEpy 1.1.x's `FFTKDE(bw="ISJ")` that differ from Botev's algorithm.

use crate::brent::{BrentOptions, RootSearch, brentq};
use crate::{Grid, gaussian_pdf};

/// KDEpy's ISJ grid: `linspace(min - o, max + o, 1024)` with `o = max(0.5 × range, 6)`.
/// The absolute 6 makes the bandwidth depend on the data's unit.
pub(crate) fn isj_grid(min: f64, max: f64, points: usize) -> Grid {
    let pad = (0.5 * (max - min)).max(6.0);
    Grid::new(min - pad, max + pad, points)
}

/// KDEpy's evaluation grid: padded by `max(0.05 × range, practical support)`.
pub(crate) fn evaluation_grid(min: f64, max: f64, support: f64, points: usize) -> Grid {
    let pad = (0.05 * (max - min)).max(support);
    Grid::new(min - pad, max + pad, points)
}

/// The "practical support" of a Gaussian of std `h`: where its density falls to `1e-4`,
/// found by Brent with KDEpy's absolute `xtol = 1e-3` (in data units) plus that `1e-3`.
/// When even the peak is below `1e-4` (a bandwidth above ~4000 units) KDEpy raises; `8h` then.
pub(crate) fn practical_support(h: f64) -> f64 {
    const ATOL: f64 = 10e-5;
    const XTOL: f64 = 1e-3;
    let opts = BrentOptions {
        xtol: XTOL,
        ..BrentOptions::default()
    };
    match brentq(|x| gaussian_pdf(x, h) - ATOL, 0.0, 8.0 * h, opts) {
        RootSearch::Converged(x) | RootSearch::NotConverged(x) => x + XTOL,
        RootSearch::NoSignChange => 8.0 * h,
    }
}

/// The kernel KDEpy convolves with: the pdf on `2L + 1` grid offsets, `L = floor(support/dx)`
/// capped at one grid length.
pub(crate) fn truncated_kernel(h: f64, support: f64, grid: &Grid, out: &mut Vec<f64>) -> usize {
    let dx = grid.step();
    let half = ((support / dx).floor() as usize).min(grid.len);
    out.clear();
    out.extend((0..=2 * half).map(|j| gaussian_pdf((j as f64 - half as f64) * dx, h)));
    half
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn practical_support_matches_kdepy() {
        // KDEpy 1.1.12: gaussian.practical_support(0.05), (1.0)
        assert!((practical_support(0.05) - 0.238_616_980_454_487_12).abs() < 1e-12);
        assert!((practical_support(1.0) - 4.073_159_992_998_083).abs() < 1e-12);
    }
}
