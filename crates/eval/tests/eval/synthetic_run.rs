//! A whole run on the synthetic world, scored against its ground-truth mesh.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_eval::protocols::surface_report;
use voxpan_map::Coloring;
use voxpan_pipeline::{Config, RunFolder, run_dataset};
use voxpan_sim::{MaskErrors, SensorModel, SynthConfig, generate};

#[test]
fn the_mesh_of_the_synthetic_world_matches_its_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let synth = SynthConfig {
        frames: 20,
        sensor: SensorModel::ideal(),
        masks: MaskErrors::new(0.0),
        ..SynthConfig::tiny()
    };
    generate(&data, &synth, |_| {}).unwrap();
    let source: Arc<dyn FrameSource> = Arc::new(FlatDataset::open(&data).unwrap());
    let voxel = 0.04;
    let mut config = Config::default();
    config.tsdf.voxel_size = voxel;
    config.tsdf.max_range = 10.0;
    let (mut mapped, _) = run_dataset(
        source,
        (0..20).collect(),
        &config,
        &mut RunFolder::open(&dir.path().join("out")).unwrap(),
        &AtomicBool::new(false),
        |_| {},
    )
    .unwrap();
    let truth = voxpan_io::read_ply(&data.join("groundtruth_mesh.ply")).unwrap();
    let mesh = mapped.map.mesh(Coloring::Rgb);
    let s = surface_report(&mapped.map, &mesh, &truth);
    eprintln!("{s:?}");
    // Ideal depth: every vertex near the truth, and the observed truth covered.
    assert!(s.accuracy_median_m < 0.25 * voxel, "{s:?}");
    assert!(s.accuracy_mean_m < 0.5 * voxel, "{s:?}");
    assert!(s.accuracy_p95_m < voxel, "{s:?}");
    assert!(s.accuracy_within > 95.0, "{s:?}");
    assert!(s.completeness_within > 90.0, "{s:?}");
    // Perfect masks: nearly every labelled voxel agrees with its instance's object.
    assert!(s.label_agreement > 95.0, "{s:?}");
}
