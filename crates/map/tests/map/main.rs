//! voxpan-map through its facade, on analytic and synthetic scenes (one test binary).

mod association;
mod changes;
mod esdf;
mod fusion;
mod labels;
mod limits;
mod render;

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{Frame, Intrinsics, Pose, Segments};
use voxpan_map::{MapConfig, PanopticMap};
use voxpan_sim::trajectory::look_along;
use voxpan_sim::{Object, Scene, Shape, Surface, SynthConfig, render};

pub const VOXEL: f64 = 0.02;

/// 160×120 pixels, 90° horizontal field of view.
pub fn camera() -> Intrinsics {
    SynthConfig::tiny().intrinsics()
}

/// An empty room-sized scene with one object made of `shape`.
pub fn scene_with(shape: Shape) -> Scene {
    let mut scene = Scene::empty(Vector3::new(10.0, 10.0, 10.0));
    scene.add(Object {
        instance_id: 1,
        class_id: 9,
        is_thing: true,
        color: [200, 50, 50],
        surface: Surface::Plain,
        specular: false,
        shapes: vec![shape],
    });
    scene
}

/// The ideal view of `scene` from `pose`, as a frame (with the ground truth's instances).
pub fn view(scene: &Scene, pose: &Pose, k: &Intrinsics) -> Frame {
    let v = render(scene, pose, k);
    Frame {
        id: "view".into(),
        timestamp: 0.0,
        color: v.color,
        depth: v.depth,
        pose: *pose,
        intrinsics: *k,
        segments: None,
        ground_truth: Some(v.instances),
    }
}

/// Fuses views of `scene` from `positions`, all looking at `target` (no segments).
pub fn fuse(scene: &Scene, positions: &[Point3<f64>], target: Point3<f64>) -> PanopticMap {
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    for p in positions {
        let pose = look_along(*p, target - p);
        map.integrate(view(scene, &pose, &camera()).view(), None::<&Segments>)
            .unwrap();
    }
    map
}
