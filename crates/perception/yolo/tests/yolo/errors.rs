//! Unusable models and libraries: each a clear error naming the file.

use std::path::Path;

use voxpan_yolo::{BackendKind, Yolo, YoloOptions};

#[cfg(any(feature = "ort", feature = "tract"))]
use crate::common::backends;
use crate::common::tiny;

fn open_error(model: &Path, options: &YoloOptions) -> String {
    match Yolo::open(model, options) {
        Ok(_) => panic!("{} opened", model.display()),
        Err(e) => e.to_string(),
    }
}

#[cfg(any(feature = "ort", feature = "tract"))]
#[test]
fn bad_models_are_named_and_explained() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.onnx");
    std::fs::write(&garbage, b"this is not a protobuf \x00\xff\x13 at all").unwrap();
    let truncated = dir.path().join("truncated.onnx");
    let bytes = std::fs::read(tiny("tiny-yolov8-seg-random.onnx")).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let missing = dir.path().join("missing.onnx");
    for options in &backends("bad_models_are_named_and_explained") {
        for (model, says) in [
            (garbage.as_path(), "cannot load it"),
            (truncated.as_path(), "cannot load it"),
            (missing.as_path(), "no such file"),
            (&tiny("foreign-conv.onnx"), "not a YOLO segmentation model"),
            (&tiny("det-only.onnx"), "1 output(s): [1, 41, 64]"),
        ] {
            let e = open_error(model, options);
            eprintln!("{:?}: {e}", options.backend);
            assert!(
                e.starts_with(&format!("{}: ", model.display())) && e.contains(says),
                "{:?}: {e}",
                options.backend
            );
        }
        // Stuff classes must be the model's.
        let e = voxpan_yolo::YoloSegmenter::open(
            &tiny("tiny-yolov8-seg-random.onnx"),
            options,
            &["wall".to_string()],
        )
        .err()
        .unwrap()
        .to_string();
        assert!(
            e.contains("\"wall\" is not one of the model's classes (chair, couch"),
            "{e}"
        );
    }
}

#[cfg(feature = "ort")]
#[test]
fn a_missing_onnx_runtime_library_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let options = |lib: &Path| YoloOptions {
        backend: BackendKind::Ort,
        ort_library: Some(lib.to_owned()),
        ..YoloOptions::default()
    };
    let missing = dir.path().join("libonnxruntime.so.1.31.1");
    let e = open_error(&tiny("tiny-yolov8-seg-random.onnx"), &options(&missing));
    assert!(
        e.starts_with(&format!(
            "cannot load ONNX Runtime from {}: no such file",
            missing.display()
        )) && e.contains("ORT_DYLIB_PATH"),
        "{e}"
    );
}

#[cfg(not(feature = "ort"))]
#[test]
fn a_backend_not_built_in_says_how_to_build_it() {
    let options = YoloOptions {
        backend: BackendKind::Ort,
        ..YoloOptions::default()
    };
    let e = open_error(&tiny("tiny-yolov8-seg-random.onnx"), &options);
    assert!(
        e.contains("built without the ort backend") && e.contains("--features ort"),
        "{e}"
    );
    if BackendKind::built().is_empty() {
        let e = open_error(
            &tiny("tiny-yolov8-seg-random.onnx"),
            &YoloOptions::default(),
        );
        assert!(e.contains("built without a network backend"), "{e}");
    }
}
