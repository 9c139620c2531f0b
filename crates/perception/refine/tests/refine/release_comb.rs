//! The released rule on a real comb-shaped mask, against the original code's interval.
//!
//! `../shared/data/golden/release_rule_comb_mask.json` holds the depths under one real flat
//! mask (43,980 pixels, 24 distinct half-float values) and the interval the released code
//! (KDEpy 1.1.12, `tools/kdepy_reference.py`) keeps. Its density peaks on two grid points of
//! equal height; taking the wrong one of them once kept 33,730 pixels instead of 42,293.

use std::path::PathBuf;

use voxpan_refine::{RefineConfig, Refiner, Rule};
use voxpan_test_support::ALLOW_MISSING_ENV;

const FILE: &str = "release_rule_comb_mask.json";

/// The shared golden file, or `None` (skipped, loudly) when it is missing and the environment
/// allows that; otherwise a missing file fails the test, as the other data tests do.
fn golden_file() -> Option<PathBuf> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../../shared/data/golden")
        .join(FILE);
    if path.is_file() {
        return Some(path);
    }
    let msg = format!(
        "release_rule_matches_the_original_on_a_comb_mask: {} is missing (the shared data \
         beside the checkout)",
        path.display()
    );
    if voxpan_test_support::missing_data_allowed() {
        eprintln!("SKIPPED {msg}");
        None
    } else {
        panic!("{msg} (or set {ALLOW_MISSING_ENV}=1 to skip)");
    }
}

/// The golden file's fields.
#[derive(serde::Deserialize)]
struct Golden {
    values: Vec<f64>,
    counts: Vec<usize>,
    release_rule_low: f64,
    release_rule_high: f64,
    release_rule_kept_pixels: usize,
}

#[test]
fn release_rule_matches_the_original_on_a_comb_mask() {
    let Some(path) = golden_file() else {
        return;
    };
    let golden: Golden = serde_json::from_str(&std::fs::read_to_string(&path).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (values, counts) = (&golden.values, &golden.counts);
    assert_eq!(
        values.len(),
        counts.len(),
        "{FILE}: values and counts differ in length"
    );
    // The values are float32 depths written exactly; the rule normalises them in float32.
    let depths: Vec<f32> = values
        .iter()
        .zip(counts)
        .flat_map(|(&v, &c)| std::iter::repeat_n(v as f32, c))
        .collect();
    assert_eq!(depths.len(), 43_980);
    let (low, high) = (golden.release_rule_low, golden.release_rule_high);
    let kept_expected = golden.release_rule_kept_pixels;

    let interval = Refiner::new(RefineConfig::new(Rule::Release))
        .interval(&depths)
        .unwrap();
    let kept = depths.iter().filter(|&&d| interval.contains(d)).count();
    // The ends are KDEpy grid points mapped back to metres; ours are computed the same way
    // and differ only by rounding (~1e-15 m). 1e-9 m is far below the grid step (2.8e-4 m),
    // so landing on a neighbouring grid point fails. The ends lie between the depths
    // (half-float steps of ~1e-3 m), so the kept count must agree exactly.
    assert!(
        (interval.low - low).abs() < 1e-9 && (interval.high - high).abs() < 1e-9,
        "kept [{}, {}] m, the original [{low}, {high}] m",
        interval.low,
        interval.high
    );
    assert_eq!(kept, kept_expected, "{interval:?}");
}
