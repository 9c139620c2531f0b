//! Analytic scenes: the fused zero crossing lies on the true surface; the map file round-trips
//! and rejects corruption.

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{ColorImage, DepthImage, Intrinsics};
use voxpan_map::{io, Layer, TsdfConfig, TsdfIntegrator};
use voxpan_sim::trajectory::look_along;
use voxpan_sim::{render, Object, Scene, Shape, Surface, SynthConfig};

const VOXEL: f64 = 0.02;

/// 160×120 pixels, 90° horizontal field of view.
fn camera() -> Intrinsics {
    SynthConfig::tiny().intrinsics()
}

fn scene_with(shape: Shape) -> Scene {
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

/// Fuses views of `scene` from `positions`, all looking at `target`.
fn fuse(scene: &Scene, positions: &[Point3<f64>], target: Point3<f64>) -> Layer {
    let mut layer = Layer::new(VOXEL);
    let integrator = TsdfIntegrator::new(TsdfConfig::default());
    for p in positions {
        let pose = look_along(*p, target - p);
        let view = render(scene, &pose, &camera());
        integrator.integrate(
            &mut layer,
            &view.depth,
            Some(&view.color),
            None,
            &pose,
            &camera(),
        );
    }
    layer
}

/// Where the fused distance changes sign along `origin + t·dir`, by linear interpolation
/// between voxel samples.
fn zero_crossing(layer: &Layer, origin: Point3<f64>, dir: Vector3<f64>, t_max: f64) -> Option<f64> {
    let step = VOXEL / 4.0;
    let mut previous: Option<(f64, f32)> = None;
    let mut t = 0.0;
    while t < t_max {
        if let Some(v) = layer.voxel_at(&(origin + dir * t)).filter(|v| v.observed()) {
            if let Some((t0, d0)) = previous {
                if d0 > 0.0 && v.distance <= 0.0 {
                    return Some(t0 + (t - t0) * (d0 / (d0 - v.distance)) as f64);
                }
            }
            previous = Some((t, v.distance));
        }
        t += step;
    }
    None
}

#[test]
fn a_plane_is_fused_within_half_a_voxel() {
    // A wall whose face is the plane y = 2.
    let scene = scene_with(Shape::Cuboid {
        center: Point3::new(0.0, 2.5, 0.0),
        half: Vector3::new(5.0, 0.5, 5.0),
        yaw: 0.0,
    });
    let views = [
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(0.3, 0.1, 0.1),
        Point3::new(-0.2, -0.1, -0.2),
    ];
    let layer = fuse(&scene, &views, Point3::new(0.0, 2.0, 0.0));
    for x in [-0.5, 0.0, 0.37] {
        for z in [-0.3, 0.0, 0.21] {
            let t = zero_crossing(&layer, Point3::new(x, 0.5, z), Vector3::y(), 2.5)
                .expect("a surface");
            assert!(
                (0.5 + t - 2.0).abs() < VOXEL / 2.0,
                "at ({x}, {z}): surface at y = {}",
                0.5 + t
            );
        }
    }
    // The colour of surface voxels is the wall's (lit: 0.45 + 0.55·|n·l|).
    let v = layer
        .voxel_at(&Point3::new(0.0, 2.0 - VOXEL / 2.0, 0.0))
        .unwrap();
    assert!(v.color[0] > v.color[1] + 50, "{:?}", v.color);
}

#[test]
fn a_sphere_is_fused_within_half_a_voxel() {
    let (center, r) = (Point3::new(0.0, 2.0, 0.0), 0.4);
    let scene = scene_with(Shape::Sphere { center, radius: r });
    let views: Vec<Point3<f64>> = (0..8)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 8.0;
            center + Vector3::new(1.5 * a.cos(), 1.5 * a.sin(), 0.3 * (k % 2) as f64)
        })
        .collect();
    let layer = fuse(&scene, &views, center);
    let mut worst: f64 = 0.0;
    for k in 0..16 {
        let a = std::f64::consts::TAU * (k as f64 + 0.5) / 16.0;
        let dir = Vector3::new(a.cos(), a.sin(), 0.0);
        // Walk inwards from outside the sphere.
        let origin = center + dir * (r + 0.3);
        let t = zero_crossing(&layer, origin, -dir, 0.3 + r).expect("a surface");
        worst = worst.max((0.3 - t).abs());
    }
    assert!(worst < VOXEL / 2.0, "worst radial error {worst}");
}

#[test]
fn integration_ignores_invalid_and_out_of_range_depth() {
    let k = camera();
    let depth = DepthImage::from_fn(k.width, k.height, |x, _| match x % 3 {
        0 => 0.0,
        1 => f32::NAN,
        _ => 9.0,
    });
    let mut layer = Layer::new(VOXEL);
    let stats = TsdfIntegrator::default().integrate(
        &mut layer,
        &depth,
        None::<&ColorImage>,
        None,
        &look_along(Point3::origin(), Vector3::y()),
        &k,
    );
    assert_eq!(stats.updated_voxels, 0);
    assert!(layer.blocks.is_empty());
}

#[test]
fn map_files_round_trip_and_reject_corruption() {
    let scene = scene_with(Shape::Sphere {
        center: Point3::new(0.0, 2.0, 0.0),
        radius: 0.3,
    });
    let layer = fuse(&scene, &[Point3::origin()], Point3::new(0.0, 2.0, 0.0));
    assert!(!layer.blocks.is_empty());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map.voxpan");
    let mut instances = std::collections::BTreeMap::new();
    let mut info = voxpan_map::InstanceInfo::default();
    info.class_votes.insert(9, 4);
    info.thing_votes = [4, 1];
    instances.insert(3u16, info);
    let mut layer = layer;
    let voxel_size = layer.voxel_size();
    let block = layer.blocks.values_mut().next().unwrap();
    block.labels[17].observe(3);
    block.refresh_surface(voxel_size);
    io::save(&layer, &instances, &path).unwrap();
    let map = io::load(&path).unwrap();
    assert_eq!(map.instances, instances);
    let loaded = map.layer;
    assert_eq!(loaded.voxel_size(), layer.voxel_size());
    assert_eq!(
        loaded.blocks,
        layer
            .blocks
            .iter()
            .map(|(k, b)| (*k, {
                let mut b = b.clone();
                b.updated = false;
                b
            }))
            .collect()
    );

    let bytes = std::fs::read(&path).unwrap();
    for position in [3, 40, bytes.len() / 2, bytes.len() - 2] {
        let mut flipped = bytes.clone();
        flipped[position] ^= 0x10;
        let err = io::from_bytes(&flipped, &path).unwrap_err().to_string();
        assert!(err.contains("map.voxpan"), "{err}");
    }
    let err = io::from_bytes(&bytes[..bytes.len() - 100], &path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("checksum") || err.contains("blocks"), "{err}");
    assert!(io::from_bytes(b"not a map", &path).is_err());
    assert!(io::load(&dir.path().join("missing.voxpan"))
        .unwrap_err()
        .to_string()
        .contains("missing.voxpan"));
}

#[test]
fn an_integrated_sphere_meshes_to_its_area() {
    let (center, r) = (Point3::new(0.0, 2.0, 0.0), 0.4);
    let scene = scene_with(Shape::Sphere { center, radius: r });
    // Views all around, from above and from below.
    let mut views: Vec<Point3<f64>> = (0..8)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 8.0;
            center + Vector3::new(1.5 * a.cos(), 1.5 * a.sin(), 0.0)
        })
        .collect();
    for z in [-1.2, 1.2] {
        for k in 0..4 {
            let a = std::f64::consts::TAU * (k as f64 + 0.5) / 4.0;
            views.push(center + Vector3::new(0.9 * a.cos(), 0.9 * a.sin(), z));
        }
    }
    let mut layer = fuse(&scene, &views, center);
    let mut meshes = voxpan_map::MeshLayer::default();
    meshes.update(&mut layer);
    let area = meshes.combined().area();
    let expected = 4.0 * std::f64::consts::PI * r * r;
    assert!(
        (area / expected - 1.0).abs() < 0.05,
        "area {area} vs {expected}"
    );
}
