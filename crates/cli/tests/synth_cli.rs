//! `voxpan synth` writes a flat dataset the reader accepts, deterministically.

use std::process::Command;

use voxpan_dataset::{FlatDataset, FrameSource};

fn synth(out: &std::path::Path, seed: &str) {
    let result = Command::new(env!("CARGO_BIN_EXE_voxpan"))
        .args([
            "synth", "--preset", "tiny", "--frames", "3", "--seed", seed, "--out",
        ])
        .arg(out)
        .output()
        .unwrap();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(String::from_utf8_lossy(&result.stdout).contains("wrote 3 frames (160x120"));
}

#[test]
fn tiny_preset_round_trips_through_the_reader() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    synth(a.path(), "9");
    synth(b.path(), "9");
    let dataset = FlatDataset::open(a.path()).unwrap();
    assert_eq!(dataset.len(), 3);
    let frame = dataset.load(2).unwrap();
    assert!(frame.segments.is_some() && frame.ground_truth.is_some());
    // Same seed, same bytes.
    for name in [
        "run1/000002_depth.tiff",
        "run1/000002_predicted.png",
        "groundtruth_mesh.ply",
    ] {
        assert_eq!(
            std::fs::read(a.path().join(name)).unwrap(),
            std::fs::read(b.path().join(name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn rejects_nonsense_options() {
    let dir = tempfile::tempdir().unwrap();
    let result = Command::new(env!("CARGO_BIN_EXE_voxpan"))
        .args(["synth", "--frames", "0", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("at least one frame"));
}
