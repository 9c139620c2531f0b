//! `voxpan segment` and `voxpan run --model`: the segmentation network from the command line.
//! Without a backend feature, `--model` says which feature to build with; with one, the
//! committed tiny random-weight model runs end to end and, when `tools/yolo/fetch_weights.sh`
//! has fetched them, the real YOLOv5s-seg weights find the chair in flat frame 74.

use std::path::{Path, PathBuf};
#[cfg(any(feature = "ort", feature = "tract"))]
use std::process::{Command, Output};

use crate::common::voxpan;

/// The tiny random-weight YOLOv8-seg-layout model committed with voxpan-yolo (ours).
fn tiny_model() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../perception/yolo/tests/data/tiny-yolov8-seg-random.onnx")
}

/// A small colour PNG.
fn write_image(path: &Path) {
    image::RgbImage::from_fn(64, 48, |x, y| {
        image::Rgb([(4 * x) as u8, (5 * y) as u8, 90])
    })
    .save(path)
    .unwrap();
}

#[cfg(not(any(feature = "ort", feature = "tract")))]
#[test]
fn without_a_backend_model_says_which_feature_to_build_with() {
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("a_color.png");
    write_image(&image);
    let model = tiny_model();
    let out = dir.path().join("out");
    for args in [
        vec![
            "segment".as_ref(),
            "--model".as_ref(),
            model.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
            image.as_os_str(),
        ],
        vec![
            "run".as_ref(),
            "--model".as_ref(),
            model.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ],
    ] {
        let o = voxpan(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            err.contains("--model") && err.contains("--features ort") && err.contains("tract"),
            "{err}"
        );
    }
    assert!(
        !out.exists(),
        "nothing written when the model cannot be used"
    );
}

#[test]
fn network_options_need_a_model() {
    let o = voxpan(["run", "--input-size", "320", "--out", "/nonexistent/x"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--model"), "{err}");
}

/// `voxpan` with the network's backend ready: ONNX Runtime's library in the environment
/// when that backend is built in. `None` when the test must be skipped.
#[cfg(any(feature = "ort", feature = "tract"))]
fn network_voxpan(test: &str) -> Option<Command> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_voxpan"));
    if cfg!(feature = "ort") {
        cmd.env(
            voxpan_io::ORT_LIBRARY_ENV,
            voxpan_test_support::require_onnxruntime(test)?,
        );
    }
    Some(cmd)
}

#[cfg(any(feature = "ort", feature = "tract"))]
fn run(mut cmd: Command, args: &[&std::ffi::OsStr]) -> Output {
    cmd.args(args).output().unwrap()
}

#[cfg(any(feature = "ort", feature = "tract"))]
fn ok(o: Output) -> String {
    assert!(
        o.status.success(),
        "voxpan failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[cfg(any(feature = "ort", feature = "tract"))]
#[test]
fn segment_writes_flat_label_images_and_lists() {
    let Some(cmd) = network_voxpan("segment_writes_flat_label_images_and_lists") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (
        dir.path().join("000007_color.png"),
        dir.path().join("b.png"),
    );
    write_image(&a);
    write_image(&b);
    let out = dir.path().join("out");
    let model = tiny_model();
    let stdout = ok(run(
        cmd,
        &[
            "segment".as_ref(),
            "--model".as_ref(),
            model.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
            "--confidence".as_ref(),
            "0.05".as_ref(),
            a.as_os_str(),
            b.as_os_str(),
        ],
    ));
    assert!(
        stdout.contains("000007: ") && stdout.contains("b: "),
        "{stdout}"
    );
    let classes = voxpan_io::read_class_csv(&out.join("labels.csv")).unwrap();
    assert_eq!(classes.name(0), Some("chair"));
    assert_eq!(classes.entries.len(), 5);
    for id in ["000007", "b"] {
        let labels = voxpan_io::read_label_png(&out.join(format!("{id}_predicted.png"))).unwrap();
        assert_eq!(labels.dims(), (64, 48));
        let segments =
            voxpan_io::read_segments_json(&out.join(format!("{id}_labels.json"))).unwrap();
        // Every id in the image is listed, as a thing of one of the model's classes.
        for &l in labels.pixels() {
            assert!(l == 0 || segments.iter().any(|s| s.id == l), "{id}: id {l}");
        }
        for s in &segments {
            assert_eq!(s.is_thing, Some(true));
            assert!(classes.get(s.class_id.unwrap()).is_some());
            assert!(s.score.unwrap() > 0.05);
        }
    }
    // Into the images' own folder (a dataset's run folder): masks already there are
    // replaced only with --force.
    let own = |force: bool| {
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "segment".as_ref(),
            "--model".as_ref(),
            model.as_os_str(),
            "--out".as_ref(),
            dir.path().as_os_str(),
            a.as_os_str(),
        ];
        if force {
            args.push("--force".as_ref());
        }
        run(
            network_voxpan("segment into the images' folder").unwrap(),
            &args,
        )
    };
    ok(own(false));
    let masks = dir.path().join("000007_predicted.png");
    let written = std::fs::read(&masks).unwrap();
    std::fs::write(&masks, b"the dataset's masks").unwrap();
    let refused = own(false);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read(&masks).unwrap(), b"the dataset's masks");
    ok(own(true));
    assert_eq!(std::fs::read(&masks).unwrap(), written);
}

#[cfg(any(feature = "ort", feature = "tract"))]
#[test]
fn segment_errors_name_the_file_or_option() {
    let test = "segment_errors_name_the_file_or_option";
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("x_color.png");
    write_image(&image);
    let twin = dir.path().join("sub");
    std::fs::create_dir(&twin).unwrap();
    let twin = twin.join("x.png");
    write_image(&twin);
    let (out, missing, tiny) = (
        dir.path().join("out"),
        dir.path().join("missing.onnx"),
        tiny_model(),
    );
    let not_png = dir.path().join("y_color.png");
    std::fs::write(&not_png, b"not a png").unwrap();
    let cases: [(&[&Path], &[&str], String); 7] = [
        (
            &[&missing, &image],
            &[],
            format!("{}: no such file", missing.display()),
        ),
        (
            &[&tiny, &image],
            &["--input-size", "320"],
            "160x128 input".into(),
        ),
        (
            &[&tiny, &image],
            &["--confidence", "2"],
            "confidence = 2".into(),
        ),
        (&[&tiny, &image, &twin], &[], "both give frame id x".into()),
        (&[&tiny, &not_png], &[], not_png.display().to_string()),
        (
            &[dir.path(), &image],
            &[],
            format!("{}: a folder, not a model", dir.path().display()),
        ),
        // A bad image after a good one: refused before the good one's outputs are written.
        (
            &[&tiny, &image, &not_png],
            &[],
            not_png.display().to_string(),
        ),
    ];
    for (files, options, says) in cases {
        let Some(cmd) = network_voxpan(test) else {
            return;
        };
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "segment".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
            "--model".as_ref(),
            files[0].as_os_str(),
        ];
        args.extend(options.iter().map(std::ffi::OsStr::new));
        args.extend(files[1..].iter().map(|f| f.as_os_str()));
        let o = run(cmd, &args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(&says), "{says}: {err}");
        assert!(
            !out.join("x_predicted.png").exists(),
            "{says}: an output was written"
        );
    }
}

/// The real weights (GPL, fetched by tools/yolo/fetch_weights.sh, never committed).
#[cfg(any(feature = "ort", feature = "tract"))]
#[test]
fn yolov5s_seg_finds_the_chair_in_flat_frame_74() {
    let test = "yolov5s_seg_finds_the_chair_in_flat_frame_74";
    let Some(flat) = voxpan_test_support::require_flat_sample(test) else {
        return;
    };
    let Some(model) = voxpan_test_support::require_model("yolov5s-seg-640.onnx", test) else {
        return;
    };
    let Some(cmd) = network_voxpan(test) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let image = flat.join("run1/000074_color.png");
    ok(run(
        cmd,
        &[
            "segment".as_ref(),
            "--model".as_ref(),
            model.as_os_str(),
            "--out".as_ref(),
            dir.path().as_os_str(),
            image.as_os_str(),
        ],
    ));
    let classes = voxpan_io::read_class_csv(&dir.path().join("labels.csv")).unwrap();
    let segments = voxpan_io::read_segments_json(&dir.path().join("000074_labels.json")).unwrap();
    let labels = voxpan_io::read_label_png(&dir.path().join("000074_predicted.png")).unwrap();
    // ONNX Runtime from Python: a chair at 0.92, box (204, 259)-(317, 429).
    let chair = segments
        .iter()
        .find(|s| classes.name(s.class_id.unwrap()) == Some("chair"))
        .unwrap_or_else(|| panic!("no chair in {segments:?}"));
    assert!((chair.score.unwrap() - 0.92).abs() < 0.01, "{chair:?}");
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, _) in labels
        .pixels()
        .iter()
        .enumerate()
        .filter(|(_, l)| **l == chair.id)
    {
        let (x, y) = (i % 640, i / 640);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    // The mask lies in the box and fills most of its extent.
    assert!(
        x0 >= 204 && y0 >= 259 && x1 < 317 && y1 < 429,
        "{x0},{y0}-{x1},{y1}"
    );
    assert!(x1 - x0 > 80 && y1 - y0 > 120, "{x0},{y0}-{x1},{y1}");
}

/// `voxpan run --model` maps with the network (320 px: the quick one) and names the map's
/// instances with the model's classes.
#[cfg(any(feature = "ort", feature = "tract"))]
#[test]
fn run_with_a_network_maps_its_instances() {
    let test = "run_with_a_network_maps_its_instances";
    let Some(flat) = voxpan_test_support::require_flat_sample(test) else {
        return;
    };
    let Some(model) = voxpan_test_support::require_model("yolov5s-seg-320.onnx", test) else {
        return;
    };
    let Some(cmd) = network_voxpan(test) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let stdout = ok(run(
        cmd,
        &[
            "run".as_ref(),
            flat.as_os_str(),
            "--model".as_ref(),
            model.as_os_str(),
            "--frames".as_ref(),
            "60:80".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ],
    ));
    assert!(
        stdout.contains("11 frames") && stdout.contains("voxel PQ"),
        "{stdout}"
    );
    let names: Vec<String> = std::fs::read_dir(out.join("instances"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().any(|n| n.ends_with("_chair.ply")), "{names:?}");
}
