//! Properties of the estimator that hold for any data.

use proptest::prelude::*;
use voxpan_kde::{Kde, KdeError, KdeMethod};

/// A bimodal sample from a fixed low-discrepancy sequence (no RNG needed).
fn bimodal(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let u = (i as f64 * 0.618_033_988_749_895).fract();
            let v = (i as f64 * 0.414_213_562_373_095).fract();
            // Box-Muller on two quasi-random uniforms.
            let z = (-2.0 * (u.max(1e-12)).ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos();
            if i % 3 == 0 {
                3.0 + 0.2 * z
            } else {
                1.5 + 0.05 * z
            }
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The float32 entry point gives exactly the density of the same values widened to f64,
    /// non-finite values and negative zeros included, for both methods; with a limit, that of
    /// the values within it.
    #[test]
    fn float32_data_give_the_same_density(
        n in 2usize..3000,
        quantum in prop::sample::select(vec![0.0f64, 1e-3, 0.05]),
        specials in prop::collection::vec(
            prop::sample::select(vec![f32::NAN, f32::INFINITY, -0.0, 0.0]), 0..4),
        resolution_floor in any::<bool>(),
    ) {
        let mut data: Vec<f32> = bimodal(n)
            .into_iter()
            .map(|v| if quantum > 0.0 { (v / quantum).round() * quantum } else { v } as f32)
            .collect();
        data.extend(specials);
        let wide: Vec<f64> = data.iter().map(|&v| v as f64).collect();
        for method in [KdeMethod::Isj, KdeMethod::Kdepy] {
            let kde = || {
                let kde = Kde::new(method);
                if resolution_floor { kde.with_resolution_floor() } else { kde }
            };
            prop_assert_eq!(kde().estimate_f32(&data), kde().estimate(&wide));
            // A limit gives the density of the values within it, the rest counted as ignored.
            let limit = data[n / 3] as f64;
            let within: Vec<f64> =
                wide.iter().copied().filter(|&v| v <= limit || v.is_nan()).collect();
            let expected = kde().estimate(&within).map(|mut d| {
                d.n_ignored = data.len() - d.n_used;
                d
            });
            prop_assert_eq!(kde().estimate_f32_up_to(&data, limit), expected);
        }
    }

    /// The AVX2 path (tallying distinct depths, the ISJ functional) gives the baseline's
    /// density bit for bit. On a CPU without AVX2 both runs take the baseline path.
    #[test]
    fn the_avx2_path_gives_the_baseline_density(
        n in 2usize..3000,
        quantum in prop::sample::select(vec![0.0f64, 1e-3, 0.05]),
    ) {
        let data: Vec<f32> = bimodal(n)
            .into_iter()
            .map(|v| if quantum > 0.0 { (v / quantum).round() * quantum } else { v } as f32)
            .collect();
        for method in [KdeMethod::Isj, KdeMethod::Kdepy] {
            let widest = Kde::new(method).with_resolution_floor().estimate_f32(&data);
            let as_built = voxpan_core::cpu::as_built(|| {
                Kde::new(method).with_resolution_floor().estimate_f32(&data)
            });
            prop_assert_eq!(widest, as_built);
        }
    }

    /// Scaling the data by c scales the ISJ bandwidth by c.
    #[test]
    fn isj_bandwidth_is_scale_equivariant(log_c in -3.0f64..3.0, n in 50usize..3000) {
        let c = 10f64.powf(log_c);
        let data = bimodal(n);
        let scaled: Vec<f64> = data.iter().map(|v| v * c).collect();
        let mut kde = Kde::new(KdeMethod::Isj);
        let h = kde.bandwidth(&data).unwrap();
        let hc = kde.bandwidth(&scaled).unwrap();
        prop_assert_eq!(h.fallback, hc.fallback);
        let ratio = hc.value / (c * h.value);
        prop_assert!((ratio - 1.0).abs() < 1e-6, "c = {}, ratio {}", c, ratio);
    }

    /// Shifting the data shifts the density and leaves the bandwidth alone.
    #[test]
    fn isj_is_shift_invariant(shift in -100.0f64..100.0) {
        let data = bimodal(800);
        let shifted: Vec<f64> = data.iter().map(|v| v + shift).collect();
        let mut kde = Kde::new(KdeMethod::Isj);
        let a = kde.estimate(&data).unwrap();
        let b = kde.estimate(&shifted).unwrap();
        prop_assert!((a.bandwidth.value / b.bandwidth.value - 1.0).abs() < 1e-6);
        prop_assert!((a.x(a.peak_index()) + shift - b.x(b.peak_index())).abs() < 2.0 * a.grid.step());
    }

    /// Any input, NaN and infinities included, gives a density or a typed error; never a panic.
    #[test]
    fn never_panics(data in prop::collection::vec(prop_oneof![
        any::<f64>(),
        -1e3f64..1e3,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(1.0),
    ], 0..200), kdepy in any::<bool>()) {
        let mut kde = Kde::new(if kdepy { KdeMethod::Kdepy } else { KdeMethod::Isj });
        match kde.estimate(&data) {
            Ok(d) => {
                prop_assert!(d.bandwidth.value.is_finite() || d.n_used > 0);
                prop_assert!(d.values.iter().all(|v| !v.is_nan()));
            }
            Err(KdeError::Empty) => prop_assert!(data.iter().all(|v| !v.is_finite())),
            Err(KdeError::Constant { .. }) => {}
            Err(KdeError::RangeOverflow { min, max }) => prop_assert!((max - min) > 1e300 || min.abs() > 1e300 || max.abs() > 1e300),
        }
    }
}

#[test]
fn density_integrates_to_one_and_peaks_at_the_mode() {
    let data = bimodal(3000);
    for method in [KdeMethod::Isj, KdeMethod::Kdepy] {
        let d = Kde::new(method).estimate(&data).unwrap();
        let mass: f64 = d.values.iter().sum::<f64>() * d.grid.step();
        assert!((mass - 1.0).abs() < 1e-3, "{method:?}: mass {mass}");
        // Two thirds of the data sit at 1.5.
        assert!((d.x(d.peak_index()) - 1.5).abs() < 0.02, "{method:?}");
    }
}

#[test]
fn isj_density_decays_inside_its_grid() {
    let d = Kde::new(KdeMethod::Isj).estimate(&bimodal(500)).unwrap();
    let peak = d.values[d.peak_index()];
    assert!(d.values[0] < 1e-12 * peak && d.values[d.values.len() - 1] < 1e-12 * peak);
}

#[test]
fn isj_bandwidth_of_a_gaussian_sample_is_near_the_normal_reference() {
    // For normal data the AMISE-optimal bandwidth is about 1.06 σ n^(-1/5); ISJ should be close.
    let n = 4000;
    let data: Vec<f64> = bimodal(3 * n)
        .into_iter()
        .skip(1)
        .step_by(3)
        .take(n)
        .collect();
    let h = Kde::new(KdeMethod::Isj).bandwidth(&data).unwrap().value;
    let reference = 1.06 * 0.05 * (n as f64).powf(-0.2);
    assert!((h / reference - 1.0).abs() < 0.3, "h {h} vs {reference}");
}

#[test]
fn degenerate_inputs_are_typed_errors() {
    let mut kde = Kde::new(KdeMethod::Isj);
    assert_eq!(kde.estimate(&[]).unwrap_err(), KdeError::Empty);
    assert_eq!(
        kde.estimate(&[f64::NAN, f64::INFINITY]).unwrap_err(),
        KdeError::Empty
    );
    assert_eq!(
        kde.estimate(&[2.5]).unwrap_err(),
        KdeError::Constant {
            value: 2.5,
            count: 1
        }
    );
    assert_eq!(
        kde.estimate(&[2.5, 2.5, f64::NAN]).unwrap_err(),
        KdeError::Constant {
            value: 2.5,
            count: 2
        }
    );
    assert!(matches!(
        kde.estimate(&[-1.6e308, 0.0]).unwrap_err(),
        KdeError::RangeOverflow { .. }
    ));
    // Two distinct values are enough for a density.
    let d = kde.estimate(&[1.0, 2.0, f64::NAN]).unwrap();
    assert_eq!((d.n_used, d.n_ignored), (2, 1));
}
