use crate::Grid;

/// Linear binning: each value splits a unit mass between its two neighbouring grid points in
/// proportion to closeness; the result (one weight per grid point) sums to 1.
///
/// Values must lie inside the grid; a value outside is clamped to the nearest end rather than
/// indexing out of bounds. `out` is reused to avoid an allocation per call.
pub fn linear_binning(data: &[f64], grid: &Grid, out: &mut Vec<f64>) {
    // KDEpy divides by the step; matching its arithmetic keeps the compatible mode bit-close.
    let step = grid.step();
    bin_by(data, grid, out, |x| (x - grid.start) / step);
}

/// Like [`linear_binning`], multiplying by the reciprocal step (faster, not KDEpy's rounding).
pub(crate) fn linear_binning_fast(data: &[f64], grid: &Grid, out: &mut Vec<f64>) {
    let inv_step = 1.0 / grid.step();
    bin_by(data, grid, out, |x| (x - grid.start) * inv_step);
}

/// [`linear_binning_fast`] of data given as distinct values with their counts (`total` values
/// in all): the same shares, each value's weighted by its count.
pub(crate) fn linear_binning_tallied(
    tallies: impl Iterator<Item = (f64, u32)>,
    total: usize,
    grid: &Grid,
    out: &mut Vec<f64>,
) {
    let inv_step = 1.0 / grid.step();
    out.clear();
    out.resize(grid.len + 1, 0.0);
    let last = (grid.len - 1) as f64;
    for (x, count) in tallies {
        let t = ((x - grid.start) * inv_step).clamp(0.0, last);
        let whole = t as i32;
        let frac = t - whole as f64;
        let (i, count) = (whole as usize, count as f64);
        out[i] += count * (1.0 - frac);
        out[i + 1] += count * frac;
    }
    out.truncate(grid.len);
    let n = total.max(1) as f64;
    for w in out.iter_mut() {
        *w /= n;
    }
}

#[inline(always)]
fn bin_by(data: &[f64], grid: &Grid, out: &mut Vec<f64>, position: impl Fn(f64) -> f64) {
    out.clear();
    // One slot past the end takes the zero right-hand share of a value on the last point.
    out.resize(grid.len + 1, 0.0);
    let last = (grid.len - 1) as f64;
    for &x in data {
        let t = position(x).clamp(0.0, last);
        // 0 <= t < 2^31, so an i32 truncation is floor: one instruction, where `floor` is a
        // libm call on baseline x86-64 and a usize conversion a branchy sequence.
        let whole = t as i32;
        let frac = t - whole as f64;
        let i = whole as usize;
        out[i] += 1.0 - frac;
        out[i + 1] += frac;
    }
    out.truncate(grid.len);
    let n = data.len().max(1) as f64;
    for w in out.iter_mut() {
        *w /= n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_kdepy_doc_example() {
        // KDEpy's own example: data [2, 2.5, 3, 4] on the grid 0..5.
        let mut out = Vec::new();
        linear_binning(&[2.0, 2.5, 3.0, 4.0], &Grid::new(0.0, 5.0, 6), &mut out);
        let expected = [0.0, 0.0, 0.375, 0.375, 0.25, 0.0];
        for (a, b) in out.iter().zip(expected) {
            assert!((a - b).abs() < 1e-15, "{out:?}");
        }
    }

    #[test]
    fn mass_is_one_and_mean_is_preserved() {
        let data: Vec<f64> = (0..1000).map(|i| 1.0 + (i as f64 * 0.618).sin()).collect();
        let grid = Grid::new(-0.5, 2.5, 64);
        let mut w = Vec::new();
        linear_binning_fast(&data, &grid, &mut w);
        let mass: f64 = w.iter().sum();
        let mean: f64 = w.iter().enumerate().map(|(i, w)| w * grid.point(i)).sum();
        let true_mean = data.iter().sum::<f64>() / data.len() as f64;
        assert!((mass - 1.0).abs() < 1e-12);
        // Linear binning preserves the first moment exactly.
        assert!((mean - true_mean).abs() < 1e-12);
    }

    #[test]
    fn binning_tallies_equals_binning_every_value() {
        // Quantised values, as depths are: many repeats of few values, some off the grid.
        let data: Vec<f64> = (0..10_000)
            .map(|i| ((i * 7919) % 301) as f64 * 0.01 - 0.2)
            .collect();
        let grid = Grid::new(0.0, 2.9, 64);
        let mut per_value = Vec::new();
        linear_binning_fast(&data, &grid, &mut per_value);
        let mut counts = std::collections::BTreeMap::new();
        for v in &data {
            *counts.entry(v.to_bits()).or_insert(0u32) += 1;
        }
        let tallies = counts.iter().map(|(&bits, &c)| (f64::from_bits(bits), c));
        let mut tallied = Vec::new();
        linear_binning_tallied(tallies, data.len(), &grid, &mut tallied);
        assert_eq!(tallied.len(), per_value.len());
        for (a, b) in tallied.iter().zip(&per_value) {
            // Only the order of the additions differs.
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-3), "{a} vs {b}");
        }
    }

    #[test]
    fn out_of_grid_values_are_clamped_not_panicking() {
        let mut w = Vec::new();
        linear_binning(&[-10.0, 10.0, f64::NAN], &Grid::new(0.0, 1.0, 4), &mut w);
        assert_eq!(w.len(), 4);
    }
}
