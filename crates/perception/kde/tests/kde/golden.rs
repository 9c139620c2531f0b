//! Agreement with KDEpy 1.1.12 (the original code's KDE) and with an independent Python
//! computation of Botev's ISJ. The golden file is written by `tools/kdepy_reference.py golden`.

use serde_json::Value;
use voxpan_kde::{Kde, KdeMethod};

fn cases() -> serde_json::Map<String, Value> {
    let text = include_str!("../golden/kdepy_1_1_12.json");
    match serde_json::from_str(text).expect("golden JSON parses") {
        Value::Object(map) => map,
        _ => panic!("golden file must be an object"),
    }
}

fn data_of(case: &Value) -> Vec<f64> {
    case["data"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn kdepy_mode_reproduces_kdepy_bandwidth_and_density() {
    let mut kde = Kde::new(KdeMethod::Kdepy);
    for (name, case) in cases() {
        let density = kde.estimate(&data_of(&case)).unwrap();
        let bw = case["kdepy_bandwidth"].as_f64().unwrap();
        assert!(
            rel(density.bandwidth.value, bw) < 1e-9,
            "{name}: bandwidth {} vs KDEpy {bw}",
            density.bandwidth.value
        );
        assert!(
            rel(density.x(0), case["x0"].as_f64().unwrap()) < 1e-9,
            "{name}: grid start"
        );
        assert!(
            rel(density.x(1023), case["x_last"].as_f64().unwrap()) < 1e-9,
            "{name}: grid end"
        );
        let peak = density.values.iter().cloned().fold(0.0, f64::max);
        for (i, y) in case["y_samples"].as_object().unwrap() {
            let i: usize = i.parse().unwrap();
            let y = y.as_f64().unwrap();
            assert!(
                (density.values[i] - y).abs() <= 1e-7 * peak,
                "{name}: density at {i}: {} vs KDEpy {y}",
                density.values[i]
            );
        }
        assert_eq!(
            density.peak_index() as u64,
            case["argmax"].as_u64().unwrap(),
            "{name}: peak"
        );
    }
}

#[test]
fn isj_mode_matches_independent_botev_computation() {
    let mut kde = Kde::new(KdeMethod::Isj);
    for (name, case) in cases() {
        let bw = kde.bandwidth(&data_of(&case)).unwrap();
        let expected = case["botev_bandwidth"].as_f64().unwrap();
        assert!(bw.fallback.is_none(), "{name}");
        assert!(
            rel(bw.value, expected) < 1e-9,
            "{name}: {} vs {expected}",
            bw.value
        );
    }
}

#[test]
fn kdepy_mode_is_unit_dependent_and_isj_is_not() {
    let all = cases();
    let metres = data_of(&all["bimodal_2000"]);
    let millimetres = data_of(&all["depth_mm_bimodal"]);
    let mut isj = Kde::new(KdeMethod::Isj);
    let ratio = isj.bandwidth(&millimetres).unwrap().value / isj.bandwidth(&metres).unwrap().value;
    assert!((ratio - 1000.0).abs() < 1e-6, "ISJ ratio {ratio}");
    let mut kdepy = Kde::new(KdeMethod::Kdepy);
    let ratio =
        kdepy.bandwidth(&millimetres).unwrap().value / kdepy.bandwidth(&metres).unwrap().value;
    // KDEpy's absolute 6-unit padding: a metre-scale bandwidth is ~6x too small relative to mm.
    assert!(ratio > 2000.0, "KDEpy ratio {ratio}");
}
