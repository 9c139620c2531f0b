//! The distance field through the facade: distances and gradients around a fused sphere
//! against the sphere's own, the costmap cut through it, and per-frame updates against a
//! rebuild from the saved map.

use voxpan_core::Segments;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_map::{CostmapCell, MapConfig, PanopticMap};
use voxpan_sim::Shape;
use voxpan_sim::trajectory::look_along;

use super::{VOXEL, camera, scene_with, view};

const CENTRE: Point3<f64> = Point3::new(0.0, 2.0, 0.5);
const RADIUS: f64 = 0.4;

fn cameras() -> Vec<Point3<f64>> {
    vec![
        Point3::new(-1.0, 0.2, 0.6),
        Point3::new(0.0, 0.0, 0.5),
        Point3::new(1.0, 0.2, 0.4),
    ]
}

/// The sphere fused from three views with the field on, updated after every frame.
fn sphere_map() -> PanopticMap {
    let scene = scene_with(Shape::Sphere {
        center: CENTRE,
        radius: RADIUS,
    });
    let mut config = MapConfig::default();
    config.esdf.enabled = true;
    config.esdf.slice_min_z = 0.3;
    config.esdf.slice_max_z = 0.7;
    let mut map = PanopticMap::new(config).unwrap();
    for p in cameras() {
        let pose = look_along(p, CENTRE - p);
        map.integrate(view(&scene, &pose, &camera()).view(), None::<&Segments>)
            .unwrap();
        map.update_esdf();
    }
    map
}

#[test]
fn distances_and_gradients_follow_the_sphere() {
    let map = sphere_map();
    let mut checked = 0;
    for camera in cameras() {
        let towards = (CENTRE - camera).normalize();
        let surface = (CENTRE - camera).norm() - RADIUS;
        // From 1.2 m to 10 cm in front of the sphere, on the way from each camera (nearer,
        // the eight voxels around a point straddle the surface's discrete shell).
        for k in 0..23 {
            let gap = 0.1 + 0.05 * k as f64;
            let p = camera + towards * (surface - gap);
            let (d, g) = map
                .distance_and_gradient(&p)
                .unwrap_or_else(|| panic!("{p:?} was seen"));
            let truth = (p - CENTRE).norm() - RADIUS;
            // Sites are within a voxel of the surface.
            assert!(
                (d as f64 - truth).abs() <= 1.5 * VOXEL,
                "{p:?}: {d} vs {truth}"
            );
            let away = (p - CENTRE).normalize().cast::<f32>();
            assert!(g.dot(&away) > 0.9, "{p:?}: gradient {g:?}");
            checked += 1;
        }
    }
    assert_eq!(checked, 69);
    // The sphere's far side was never seen; nor was the space far to its side.
    assert_eq!(
        map.distance(&(CENTRE + Vector3::new(0.0, RADIUS + 0.3, 0.0))),
        None
    );
    assert_eq!(map.distance(&Point3::new(4.0, 2.0, 0.5)), None);
    // Batched queries answer as single ones.
    let points: Vec<Point3<f64>> = (0..50)
        .map(|i| Point3::new(-0.5 + 0.02 * i as f64, 1.0, 0.5))
        .collect();
    let batched = map.distances(&points);
    for (p, d) in points.iter().zip(batched) {
        assert_eq!(d, map.distance(p));
    }
    // A point no voxel holds is unknown, not clamped onto a voxel (NaN casts to 0).
    assert!(map.distance(&Point3::new(0.0, 1.0, 0.5)).is_some());
    for p in [
        Point3::new(f64::NAN, 1.0, 0.5),
        Point3::new(0.0, f64::INFINITY, 0.0),
        Point3::new(0.0, 1.0, 1e300),
    ] {
        assert_eq!(map.distance(&p), None, "{p:?}");
        assert_eq!(map.distance_and_gradient(&p), None, "{p:?}");
    }
}

#[test]
fn the_costmap_holds_the_sphere_in_front_of_free_space() {
    let map = sphere_map();
    let costmap = map.costmap().expect("voxels between 0.3 and 0.7 m");
    assert_eq!(costmap.axes, [0, 1]);
    assert_eq!(costmap.resolution, VOXEL);
    let cell = |x: f64, y: f64| {
        let column = ((x - costmap.origin[0]) / VOXEL).floor() as usize;
        let row = ((y - costmap.origin[1]) / VOXEL).floor() as usize;
        costmap.cell(column, row)
    };
    // The sphere's near side is surface; the way to it from the cameras is free; beside the
    // views nothing was seen.
    assert_eq!(cell(0.0, CENTRE.y - RADIUS), CostmapCell::Occupied);
    assert_eq!(cell(0.0, 1.0), CostmapCell::Free);
    assert_eq!(cell(-0.5, 1.1), CostmapCell::Free);
    assert_eq!(cell(0.3, 0.8), CostmapCell::Unknown);
    let (unknown, free, occupied) = costmap.counts();
    assert!(
        free > 10 * occupied && occupied > 50,
        "{free} free, {occupied} occupied"
    );
    assert!(unknown > 0);
    // The PGM is what map_server reads: header, then one byte per cell, top row first.
    let pgm = costmap.pgm();
    let header = format!(
        "P5\n# voxpan costmap\n{} {}\n255\n",
        costmap.width, costmap.height
    );
    assert!(pgm.starts_with(header.as_bytes()));
    assert_eq!(pgm.len(), header.len() + costmap.width * costmap.height);
    let top_left = pgm[header.len()];
    let expected = match costmap.cell(0, costmap.height - 1) {
        CostmapCell::Unknown => 205,
        CostmapCell::Free => 254,
        CostmapCell::Occupied => 0,
    };
    assert_eq!(top_left, expected);
    let occupancy = costmap.occupancy();
    assert_eq!(occupancy.iter().filter(|&&c| c == 100).count(), occupied);
    assert_eq!(occupancy.iter().filter(|&&c| c == -1).count(), unknown);
    // Clearance is the distance in the plane to the sphere's slice (radius about 0.39 m at
    // 0.3 m below the centre, 0.4 at it): 0.6 m in front of its near side.
    let clearance = |x: f64, y: f64| {
        let column = ((x - costmap.origin[0]) / VOXEL).floor() as usize;
        let row = ((y - costmap.origin[1]) / VOXEL).floor() as usize;
        costmap.clearance[row * costmap.width + column].unwrap()
    };
    assert!((clearance(0.0, 1.0) - 0.6).abs() < 1.5 * VOXEL as f32);
    // The distance slice: a point per known cell, at its centre on the band's lower height,
    // with its clearance (capped).
    let slice = costmap.clearance_points(0.5);
    assert_eq!(slice.len(), free + occupied);
    for ([x, y, z], d) in &slice {
        assert_eq!(*z, costmap.elevation);
        let c = clearance(*x, *y);
        assert_eq!(*d, c.min(0.5), "({x}, {y})");
    }
    let [x, y, _] = costmap.cell_centre(0, 0);
    assert!((x - costmap.origin[0] - VOXEL / 2.0).abs() < 1e-9);
    assert!((y - costmap.origin[1] - VOXEL / 2.0).abs() < 1e-9);
    // A robot's radius inflates the sphere by that much, and no more.
    let mut map = map;
    let mut esdf = map.config().esdf;
    esdf.robot_radius = 0.2;
    map.set_esdf_config(esdf).unwrap();
    let inflated = map.costmap().unwrap();
    let cell = |x: f64, y: f64| {
        let column = ((x - inflated.origin[0]) / VOXEL).floor() as usize;
        let row = ((y - inflated.origin[1]) / VOXEL).floor() as usize;
        inflated.cell(column, row)
    };
    assert_eq!(cell(0.0, CENTRE.y - RADIUS - 0.15), CostmapCell::Occupied);
    assert_eq!(cell(0.0, CENTRE.y - RADIUS - 0.3), CostmapCell::Free);
    assert!(inflated.counts().2 > 2 * occupied);
}

#[test]
fn updates_per_frame_match_a_rebuild_of_the_saved_map() {
    let mut map = sphere_map();
    let memory_with_field = map.memory_bytes();
    let mut loaded = PanopticMap::from_bytes(&map.to_bytes(), "memory".as_ref()).unwrap();
    assert!(!loaded.has_esdf());
    assert!(loaded.memory_bytes() < memory_with_field);
    loaded.update_esdf();
    assert_same_field(&map, &loaded, 10_000);
    // Nothing changed since: an update does nothing.
    let stats = map.update_esdf();
    assert_eq!((stats.changed_blocks, stats.rounds), (0, 0));
}

/// `ours` and `rebuilt` hold the same voxels with the same distances, bit for bit (the field
/// has one fixed point), and at least `at_least` of them.
fn assert_same_field(ours: &PanopticMap, rebuilt: &PanopticMap, at_least: usize) {
    let (mut ours, mut rebuilt) = (ours.esdf_voxels(), rebuilt.esdf_voxels());
    ours.sort_unstable_by_key(|(v, _)| *v);
    rebuilt.sort_unstable_by_key(|(v, _)| *v);
    assert!(ours.len() >= at_least, "{} voxels", ours.len());
    assert_eq!(ours.len(), rebuilt.len());
    let differ = ours
        .iter()
        .zip(&rebuilt)
        .filter(|(a, b)| a.0 != b.0 || a.1.to_bits() != b.1.to_bits())
        .count();
    assert_eq!(differ, 0, "{differ} of {} voxels differ", ours.len());
}

#[test]
fn the_flat_field_updated_every_frame_equals_its_rebuild() {
    let Some(dir) = voxpan_test_support::require_flat_sample(
        "the_flat_field_updated_every_frame_equals_its_rebuild",
    ) else {
        return;
    };
    use voxpan_dataset::FrameSource;
    let dataset = voxpan_dataset::FlatDataset::open(&dir).unwrap();
    let mut config = MapConfig::default();
    config.tsdf.voxel_size = 0.05;
    config.esdf.enabled = true;
    let mut map = PanopticMap::new(config).unwrap();
    let mut raised = 0;
    for i in 0..dataset.len() {
        let frame = dataset.load(i).unwrap();
        map.integrate(frame.view(), None).unwrap();
        raised += map.update_esdf().raised_voxels;
    }
    // Surfaces moved as the views refined them: sites came and went, not only came.
    assert!(raised > 10_000, "{raised} voxels raised");
    let mut loaded = PanopticMap::from_bytes(&map.to_bytes(), "memory".as_ref()).unwrap();
    loaded.update_esdf();
    assert_same_field(&map, &loaded, 500_000);
}
