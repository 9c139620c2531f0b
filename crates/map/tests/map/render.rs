//! The ray cast sees what the camera saw: depth, colour, instances and normals of the fused
//! map match the scene rendered directly.

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{Segment, Segments, is_valid_depth};
use voxpan_map::{MapConfig, PanopticMap};
use voxpan_sim::Shape;
use voxpan_sim::trajectory::look_along;

use super::{camera, scene_with, view};

#[test]
fn rendering_the_map_reproduces_the_depth_it_was_built_from() {
    let (center, r) = (Point3::new(0.1, 2.0, -0.1), 0.45);
    let scene = scene_with(Shape::Sphere { center, radius: r });
    let k = camera();
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let poses: Vec<_> = (0..5)
        .map(|i| {
            let p = Point3::new(-0.4 + 0.2 * i as f64, 0.0, 0.1 * (i % 2) as f64);
            look_along(p, center - p)
        })
        .collect();
    for pose in &poses {
        let frame = view(&scene, pose, &k);
        // The ground truth's ids as segments: the ball becomes one map instance.
        let labels = frame.ground_truth.clone().unwrap();
        let segments = Segments {
            labels,
            segments: vec![Segment::bare(1)],
        };
        map.integrate(frame.view(), Some(&segments)).unwrap();
    }
    let ball = map.instances()[0].id;
    // A viewpoint between the fused ones.
    let p = Point3::new(-0.1, 0.05, 0.05);
    let pose = look_along(p, center - p);
    let truth = view(&scene, &pose, &k);
    let seen = map.render(&k, &pose);
    let (mut errors, mut wrong_instance, mut bent_normals) = (Vec::new(), 0, 0);
    for y in 0..k.height {
        for x in 0..k.width {
            let (t, s) = (*truth.depth.get(x, y), *seen.depth.get(x, y));
            let on_ball = *truth.ground_truth.as_ref().unwrap().get(x, y) == 1;
            // Away from the silhouette, where a pixel can see either side.
            let inside = (1..=2).all(|d| {
                let g = truth.ground_truth.as_ref().unwrap();
                x >= d
                    && y >= d
                    && x + d < k.width
                    && y + d < k.height
                    && *g.get(x - d, y) == 1
                    && *g.get(x + d, y) == 1
                    && *g.get(x, y - d) == 1
                    && *g.get(x, y + d) == 1
            });
            if !(on_ball && inside && is_valid_depth(t)) {
                continue;
            }
            assert!(is_valid_depth(s), "no surface at ({x}, {y})");
            errors.push((s - t).abs());
            wrong_instance += (*seen.instances.get(x, y) != ball) as usize;
            // Normals agree with the sphere's (where the map observed the voxels around the
            // surface; behind a curved surface's limb the projective band has gaps).
            let n = Vector3::from(seen.normals.get(x, y).map(f64::from));
            let hit = pose * Point3::from(k.ray(x as f64, y as f64) * s as f64);
            bent_normals += (n.dot(&(hit - center).normalize()) < 0.95) as usize;
        }
    }
    let compared = errors.len();
    assert!(compared > 500, "{compared} pixels compared");
    errors.sort_by(f32::total_cmp);
    let (median, worst) = (errors[compared / 2], errors[compared - 1]);
    // Five ideal views fuse to within a few millimetres (measured: median 1.9 mm, mean signed
    // +0.5 mm: no bias); near the limbs of the fused views the surface is off by up to a voxel.
    assert!(
        median < 0.15 * 0.02 && worst < 1.5 * 0.02,
        "depth error median {median}, worst {worst}"
    );
    assert!(
        wrong_instance * 100 < compared,
        "{wrong_instance} of {compared} with the wrong instance"
    );
    assert!(
        bent_normals * 50 < compared,
        "{bent_normals} of {compared} normals off"
    );
    // The ball is red; its rendered colour too.
    let c = seen.color.get(k.width / 2, k.height / 2);
    assert!(c[0] > c[1] + 50, "{c:?}");
    // Nothing behind the camera: looking away, the map is empty.
    let away = map.render(&k, &look_along(p, p - center));
    assert!(away.depth.pixels().iter().all(|&d| d == 0.0));
}

/// Between keyframes a frame's masks are the map's instances at the surface it measures: on
/// a map built from ground-truth masks, those masks are the frame's own ground truth wherever
/// they label a pixel, and they label most of the frame.
#[test]
fn carried_masks_are_the_true_instances_where_the_map_knows_the_surface() {
    use voxpan_sim::{Scene, SynthConfig, synth_frame, trajectory};
    let config = SynthConfig {
        frames: 12,
        ..SynthConfig::tiny()
    };
    let scene = Scene::generate(config.seed);
    let poses = trajectory(&scene, config.frames);
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let identified = |frame: &voxpan_core::Frame| {
        let labels = frame.ground_truth.clone().unwrap();
        let mut ids: Vec<u16> = labels
            .pixels()
            .iter()
            .copied()
            .filter(|&l| l != 0)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        Segments {
            labels,
            segments: ids.into_iter().map(Segment::bare).collect(),
        }
    };
    for (i, pose) in poses.iter().enumerate().filter(|(i, _)| i % 2 == 0) {
        let frame = synth_frame(&scene, &config, i, pose);
        map.integrate_identified(frame.view(), &identified(&frame))
            .unwrap();
    }
    let (mut labelled, mut right, mut valid) = (0, 0, 0);
    for (i, pose) in poses.iter().enumerate().filter(|(i, _)| i % 2 == 1) {
        let frame = synth_frame(&scene, &config, i, pose);
        let carried = map.carried_segments(&frame.depth, &frame.intrinsics, pose);
        let truth = frame.ground_truth.as_ref().unwrap();
        for ((&c, &t), &z) in carried
            .labels
            .pixels()
            .iter()
            .zip(truth.pixels())
            .zip(frame.depth.pixels())
        {
            valid += usize::from(is_valid_depth(z) && t != 0);
            if c != 0 {
                labelled += 1;
                right += usize::from(c == t);
                assert!(carried.get(c).is_some(), "instance {c} has no segment");
            }
        }
    }
    let (share_right, share_labelled) = (
        right as f64 / labelled as f64,
        labelled as f64 / valid as f64,
    );
    // Measured: 99.8 % right, 67 % labelled (twelve frames span the whole trajectory, so each
    // frame between two keyframes sees surface neither saw, and an instance in one keyframe
    // only is not shown; unlabelled pixels stay 0).
    assert!(
        share_right > 0.98,
        "{right} of {labelled} carried labels right"
    );
    assert!(
        share_labelled > 0.6,
        "{labelled} of {valid} pixels labelled"
    );
}
