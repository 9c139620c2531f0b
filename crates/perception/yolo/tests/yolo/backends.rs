//! Both backends against ONNX Runtime's goldens (written from Python by `golden.py`): the
//! committed tiny random-weight models (both head layouts) and, fetched by
//! `tools/yolo/fetch_weights.sh`, the real YOLOv5s-seg at 640 and 320 on a uniform input and
//! on a letterboxed flat frame.

use serde_json::Value;
use voxpan_yolo::{Layout, Letterbox, Yolo, YoloOptions};

use crate::common::{Golden, backends, golden_options, open, tiny};
use crate::postprocess::check_case;

/// Largest absolute errors of a backend's raw outputs: box fields (pixels), the other fields
/// of `output0` (objectness, class probabilities, coefficients) and the prototypes.
#[derive(Debug, Default)]
struct Errors {
    boxes: f32,
    fields: f32,
    protos: f32,
}

fn errors(yolo: &mut Yolo, golden: &Golden, case: &Value) -> Errors {
    let input = golden.tensor(case, "images");
    let raw = yolo.raw(&input.data).unwrap();
    let (want0, want1) = (
        golden.tensor(case, "output0"),
        golden.tensor(case, "output1"),
    );
    assert_eq!(raw.detections.shape, want0.shape);
    assert_eq!(raw.protos.shape, want1.shape);
    let info = yolo.info();
    let fields = info.layout.box_fields() + info.classes() + info.mask_dim;
    let mut e = Errors::default();
    for (i, (a, b)) in raw.detections.data.iter().zip(&want0.data).enumerate() {
        let field = match info.layout {
            Layout::V5 => i % fields,
            Layout::V8 => i / info.candidates,
        };
        let slot = if field < 4 {
            &mut e.boxes
        } else {
            &mut e.fields
        };
        *slot = slot.max((a - b).abs());
    }
    for (a, b) in raw.protos.data.iter().zip(&want1.data) {
        e.protos = e.protos.max((a - b).abs());
    }
    e
}

fn check(name: &str, options: &YoloOptions, e: &Errors) {
    eprintln!("{name} on {:?}: max abs error {e:?}", options.backend);
    assert!(
        e.boxes <= 1e-2,
        "{name} on {:?}: box error {}",
        options.backend,
        e.boxes
    );
    assert!(
        e.fields <= 1e-4,
        "{name} on {:?}: score/coefficient error {}",
        options.backend,
        e.fields
    );
    assert!(
        e.protos <= 1e-4,
        "{name} on {:?}: prototype error {}",
        options.backend,
        e.protos
    );
}

#[test]
fn tiny_models_match_onnx_runtime_from_python() {
    let all = backends("tiny_models_match_onnx_runtime_from_python");
    assert!(!all.is_empty() || voxpan_test_support::missing_data_allowed());
    for options in &all {
        for (file, first) in [
            ("tiny-yolov8-seg-random.onnx", "chair"),
            ("tiny-yolov5-seg-random.onnx", "person"),
        ] {
            let model = tiny(file);
            let golden = Golden::load(&model);
            let mut yolo = open(&model, options);
            assert_eq!(yolo.info().input, (160, 128));
            let names: Vec<&str> = yolo.info().names.iter().map(String::as_str).collect();
            assert_eq!(names[0], first, "{file}: names from the metadata");
            check(
                file,
                options,
                &errors(&mut yolo, &golden, golden.case("uniform")),
            );
        }
    }
}

#[test]
fn yolov5s_seg_matches_onnx_runtime_from_python() {
    let test = "yolov5s_seg_matches_onnx_runtime_from_python";
    for size in [640, 320] {
        let Some(model) =
            voxpan_test_support::require_model(&format!("yolov5s-seg-{size}.onnx"), test)
        else {
            return;
        };
        let golden = Golden::load(&model);
        for options in &backends(test) {
            let mut yolo = open(&model, options);
            let info = yolo.info();
            assert_eq!(
                (info.layout, info.input, info.classes()),
                (Layout::V5, (size, size), 80)
            );
            for case in golden.cases() {
                let name = format!("yolov5s-seg-{size} {}", case["name"]);
                check(&name, options, &errors(&mut yolo, &golden, case));
            }
        }
    }
}

/// The letterbox gives the goldens' input tensors bit for bit: flat frame 74 into 640, 320
/// and the tiny models' 160×128 (a quarter: real resampling).
#[test]
fn letterbox_reproduces_the_reference_inputs() {
    let test = "letterbox_reproduces_the_reference_inputs";
    let Some(flat) = voxpan_test_support::require_flat_sample(test) else {
        return;
    };
    let image = voxpan_io::read_color_png(&flat.join("run1/000074_color.png")).unwrap();
    for file in [
        "yolov5s-seg-640.onnx",
        "yolov5s-seg-320.onnx",
        "tiny-yolov8-seg-random.onnx",
    ] {
        let Some(model) = voxpan_test_support::require_model(file, test) else {
            return;
        };
        let golden = Golden::load(&model);
        let case = golden.case("flat");
        assert_eq!(case["frame"], "000074_color.png");
        let want = golden.tensor(case, "images");
        let (h, w) = (want.shape[2], want.shape[3]);
        let lb = Letterbox::new(image.width(), image.height(), w, h).unwrap();
        let lbj = &case["letterbox"];
        assert_eq!(lb.left as u64, lbj["left"].as_u64().unwrap());
        assert_eq!(lb.top as u64, lbj["top"].as_u64().unwrap());
        let mut ours = Vec::new();
        lb.fill_input(&image, &mut ours);
        let differ = ours.iter().zip(&want.data).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{file}: {differ} input values differ");
    }
}

/// Post-processing on the real model's golden outputs for the flat frame and the uniform
/// input reproduces the reference's detections.
#[test]
fn yolov5s_seg_detections_match_the_reference() {
    let test = "yolov5s_seg_detections_match_the_reference";
    for size in [640, 320] {
        let Some(model) =
            voxpan_test_support::require_model(&format!("yolov5s-seg-{size}.onnx"), test)
        else {
            return;
        };
        let golden = Golden::load(&model);
        for case in golden.cases() {
            check_case(&model, &golden, case);
        }
    }
}

#[test]
fn options_reach_the_backend() {
    for options in &backends("options_reach_the_backend") {
        // A fixed-size model refuses another input size, naming the file.
        let model = tiny("tiny-yolov8-seg-random.onnx");
        let e = Yolo::open(
            &model,
            &YoloOptions {
                input_size: Some(320),
                ..options.clone()
            },
        )
        .err()
        .unwrap()
        .to_string();
        assert!(
            e.contains("tiny-yolov8-seg-random.onnx") && e.contains("160x128"),
            "{e}"
        );
        // One thread works too.
        let yolo = open(
            &model,
            &YoloOptions {
                threads: 1,
                ..options.clone()
            },
        );
        assert_eq!(yolo.info().candidates, 420);
        let _ = golden_options();
    }
}
