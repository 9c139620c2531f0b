//! The Improved Sheather-Jones plug-in: Botev's fixed-point equation `t = ξ γ^[ℓ](t)` with
//! `ℓ = 7`, solved on the DCT of the binned data.

use std::f64::consts::PI;
use std::sync::Arc;

use voxpan_core::widest;

use rustdct::{DctPlanner, TransformType2And3};

use crate::bandwidth::BandwidthFallback;
use crate::brent::{BrentOptions, RootSearch, brentq, minimise_golden};

/// Points of the ISJ grid: Botev's default is 2^14; KDEpy (and the original code) use 2^10,
/// which resolves a bandwidth of a thousandth of the grid and keeps a mask's cost in microseconds.
pub const GRID_POINTS: usize = 1024;

/// `ℓ`: the number of plug-in stages is `ℓ - 1`; Botev recommends 7.
const ELL: usize = 7;

/// A term is dropped once the whole remaining tail is below this fraction of the partial sum.
const TAIL_RELATIVE: f64 = 1e-17;

/// The slots a tally of distinct float32 values starts with at most (32 kB with the counts,
/// within a core's L1 and L2): room for 4,096 distinct values at half load, more than the
/// depths of a 5 m range hold on a sensor of half-float or millimetre steps (~3,400 and 5,000
/// at most; a mask spans a fraction of the range). Sizing the table for every value of a large
/// mask being distinct (2 MB for 100 k pixels) spread the few it held over cache lines all
/// over the table. Tallies with more values grow it.
const TALLY_SLOTS: usize = 8192;

/// The data-dependent parts of Botev's fixed-point function.
pub(crate) struct FixedPoint {
    /// `N`: Botev uses the number of distinct observations.
    n: f64,
    /// `k²` for `k = 1 .. M-1`.
    k_sq: Vec<f64>,
    /// `k_sq` holds the squares 1, 4, 9, ... (always, except in the MATLAB check cases, whose
    /// "k²" are 1, 2, 3, ...): then `exp(-k² c)` is computed by recurrence.
    consecutive_squares: bool,
    /// `k^(2s) a_k²` for `s = 2 ..= ℓ` (index `s - 2`), `a_k` the DCT coefficients scaled as
    /// SciPy's unnormalised DCT-II.
    weighted: Vec<Vec<f64>>,
    /// `max a_k²`, for bounding the tail of the sums.
    a_sq_max: f64,
}

impl FixedPoint {
    /// `a`: SciPy-scaled DCT-II of the binned data (`a[0]` is unused).
    pub(crate) fn new(a: &[f64], n_unique: usize) -> Self {
        let k_sq: Vec<f64> = (1..a.len()).map(|k| (k * k) as f64).collect();
        let a_sq: Vec<f64> = a[1..].iter().map(|v| v * v).collect();
        let weighted = (2..=ELL)
            .map(|s| {
                k_sq.iter()
                    .zip(&a_sq)
                    .map(|(&k2, &a2)| k2.powi(s as i32) * a2)
                    .collect()
            })
            .collect();
        let a_sq_max = a_sq.iter().copied().fold(0.0, f64::max);
        Self {
            n: n_unique as f64,
            k_sq,
            consecutive_squares: true,
            weighted,
            a_sq_max,
        }
    }

    /// `‖f^(s)‖²` of the density diffused for `time`: `½ π^(2s) Σ k^(2s) a_k² exp(-k² π² time)`.
    ///
    /// Past `k = 2 sqrt(s / (π² time))` the terms fall faster than a geometric series of ratio
    /// `exp(-2s/k)`, so the tail is at most `max a² k^(2s) exp(-k² π² time) · k/(2s)`; the sum
    /// stops once that bound is below [`TAIL_RELATIVE`] of what has been summed. This skips most
    /// of the grid at the times the root search visits.
    fn functional(&self, s: usize, time: f64) -> f64 {
        // Its four f64 lanes are one AVX2 register.
        widest!(self.functional_with(s, time))
    }

    #[inline(always)]
    fn functional_with(&self, s: usize, time: f64) -> f64 {
        let c = PI * PI * time;
        let weights = &self.weighted[s - 2];
        let s_f = s as f64;
        let k_tail = if c > 0.0 {
            2.0 * (s_f / c).sqrt()
        } else {
            f64::INFINITY
        };
        let scale = 0.5 * PI.powi(2 * s as i32);
        if !self.consecutive_squares {
            let mut sum = 0.0;
            for (i, (&w, &k2)) in weights.iter().zip(&self.k_sq).enumerate() {
                sum += w * (-k2 * c).exp();
                let k = (i + 1) as f64;
                if i % 8 == 7 && k >= k_tail && self.tail_is_negligible(s_f, k, k2, c, sum) {
                    break;
                }
            }
            return scale * sum;
        }
        // exp(-k² c) by recurrence, two products a term instead of an `exp` (the sums are most
        // of the KDE's time), in four independent lanes k, k + 1, k + 2, k + 3, so that the
        // products' latencies overlap: from k to k + 4 the exponent drops by (8k + 16) c, and
        // that step's factor by 32 c. The relative error grows by about an ulp a step (~1e-13
        // over a 1024-point grid; tested), far below what the root search resolves.
        let exp_of = |exponent: f64| (-exponent * c).exp();
        let mut term: [f64; 4] = std::array::from_fn(|j| exp_of(((j + 1) * (j + 1)) as f64));
        let mut step: [f64; 4] = std::array::from_fn(|j| exp_of((8 * (j + 1) + 16) as f64));
        let drop = exp_of(32.0);
        let mut sums = [0.0; 4];
        let mut chunks = weights.chunks_exact(4);
        for (n, chunk) in chunks.by_ref().enumerate() {
            for j in 0..4 {
                sums[j] += chunk[j] * term[j];
                term[j] *= step[j];
                step[j] *= drop;
            }
            // Every eighth term (k a multiple of 8), once past k_tail.
            let k = (4 * n + 4) as f64;
            if n % 2 == 1 && k >= k_tail {
                let sum: f64 = sums.iter().sum();
                if self.tail_is_negligible(s_f, k, k * k, c, sum) {
                    return scale * sum;
                }
            }
        }
        for (j, &w) in chunks.remainder().iter().enumerate() {
            sums[j] += w * term[j];
        }
        scale * sums.iter().sum::<f64>()
    }

    /// Whether the terms after `k` (whose square is `k2`) add less than [`TAIL_RELATIVE`] of
    /// `sum`, by the bound in [`Self::functional`]'s description.
    fn tail_is_negligible(&self, s: f64, k: f64, k2: f64, c: f64, sum: f64) -> bool {
        let log_bound = self.a_sq_max.ln() + s * k2.ln() - k2 * c + (k / (2.0 * s)).ln();
        log_bound < (TAIL_RELATIVE * sum).ln()
    }

    /// `t - ξ γ^[ℓ](t)`; its root is the optimal squared bandwidth in grid units.
    pub(crate) fn residual(&self, t: f64) -> f64 {
        let mut f = self.functional(ELL, t);
        if f <= 0.0 {
            // A norm cannot vanish unless every coefficient did; KDEpy returns -1 here too.
            return -1.0;
        }
        for s in (2..ELL).rev() {
            let odd_product: f64 = (1..=s).map(|j| (2 * j - 1) as f64).product();
            let k0 = odd_product / (2.0 * PI).sqrt();
            let constant = (1.0 + 0.5_f64.powf(s as f64 + 0.5)) / 3.0;
            let time = (2.0 * constant * k0 / (self.n * f)).powf(2.0 / (3.0 + 2.0 * s as f64));
            f = self.functional(s, time);
        }
        t - (2.0 * self.n * PI.sqrt() * f).powf(-0.4)
    }
}

/// How the root of the fixed-point equation is searched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RootStrategy {
    /// Botev's `kde.m`: brackets `[0, tol]` from `tol = 1e-12 + 0.01 (N - 50)/1000`, doubling up
    /// to 0.1; then the minimiser of `|residual|` on `[0, 0.1]`.
    Botev,
    /// KDEpy 1.1.x with the released code's patch: `tol` starts at `1e-11 + ...`, doubles while
    /// below 1; then `t* = 0.01`.
    KdepyReleased,
}

/// Solves for `t*`; the fallback says when no root was found.
pub(crate) fn solve_t_star(
    fp: &FixedPoint,
    strategy: RootStrategy,
) -> (f64, Option<BandwidthFallback>) {
    let n = fp.n.clamp(50.0, 1050.0);
    let residual = |t: f64| fp.residual(t);
    match strategy {
        RootStrategy::Botev => {
            let mut tol = 1e-12 + 0.01 * (n - 50.0) / 1000.0;
            loop {
                if let RootSearch::Converged(t) =
                    brentq(residual, 0.0, tol, BrentOptions::default())
                    && t > 0.0
                {
                    return (t, None);
                }
                tol = (2.0 * tol).min(0.1);
                if tol >= 0.1 {
                    let t = minimise_golden(|t| residual(t).abs(), 0.0, 0.1, 1e-12);
                    return (t, Some(BandwidthFallback::MinimisedResidual));
                }
            }
        }
        RootStrategy::KdepyReleased => {
            let mut tol = 10e-12 + 0.01 * (n - 50.0) / 1000.0;
            loop {
                if let RootSearch::Converged(t) =
                    brentq(residual, 0.0, tol, BrentOptions::default())
                    && t > 0.0
                {
                    return (t, None);
                }
                // KDEpy retries the same bracket forever when Brent stops unconverged or at
                // t = 0; widening it instead is the only change from the original.
                tol *= 2.0;
                if tol >= 1.0 {
                    return (0.01, Some(BandwidthFallback::ReleasedDefault));
                }
            }
        }
    }
}

/// A reusable DCT-II plan producing SciPy-scaled coefficients.
pub(crate) struct Dct {
    plan: Arc<dyn TransformType2And3<f64>>,
    scratch: Vec<f64>,
}

impl Dct {
    pub(crate) fn new(len: usize) -> Self {
        let plan = DctPlanner::new().plan_dct2(len);
        let scratch = vec![0.0; plan.get_scratch_len()];
        Self { plan, scratch }
    }

    /// In place: `x_k ← 2 Σ_j x_j cos(π k (2j+1) / 2M)` (rustdct's DCT-II is half SciPy's).
    pub(crate) fn forward(&mut self, buffer: &mut [f64]) {
        self.plan
            .process_dct2_with_scratch(buffer, &mut self.scratch);
        for v in buffer.iter_mut() {
            *v *= 2.0;
        }
    }
}

/// Number of distinct values (Botev's `N`).
///
/// Depths are float32 at heart; when every value is exactly a float32, the count runs on their
/// 32-bit patterns in an open-addressing hash set (linear time; a sort of 50 000 depths costs
/// several times more). Otherwise it sorts.
/// `all_f32` says every value is exactly a float32 (the caller already looked).
pub(crate) fn count_unique(data: &[f64], all_f32: bool, scratch: &mut UniqueScratch) -> usize {
    if data.is_empty() {
        return 0;
    }
    if all_f32 {
        let distinct = scratch.tally_f32(data);
        scratch.reset();
        return distinct;
    }
    scratch.values.clear();
    scratch.values.extend(data.iter().map(|&v| v + 0.0));
    scratch.values.sort_unstable_by(f64::total_cmp);
    1 + scratch.values.windows(2).filter(|w| w[0] != w[1]).count()
}

/// Buffers for [`count_unique`] and for tallies of distinct float32 values.
///
/// The table is kept between calls and only its used slots are emptied afterwards: clearing
/// a table sized for a large mask cost as much as counting a small one.
#[derive(Default)]
pub(crate) struct UniqueScratch {
    /// Open-addressing table of float32 bit patterns.
    table: Vec<u32>,
    /// Occurrences of each slot's value.
    counts: Vec<u32>,
    /// Slots in use, in order of first occurrence.
    occupied: Vec<u32>,
    values: Vec<f64>,
}

impl UniqueScratch {
    /// `u32::MAX` is a NaN pattern, which finite data never has: it marks an empty slot.
    const EMPTY: u32 = u32::MAX;

    /// Counts the occurrences of each distinct value of `data` (every value exactly a float32,
    /// all finite); returns how many distinct values there are. Read them with
    /// [`tallies`](Self::tallies), then [`reset`](Self::reset).
    pub(crate) fn tally_f32(&mut self, data: &[f64]) -> usize {
        self.tally_runs(data, |v| (v as f32 + 0.0).to_bits())
    }

    /// [`tally_f32`](Self::tally_f32) of the finite values of float32 data.
    pub(crate) fn tally_f32_finite(&mut self, data: &[f32]) -> usize {
        // Non-finite values become the empty slot's pattern, a run never added.
        let key = |v: f32| {
            if v.is_finite() {
                (v + 0.0).to_bits()
            } else {
                Self::EMPTY
            }
        };
        widest!(self.tally_runs(data, key))
    }

    /// Tallies the float32 bit patterns `key` gives `data`'s values (`+ 0.0` maps -0.0 to
    /// 0.0, so that equal values have equal patterns; [`Self::EMPTY`] is skipped).
    ///
    /// Neighbouring pixels often hold the same depth (two in three on flat's frames, whose
    /// depths are half-float steps; sensors' millimetres repeat too): a run of one value is
    /// added to its slot at once, entering the table at its first value, so the order of first
    /// occurrence is kept. Where runs start is found 64 values at a time, as a bit mask
    /// computed without branches, and the runs are visited by the mask's set bits: testing
    /// every value for the end of its run mispredicted about once per run.
    #[inline(always)]
    fn tally_runs<T: Copy>(&mut self, data: &[T], key: impl Fn(T) -> u32) -> usize {
        self.reserve_for(data.len());
        const CHUNK: usize = 64;
        let (mut run_key, mut run_start) = (Self::EMPTY, 0);
        for (c, chunk) in data.chunks(CHUNK).enumerate() {
            let base = c * CHUNK;
            let mut keys = [0u32; CHUNK + 1];
            keys[0] = run_key;
            for (k, &v) in keys[1..].iter_mut().zip(chunk) {
                *k = key(v);
            }
            let mut starts = 0u64;
            for j in 0..chunk.len() {
                starts |= ((keys[j + 1] != keys[j]) as u64) << j;
            }
            while starts != 0 {
                let j = starts.trailing_zeros() as usize;
                starts &= starts - 1;
                if run_key != Self::EMPTY {
                    self.add(run_key, (base + j - run_start) as u32);
                }
                (run_key, run_start) = (keys[j + 1], base + j);
            }
        }
        if run_key != Self::EMPTY {
            self.add(run_key, (data.len() - run_start) as u32);
        }
        self.occupied.len()
    }

    /// Makes the table large enough for `len` distinct values.
    fn reserve_for(&mut self, len: usize) {
        // At most half full: room for `len` distinct values, up to `TALLY_SLOTS`; more grow
        // the table as they come (see `add`).
        let capacity = (2 * len).next_power_of_two().clamp(16, TALLY_SLOTS);
        if self.table.len() < capacity {
            self.table = vec![Self::EMPTY; capacity];
            self.counts = vec![0; capacity];
        }
    }

    /// The slot of `key`: where it is, or the empty slot where it goes.
    #[inline(always)]
    fn slot_of(table: &[u32], key: u32) -> usize {
        let mask = table.len() - 1;
        let shift = 32 - table.len().trailing_zeros();
        // Fibonacci hashing spreads the near-consecutive patterns of nearby depths.
        let mut i = (key.wrapping_mul(0x9E37_79B1) >> shift) as usize;
        while table[i] != key && table[i] != Self::EMPTY {
            i = (i + 1) & mask;
        }
        i
    }

    /// Doubles the table, keeping every value's count and the order of first occurrence.
    #[cold]
    fn grow(&mut self) {
        let capacity = 2 * self.table.len();
        let mut table = vec![Self::EMPTY; capacity];
        let mut counts = vec![0; capacity];
        for slot in &mut self.occupied {
            let key = self.table[*slot as usize];
            let i = Self::slot_of(&table, key);
            table[i] = key;
            counts[i] = self.counts[*slot as usize];
            *slot = i as u32;
        }
        self.table = table;
        self.counts = counts;
    }

    /// Adds `n` occurrences of `key`.
    #[inline(always)]
    fn add(&mut self, key: u32, n: u32) {
        let mut i = Self::slot_of(&self.table, key);
        if self.table[i] == Self::EMPTY {
            // Kept at most half full.
            if 2 * (self.occupied.len() + 1) > self.table.len() {
                self.grow();
                i = Self::slot_of(&self.table, key);
            }
            self.table[i] = key;
            self.occupied.push(i as u32);
        }
        self.counts[i] += n;
    }

    /// The distinct values of the last [`tally_f32`](Self::tally_f32) with their counts, in
    /// order of first occurrence.
    pub(crate) fn tallies(&self) -> impl Iterator<Item = (f64, u32)> + '_ {
        self.occupied.iter().map(|&i| {
            let i = i as usize;
            (f32::from_bits(self.table[i]) as f64, self.counts[i])
        })
    }

    /// Empties the slots the last tally used.
    pub(crate) fn reset(&mut self) {
        for &i in &self.occupied {
            self.table[i as usize] = Self::EMPTY;
            self.counts[i as usize] = 0;
        }
        self.occupied.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Botev's MATLAB check cases (KDEpy's doctests; values from KDEpy 1.1.12, float128): with
    /// `I = 1..50` (as k²) and `a² = 1..50`.
    fn matlab_case(len: usize) -> FixedPoint {
        let ks: Vec<f64> = (1..=len).map(|k| k as f64).collect();
        FixedPoint {
            n: 0.0,
            k_sq: ks.clone(),
            consecutive_squares: false,
            weighted: (2..=ELL)
                .map(|s| ks.iter().map(|&k| k.powi(s as i32) * k).collect())
                .collect(),
            a_sq_max: len as f64,
        }
    }

    #[test]
    fn fixed_point_matches_matlab_check_values() {
        let mut fp = matlab_case(50);
        fp.n = 50.0;
        assert!((fp.residual(0.01) - 0.009_907_622_029_396_762).abs() < 1e-12);
        let mut fp = matlab_case(10);
        fp.n = 25.0;
        assert!((fp.residual(0.07) - 0.068_342_291_525_717_48).abs() < 1e-12);
    }

    #[test]
    fn the_exp_recurrence_matches_direct_exponentials() {
        // Coefficients of a bimodal sample on a 1024-point grid, at the times the root search
        // visits: every functional agrees with the term-by-term `exp` to 1e-12 relative.
        let a: Vec<f64> = (0..1024)
            .map(|k| {
                let k = k as f64;
                (-(k * 0.01).powi(2)).exp() * (1.0 + (k * 0.37).cos()) / (1.0 + k)
            })
            .collect();
        let fast = FixedPoint::new(&a, 500);
        let direct = FixedPoint {
            consecutive_squares: false,
            ..FixedPoint::new(&a, 500)
        };
        for time in [1e-7, 1e-5, 1e-3, 1e-2, 0.1] {
            for s in 2..=ELL {
                let (f, d) = (fast.functional(s, time), direct.functional(s, time));
                assert!(((f - d) / d).abs() < 1e-12, "s {s} time {time}: {f} vs {d}");
            }
        }
    }

    #[test]
    fn root_matches_matlab_check_value() {
        let mut fp = matlab_case(50);
        fp.n = 50.0;
        let (t, fallback) = solve_t_star(&fp, RootStrategy::KdepyReleased);
        assert!(fallback.is_none());
        assert!((t - 9.237_610_787_616_029e-5).abs() < 1e-12, "{t}");
    }

    #[test]
    fn dct_is_scipy_scaled() {
        let mut dct = Dct::new(4);
        let mut x = [1.0, 2.0, 3.0, 4.0];
        dct.forward(&mut x);
        // scipy.fftpack.dct([1, 2, 3, 4]) = [20, -6.3086..., 0, -0.4483...]
        assert!((x[0] - 20.0).abs() < 1e-12);
        assert!((x[1] + 6.308_644_059_797_899).abs() < 1e-12);
        assert!(x[2].abs() < 1e-12);
        assert!((x[3] + 0.448_341_529_167_965_1).abs() < 1e-12);
    }

    #[test]
    fn unique_count() {
        let mut s = UniqueScratch::default();
        assert_eq!(count_unique(&[1.0, 2.0, 1.0, 3.0, 2.0], true, &mut s), 3);
        assert_eq!(count_unique(&[], true, &mut s), 0);
        assert_eq!(count_unique(&[0.0, -0.0, 0.1], false, &mut s), 2);
        // The hashing path (float32-exact values) agrees with a plain count.
        let data: Vec<f64> = (0..5000)
            .map(|i| ((i * 7919) % 1237) as f32 as f64 * 0.25 - 100.0)
            .collect();
        let mut sorted = data.clone();
        sorted.sort_by(f64::total_cmp);
        sorted.dedup();
        assert_eq!(count_unique(&data, true, &mut s), sorted.len());
        // ... and the general path for values that are not float32.
        let data: Vec<f64> = data.iter().map(|v| v + 1e-12).collect();
        assert_eq!(count_unique(&data, false, &mut s), sorted.len());
    }

    #[test]
    fn tallies_count_every_value_and_reset_between_calls() {
        let mut s = UniqueScratch::default();
        // A large call first leaves a large table behind; later small calls reuse it.
        let big: Vec<f64> = (0..20_000)
            .map(|i| (i % 997) as f32 as f64 * 0.01)
            .collect();
        assert_eq!(s.tally_f32(&big), 997);
        assert_eq!(
            s.tallies().map(|(_, c)| c as usize).sum::<usize>(),
            big.len()
        );
        s.reset();
        let small = [1.5, -0.0, 2.25, 1.5, 0.0, 1.5];
        assert_eq!(s.tally_f32(&small), 3);
        let tallies: Vec<(f64, u32)> = s.tallies().collect();
        // First-occurrence order; -0.0 and 0.0 are one value.
        assert_eq!(tallies, [(1.5, 3), (0.0, 2), (2.25, 1)]);
        s.reset();
        assert_eq!(s.tally_f32(&[]), 0);
        assert!(s.table.iter().all(|&k| k == UniqueScratch::EMPTY));
        assert!(s.counts.iter().all(|&c| c == 0));
    }

    #[test]
    fn float32_tallies_skip_non_finite_values_and_count_runs_across_chunks() {
        // Runs of 1 to 150 values (across the 64-value chunks), non-finite values inside and
        // between runs (skipped), -0.0 beside 0.0, a run at the very end: counts and order as
        // a plain first-occurrence count of the finite values.
        let mut data: Vec<f32> = Vec::new();
        for i in 0..400u32 {
            let value = match i % 7 {
                0 => f32::NAN,
                1 => -0.0,
                2 => 0.0,
                3 if i % 3 == 0 => f32::INFINITY,
                _ => (i % 23) as f32 * 0.5,
            };
            data.extend(std::iter::repeat_n(value, 1 + (i as usize * 37) % 150));
        }
        let mut expected: Vec<(f64, u32)> = Vec::new();
        for v in data.iter().filter(|v| v.is_finite()) {
            let v = (v + 0.0) as f64;
            match expected.iter_mut().find(|(x, _)| *x == v) {
                Some((_, n)) => *n += 1,
                None => expected.push((v, 1)),
            }
        }
        let mut s = UniqueScratch::default();
        assert_eq!(s.tally_f32_finite(&data), expected.len());
        assert_eq!(s.tallies().collect::<Vec<_>>(), expected);
        s.reset();
        assert_eq!(s.tally_f32_finite(&[f32::NAN, f32::INFINITY]), 0);
        assert_eq!(s.tally_f32_finite(&[]), 0);
    }

    #[test]
    fn tallies_of_runs_keep_first_occurrence_order() {
        // 6,000 distinct values in runs of 1-4 repeats, each value coming back later: counts
        // and order as a plain first-occurrence count, through the table's growth.
        let data: Vec<f64> = (0..30_000)
            .map(|i: u64| (((i / (1 + i % 4)) * 7919 % 6000) as f32 * 0.001) as f64)
            .collect();
        let mut expected: Vec<(f64, u32)> = Vec::new();
        for &v in &data {
            match expected.iter_mut().find(|(x, _)| *x == v) {
                Some((_, n)) => *n += 1,
                None => expected.push((v, 1)),
            }
        }
        let mut s = UniqueScratch::default();
        assert_eq!(s.tally_f32(&data), expected.len());
        assert!(expected.len() > 5000);
        let tallies: Vec<(f64, u32)> = s.tallies().collect();
        assert!(tallies == expected, "tallies differ from a plain count");
        assert!(s.table.len() > TALLY_SLOTS, "the table did not grow");
        s.reset();
        assert!(s.table.iter().all(|&k| k == UniqueScratch::EMPTY));
    }
}
