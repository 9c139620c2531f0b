//! Analytic scenes: the fused zero crossing lies on the true surface; bad depth is ignored;
//! the map file round-trips through the facade.

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{DepthImage, Image, Segments};
use voxpan_map::{Coloring, MapConfig, MapError, PanopticMap};
use voxpan_sim::Shape;
use voxpan_sim::trajectory::look_along;

use super::{VOXEL, camera, fuse, scene_with, view};

/// Where the fused distance changes sign along `origin + t·dir`, by linear interpolation
/// between voxel samples.
fn zero_crossing(
    map: &PanopticMap,
    origin: Point3<f64>,
    dir: Vector3<f64>,
    t_max: f64,
) -> Option<f64> {
    let step = VOXEL / 4.0;
    let mut previous: Option<(f64, f32)> = None;
    let mut t = 0.0;
    while t < t_max {
        if let Some(v) = map.voxel(&(origin + dir * t)) {
            if let Some((t0, d0)) = previous
                && d0 > 0.0
                && v.distance <= 0.0
            {
                return Some(t0 + (t - t0) * (d0 / (d0 - v.distance)) as f64);
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
    let map = fuse(&scene, &views, Point3::new(0.0, 2.0, 0.0));
    for x in [-0.5, 0.0, 0.37] {
        for z in [-0.3, 0.0, 0.21] {
            let t =
                zero_crossing(&map, Point3::new(x, 0.5, z), Vector3::y(), 2.5).expect("a surface");
            assert!(
                (0.5 + t - 2.0).abs() < VOXEL / 2.0,
                "at ({x}, {z}): surface at y = {}",
                0.5 + t
            );
        }
    }
    // The colour of surface voxels is the wall's (lit: 0.45 + 0.55·|n·l|).
    let v = map
        .voxel(&Point3::new(0.0, 2.0 - VOXEL / 2.0, 0.0))
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
    let map = fuse(&scene, &views, center);
    let mut worst: f64 = 0.0;
    for k in 0..16 {
        let a = std::f64::consts::TAU * (k as f64 + 0.5) / 16.0;
        let dir = Vector3::new(a.cos(), a.sin(), 0.0);
        // Walk inwards from outside the sphere.
        let origin = center + dir * (r + 0.3);
        let t = zero_crossing(&map, origin, -dir, 0.3 + r).expect("a surface");
        worst = worst.max((0.3 - t).abs());
    }
    assert!(worst < VOXEL / 2.0, "worst radial error {worst}");
}

#[test]
fn integration_ignores_invalid_and_out_of_range_depth() {
    let k = camera();
    let pose = look_along(Point3::origin(), Vector3::y());
    let mut frame = view(
        &scene_with(Shape::Sphere {
            center: Point3::new(0.0, 2.0, 0.0),
            radius: 0.3,
        }),
        &pose,
        &k,
    );
    frame.depth = DepthImage::from_fn(k.width, k.height, |x, _| match x % 4 {
        0 => 0.0,
        1 => f32::NAN,
        2 => -1.0,
        _ => 9.0,
    });
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let report = map.integrate(frame.view(), None::<&Segments>).unwrap();
    assert_eq!(report.integration.updated_voxels, 0);
    assert_eq!(map.block_count(), 0);
}

#[test]
fn frames_that_do_not_fit_the_camera_are_refused_and_leave_the_map_alone() {
    let k = camera();
    let pose = look_along(Point3::origin(), Vector3::y());
    let scene = scene_with(Shape::Sphere {
        center: Point3::new(0.0, 2.0, 0.0),
        radius: 0.3,
    });
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let mut frame = view(&scene, &pose, &k);
    frame.color = Image::filled(10, 10, [0; 3]);
    let err = map.integrate(frame.view(), None::<&Segments>).unwrap_err();
    assert!(matches!(err, MapError::Frame { .. }));
    // The image that does not fit is named; which frame it was, the caller says.
    assert!(err.to_string().contains("colour"), "{err}");
    let frame = view(&scene, &pose, &k);
    let segments = Segments {
        labels: Image::filled(k.width + 1, k.height, 1),
        segments: vec![],
    };
    assert!(matches!(
        map.integrate(frame.view(), Some(&segments)),
        Err(MapError::SegmentsSize { .. })
    ));
    assert_eq!(map.block_count(), 0);
}

#[test]
fn maps_save_and_load_through_the_facade() {
    let scene = scene_with(Shape::Sphere {
        center: Point3::new(0.0, 2.0, 0.0),
        radius: 0.3,
    });
    let mut map = fuse(&scene, &[Point3::origin()], Point3::new(0.0, 2.0, 0.0));
    map.set_class_names([(9, "ball".to_owned())].into());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map.voxpan");
    map.save(&path).unwrap();
    let mut loaded = PanopticMap::load(&path).unwrap();
    assert_eq!(loaded, map);
    assert_eq!(loaded.class_name(9), Some("ball"));
    // Mapping and meshing go on from a loaded map as from the original.
    assert_eq!(loaded.mesh(Coloring::Rgb), map.mesh(Coloring::Rgb));
    let err = PanopticMap::load(&dir.path().join("missing.voxpan")).unwrap_err();
    assert!(err.to_string().contains("missing.voxpan"), "{err}");
    std::fs::write(&path, b"not a map").unwrap();
    assert!(PanopticMap::load(&path).is_err());
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
    let mut map = fuse(&scene, &views, center);
    let mesh = map.mesh(Coloring::Rgb);
    let area = mesh.area();
    let expected = 4.0 * std::f64::consts::PI * r * r;
    assert!(
        (area / expected - 1.0).abs() < 0.05,
        "area {area} vs {expected}"
    );
    // Welded: far fewer vertices than three per triangle (a closed mesh has about half as many
    // vertices as triangles).
    assert!(
        mesh.vertices.len() * 3 < mesh.triangles.len() * 2,
        "{} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    assert_eq!(mesh.normals.len(), mesh.vertices.len());
}
