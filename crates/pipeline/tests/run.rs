//! The whole pipeline on the tiny synthetic preset.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_pipeline::{run, RunConfig};
use voxpan_sim::{generate, SynthConfig};

#[test]
fn writes_every_output_and_skips_a_corrupted_frame() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let config = SynthConfig {
        frames: 12,
        ..SynthConfig::tiny()
    };
    generate(&data, &config, |_| {}).unwrap();
    // Corrupt a frame in the middle.
    std::fs::write(data.join("run1/000005_depth.tiff"), b"garbage").unwrap();
    let source: Arc<dyn FrameSource> = Arc::new(FlatDataset::open(&data).unwrap());
    let out = dir.path().join("out");
    let run_config = RunConfig {
        voxel_size: 0.05,
        save_refined: true,
        ..RunConfig::default()
    };
    let report = run(
        source,
        (0..12).collect(),
        &run_config,
        &out,
        &AtomicBool::new(false),
        |_| {},
    )
    .unwrap();
    assert_eq!(report.frames, 11);
    assert_eq!(report.skipped.len(), 1);
    assert!(report.skipped[0].0 == "000005" && report.skipped[0].1.contains("000005_depth.tiff"));
    for f in [
        "map.voxpan",
        "mesh_rgb.ply",
        "mesh_instance.ply",
        "mesh_class.ply",
        "metrics.json",
        "refined/000004.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(std::fs::read_dir(out.join("instances")).unwrap().count() >= 3);
    assert!(report.triangles > 1000 && report.instances >= 3);
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    for stage in ["decode", "fill", "refine", "track", "integrate", "mesh"] {
        assert!(
            metrics["report"]["stage_ms"][stage].as_f64().is_some(),
            "stage {stage}"
        );
    }
    assert_eq!(metrics["report"]["frames"], 11);
    // The saved map loads and holds the tracked instances.
    let map = voxpan_map::io::load(&out.join("map.voxpan")).unwrap();
    assert_eq!(map.instances.len(), report.instances);
}

#[test]
fn a_stop_request_still_writes_the_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    generate(
        &data,
        &SynthConfig {
            frames: 3,
            ..SynthConfig::tiny()
        },
        |_| {},
    )
    .unwrap();
    let source: Arc<dyn FrameSource> = Arc::new(FlatDataset::open(&data).unwrap());
    let stop = AtomicBool::new(false);
    let out = dir.path().join("out");
    let report = run(
        source,
        vec![0, 1, 2],
        &RunConfig::default(),
        &out,
        &stop,
        |done| {
            if done == 1 {
                stop.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        },
    )
    .unwrap();
    assert!(report.stopped_early && report.frames == 1);
    assert!(out.join("map.voxpan").is_file());
}
