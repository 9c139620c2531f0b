//! The real weights in the loop: YOLOv5s-seg (GPL, fetched by `tools/yolo/fetch_weights.sh`,
//! never committed) finds the chair in flat frame 74 on every backend, at 640 and 320.

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_perception::Segmenter;
use voxpan_yolo::YoloSegmenter;

use crate::common::backends;

/// Flat frame 74, where both tests look for the chair.
fn frame_74(flat: &std::path::Path) -> voxpan_core::Frame {
    let dataset = FlatDataset::open(flat).unwrap();
    let index = (0..dataset.len())
        .find(|&i| dataset.frame_id(i) == "000074")
        .unwrap();
    dataset.load(index).unwrap()
}

#[test]
fn finds_the_chair_in_flat_frame_74() {
    let test = "finds_the_chair_in_flat_frame_74";
    let Some(flat) = voxpan_test_support::require_flat_sample(test) else {
        return;
    };
    let frame = frame_74(&flat);
    // ONNX Runtime from Python, in original 640×480 pixels (tools/yolo/check_detection.py).
    for (size, score, bbox) in [
        (640, 0.92, [204.0, 259.0, 317.0, 429.0]),
        (320, 0.887, [199.0, 256.0, 322.0, 434.0]),
    ] {
        let Some(model) =
            voxpan_test_support::require_model(&format!("yolov5s-seg-{size}.onnx"), test)
        else {
            return;
        };
        for options in &backends(test) {
            let mut seg = YoloSegmenter::open(&model, options, &[]).unwrap();
            let (segments, instances) = seg.segment_image(&frame.color).unwrap();
            // The best chair and its label id.
            let (id, chair) = instances
                .owners
                .iter()
                .enumerate()
                .map(|(k, &d)| (k as u16 + 1, &instances.detections[d]))
                .find(|(_, d)| seg.yolo().info().names[d.class] == "chair")
                .unwrap_or_else(|| panic!("{size} on {:?}: no chair", options.backend));
            let b = instances.image_box(chair);
            eprintln!(
                "{size} on {:?}: chair {:.3} at {b:.1?}",
                options.backend, chair.score
            );
            assert!(
                (chair.score as f64 - score).abs() < 0.006,
                "{size}: score {}",
                chair.score
            );
            for (got, want) in b.iter().zip(bbox) {
                assert!((got - want).abs() < 1.0, "{size}: box {b:?} vs {bbox:?}");
            }
            // Its mask: a segment of class chair, a thing, mostly inside its box.
            let s = segments.get(id).unwrap();
            assert_eq!((s.is_thing, s.score), (Some(true), Some(chair.score)));
            let (mut inside, mut all) = (0, 0);
            for (i, &l) in segments.labels.pixels().iter().enumerate() {
                if l == id {
                    all += 1;
                    let (x, y) = ((i % 640) as f64 + 0.5, (i / 640) as f64 + 0.5);
                    inside += usize::from(x >= b[0] && x < b[2] && y >= b[1] && y < b[3]);
                }
            }
            let box_area = (b[2] - b[0]) * (b[3] - b[1]);
            assert_eq!(inside, all, "the mask is cut to the box");
            assert!(
                all as f64 > 0.3 * box_area,
                "{size}: chair mask of {all} px in a {box_area} px box"
            );
            // As a Segmenter: the frame's segments, at the frame's size, with the model's classes.
            let via_trait = seg.segment(&frame).unwrap().unwrap();
            assert_eq!(via_trait.labels.dims(), frame.depth.dims());
            assert_eq!(
                seg.classes().unwrap().name(chair.class as u32),
                Some("chair")
            );
        }
    }
}

/// The INT8 copy `tools/yolo/quantize.py` makes (calibrated on flat frames 0..98, step 6)
/// reads on every backend and finds frame 74's chair where the float model does: the same box
/// within a few pixels, a score within a few hundredths.
#[test]
fn the_int8_model_finds_the_chair_where_the_float_model_does() {
    let test = "the_int8_model_finds_the_chair_where_the_float_model_does";
    let Some(flat) = voxpan_test_support::require_flat_sample(test) else {
        return;
    };
    let Some(model) = voxpan_test_support::require_model("yolov5s-seg-640-int8.onnx", test) else {
        return;
    };
    let frame = frame_74(&flat);
    let (score, bbox) = (0.92, [204.0, 259.0, 317.0, 429.0]);
    for options in &backends(test) {
        let mut seg = YoloSegmenter::open(&model, options, &[]).unwrap();
        let (_, instances) = seg.segment_image(&frame.color).unwrap();
        let chair = instances
            .detections
            .iter()
            .filter(|d| seg.yolo().info().names[d.class] == "chair")
            .max_by(|a, b| a.score.total_cmp(&b.score))
            .unwrap_or_else(|| panic!("INT8 on {:?}: no chair", options.backend));
        let b = instances.image_box(chair);
        eprintln!(
            "INT8 on {:?}: chair {:.3} at {b:.1?}",
            options.backend, chair.score
        );
        assert!(
            (chair.score as f64 - score).abs() < 0.02,
            "INT8 on {:?}: score {}",
            options.backend,
            chair.score
        );
        for (got, want) in b.iter().zip(bbox) {
            assert!(
                (got - want).abs() < 3.0,
                "INT8 on {:?}: box {b:?} vs {bbox:?}",
                options.backend
            );
        }
    }
}
