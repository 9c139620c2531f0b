//! The synthetic world: analytic rendering checks, the error model's properties, the flat
//! round trip and reproducibility.

use voxpan_core::Intrinsics;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_io::read_ply;
use voxpan_sim::trajectory::look_along;
use voxpan_sim::*;

fn camera(width: usize, height: usize) -> Intrinsics {
    Intrinsics {
        width,
        height,
        fx: width as f64 / 2.0,
        fy: width as f64 / 2.0,
        cx: width as f64 / 2.0,
        cy: height as f64 / 2.0,
    }
}

fn object(id: u16, thing: bool, shape: Shape) -> Object {
    Object {
        instance_id: id,
        class_id: if thing { 9 } else { 1 },
        is_thing: thing,
        color: [200, 100, 50],
        surface: Surface::Plain,
        specular: false,
        shapes: vec![shape],
    }
}

#[test]
fn a_plane_at_known_distance_gives_exact_depth() {
    let mut scene = Scene::empty(Vector3::new(10.0, 10.0, 10.0));
    // A wall whose near face is the plane y = 3, the camera at the origin looking along +y.
    scene.add(object(
        1,
        false,
        Shape::Cuboid {
            center: Point3::new(0.0, 3.5, 0.0),
            half: Vector3::new(50.0, 0.5, 50.0),
            yaw: 0.0,
        },
    ));
    let pose = look_along(Point3::origin(), Vector3::y());
    let view = render(&scene, &pose, &camera(64, 48));
    assert!(
        view.depth.pixels().iter().all(|&d| (d - 3.0).abs() < 1e-6),
        "planar depth is 3 everywhere"
    );
    assert!(view.instances.pixels().iter().all(|&i| i == 1));
}

#[test]
fn a_sphere_silhouette_has_the_analytic_area() {
    let (d, r) = (4.0, 0.5);
    let mut scene = Scene::empty(Vector3::new(10.0, 10.0, 10.0));
    scene.add(object(
        7,
        true,
        Shape::Sphere {
            center: Point3::new(0.0, d, 0.0),
            radius: r,
        },
    ));
    let k = camera(640, 480);
    let view = render(&scene, &look_along(Point3::origin(), Vector3::y()), &k);
    let area = view.instances.pixels().iter().filter(|&&i| i == 7).count() as f64;
    // On-axis sphere: a disc of radius f·r / sqrt(d² - r²) pixels.
    let radius = k.fx * r / (d * d - r * r).sqrt();
    let expected = std::f64::consts::PI * radius * radius;
    assert!(
        (area / expected - 1.0).abs() < 0.01,
        "area {area} vs {expected}"
    );
    // Its nearest point is at depth d - r.
    let nearest = view
        .depth
        .pixels()
        .iter()
        .copied()
        .filter(|&z| z > 0.0)
        .fold(f32::MAX, f32::min);
    assert!((nearest as f64 - (d - r)).abs() < 1e-3);
}

#[test]
fn over_coverage_only_adds_background_next_to_the_object() {
    let scene = Scene::generate(3);
    let config = SynthConfig {
        masks: MaskErrors::over_cover_only(1.0),
        sensor: SensorModel::ideal(),
        ..SynthConfig::tiny()
    };
    let k = config.intrinsics();
    let poses = trajectory(&scene, 10);
    let mut checked = 0;
    for (i, pose) in poses.iter().enumerate() {
        let view = render(&scene, pose, &k);
        let mut rng = Rand::stream(7, i as u64);
        let (pred, segments, sources) =
            config
                .masks
                .predict_traced(&view.instances, &view.depth, &scene, &mut rng);
        let (w, h) = pred.dims();
        for (seg, source) in segments
            .iter()
            .zip(&sources)
            .filter(|(s, _)| s.is_thing == Some(true))
        {
            let truth = source.expect("over-coverage alone makes no fragments");
            let truth_pixels: Vec<(i64, i64)> = (0..w * h)
                .filter(|&j| view.instances.pixels()[j] == truth)
                .map(|j| ((j % w) as i64, (j / w) as i64))
                .collect();
            let mut depths: Vec<f32> = truth_pixels
                .iter()
                .map(|&(x, y)| *view.depth.get(x as usize, y as usize))
                .collect();
            depths.sort_by(f32::total_cmp);
            let median = depths[depths.len() / 2];
            let r = config.masks.max_bleed() as i64;
            for j in 0..w * h {
                if pred.pixels()[j] != seg.id || view.instances.pixels()[j] == truth {
                    continue;
                }
                let (x, y) = ((j % w) as i64, (j / w) as i64);
                assert!(
                    view.depth.pixels()[j] > median,
                    "added pixel in front of the object"
                );
                assert!(
                    truth_pixels
                        .iter()
                        .any(|&(a, b)| (a - x).pow(2) + (b - y).pow(2) <= r * r),
                    "added pixel farther than {r} px"
                );
                checked += 1;
            }
        }
    }
    assert!(
        checked > 100,
        "the test must see over-coverage ({checked} pixels)"
    );
}

#[test]
fn zero_strength_predicts_the_truth_with_new_ids() {
    let scene = Scene::generate(5);
    let config = SynthConfig {
        masks: MaskErrors::new(0.0),
        sensor: SensorModel::ideal(),
        ..SynthConfig::tiny()
    };
    let frame = synth_frame(&scene, &config, 4, &trajectory(&scene, 20)[4]);
    let pred = frame.segments.unwrap().labels;
    let truth = frame.ground_truth.unwrap();
    // A bijection between predicted and true ids.
    let mut map = std::collections::BTreeMap::new();
    for (&p, &t) in pred.pixels().iter().zip(truth.pixels()) {
        assert_eq!(*map.entry(p).or_insert(t), t);
    }
    let values: std::collections::BTreeSet<_> = map.values().collect();
    assert_eq!(values.len(), map.len());
}

#[test]
fn the_seed_reproduces_and_changes_everything() {
    let config = SynthConfig::tiny();
    let scene = Scene::generate(config.seed);
    let pose = trajectory(&scene, config.frames)[7];
    let a = synth_frame(&scene, &config, 7, &pose);
    let b = synth_frame(&Scene::generate(config.seed), &config, 7, &pose);
    assert_eq!(a, b);
    let other = SynthConfig { seed: 2, ..config };
    let c = synth_frame(
        &Scene::generate(2),
        &other,
        7,
        &trajectory(&Scene::generate(2), 20)[7],
    );
    assert_ne!(a.depth, c.depth);
    assert_ne!(Scene::generate(1), Scene::generate(2));
}

#[test]
fn a_mask_seed_redraws_the_masks_alone() {
    let config = SynthConfig::tiny();
    let scene = Scene::generate(config.seed);
    let poses = trajectory(&scene, config.frames);
    let draw = |mask_seed| {
        let config = SynthConfig {
            mask_seed,
            ..config
        };
        (0..config.frames)
            .map(|i| synth_frame(&scene, &config, i, &poses[i]))
            .collect::<Vec<_>>()
    };
    let (own, other, again) = (draw(None), draw(Some(7)), draw(Some(7)));
    assert_eq!(other, again, "a mask seed reproduces");
    let masks = |f: &voxpan_core::Frame| f.segments.clone().unwrap();
    let mut redrawn = 0;
    for (a, b) in own.iter().zip(&other) {
        assert_eq!(a.depth, b.depth);
        assert_eq!(a.color, b.color);
        assert_eq!(a.ground_truth, b.ground_truth);
        assert_eq!(a.pose, b.pose);
        redrawn += usize::from(masks(a) != masks(b));
    }
    assert_eq!(
        redrawn, config.frames,
        "every frame's masks are drawn again"
    );
}

#[test]
fn written_sequences_read_back_identically() {
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig {
        frames: 4,
        ..SynthConfig::tiny()
    };
    let summary = generate(dir.path(), &config, |_| {}).unwrap();
    assert_eq!(summary.frames, 4);
    let dataset = FlatDataset::open(dir.path()).unwrap();
    assert_eq!(dataset.len(), 4);
    let scene = Scene::generate(config.seed);
    let poses = trajectory(&scene, config.frames);
    for (i, pose) in poses.iter().enumerate() {
        let read = dataset.load(i).unwrap();
        let made = synth_frame(&scene, &config, i, pose);
        assert_eq!(read.color, made.color);
        assert_eq!(read.depth, made.depth);
        assert_eq!(read.segments, made.segments);
        assert_eq!(read.ground_truth, made.ground_truth);
        assert!(
            (read.pose.to_homogeneous() - made.pose.to_homogeneous())
                .abs()
                .max()
                < 1e-12
        );
        assert!((read.timestamp - made.timestamp).abs() < 1e-9);
        assert_eq!(read.intrinsics, made.intrinsics);
    }
    // The label CSVs name every instance and class the frames use.
    assert!(dataset.ground_truth_classes.as_ref().unwrap().entries.len() == scene.objects.len());
    let ply = std::fs::read(dir.path().join("groundtruth_mesh.ply")).unwrap();
    assert!(ply.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
    // The mesh reads back as written.
    assert_eq!(
        read_ply(&dir.path().join("groundtruth_mesh.ply")).unwrap(),
        scene_mesh(&scene)
    );
    std::fs::write(dir.path().join("bad.ply"), &ply[..ply.len() - 5]).unwrap();
    assert!(
        read_ply(&dir.path().join("bad.ply"))
            .unwrap_err()
            .to_string()
            .contains("bad.ply")
    );
}

#[test]
fn mesh_of_a_unit_cube_has_area_six() {
    let mut scene = Scene::empty(Vector3::new(1.0, 1.0, 1.0));
    scene.add(object(
        4,
        true,
        Shape::Cuboid {
            center: Point3::new(0.5, 0.5, 0.5),
            half: Vector3::new(0.5, 0.5, 0.5),
            yaw: 0.7,
        },
    ));
    let mesh = scene_mesh(&scene);
    assert!((mesh.area() - 6.0).abs() < 1e-5);
    assert!(mesh.instances.iter().all(|&i| i == 4));
}

#[test]
fn sensor_model_effects() {
    let scene = Scene::generate(1);
    let k = SynthConfig::tiny().intrinsics();
    let view = render(&scene, &trajectory(&scene, 20)[3], &k);
    let ideal = SensorModel::ideal().measure(
        &view.depth,
        &view.color,
        &view.instances,
        &scene,
        &mut Rand::new(1),
    );
    assert_eq!(ideal, view.depth);
    let sensor = SensorModel {
        holes: false,
        ..SensorModel::default()
    };
    let noisy = sensor.measure(
        &view.depth,
        &view.color,
        &view.instances,
        &scene,
        &mut Rand::new(1),
    );
    for (&m, &t) in noisy.pixels().iter().zip(view.depth.pixels()) {
        if m > 0.0 {
            // Millimetre steps, within 6σ of the truth.
            assert!(((m as f64) * 1000.0 - ((m as f64) * 1000.0).round()).abs() < 1e-3);
            let sigma = 0.001 + 0.002 * (t as f64).powi(2);
            assert!(((m - t) as f64).abs() < 6.0 * sigma + 0.001);
        }
    }
}
