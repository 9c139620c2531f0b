//! One-dimensional kernel density estimation for mask refinement.
//!
//! A binned Gaussian KDE on an equidistant grid, evaluated by FFT convolution, whose bandwidth
//! comes from the Improved Sheather-Jones (ISJ) rule of Botev, Grotowski & Kroese, "Kernel
//! density estimation via diffusion", Annals of Statistics 38(5), 2010.
//!
//! Two methods ([`KdeMethod`]):
//! - [`KdeMethod::Isj`]: Botev's algorithm as published (his MATLAB `kde.m`): grid padded by a
//!   tenth of the data range, bandwidth `sqrt(t*) × grid range`. Scale-equivariant: data scaled
//!   by `c` gives a bandwidth scaled by `c`.
//! - [`KdeMethod::Kdepy`]: KDEpy 1.1.x `FFTKDE(bw="ISJ").fit(x).evaluate()` as the original
//!   refinement code used it, quirks included (absolute 6-unit padding, bandwidth scaled by the
//!   data range, the released code's `t* = 0.01` fallback). Exists to reproduce published numbers.
//!
//! Cost: `O(n + M log M)` for `n` values and an `M = 1024`-point grid, plus a unique-value count
//! (`O(n log n)`, Botev's `N`). The estimator keeps its FFT plans and buffers, so reuse one
//! [`Kde`] per thread.
//!
//! ```
//! use voxpan_kde::{Kde, KdeMethod};
//!
//! // Depths of two surfaces, 1 m and 3 m away.
//! let values: Vec<f64> = (0..400)
//!     .map(|i| if i % 2 == 0 { 1.0 } else { 3.0 } + 0.01 * ((i * 37 % 101) as f64 / 101.0 - 0.5))
//!     .collect();
//! let density = Kde::new(KdeMethod::Isj).estimate(&values)?;
//! // The bandwidth resolves the two surfaces: the density between them is near zero.
//! assert!(density.bandwidth.value < 0.05);
//! let middle = ((2.0 - density.grid.point(0)) / density.grid.step()).round() as usize;
//! let between = density.values[middle];
//! assert!(between < 1e-3 * density.values[density.peak_index()]);
//! # Ok::<(), voxpan_kde::KdeError>(())
//! ```

mod bandwidth;
mod binning;
mod brent;
mod convolve;
mod estimator;
mod grid;
mod isj;
mod kdepy;

pub use bandwidth::{Bandwidth, BandwidthFallback, KdeMethod};
pub use binning::linear_binning;
pub use brent::{BrentOptions, RootSearch, brentq};
pub use estimator::{Density, Kde, KdeError};
pub use grid::Grid;
pub use isj::GRID_POINTS;

/// The Gaussian probability density with standard deviation `h` at offset `x`.
#[inline]
pub fn gaussian_pdf(x: f64, h: f64) -> f64 {
    let z = x / h;
    (-0.5 * z * z).exp() / (h * (2.0 * std::f64::consts::PI).sqrt())
}
