//! Labels land on the right voxels, and association keeps one id per object although the
//! network's ids change every frame.

use voxpan_core::Segments;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_map::{Coloring, MapConfig, PanopticMap};
use voxpan_sim::trajectory::look_along;
use voxpan_sim::{MaskErrors, Object, Rand, Scene, Shape, Surface, render};

use super::{camera, view};

/// Two balls in front of a wall.
fn two_balls() -> Scene {
    let mut scene = Scene::empty(Vector3::new(10.0, 10.0, 10.0));
    let ball = |id: u16, x: f64| Object {
        instance_id: id,
        class_id: 9,
        is_thing: true,
        color: [200, 40, 40],
        surface: Surface::Plain,
        specular: false,
        shapes: vec![Shape::Sphere {
            center: Point3::new(x, 2.0, 0.0),
            radius: 0.25,
        }],
    };
    scene.add(ball(5, -0.4));
    scene.add(ball(6, 0.4));
    scene.add(Object {
        instance_id: 1,
        class_id: 1,
        is_thing: false,
        color: [180, 180, 170],
        surface: Surface::Plain,
        specular: false,
        shapes: vec![Shape::Cuboid {
            center: Point3::new(0.0, 3.5, 0.0),
            half: Vector3::new(5.0, 0.5, 5.0),
            yaw: 0.0,
        }],
    });
    scene
}

/// The instance labels of the labelled surface voxels within `radius` of `p`.
fn labels_near(map: &PanopticMap, p: Point3<f64>, radius: f64) -> Vec<u16> {
    map.surface_voxels()
        .filter(|v| v.instance != 0 && (v.position - p).norm() <= radius)
        .map(|v| v.instance)
        .collect()
}

#[test]
fn tracked_labels_land_on_the_right_voxels_with_stable_ids() {
    let scene = two_balls();
    let k = camera();
    let mut config = MapConfig::default();
    config.tracking.downscale = 2;
    let mut map = PanopticMap::new(config).unwrap();
    // Perfect masks, but the network numbers its segments at random in every frame.
    let masks = MaskErrors::new(0.0);
    let mut ball_ids: Vec<(u16, u16)> = Vec::new();
    for f in 0..6 {
        let position = Point3::new(-0.3 + 0.12 * f as f64, 0.0, 0.05 * (f % 2) as f64);
        let pose = look_along(position, Point3::new(0.0, 2.0, 0.0) - position);
        let ideal = render(&scene, &pose, &k);
        let (labels, segments) =
            masks.predict(&ideal.instances, &ideal.depth, &scene, &mut Rand::new(f));
        let frame = view(&scene, &pose, &k);
        let report = map
            .integrate(frame.view(), Some(&Segments { labels, segments }))
            .unwrap();
        assert!(report.association.is_some());
        // The map instance now on each ball's front.
        let at = |x: f64| {
            let near = labels_near(&map, Point3::new(x, 1.75, 0.0), 0.03);
            near.first().copied().unwrap_or(0)
        };
        ball_ids.push((at(-0.4), at(0.4)));
    }
    // After one frame the balls are not shown yet (they must be seen again); from the second
    // on they are, and keep their ids.
    assert_eq!(ball_ids[0], (0, 0), "{ball_ids:?}");
    let ball_ids = &ball_ids[1..];
    assert!(
        ball_ids.iter().all(|&(a, b)| a != 0 && b != 0 && a != b),
        "{ball_ids:?}"
    );
    assert!(
        ball_ids.windows(2).all(|w| w[0] == w[1]),
        "ids must not change: {ball_ids:?}"
    );
    assert_eq!(map.instance_count(), 3, "two balls and the wall");
    // Surface voxels of each ball carry its instance only.
    let (left, right) = ball_ids[0];
    for (x, id) in [(-0.4, left), (0.4, right)] {
        let v = labels_near(&map, Point3::new(x, 1.75, 0.0), 0.03);
        assert!(!v.is_empty());
        assert!(v.iter().all(|&l| l == id), "ball at {x}: {v:?} vs {id}");
    }
    let instances = map.instances();
    let ball = instances.iter().find(|i| i.id == left).unwrap();
    assert!(ball.is_thing && ball.class_id == Some(9) && ball.frames_seen == 6);
    // Its box is the ball's front: about 0.5 m wide, around x = -0.4.
    let b = ball.bounds.unwrap();
    assert!(
        (b.size()[0] - 0.5).abs() < 0.1 && ((b.min[0] + b.max[0]) / 2.0 + 0.4).abs() < 0.05,
        "{b:?}"
    );
    // The mesh splits into the three instances; each ball's part lies on its ball.
    let parts = map.mesh(Coloring::Instance).split_by_instance();
    assert_eq!(parts.len(), 3, "{:?}", parts.keys().collect::<Vec<_>>());
    for (x, id) in [(-0.4, left), (0.4, right)] {
        let centre = Vector3::new(x, 2.0, 0.0);
        let off = parts[&id]
            .vertices
            .iter()
            .filter(|v| {
                ((Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64) - centre).norm() - 0.25).abs()
                    > 0.03
            })
            .count();
        assert!(
            off * 20 < parts[&id].vertices.len(),
            "ball {id}: {off} vertices off its surface"
        );
    }
}

/// Surface the masks left unlabelled inside a wall (every frame's wall mask has the same
/// hole) is fused as geometry without a label; consolidation gives it the wall's instance,
/// and leaves the balls' surfaces as they were.
#[test]
fn consolidation_fills_a_hole_in_the_walls_labels_with_the_wall() {
    let scene = two_balls();
    let k = camera();
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let masks = MaskErrors::new(0.0);
    let (cx, cy) = (k.cx as i64, k.cy as i64);
    for f in 0..3 {
        let position = Point3::new(0.02 * f as f64, 0.0, 0.0);
        let pose = look_along(position, Point3::new(0.0, 2.0, 0.0) - position);
        let ideal = render(&scene, &pose, &k);
        let (mut labels, segments) =
            masks.predict(&ideal.instances, &ideal.depth, &scene, &mut Rand::new(f));
        // A 7 x 7 pixel hole in the middle of the wall, between the balls.
        for y in cy - 3..=cy + 3 {
            for x in cx - 3..=cx + 3 {
                *labels.get_mut(x as usize, y as usize) = 0;
            }
        }
        let frame = view(&scene, &pose, &k);
        map.integrate(frame.view(), Some(&Segments { labels, segments }))
            .unwrap();
    }
    // The hole on the wall (y = 3), around the camera's axis.
    let hole = |map: &PanopticMap| {
        map.surface_voxels()
            .filter(|v| (v.position - Point3::new(0.0, 3.0, 0.0)).norm() < 0.03)
            .map(|v| v.instance)
            .collect::<Vec<_>>()
    };
    let ball = |map: &PanopticMap| labels_near(map, Point3::new(-0.4, 1.75, 0.0), 0.03);
    let before = hole(&map);
    assert!(
        !before.is_empty() && before.iter().all(|&l| l == 0),
        "{before:?}"
    );
    let wall = labels_near(&map, Point3::new(0.0, 3.0, 0.0), 0.4)[0];
    let ball_before = ball(&map);
    map.consolidate();
    let after = hole(&map);
    assert!(after.iter().all(|&l| l == wall), "{after:?} (wall {wall})");
    assert_eq!(ball(&map), ball_before);
}
