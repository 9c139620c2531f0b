//! Post-processing on ONNX Runtime's raw outputs reproduces the Python reference's detections
//! (`tools/yolo/yolo_common.py`: confidence 0.25, class-aware NMS 0.45, masks at input
//! resolution): no backend needed.

use std::path::Path;

use serde_json::Value;
use voxpan_yolo::{Grid, Layout, Yolo, for_each_mask_pixel};

use crate::common::{Golden, Replay, golden_options, tiny};

/// Our detections of a golden case against the reference's: same classes in the same order,
/// scores to the JSON's 6 decimals, boxes to its 4, mask areas to the pixel.
pub fn check_case(model: &Path, golden: &Golden, case: &Value) -> usize {
    let replay = Box::new(Replay::new(golden, case));
    let mut yolo = Yolo::with_backend(model, replay, &golden_options()).unwrap();
    let input = golden.tensor(case, "images");
    let raw = yolo.raw(&input.data).unwrap();
    let ours = yolo.detections(&raw);
    let want = case["detections"].as_array().unwrap();
    let name = case["name"].as_str().unwrap();
    assert_eq!(ours.len(), want.len(), "{name}: number of detections");
    let info = yolo.info().clone();
    let (w, h) = info.input;
    let protos = yolo.protos(&raw);
    let mut area_off = 0;
    for (k, (d, g)) in ours.iter().zip(want).enumerate() {
        assert_eq!(
            d.class as u64,
            g["class"].as_u64().unwrap(),
            "{name} #{k}: class"
        );
        assert_eq!(info.names[d.class], g["name"].as_str().unwrap());
        let score = g["score"].as_f64().unwrap();
        assert!(
            (d.score as f64 - score).abs() <= 6e-7,
            "{name} #{k}: score {} vs {score}",
            d.score
        );
        for (a, b) in d.bbox.iter().zip(g["box_xyxy"].as_array().unwrap()) {
            let b = b.as_f64().unwrap();
            assert!(
                (*a as f64 - b).abs() <= 1e-4 * b.abs().max(1.0),
                "{name} #{k}: box {:?} vs {b}",
                d.bbox
            );
        }
        let mut area = 0u64;
        for_each_mask_pixel(d, &protos, (w, h), &Grid::input(w, h), |_, _| area += 1);
        let want_area = g["mask_area"].as_u64().unwrap();
        // Python sums the coefficients with BLAS and takes numpy's exp: a pixel whose
        // probability is within a rounding error of 0.5 may fall either way.
        assert!(
            area.abs_diff(want_area) <= 2,
            "{name} #{k}: mask area {area} vs {want_area}"
        );
        area_off += area.abs_diff(want_area) as usize;
    }
    area_off
}

#[test]
fn tiny_v8_and_v5_detections_match_the_reference() {
    for (file, layout) in [
        ("tiny-yolov8-seg-random.onnx", Layout::V8),
        ("tiny-yolov5-seg-random.onnx", Layout::V5),
    ] {
        let model = tiny(file);
        let golden = Golden::load(&model);
        let case = golden.case("uniform");
        let replay = Box::new(Replay::new(&golden, case));
        let yolo = Yolo::with_backend(&model, replay, &golden_options()).unwrap();
        assert_eq!(yolo.info().layout, layout, "{file}");
        let off = check_case(&model, &golden, case);
        assert!(off <= 3, "{file}: mask areas differ by {off} pixels in all");
    }
}
