//! Each consumer of map changes sees every changed block once, independently of the others
//! and of the mesher.

use voxpan_core::Segments;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_map::{Coloring, MapConfig, PanopticMap};
use voxpan_sim::Shape;
use voxpan_sim::trajectory::look_along;

use super::{camera, scene_with, view};

#[test]
fn consumers_see_changes_independently() {
    let scene = scene_with(Shape::Cuboid {
        center: Point3::new(0.0, 2.5, 0.0),
        half: Vector3::new(5.0, 0.5, 5.0),
        yaw: 0.0,
    });
    let k = camera();
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let publisher = map.subscribe().unwrap();
    let left = look_along(Point3::new(-1.0, 0.0, 0.0), Vector3::y());
    map.integrate(view(&scene, &left, &k).view(), None::<&Segments>)
        .unwrap();
    let first = map.take_changes(&publisher);
    assert_eq!(first.len(), map.block_count());
    assert!(map.take_changes(&publisher).is_empty(), "seen once");
    // The mesher has its own bits: it still re-meshes everything.
    let meshed = map.update_mesh();
    assert!(meshed.len() >= first.len());
    assert!(map.update_mesh().is_empty());
    // A late subscriber starts with every block.
    let late = map.subscribe().unwrap();
    assert_eq!(map.take_changes(&late).len(), map.block_count());
    // Another view changes some blocks; both consumers hear of exactly those.
    let right = look_along(Point3::new(1.0, 0.0, 0.0), Vector3::y());
    map.integrate(view(&scene, &right, &k).view(), None::<&Segments>)
        .unwrap();
    let (a, b) = (map.take_changes(&publisher), map.take_changes(&late));
    assert_eq!(a, b);
    assert!(!a.is_empty() && a.len() <= map.block_count());
    // A changed block's mesh is available for publishing.
    map.update_mesh();
    let with_mesh = a
        .iter()
        .filter(|i| map.block_mesh(i, Coloring::Rgb).is_some())
        .count();
    assert!(with_mesh > 0);
    map.unsubscribe(late);
    let third = map.subscribe().unwrap();
    assert!(!map.take_changes(&third).is_empty());
}
