//! A whole run on the synthetic world, scored against its ground-truth mesh.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_map::Coloring;
use voxpan_pipeline::protocols::{panoptic_against_reference, surface_report};
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

/// With perfect masks and exact depth, the instances the voxel PQ matches are the objects
/// they were made from: the match names the object's ground-truth id and class, and there is
/// one match per true positive.
#[test]
fn each_matched_instance_names_the_true_object_it_was_made_from() {
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
    let mut config = Config::default();
    config.tsdf.voxel_size = 0.04;
    config.tsdf.max_range = 10.0;
    let frames: Vec<usize> = (0..20).collect();
    let (mapped, _) = run_dataset(
        source.clone(),
        frames.clone(),
        &config,
        &mut RunFolder::open(&dir.path().join("out")).unwrap(),
        &AtomicBool::new(false),
        |_| {},
    )
    .unwrap();
    let truth = panoptic_against_reference(
        &source,
        &frames,
        &config,
        &mapped.map,
        |_| {},
        &std::sync::atomic::AtomicBool::new(false),
    )
    .unwrap()
    .expect("the synthetic world has ground truth");
    eprintln!("{:?}\n{:#?}", truth.scores, truth.matches);
    assert_eq!(truth.matches.len(), truth.scores.all.tp);
    // The objects left unmatched are the false negatives, each with where its voxels went.
    assert_eq!(truth.missed.len(), truth.scores.all.fn_);
    assert_eq!(
        truth.matches.len() + truth.missed.len(),
        truth.scores.objects
    );
    for m in &truth.missed {
        let held: usize = m.holders.iter().map(|h| h.1).sum();
        assert!(m.voxels > 0 && held + m.unlabelled <= m.voxels, "{m:?}");
        assert!(m.holders.windows(2).all(|w| w[0].1 >= w[1].1), "{m:?}");
        assert!(
            truth.matches.iter().all(|t| t.truth_id != m.truth_id),
            "{m:?} is also matched"
        );
    }
    // Floor, ceiling, walls and most objects.
    assert!(truth.matches.len() >= 5, "{:?}", truth.matches);
    let classes = source.ground_truth_classes().unwrap();
    let names = source.ground_truth_class_names().unwrap();
    let instances = mapped.map.instances();
    let mut objects = Vec::new();
    for m in &truth.matches {
        assert!(m.iou > 0.5 && m.iou <= 1.0, "{m:?}");
        let id = m.truth_id.expect("a ground-truth id");
        objects.push(id);
        // The class is the ground truth's own for that id.
        let class = classes.get(id as u32).expect("a listed object").class_id;
        assert_eq!(m.class.as_deref(), names.get(&class).map(String::as_str));
        // Perfect masks: the instance carries the class of the object it matched.
        let instance = instances.iter().find(|i| i.id == m.instance).unwrap();
        assert_eq!(instance.class_name, m.class, "{m:?}");
        assert_eq!(truth.match_of(m.instance), Some(m));
    }
    objects.sort();
    objects.dedup();
    assert_eq!(
        objects.len(),
        truth.matches.len(),
        "each object matched once"
    );
}
