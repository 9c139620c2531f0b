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
fn config_files_are_partial_and_strict() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.toml");
    std::fs::write(&path, "voxel_size = 0.05\nrefine = \"paper\"\n").unwrap();
    let c = RunConfig::from_toml_file(&path).unwrap();
    assert_eq!(
        (c.voxel_size, c.refine),
        (0.05, voxpan_pipeline::Refinement::Paper)
    );
    assert_eq!(c.max_range, RunConfig::default().max_range);
    std::fs::write(&path, "voxel_sise = 0.05\n").unwrap();
    let err = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(
        err.contains("c.toml") && err.contains("voxel_sise"),
        "{err}"
    );
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

#[test]
fn the_mesh_of_the_synthetic_world_matches_its_ground_truth() {
    use voxpan_core::nalgebra::Point3;
    use voxpan_sim::{scene_mesh, MaskErrors, Scene, SensorModel};

    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let config = SynthConfig {
        frames: 20,
        sensor: SensorModel::ideal(),
        masks: MaskErrors::new(0.0),
        ..SynthConfig::tiny()
    };
    generate(&data, &config, |_| {}).unwrap();
    let source: Arc<dyn FrameSource> = Arc::new(FlatDataset::open(&data).unwrap());
    let voxel = 0.04;
    let out = dir.path().join("out");
    let run_config = RunConfig {
        voxel_size: voxel,
        max_range: 10.0,
        ..RunConfig::default()
    };
    run(
        source,
        (0..20).collect(),
        &run_config,
        &out,
        &AtomicBool::new(false),
        |_| {},
    )
    .unwrap();

    let mut map = voxpan_map::io::load(&out.join("map.voxpan")).unwrap();
    map.layer.blocks.values_mut().for_each(|b| b.updated = true);
    let mut meshes = voxpan_map::MeshLayer::default();
    meshes.update(&mut map.layer);
    let vertices: Vec<Point3<f64>> = meshes
        .combined()
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let truth = scene_mesh(&Scene::generate(config.seed));
    let triangles = truth.triangle_points();
    // Completeness over the truth the cameras saw: samples inside the observed band.
    let layer = &map.layer;
    let seen = |p: &Point3<f64>| {
        layer
            .voxel_at(p)
            .is_some_and(|v| v.observed() && (v.distance.abs() as f64) < voxel)
    };
    let scores =
        voxpan_eval::surface::surface_scores(&vertices, triangles, voxel, voxel / 2.0, seen);
    eprintln!("{scores:?}");
    assert!(scores.accuracy_mean < 0.5 * voxel, "{scores:?}");
    assert!(scores.accuracy_within > 95.0, "{scores:?}");
    assert!(scores.completeness_within > 90.0, "{scores:?}");
}
