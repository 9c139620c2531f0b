//! `voxpan refine` end to end, as a user runs it.

use std::process::Command;

use voxpan_io::{read_label_png, require_flat_sample};

fn voxpan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_voxpan"))
}

#[test]
fn built_in_example_refines_over_covering_masks() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("refined.png");
    let result = voxpan()
        .args(["refine", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let stdout = String::from_utf8_lossy(&result.stdout);
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
    let result = voxpan()
        .arg("refine")
        .arg("--depth")
        .arg(run1.join("000100_depth.tiff"))
        .arg("--segments")
        .arg(run1.join("000100_predicted.png"))
        .arg("--labels")
        .arg(run1.join("000100_labels.json"))
        .args(["--rule", "paper", "--things-only", "--json", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let reports: serde_json::Value = serde_json::from_slice(&result.stdout).unwrap();
    let reports = reports.as_array().unwrap();
    assert!(!reports.is_empty());
    for r in reports {
        let total = r["kept"].as_u64().unwrap() + r["removed"].as_u64().unwrap();
        assert_eq!(total, r["pixels"].as_u64().unwrap());
    }
}

#[test]
fn errors_name_the_offending_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope_depth.tiff");
    let labels = dir.path().join("labels.png");
    image::GrayImage::from_raw(2, 2, vec![0, 1, 1, 0])
        .unwrap()
        .save(&labels)
        .unwrap();
    let result = voxpan()
        .arg("refine")
        .arg("--depth")
        .arg(&missing)
        .arg("--segments")
        .arg(&labels)
        .output()
        .unwrap();
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("nope_depth.tiff"), "{stderr}");

    // A depth map of another size than the labels.
    let depth = dir.path().join("d.tiff");
    voxpan_io::write_depth_tiff(&depth, &voxpan_core::DepthImage::filled(3, 2, 1.0)).unwrap();
    let result = voxpan()
        .arg("refine")
        .arg("--depth")
        .arg(&depth)
        .arg("--segments")
        .arg(&labels)
        .output()
        .unwrap();
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("3x2") && stderr.contains("2x2") && stderr.contains("d.tiff"),
        "{stderr}"
    );
}
