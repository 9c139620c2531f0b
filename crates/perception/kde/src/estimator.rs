use crate::bandwidth::{Bandwidth, KdeMethod};
use crate::binning::{linear_binning, linear_binning_fast, linear_binning_tallied};
use crate::convolve::FftConvolver;
use crate::isj::{
    Dct, FixedPoint, GRID_POINTS, RootStrategy, UniqueScratch, count_unique, solve_t_star,
};
use crate::{Grid, gaussian_pdf, kdepy};

/// A density on an equidistant grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Density {
    pub grid: Grid,
    /// Density at each grid point (integrates to about 1 over the grid).
    pub values: Vec<f64>,
    pub bandwidth: Bandwidth,
    /// The smallest and the largest value used.
    pub data_range: (f64, f64),
    /// Values used (finite ones).
    pub n_used: usize,
    /// Values that were ignored: non-finite ones, and those beyond the limit of
    /// [`Kde::estimate_f32_up_to`].
    pub n_ignored: usize,
}

impl Density {
    /// The grid coordinate of point `i`.
    pub fn x(&self, i: usize) -> f64 {
        self.grid.point(i)
    }

    /// Index of the global maximum (the first one on ties).
    pub fn peak_index(&self) -> usize {
        let mut best = 0;
        for (i, &v) in self.values.iter().enumerate() {
            if v > self.values[best] {
                best = i;
            }
        }
        best
    }
}

/// Inputs a density cannot be estimated from.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum KdeError {
    #[error("no finite values to estimate a density from")]
    Empty,
    #[error("all {count} finite values equal {value}: a point mass has no bandwidth")]
    Constant { value: f64, count: usize },
    #[error("values from {min:e} to {max:e} span more than a grid can represent")]
    RangeOverflow { min: f64, max: f64 },
}

/// Kernels are cut where the Gaussian has fallen by `exp(-36) ≈ 2e-16` of its peak.
const KERNEL_SIGMAS: f64 = 8.5;

/// A reusable estimator: keeps FFT/DCT plans and buffers between calls (one per thread).
pub struct Kde {
    method: KdeMethod,
    dct: Dct,
    convolver: FftConvolver,
    finite: Vec<f64>,
    unique: UniqueScratch,
    binned: Vec<f64>,
    coefficients: Vec<f64>,
    kernel: Vec<f64>,
    resolution_floor: bool,
}

impl Kde {
    /// [`KdeMethod::Isj`] only: never smooth less than the data resolve, i.e. use at least
    /// `range / distinct values` as bandwidth. Quantised data (16-bit millimetre depth,
    /// simulators' half-float depth) otherwise get a bandwidth below the quantisation step and a
    /// density that is a comb of spikes, one per representable value. Scale-equivariant, like
    /// ISJ itself.
    pub fn with_resolution_floor(mut self) -> Self {
        self.resolution_floor = true;
        self
    }

    pub fn new(method: KdeMethod) -> Self {
        Self {
            method,
            dct: Dct::new(GRID_POINTS),
            convolver: FftConvolver::new(),
            finite: Vec::new(),
            unique: UniqueScratch::default(),
            binned: Vec::new(),
            coefficients: Vec::new(),
            kernel: Vec::new(),
            resolution_floor: false,
        }
    }

    pub fn method(&self) -> KdeMethod {
        self.method
    }

    /// The ISJ bandwidth of `data` (non-finite values are ignored).
    pub fn bandwidth(&mut self, data: &[f64]) -> Result<Bandwidth, KdeError> {
        let (finite, summary) = self.finite_values(data);
        let result = summary
            .range()
            .map(|(min, max)| self.isj_bandwidth(&finite, &summary, min, max));
        self.finite = finite;
        result
    }

    /// The density of `data` on a grid covering it (non-finite values are ignored).
    pub fn estimate(&mut self, data: &[f64]) -> Result<Density, KdeError> {
        let (finite, summary) = self.finite_values(data);
        let result = summary.range().map(|(min, max)| {
            let bandwidth = self.isj_bandwidth(&finite, &summary, min, max);
            let (grid, values) = match self.method {
                KdeMethod::Isj => self.evaluate_isj(bandwidth.value, min, max),
                KdeMethod::Kdepy => self.evaluate_kdepy(&finite, bandwidth.value, min, max),
            };
            Density {
                grid,
                values,
                bandwidth,
                data_range: (min, max),
                n_used: finite.len(),
                n_ignored: data.len() - finite.len(),
            }
        });
        self.finite = finite;
        result
    }

    /// [`estimate`](Self::estimate) of float32 data (depth images), the same density: ISJ
    /// tallies their distinct values straight from the input, without a widened copy.
    pub fn estimate_f32(&mut self, data: &[f32]) -> Result<Density, KdeError> {
        self.estimate_f32_up_to(data, f64::INFINITY)
    }

    /// [`estimate_f32`](Self::estimate_f32) of the values of `data` at most `limit`; the
    /// others are ignored as non-finite ones are. ISJ reads the data once: the range, the
    /// count and the limit are taken over the tallied distinct values, not every value.
    pub fn estimate_f32_up_to(&mut self, data: &[f32], limit: f64) -> Result<Density, KdeError> {
        if self.method != KdeMethod::Isj {
            // NaNs stay: `estimate` counts them as ignored.
            let wide: Vec<f64> = data
                .iter()
                .map(|&v| v as f64)
                .filter(|&v| v <= limit || v.is_nan())
                .collect();
            let mut density = self.estimate(&wide)?;
            density.n_ignored = data.len() - density.n_used;
            return Ok(density);
        }
        self.unique.tally_f32_finite(data);
        let mut summary = Summary {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            count: 0,
            all_f32: true,
        };
        let mut n_unique = 0;
        for (v, n) in self.unique.tallies().filter(|&(v, _)| v <= limit) {
            summary.min = summary.min.min(v);
            summary.max = summary.max.max(v);
            summary.count += n as usize;
            n_unique += 1;
        }
        let (min, max) = match summary.range() {
            Ok(range) => range,
            Err(e) => {
                self.unique.reset();
                return Err(e);
            }
        };
        let grid = isj_grid(min, max);
        let used = self.unique.tallies().filter(|&(v, _)| v <= limit);
        linear_binning_tallied(used, summary.count, &grid, &mut self.binned);
        self.unique.reset();
        let bandwidth =
            self.bandwidth_of_binned(n_unique, RootStrategy::Botev, grid.range(), min, max);
        let (grid, values) = self.evaluate_isj(bandwidth.value, min, max);
        Ok(Density {
            grid,
            values,
            bandwidth,
            data_range: (min, max),
            n_used: summary.count,
            n_ignored: data.len() - summary.count,
        })
    }

    /// The finite values of `data` (in a buffer taken from `self`, which the caller returns)
    /// and what one pass over them learns.
    fn finite_values(&mut self, data: &[f64]) -> (Vec<f64>, Summary) {
        let mut finite = std::mem::take(&mut self.finite);
        finite.clear();
        let mut summary = Summary {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            count: 0,
            all_f32: true,
        };
        for &v in data {
            if v.is_finite() {
                finite.push(v);
                summary.min = summary.min.min(v);
                summary.max = summary.max.max(v);
                summary.all_f32 &= v as f32 as f64 == v;
            }
        }
        summary.count = finite.len();
        (finite, summary)
    }

    fn isj_bandwidth(&mut self, data: &[f64], summary: &Summary, min: f64, max: f64) -> Bandwidth {
        let (grid, strategy, scale) = match self.method {
            // Botev: grid padded by a tenth of the range; bandwidth in units of the grid range.
            KdeMethod::Isj => {
                let grid = isj_grid(min, max);
                (grid, RootStrategy::Botev, grid.range())
            }
            // KDEpy: absolute padding, and the bandwidth scaled by the *data* range.
            KdeMethod::Kdepy => (
                kdepy::isj_grid(min, max, GRID_POINTS),
                RootStrategy::KdepyReleased,
                max - min,
            ),
        };
        let n_unique = match self.method {
            // Depths take few distinct values (millimetres, half floats): one pass tallies
            // them, and binning runs over the distinct values, not every pixel.
            KdeMethod::Isj if summary.all_f32 => {
                let n_unique = self.unique.tally_f32(data);
                self.bin_tallies(data.len(), &grid);
                n_unique
            }
            KdeMethod::Isj => {
                linear_binning_fast(data, &grid, &mut self.binned);
                count_unique(data, false, &mut self.unique)
            }
            KdeMethod::Kdepy => {
                linear_binning(data, &grid, &mut self.binned);
                count_unique(data, summary.all_f32, &mut self.unique)
            }
        };
        self.bandwidth_of_binned(n_unique, strategy, scale, min, max)
    }

    /// Bins the last tally of `count` values on `grid` (into `binned`) and clears the tally.
    fn bin_tallies(&mut self, count: usize, grid: &Grid) {
        linear_binning_tallied(self.unique.tallies(), count, grid, &mut self.binned);
        self.unique.reset();
    }

    /// The bandwidth from the data binned on the ISJ grid (in `binned`), `n_unique` distinct
    /// values; `scale` converts Botev's grid units to the data's.
    fn bandwidth_of_binned(
        &mut self,
        n_unique: usize,
        strategy: RootStrategy,
        scale: f64,
        min: f64,
        max: f64,
    ) -> Bandwidth {
        // `binned` stays intact: the ISJ evaluation convolves the same binned data.
        self.coefficients.clear();
        self.coefficients.extend_from_slice(&self.binned);
        self.dct.forward(&mut self.coefficients);
        let fixed_point = FixedPoint::new(&self.coefficients, n_unique);
        let (t_star, fallback) = solve_t_star(&fixed_point, strategy);
        let isj = t_star.sqrt() * scale;
        let resolution = (max - min) / n_unique.max(1) as f64;
        let floored = self.resolution_floor && self.method == KdeMethod::Isj && resolution > isj;
        Bandwidth {
            value: if floored { resolution } else { isj },
            t_star,
            n_unique,
            fallback,
            floored,
        }
    }

    /// Exact Gaussian KDE of the linearly binned data (binned on the ISJ grid by
    /// `isj_bandwidth`): the grid extended on both sides by the kernel's reach, so the density
    /// decays to ~0 inside the returned grid.
    fn evaluate_isj(&mut self, h: f64, min: f64, max: f64) -> (Grid, Vec<f64>) {
        let grid = isj_grid(min, max);
        let dx = grid.step();
        // Bounded so that a pathological bandwidth cannot ask for a huge FFT.
        let half = ((KERNEL_SIGMAS * h / dx).ceil() as usize).clamp(1, 8 * GRID_POINTS);
        self.kernel.clear();
        self.kernel
            .extend((0..=2 * half).map(|j| gaussian_pdf((j as f64 - half as f64) * dx, h)));
        let mut values = Vec::new();
        self.convolver.full(&self.binned, &self.kernel, &mut values);
        // FFT rounding leaves ±1e-17 noise where the density is zero; a density is not negative.
        for v in values.iter_mut() {
            *v = v.max(0.0);
        }
        let extended = Grid::new(
            grid.start - half as f64 * dx,
            grid.end + half as f64 * dx,
            values.len(),
        );
        (extended, values)
    }

    /// KDEpy's `evaluate()`: a second 1024-point grid, a kernel truncated at its practical
    /// support, a "same"-size convolution, and machine epsilon added to every value.
    fn evaluate_kdepy(&mut self, data: &[f64], h: f64, min: f64, max: f64) -> (Grid, Vec<f64>) {
        let support = kdepy::practical_support(h);
        let grid = kdepy::evaluation_grid(min, max, support, GRID_POINTS);
        linear_binning(data, &grid, &mut self.binned);
        let half = kdepy::truncated_kernel(h, support, &grid, &mut self.kernel);
        let mut full = Vec::new();
        self.convolver.full(&self.binned, &self.kernel, &mut full);
        let values = full[half..half + grid.len]
            .iter()
            .map(|v| v + f64::EPSILON)
            .collect();
        (grid, values)
    }
}

/// Botev's grid: the data range padded by a tenth on each side.
fn isj_grid(min: f64, max: f64) -> Grid {
    let pad = (max - min) / 10.0;
    Grid::new(min - pad, max + pad, GRID_POINTS)
}

/// One pass's worth of facts about the finite values.
struct Summary {
    min: f64,
    max: f64,
    count: usize,
    /// Every value is exactly a float32 (depth images are), which speeds up counting.
    all_f32: bool,
}

impl Summary {
    fn range(&self) -> Result<(f64, f64), KdeError> {
        if self.count == 0 {
            Err(KdeError::Empty)
        } else if self.max <= self.min {
            Err(KdeError::Constant {
                value: self.min,
                count: self.count,
            })
        } else if !(self.min.abs().max(self.max.abs()) + 8.0 * (self.max - self.min)).is_finite() {
            // Padding and kernel reach (a few ranges) would overflow to infinity.
            Err(KdeError::RangeOverflow {
                min: self.min,
                max: self.max,
            })
        } else {
            Ok((self.min, self.max))
        }
    }
}
