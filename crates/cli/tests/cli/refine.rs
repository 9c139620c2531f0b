//! `voxpan refine` end to end, as a user runs it.

use std::ffi::OsStr;

use super::common::{voxpan, voxpan_ok};
use voxpan_io::read_label_png;
use voxpan_test_support::require_flat_sample;

#[test]
fn built_in_example_refines_over_covering_masks() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("refined.png");
    let stdout = voxpan_ok([OsStr::new("refine"), OsStr::new("--out"), out.as_os_str()]);
    // The box (1) and ball (2) rows of the IoU table go up to 1.000.
    assert!(stdout.contains("    1  0.808 -> 1.000"), "{stdout}");
    assert!(stdout.contains("    2  0.749 -> 1.000"), "{stdout}");
    assert!(read_label_png(&out).is_ok());
}

#[test]
fn refines_a_flat_frame_with_json_output() {
    let Some(flat) = require_flat_sample("refines_a_flat_frame_with_json_output") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.png");
    let run1 = flat.join("run1");
    let (depth, segments, labels) = (
        run1.join("000100_depth.tiff"),
        run1.join("000100_predicted.png"),
        run1.join("000100_labels.json"),
    );
    let stdout = voxpan_ok(
        [
            OsStr::new("refine"),
            OsStr::new("--depth"),
            depth.as_os_str(),
            OsStr::new("--segments"),
            segments.as_os_str(),
            OsStr::new("--labels"),
            labels.as_os_str(),
        ]
        .into_iter()
        .chain(["--rule", "paper", "--things-only", "--json", "--out"].map(OsStr::new))
        .chain([out.as_os_str()]),
    );
    let reports: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let reports = reports.as_array().unwrap();
    assert!(!reports.is_empty());
    for r in reports {
        let total = r["kept"].as_u64().unwrap() + r["removed"].as_u64().unwrap();
        assert_eq!(total, r["pixels"].as_u64().unwrap());
    }
}

/// Runs `voxpan refine --depth D --segments S`, expecting failure; returns stderr.
fn refine_fails(depth: &std::path::Path, segments: &std::path::Path) -> String {
    let result = voxpan([
        OsStr::new("refine"),
        OsStr::new("--depth"),
        depth.as_os_str(),
        OsStr::new("--segments"),
        segments.as_os_str(),
    ]);
    assert!(!result.status.success());
    String::from_utf8_lossy(&result.stderr).into_owned()
}

#[test]
fn errors_name_the_offending_file() {
    let dir = tempfile::tempdir().unwrap();
    let labels = dir.path().join("labels.png");
    image::GrayImage::from_raw(2, 2, vec![0, 1, 1, 0])
        .unwrap()
        .save(&labels)
        .unwrap();
    let stderr = refine_fails(&dir.path().join("nope_depth.tiff"), &labels);
    assert!(stderr.contains("nope_depth.tiff"), "{stderr}");

    // A depth map of another size than the labels.
    let depth = dir.path().join("d.tiff");
    voxpan_io::write_depth_tiff(&depth, &voxpan_core::DepthImage::filled(3, 2, 1.0)).unwrap();
    let stderr = refine_fails(&depth, &labels);
    assert!(
        stderr.contains("3x2") && stderr.contains("2x2") && stderr.contains("d.tiff"),
        "{stderr}"
    );
}
