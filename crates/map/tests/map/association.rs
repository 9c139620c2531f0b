//! Association on constructed scenes where matching rendered instances by IoU failed: a wall
//! seen in pieces, a picture on the wall, two chairs side by side, an object first seen from
//! afar, a clock the network first took for its wall. Masks are perfect (unless a test edits
//! them) but, as a network's, renumbered at random in every frame.

use std::collections::BTreeMap;

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{Intrinsics, LabelImage, Segments};
use voxpan_map::{AssociationStats, Coloring, MapConfig, PanopticMap, VoxelIndex};
use voxpan_sim::trajectory::look_along;
use voxpan_sim::{MaskErrors, Object, Rand, Scene, Shape, Surface, render};

use super::{camera, view};

fn object(id: u16, class: u32, thing: bool, shapes: Vec<Shape>) -> Object {
    Object {
        instance_id: id,
        class_id: class,
        is_thing: thing,
        color: [150 + 10 * (id % 8) as u8, 120, 100],
        surface: Surface::Plain,
        specular: false,
        shapes,
    }
}

fn cuboid(center: [f64; 3], half: [f64; 3]) -> Shape {
    Shape::Cuboid {
        center: Point3::from(center),
        half: Vector3::from(half),
        yaw: 0.0,
    }
}

/// The frame seen from `pose`, its true instance image, and its masks as a perfect network's
/// renumbered at random (seeded by the frame number `f`).
fn perceive(
    scene: &Scene,
    pose: &voxpan_core::Pose,
    f: usize,
) -> (voxpan_core::Frame, LabelImage, Segments) {
    let k = camera();
    let ideal = render(scene, pose, &k);
    let (labels, segments) = MaskErrors::new(0.0).predict(
        &ideal.instances,
        &ideal.depth,
        scene,
        &mut Rand::new(f as u64),
    );
    (
        view(scene, pose, &k),
        ideal.instances,
        Segments { labels, segments },
    )
}

/// Fuses the views from `poses` twice over: once with perfect masks renumbered at random
/// (association at work), once with the true ids (the reference). Returns both maps.
fn fuse(scene: &Scene, poses: &[voxpan_core::Pose]) -> (PanopticMap, PanopticMap) {
    fuse_edited(scene, poses, |_, _, _| {})
}

/// [`fuse`], with each frame's masks passed through `edit(frame, true ids, masks)` first.
fn fuse_edited(
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    edit: impl FnMut(usize, &LabelImage, &mut Segments),
) -> (PanopticMap, PanopticMap) {
    fuse_named(scene, poses, &[], edit)
}

/// [`fuse_edited`] into a map that knows the class `names` (which stuff is the building's
/// shell, which classes form a family).
fn fuse_named(
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    names: &[(u32, &str)],
    edit: impl FnMut(usize, &LabelImage, &mut Segments),
) -> (PanopticMap, PanopticMap) {
    let (map, reference, _) = fuse_reporting(scene, poses, names, edit);
    (map, reference)
}

/// [`fuse_named`], also returning what association did in each frame.
fn fuse_reporting(
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    names: &[(u32, &str)],
    edit: impl FnMut(usize, &LabelImage, &mut Segments),
) -> (PanopticMap, PanopticMap, Vec<AssociationStats>) {
    fuse_configured(MapConfig::default(), scene, poses, names, edit)
}

/// [`fuse_reporting`] into a map and a reference of `config`.
fn fuse_configured(
    config: MapConfig,
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    names: &[(u32, &str)],
    mut edit: impl FnMut(usize, &LabelImage, &mut Segments),
) -> (PanopticMap, PanopticMap, Vec<AssociationStats>) {
    let mut reports = Vec::new();
    let mut map = PanopticMap::new(config).unwrap();
    map.set_class_names(names.iter().map(|&(c, n)| (c, n.to_string())).collect());
    // The true ids, every instance shown from its first frame (as `voxpan eval`'s reference).
    let mut every_instance = config;
    every_instance.tracking.min_observations = 1;
    let mut reference = PanopticMap::new(every_instance).unwrap();
    for (f, pose) in poses.iter().enumerate() {
        let (frame, truth, mut masks) = perceive(scene, pose, f);
        edit(f, &truth, &mut masks);
        let report = map.integrate(frame.view(), Some(&masks)).unwrap();
        reports.extend(report.association);
        let truth = frame.ground_truth.clone().unwrap();
        let ids: Vec<voxpan_core::Segment> = scene
            .objects
            .iter()
            .map(|o| voxpan_core::Segment {
                id: o.instance_id,
                class_id: Some(o.class_id),
                is_thing: Some(o.is_thing),
                score: None,
            })
            .collect();
        reference
            .integrate_identified(
                frame.view(),
                &Segments {
                    labels: truth,
                    segments: ids,
                },
            )
            .unwrap();
    }
    (map, reference, reports)
}

/// Edits a frame's `masks` as a network that misses true object `object` and leaves its
/// pixels inside `into`'s segment (both must be in view; `truth` holds the true ids).
fn leave_inside(truth: &LabelImage, masks: &mut Segments, object: u16, into: u16) {
    let segment_on = |o: u16| {
        let pixel = truth.pixels().iter().position(|&t| t == o).unwrap();
        masks.labels.pixels()[pixel]
    };
    let (missed, kept) = (segment_on(object), segment_on(into));
    for l in masks.labels.pixels_mut() {
        if *l == missed {
            *l = kept;
        }
    }
    masks.segments.retain(|s| s.id != missed);
}

/// For each true object: the map instances its surface voxels carry, with counts.
fn instances_of_objects(
    map: &PanopticMap,
    reference: &PanopticMap,
) -> BTreeMap<u16, BTreeMap<u16, usize>> {
    let truth: BTreeMap<VoxelIndex, u16> = reference
        .surface_voxels()
        .filter(|v| v.instance != 0)
        .map(|v| (v.index, v.instance))
        .collect();
    let mut out: BTreeMap<u16, BTreeMap<u16, usize>> = BTreeMap::new();
    for v in map.surface_voxels() {
        if let Some(&object) = truth.get(&v.index) {
            *out.entry(object)
                .or_default()
                .entry(v.instance)
                .or_default() += 1;
        }
    }
    out
}

/// The instance holding most of `object`'s voxels, and its share.
fn main_instance(of: &BTreeMap<u16, BTreeMap<u16, usize>>, object: u16) -> (u16, f64) {
    let counts = &of[&object];
    let total: usize = counts.values().sum();
    let (&id, &n) = counts.iter().max_by_key(|(_, n)| **n).unwrap();
    (id, n as f64 / total as f64)
}

/// The instance holding over 90 % of thing `object`'s voxels (`what` names the thing).
fn whole_thing(of: &BTreeMap<u16, BTreeMap<u16, usize>>, object: u16, what: &str) -> u16 {
    let (id, share) = main_instance(of, object);
    assert!(
        id != 0 && share > 0.9,
        "the {what} is split: {:?}",
        of[&object]
    );
    id
}

/// A long wall (object 1, stuff) with things in front of it.
fn wall_scene(things: Vec<Object>) -> Scene {
    let mut scene = Scene::empty(Vector3::new(20.0, 20.0, 10.0));
    scene.add(object(
        1,
        1,
        false,
        vec![cuboid([0.0, 3.0, 0.0], [8.0, 0.1, 2.0])],
    ));
    for t in things {
        scene.add(t);
    }
    scene
}

#[test]
fn a_wall_seen_in_pieces_stays_one_instance() {
    let scene = wall_scene(vec![]);
    // Sliding along the wall 1.2 m away: each frame sees about 2.4 m of it, the first and the
    // last frame see none of each other's.
    let poses: Vec<_> = (0..14)
        .map(|i| look_along(Point3::new(-3.5 + 0.5 * i as f64, 1.7, 0.0), Vector3::y()))
        .collect();
    let (map, reference) = fuse(&scene, &poses);
    let of = instances_of_objects(&map, &reference);
    let (wall, share) = main_instance(&of, 1);
    assert!(share > 0.99, "the wall is split: {:?}", of[&1]);
    assert_eq!(map.instance_count(), 1, "{:?}", map.instances());
    assert!(wall != 0);
}

#[test]
fn a_picture_on_a_wall_and_two_chairs_side_by_side_stay_themselves() {
    let scene = wall_scene(vec![
        // A picture 2 cm proud of the wall.
        object(
            2,
            5,
            true,
            vec![cuboid([-1.0, 2.88, 0.6], [0.4, 0.02, 0.3])],
        ),
        // Two chairs (as blocks) 6 cm apart.
        object(
            3,
            7,
            true,
            vec![cuboid([0.5, 2.0, -0.5], [0.25, 0.25, 0.45])],
        ),
        object(
            4,
            7,
            true,
            vec![cuboid([1.06, 2.0, -0.5], [0.25, 0.25, 0.45])],
        ),
    ]);
    let poses: Vec<_> = (0..10)
        .map(|i| {
            let p = Point3::new(-1.2 + 0.3 * i as f64, -0.5, 0.2);
            look_along(p, Point3::new(0.0, 2.5, 0.0) - p)
        })
        .collect();
    let (mut map, reference) = fuse(&scene, &poses);
    let check = |map: &PanopticMap| {
        let of = instances_of_objects(map, &reference);
        let mains: Vec<(u16, f64)> = (1..=4).map(|o| main_instance(&of, o)).collect();
        for (o, (id, share)) in mains.iter().enumerate() {
            assert!(
                *id != 0 && *share > 0.9,
                "object {}: {:?}",
                o + 1,
                of[&(o as u16 + 1)]
            );
        }
        let ids: std::collections::BTreeSet<u16> = mains.iter().map(|m| m.0).collect();
        assert_eq!(
            ids.len(),
            4,
            "wall, picture and chairs must be four instances: {mains:?}"
        );
        assert_eq!(map.instance_count(), 4, "{:?}", map.instances());
    };
    check(&map);
    // The picture meets its wall, and the chairs each other, along seams; every view
    // segments them apart, so consolidation, which weighs no class, joins none of them.
    assert_eq!(map.consolidate(), 0);
    check(&map);
}

#[test]
fn an_object_seen_from_afar_keeps_its_id_close_up() {
    let scene = wall_scene(vec![object(
        2,
        9,
        true,
        vec![Shape::Sphere {
            center: Point3::new(0.0, 2.4, 0.0),
            radius: 0.3,
        }],
    )]);
    // From 4.2 m away down to 0.9 m; every view, the first included, continues the instance.
    let positions = (0..8).map(|i| Point3::new(0.05 * i as f64, -1.8 + 0.45 * i as f64, 0.1));
    let poses = looking_at(positions, Point3::new(0.0, 2.4, 0.0));
    assert_one_thing_through_every_view(&scene, &poses, 0.95);
}

#[test]
fn a_small_object_seen_a_few_pixels_at_a_time_is_one_instance() {
    // An 8 cm box on the wall (4 cm deep), like a lamp or a plate across a room: from 2.1-2.4 m
    // it covers about 3×3 pixels of the 160×120 test camera, a sample of the coarse 4-pixel grid
    // or none. Read on the coarse grid alone, its segments found no instance at all.
    let scene = wall_scene(vec![object(
        2,
        5,
        true,
        vec![cuboid([0.0, 2.86, 0.3], [0.04, 0.04, 0.04])],
    )]);
    let positions = (0..8).map(|i| Point3::new(-0.4 + 0.1 * i as f64, 0.5 + 0.04 * i as f64, 0.1));
    let poses = looking_at(positions, Point3::new(0.0, 2.86, 0.3));
    assert_one_thing_through_every_view(&scene, &poses, 0.8);
}

/// Cameras at `positions`, each looking at `target`.
fn looking_at(
    positions: impl Iterator<Item = Point3<f64>>,
    target: Point3<f64>,
) -> Vec<voxpan_core::Pose> {
    positions.map(|p| look_along(p, target - p)).collect()
}

/// Fuses `scene` seen from `poses` and checks that its object 2 is the map's one thing
/// instance, holding more than `min_share` of the object's voxels and continued by every view.
fn assert_one_thing_through_every_view(scene: &Scene, poses: &[voxpan_core::Pose], min_share: f64) {
    let (map, reference) = fuse(scene, poses);
    let of = instances_of_objects(&map, &reference);
    let (object, share) = main_instance(&of, 2);
    assert!(object != 0 && share > min_share, "{:?}", of[&2]);
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 1, "{things:?}");
    assert_eq!(things[0].id, object);
    assert_eq!(
        things[0].frames_seen,
        poses.len() as u32,
        "every view continues it"
    );
}

/// A picture (object 2, class 5) on the wall, and views of it from 1.4 m, then from past
/// `tsdf.max_range` (5 m), where nothing is integrated.
fn picture_seen_once_close_then_from_afar() -> (Scene, Vec<voxpan_core::Pose>) {
    let scene = wall_scene(vec![object(
        2,
        5,
        true,
        vec![cuboid([0.0, 2.85, 0.0], [0.6, 0.05, 0.5])],
    )]);
    let range = MapConfig::default().tsdf.max_range;
    let poses = [1.4, range + 1.0, range + 1.2, range + 1.4]
        .iter()
        .map(|&distance| {
            let p = Point3::new(0.0, 2.8 - distance, 0.1);
            look_along(p, Vector3::new(0.0, 1.0, 0.0))
        })
        .collect();
    (scene, poses)
}

#[test]
fn an_object_mapped_once_is_confirmed_by_views_beyond_the_range() {
    // The far views integrate nothing, but their depths land on the picture's voxels, which
    // is what confirms an instance (flat's pictures: one frame within 5 m, several beyond).
    let (scene, poses) = picture_seen_once_close_then_from_afar();
    let (map, reference) = fuse(&scene, &poses);
    let of = instances_of_objects(&map, &reference);
    let (picture, share) = main_instance(&of, 2);
    assert!(picture != 0 && share > 0.95, "{:?}", of[&2]);
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 1, "{things:?}");
    assert_eq!(things[0].id, picture);
    assert_eq!(things[0].frames_seen, 4, "{things:?}");
}

#[test]
fn segments_seen_only_past_the_range_found_no_instances() {
    // Past the range nothing is integrated, so an instance founded there would hold no voxel
    // and be founded again in every later frame. Here a picture mapped once up close is then
    // seen from afar as another class (as networks flicker), which no instance matches.
    let (scene, poses) = picture_seen_once_close_then_from_afar();
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    for (f, pose) in poses.iter().enumerate() {
        let (frame, _, mut masks) = perceive(&scene, pose, f);
        if f > 0 {
            for s in masks.segments.iter_mut().filter(|s| s.class_id == Some(5)) {
                s.class_id = Some(6);
            }
        }
        let report = map.integrate(frame.view(), Some(&masks)).unwrap();
        let association = report.association.unwrap();
        if f > 0 {
            assert_eq!(association.created, 0, "frame {f}: {association:?}");
            assert_eq!(report.integration.updated_voxels, 0, "frame {f}");
        }
    }
}

/// Checks that chairs 2 and 3 are each the main object of an instance of their own, which
/// holds over 90 % of it.
fn assert_chairs_apart(map: &PanopticMap, reference: &PanopticMap) {
    let of = instances_of_objects(map, reference);
    let (left, share_left) = main_instance(&of, 2);
    let (right, share_right) = main_instance(&of, 3);
    assert!(left != right, "merged: {of:?}");
    assert!(share_left > 0.9 && share_right > 0.9, "{of:?}");
}

/// Views straight at [`wall_scene`]'s wall from each of `distances` in front of the chairs'
/// front faces (which stand at y = 1.75 m in these tests).
fn facing_the_wall_from(distances: &[f64]) -> Vec<voxpan_core::Pose> {
    distances
        .iter()
        .map(|&distance| {
            let p = Point3::new(0.0, 1.75 - distance, -0.2);
            look_along(p, Vector3::new(0.0, 1.0, 0.0))
        })
        .collect()
}

#[test]
fn neighbours_joined_by_segments_past_the_range_stay_apart() {
    // Two chairs (as blocks) 6 cm apart, mapped from 1.5 m as two segments, then seen from
    // past the range as one segment (networks join neighbours at range). Merges are never
    // undone, so the far views, which integrate nothing, must not vote for one.
    let scene = wall_scene(vec![
        object(
            2,
            7,
            true,
            vec![cuboid([-0.31, 2.0, -0.5], [0.25, 0.25, 0.45])],
        ),
        object(
            3,
            7,
            true,
            vec![cuboid([0.31, 2.0, -0.5], [0.25, 0.25, 0.45])],
        ),
    ]);
    let range = MapConfig::default().tsdf.max_range;
    let distances = [1.5, 1.6, range + 1.0, range + 1.1, range + 1.2, range + 1.3];
    let poses = facing_the_wall_from(&distances);
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        if distances[f] > range {
            leave_inside(truth, masks, 3, 2);
        }
    });
    assert_chairs_apart(&map, &reference);
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 2, "{things:?}");
}

#[test]
fn a_thing_cut_in_two_only_past_the_range_is_one_instance() {
    // A chair first mapped as two instances: its left half segmented in two close views, its
    // right half in the next two. Four views from past the integration range then segment it
    // in two pieces that do not touch (a network cuts what it sees small; those frames
    // integrate nothing), and three close views segment it whole, voting to join the two.
    // Counted as telling the halves apart, the far views outnumbered the close votes and
    // left the chair split for good.
    let scene = wall_scene(vec![object(
        2,
        7,
        true,
        vec![cuboid([0.0, 2.0, -0.5], [0.25, 0.25, 0.45])],
    )]);
    let range = MapConfig::default().tsdf.max_range;
    let far = |f: usize| (4..8).contains(&f);
    let distances: Vec<f64> = (0..11)
        .map(|f| {
            if far(f) {
                range + 0.3 + 0.1 * (f - 4) as f64
            } else {
                1.5 + 0.05 * f as f64
            }
        })
        .collect();
    let poses = facing_the_wall_from(&distances);
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| match f {
        0 | 1 => segment_half(truth, masks, 2, true),
        2 | 3 => segment_half(truth, masks, 2, false),
        _ if far(f) => {
            split_across(truth, masks, 2, 3);
            let (first, last) = object_columns(truth, 2);
            let third = (last - first + 1).div_ceil(3);
            void_columns(truth, masks, 2, |x| {
                (first + third..first + 2 * third).contains(&x)
            });
        }
        _ => {}
    });
    let of = instances_of_objects(&map, &reference);
    whole_thing(&of, 2, "chair");
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 1, "{things:?}");
}

#[test]
fn two_chairs_a_network_joins_in_every_other_view_stay_two() {
    // Two chairs 30 cm apart, the wall showing between them: every other view the network
    // joins them in one mask (a segment covering both votes to merge them); the views between
    // segment them as two, which is the segmenter telling them apart although their masks do
    // not touch. Counted only where masks touch, two votes merged the chairs for good.
    let chair = |id: u16, x: f64| {
        object(
            id,
            7,
            true,
            vec![cuboid([x, 2.0, -0.5], [0.25, 0.25, 0.45])],
        )
    };
    let scene = wall_scene(vec![chair(2, -0.4), chair(3, 0.4)]);
    let positions = (0..8).map(|i| Point3::new(-0.2 + 0.05 * i as f64, 0.4, -0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        if f % 2 == 1 {
            leave_inside(truth, masks, 3, 2);
        }
    });
    assert_chairs_apart(&map, &reference);
}

/// The classes of [`wall_scene`] and the things on its wall in these tests, named.
const WALL_CLOCK_PICTURE: [(u32, &str); 3] = [(1, "wall"), (5, "picture"), (9, "clock")];

/// Fuses the views from `poses` of `scene` (a wall, object 1, with one thing, object 2) where
/// the network leaves the thing inside the wall's segment in the frames `missed` names, and
/// checks that the thing ends as its own instance holding over `min_share` of its voxels
/// (`failure` says what went wrong otherwise). Returns the map and each object's instances.
fn assert_thing_apart_from_its_wall(
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    missed: impl Fn(usize) -> bool,
    min_share: f64,
    failure: &str,
) -> (PanopticMap, BTreeMap<u16, BTreeMap<u16, usize>>) {
    // The wall named as the building's shell: its covers count against the thing.
    let (map, reference) = fuse_named(scene, poses, &WALL_CLOCK_PICTURE, |f, truth, masks| {
        if missed(f) {
            leave_inside(truth, masks, 2, 1);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (wall, _) = main_instance(&of, 1);
    let (thing, share) = main_instance(&of, 2);
    assert!(
        thing != 0 && thing != wall && share > min_share,
        "{failure}: {:?}",
        of[&2]
    );
    (map, of)
}

#[test]
fn a_clock_first_mapped_as_its_wall_becomes_its_own_instance() {
    // A clock 2 cm proud of the wall; for the first 5 views the network misses it and its
    // pixels belong to the wall's segment, as when a panoptic network's stuff swallows an
    // undetected thing. Then it is detected in 10 views.
    let scene = wall_scene(vec![object(
        2,
        9,
        true,
        vec![cuboid([0.0, 2.88, 0.3], [0.2, 0.02, 0.2])],
    )]);
    let missed = 5;
    let poses: Vec<_> = (0..15)
        .map(|i| {
            let p = Point3::new(-0.7 + 0.1 * i as f64, 1.0, 0.2);
            look_along(p, Point3::new(0.0, 2.9, 0.3) - p)
        })
        .collect();
    let (map, _) = assert_thing_apart_from_its_wall(
        &scene,
        &poses,
        |f| f < missed,
        0.9,
        "the clock is not its own instance",
    );
    // Founded once, at its first detection, and matched in every later view: read only by
    // their voxels' leading label (the wall's), the detections would each found a new one.
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 1, "{things:?}");
    assert_eq!(things[0].frames_seen, (poses.len() - missed) as u32);
}

#[test]
fn a_thing_a_network_later_leaves_inside_its_wall_keeps_its_voxels() {
    // A picture found in 6 close views, then left inside the wall's segment in 10 views from
    // farther away (as networks do with small things at range): stuff must not take its voxels.
    let scene = wall_scene(vec![object(
        2,
        5,
        true,
        vec![cuboid([0.0, 2.88, 0.3], [0.4, 0.02, 0.3])],
    )]);
    let near = 6;
    let poses: Vec<_> = (0..16)
        .map(|i| {
            let distance = if i < near { 1.2 } else { 3.0 + 0.1 * i as f64 };
            let p = Point3::new(-0.5 + 0.07 * i as f64, 2.9 - distance, 0.3);
            look_along(p, Point3::new(0.0, 2.9, 0.3) - p)
        })
        .collect();
    assert_thing_apart_from_its_wall(
        &scene,
        &poses,
        |f| f >= near,
        0.9,
        "the wall took the picture",
    );
}

#[test]
fn a_clock_the_network_sees_on_its_wall_in_a_third_of_the_views_is_not_shown() {
    // A network's repeated false detection at one place: a board 2 cm proud of the wall,
    // which the wall's segment covers in two views of three and a `clock` mask in the third,
    // from the same distance. Matched in 4 frames and covered by the wall in more, it is not
    // an object. With the wall not known as the shell, the same masks show it.
    let scene = wall_scene(vec![object(
        2,
        9,
        true,
        vec![cuboid([0.0, 2.88, 0.3], [0.2, 0.02, 0.2])],
    )]);
    let poses: Vec<_> = (0..12)
        .map(|i| {
            let p = Point3::new(-0.3 + 0.05 * i as f64, 1.0, 0.2);
            look_along(p, Point3::new(0.0, 2.9, 0.3) - p)
        })
        .collect();
    let clocks = |names: &[(u32, &str)]| {
        let (map, _) = fuse_named(&scene, &poses, names, |f, truth, masks| {
            if f % 3 != 0 {
                leave_inside(truth, masks, 2, 1);
            }
        });
        map.instances()
            .into_iter()
            .filter(|i| i.is_thing)
            .collect::<Vec<_>>()
    };
    let shown = clocks(&WALL_CLOCK_PICTURE);
    assert!(shown.is_empty(), "{shown:?}");
    let unnamed = clocks(&[]);
    assert_eq!(unnamed.len(), 1, "{unnamed:?}");
    assert_eq!(unnamed[0].frames_seen, 4);
}

#[test]
fn a_flush_picture_the_network_often_misses_takes_its_voxels_from_the_wall() {
    // A picture 2 cm proud of its wall (within the truncation distance: refinement cannot cut
    // the wall's mask off it). The camera pans along the wall; the network misses the
    // picture in the first three views, which see its left part, then finds it in every
    // other view. Counted like the wall's, its detections never outvoted the misses: the wall
    // kept the part it saw first (flat's TV kept a quarter of its picture).
    let scene = wall_scene(vec![object(
        2,
        5,
        true,
        vec![cuboid([0.0, 2.89, 0.3], [0.4, 0.01, 0.3])],
    )]);
    let missed_first = 3;
    let poses: Vec<_> = (0..18)
        .map(|i| look_along(Point3::new(-1.6 + 0.15 * i as f64, 1.4, 0.3), Vector3::y()))
        .collect();
    let (_, of) = assert_thing_apart_from_its_wall(
        &scene,
        &poses,
        |f| f < missed_first || f % 2 == 0,
        0.8,
        "the wall kept the picture",
    );
    // Only the picture's inside took voxels over: the wall lost no more than the picture.
    let (_, wall_share) = main_instance(&of, 1);
    assert!(wall_share > 0.99, "{:?}", of[&1]);
}

/// The camera, its pose and its frame looking head-on at the wall of [`wall_scene`] from
/// 1.2 m, where a pixel is 1.5 cm.
fn wall_head_on() -> (Intrinsics, voxpan_core::Pose, voxpan_core::Frame) {
    let k = camera();
    let pose = look_along(Point3::new(0.0, 1.7, 0.0), Vector3::y());
    let frame = view(&wall_scene(vec![]), &pose, &k);
    (k, pose, frame)
}

/// A segment of an identified segmentation: `id`, of class `class`, a thing or stuff.
fn identified_segment(id: u16, class: u32, thing: bool) -> voxpan_core::Segment {
    voxpan_core::Segment {
        id,
        class_id: Some(class),
        is_thing: Some(thing),
        score: None,
    }
}

/// Known identity does not show a once-seen detection: identified instances show after
/// `min_observations` frames, as tracked ones do.
#[test]
fn identified_instances_show_once_seen_again() {
    let (_, _, frame) = wall_head_on();
    let wall = Segments {
        labels: frame.ground_truth.clone().unwrap(),
        segments: vec![identified_segment(1, 1, false)],
    };
    let config = MapConfig::default();
    assert_eq!(config.tracking.min_observations, 2);
    // One frame counts once, however many segments carry the id.
    let twice = Segments {
        labels: wall.labels.clone(),
        segments: vec![identified_segment(1, 1, false); 2],
    };
    let mut map = PanopticMap::new(config).unwrap();
    map.integrate_identified(frame.view(), &twice).unwrap();
    assert_eq!(map.instance_count(), 0);
    assert!(map.surface_voxels().all(|v| v.instance == 0));
    map.integrate_identified(frame.view(), &wall).unwrap();
    assert_eq!(map.instance_count(), 1);
    assert!(map.surface_voxels().any(|v| v.instance == 1));
    let mut at_once = config;
    at_once.tracking.min_observations = 1;
    let mut map = PanopticMap::new(at_once).unwrap();
    map.integrate_identified(frame.view(), &wall).unwrap();
    assert_eq!(map.instance_count(), 1);
}

#[test]
fn a_fragment_stays_hidden_until_it_grows_past_min_voxels() {
    let (k, pose, frame) = wall_head_on();
    // The wall as segment 1, with a `side`-pixel square at the image centre as segment 2.
    let with_square = |side: usize| {
        let (cx, cy) = (k.width / 2, k.height / 2);
        let mut labels = frame.ground_truth.clone().unwrap();
        for y in cy - side / 2..cy - side / 2 + side {
            for x in cx - side / 2..cx - side / 2 + side {
                *labels.get_mut(x, y) = 2;
            }
        }
        Segments {
            labels,
            segments: vec![
                identified_segment(1, 1, false),
                identified_segment(2, 5, true),
            ],
        }
    };
    // Size alone hides here: an instance shows from its first frame.
    let mut default = MapConfig::default();
    default.tracking.min_observations = 1;
    let min_voxels = default.tracking.min_voxels;
    assert_eq!(min_voxels, 12);
    let mut every_size = default;
    every_size.tracking.min_voxels = 0;
    let mut map = PanopticMap::new(default).unwrap();
    let mut all = PanopticMap::new(every_size).unwrap();
    // A 3 cm square: a few surface voxels.
    map.integrate_identified(frame.view(), &with_square(2))
        .unwrap();
    all.integrate_identified(frame.view(), &with_square(2))
        .unwrap();
    let fragment = all.instances().into_iter().find(|i| i.id == 2).unwrap();
    assert!(
        (1..min_voxels).contains(&fragment.voxels),
        "{} voxels",
        fragment.voxels
    );
    assert_eq!(all.instance_count(), 2);
    let shows_fragment = |m: &mut PanopticMap| {
        let listed = m.instances().iter().any(|i| i.id == 2);
        let in_voxels = m.surface_voxels().any(|v| v.instance == 2);
        let rendered = m.render(&k, &pose).instances.pixels().contains(&2);
        let meshed = m.mesh(Coloring::Instance).instances.contains(&2);
        let parts = [listed, in_voxels, rendered, meshed, m.class_of(2).is_some()];
        assert!(
            parts.iter().all(|&p| p == parts[0]),
            "outputs disagree: {parts:?}"
        );
        parts[0]
    };
    assert!(shows_fragment(&mut all));
    assert!(!shows_fragment(&mut map));
    assert_eq!(map.instance_count(), 1);
    // Seen as an 18 cm square (twice, to out-vote the wall where it was seen once), it shows.
    for _ in 0..2 {
        map.integrate_identified(frame.view(), &with_square(12))
            .unwrap();
    }
    let grown = map.instances().into_iter().find(|i| i.id == 2).unwrap();
    assert!(grown.voxels >= min_voxels, "{} voxels", grown.voxels);
    assert!(shows_fragment(&mut map));
    assert_eq!(map.instance_count(), 2);
    // Sizes are derived state: a loaded map shows the same instances.
    let loaded = PanopticMap::from_bytes(&map.to_bytes(), std::path::Path::new("memory")).unwrap();
    assert_eq!(loaded.instances(), map.instances());
}

#[test]
fn a_fragment_out_voted_where_its_masks_reached_is_hidden() {
    // A network sees a thing on a plain wall in two views (segment 2, a 54 cm square), then
    // the wall everywhere in four more, but for 3 cm squares 12 cm apart it leaves
    // unlabelled. The wall out-votes the fragment but under those pixels, where the fragment
    // keeps voxels enough to pass `min_voxels` counted together, but no piece of them does.
    // A second fragment (segment 3, a 9 cm square) the later views leave unlabelled is one
    // piece.
    let (k, _, frame) = wall_head_on();
    let (cx, cy) = (k.width / 2, k.height / 2);
    let masks = |fragments: bool| {
        let mut labels = frame.ground_truth.clone().unwrap();
        for y in cy - 18..cy + 18 {
            for x in cx - 18..cx + 18 {
                let gap = (x + 32 - cx) % 8 < 2 && (y + 32 - cy) % 8 < 2;
                *labels.get_mut(x, y) = if fragments { 2 } else { u16::from(!gap) };
            }
        }
        for y in cy - 3..cy + 3 {
            for x in cx + 24..cx + 30 {
                *labels.get_mut(x, y) = if fragments { 3 } else { 0 };
            }
        }
        Segments {
            labels,
            segments: vec![
                identified_segment(1, 1, false),
                identified_segment(2, 5, true),
                identified_segment(3, 5, true),
            ],
        }
    };
    // Two views with the fragments, then four of the wall.
    let fused = |config: MapConfig| {
        let mut map = PanopticMap::new(config).unwrap();
        for fragments in [true, true, false, false, false, false] {
            map.integrate_identified(frame.view(), &masks(fragments))
                .unwrap();
        }
        map
    };
    let mut map = fused(MapConfig::default());
    let min_voxels = map.config().tracking.min_voxels;
    let voxels_of = |m: &PanopticMap, id: u16| {
        m.instances()
            .into_iter()
            .find(|i| i.id == id)
            .map(|i| i.voxels)
    };
    let scattered = voxels_of(&map, 2).expect("shown by its count before the pass");
    assert!(scattered >= min_voxels, "{scattered} voxels");
    assert!(voxels_of(&map, 3).is_some());
    assert_eq!(map.judge_instances(), 1);
    assert_eq!(voxels_of(&map, 2), None);
    assert!(!map.surface_voxels().any(|v| v.instance == 2));
    assert!(voxels_of(&map, 3).is_some_and(|n| n >= min_voxels));
    // A loaded map judges its instances again: it shows what the saved one showed.
    let loaded = PanopticMap::from_bytes(&map.to_bytes(), std::path::Path::new("memory")).unwrap();
    assert_eq!(loaded.instances(), map.instances());
    // With `min_voxels = 0` every size shows, scattered or not.
    let mut every_size = MapConfig::default();
    every_size.tracking.min_voxels = 0;
    let mut all = fused(every_size);
    assert_eq!(all.judge_instances(), 0);
    assert!(voxels_of(&all, 2).is_some());
}

#[test]
fn a_fragment_a_thing_out_votes_where_its_masks_reached_is_hidden_and_not_under_stuff() {
    // A network sees a box (segment 2, a 54 cm square) on a surface in two views, then the
    // surface (segment 1) there in four more, but for a 9 cm corner of the box it leaves
    // unlabelled. The box keeps that corner: one piece, large enough to show. Under a thing
    // (a table) the rest of its counts lost to the table: it is hidden. Under stuff (a wall)
    // losses say nothing (masks spill over the wall behind things): it stays.
    let (k, _, frame) = wall_head_on();
    let (cx, cy) = (k.width / 2, k.height / 2);
    let masks = |surface_is_thing: bool, box_seen: bool| {
        let mut labels = frame.ground_truth.clone().unwrap();
        for y in cy - 18..cy + 18 {
            for x in cx - 18..cx + 18 {
                let corner = x >= cx + 12 && y >= cy + 12;
                *labels.get_mut(x, y) = match (box_seen, corner) {
                    (true, _) => 2,
                    (false, true) => 0,
                    (false, false) => 1,
                };
            }
        }
        let surface = if surface_is_thing {
            identified_segment(1, 7, true)
        } else {
            identified_segment(1, 1, false)
        };
        Segments {
            labels,
            segments: vec![surface, identified_segment(2, 5, true)],
        }
    };
    let fused = |surface_is_thing: bool| {
        let mut map = PanopticMap::new(MapConfig::default()).unwrap();
        for box_seen in [true, true, false, false, false, false] {
            map.integrate_identified(frame.view(), &masks(surface_is_thing, box_seen))
                .unwrap();
        }
        map
    };
    let min_voxels = MapConfig::default().tracking.min_voxels;
    let box_voxels = |m: &PanopticMap| {
        m.instances()
            .into_iter()
            .find(|i| i.id == 2)
            .map(|i| i.voxels)
    };
    let mut on_table = fused(true);
    let corner = box_voxels(&on_table).expect("shown by its count before the pass");
    assert!(corner >= min_voxels, "{corner} voxels");
    assert_eq!(on_table.judge_instances(), 1);
    assert_eq!(box_voxels(&on_table), None);
    assert!(!on_table.surface_voxels().any(|v| v.instance == 2));
    assert!(on_table.instances().iter().any(|i| i.id == 1));
    // A loaded map judges its instances again: it shows what the saved one showed.
    let loaded =
        PanopticMap::from_bytes(&on_table.to_bytes(), std::path::Path::new("memory")).unwrap();
    assert_eq!(loaded.instances(), on_table.instances());
    let mut on_wall = fused(false);
    assert_eq!(on_wall.judge_instances(), 0);
    assert_eq!(box_voxels(&on_wall), Some(corner));
}

/// Edits a frame's `masks` as a network that names true object `object` as class `class`.
fn rename(truth: &LabelImage, masks: &mut Segments, object: u16, class: u32) {
    let pixel = truth.pixels().iter().position(|&t| t == object).unwrap();
    let id = masks.labels.pixels()[pixel];
    for s in masks.segments.iter_mut().filter(|s| s.id == id) {
        s.class_id = Some(class);
    }
}

/// A chair (object 2, class 7) in front of the wall and views sweeping past it.
fn chair_in_front_of_wall() -> (Scene, Vec<voxpan_core::Pose>) {
    let scene = wall_scene(vec![object(
        2,
        7,
        true,
        vec![cuboid([0.0, 2.0, -0.5], [0.25, 0.25, 0.45])],
    )]);
    let poses = (0..10)
        .map(|i| {
            let p = Point3::new(-0.9 + 0.2 * i as f64, -0.3, 0.2);
            look_along(p, Point3::new(0.0, 2.0, -0.5) - p)
        })
        .collect();
    (scene, poses)
}

#[test]
fn a_thing_the_network_renames_stays_one_instance() {
    let (scene, poses) = chair_in_front_of_wall();
    // Called a toilet (class 8) in its first view only, as flat's network does with a chair;
    // and called one or the other in turn, as it does with a bed and a couch.
    let first_only = |f: usize| f == 0;
    let every_other = |f: usize| f.is_multiple_of(2);
    for renamed in [&first_only as &dyn Fn(usize) -> bool, &every_other] {
        let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
            if renamed(f) {
                rename(truth, masks, 2, 8);
            }
        });
        let of = instances_of_objects(&map, &reference);
        whole_thing(&of, 2, "chair");
        let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
        assert_eq!(things.len(), 1, "{things:?}");
        assert_eq!(things[0].frames_seen, poses.len() as u32, "{things:?}");
    }
}

#[test]
fn the_surface_a_settled_thing_shows_in_one_renamed_view_is_the_things() {
    // The chair seen as a chair from the front, then once from behind, beside the wall,
    // called a toilet (class 8). That segment covers the settled chair each way, so it
    // founds an instance of its own (a settled chair is no toilet guess); seen once, it is
    // hidden, and the back the chair showed only in that view is unlabelled until the map
    // is consolidated, which joins the guess to the chair.
    let (scene, mut poses) = chair_in_front_of_wall();
    let behind = Point3::new(1.0, 2.6, -0.2);
    poses.push(look_along(behind, Point3::new(0.0, 2.0, -0.5) - behind));
    let last = poses.len() - 1;
    let (mut map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        if f == last {
            rename(truth, masks, 2, 8);
        }
    });
    let unlabelled = |map: &PanopticMap| {
        instances_of_objects(map, &reference)[&2]
            .get(&0)
            .copied()
            .unwrap_or(0)
    };
    let before = unlabelled(&map);
    assert!(before > 500, "{before}: the back was seen before");
    map.consolidate();
    let of = instances_of_objects(&map, &reference);
    let (chair, share) = main_instance(&of, 2);
    assert!(chair != 0 && share > 0.97, "{:?}", of[&2]);
    assert_eq!(unlabelled(&map), 0, "{:?}", of[&2]);
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 1, "{things:?}");
    assert_eq!(things[0].frames_seen, poses.len() as u32, "{things:?}");
}

#[test]
fn a_chair_first_merged_into_its_sofas_mask_is_not_the_sofa_renamed() {
    // A sofa (class 9) and, 6 cm beside it, a chair (class 7); in the first view the network
    // leaves the chair inside the sofa's segment. In the second, the chair's own segment lies
    // on the one-frame-old sofa instance, but covers only part of it: two objects, not one
    // renamed, so it founds its own instance.
    let scene = wall_scene(vec![
        object(
            2,
            9,
            true,
            vec![cuboid([-0.6, 2.2, -0.6], [0.8, 0.35, 0.4])],
        ),
        object(
            3,
            7,
            true,
            vec![cuboid([0.51, 2.2, -0.5], [0.25, 0.25, 0.45])],
        ),
    ]);
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let mut reports = Vec::new();
    for f in 0..2 {
        let p = Point3::new(-0.4 + 0.2 * f as f64, -0.6, 0.2);
        let pose = look_along(p, Point3::new(0.0, 2.2, -0.5) - p);
        let (frame, truth, mut masks) = perceive(&scene, &pose, f);
        if f == 0 {
            leave_inside(&truth, &mut masks, 3, 2);
        }
        reports.push(map.integrate(frame.view(), Some(&masks)).unwrap());
    }
    let first = reports[0].association.unwrap();
    assert_eq!((first.created, first.matched), (2, 0), "{first:?}");
    // Wall and sofa continue; the chair founds its own.
    let second = reports[1].association.unwrap();
    assert_eq!((second.created, second.matched), (1, 2), "{second:?}");
}

#[test]
fn a_settled_thing_under_another_things_segment_is_not_renamed() {
    // A sofa (class 9) and a chair (class 7) 1.25 m apart. In 4 wide views the network leaves
    // the chair inside the sofa's segment, so the sofa's instance is settled and holds the
    // chair's voxels. Then 4 close views see only the chair, segmented as a chair: its segment
    // covers the sofa instance's whole visible part, and is still not the sofa renamed.
    let scene = wall_scene(vec![
        object(
            2,
            9,
            true,
            vec![cuboid([-1.7, 2.2, -0.6], [0.8, 0.35, 0.4])],
        ),
        object(
            3,
            7,
            true,
            vec![cuboid([0.6, 2.2, -0.5], [0.25, 0.25, 0.45])],
        ),
    ]);
    let merged = 4;
    let poses: Vec<_> = (0..8)
        .map(|i| {
            let (p, at) = if i < merged {
                (
                    Point3::new(-0.6 + 0.2 * i as f64, -0.6, 0.2),
                    Point3::new(0.0, 2.2, -0.5),
                )
            } else {
                (
                    Point3::new(0.6 + 0.02 * i as f64, 1.5, -0.45),
                    Point3::new(0.6, 2.2, -0.5),
                )
            };
            look_along(p, at - p)
        })
        .collect();
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        // The close views see no sofa.
        assert_eq!(truth.pixels().contains(&2), f < merged, "frame {f}");
        if f < merged {
            leave_inside(truth, masks, 3, 2);
        }
    });
    let (sofa, _) = main_instance(&instances_of_objects(&map, &reference), 2);
    let sofa = map.instances().into_iter().find(|i| i.id == sofa).unwrap();
    // Assigned segments in the merged views only, all of them sofas.
    assert_eq!(sofa.frames_seen, merged as u32, "{sofa:?}");
    assert_eq!(sofa.class_id, Some(9), "{sofa:?}");
}

/// Stuff pieces of one class, `pieces` (true object ids), fused from `poses`: each must be
/// its own instance, holding nearly all of its voxels; the map holds those and the wall.
fn assert_stuff_pieces_apart(
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    names: &[(u32, &str)],
    pieces: &[u16],
) {
    assert_stuff_pieces_apart_edited(scene, poses, names, pieces, |_, _, _| {});
}

/// [`assert_stuff_pieces_apart`], with each frame's masks passed through `edit` first (see
/// [`fuse_edited`]).
fn assert_stuff_pieces_apart_edited(
    scene: &Scene,
    poses: &[voxpan_core::Pose],
    names: &[(u32, &str)],
    pieces: &[u16],
    edit: impl FnMut(usize, &LabelImage, &mut Segments),
) {
    let (map, reference) = fuse_named(scene, poses, names, edit);
    let of = instances_of_objects(&map, &reference);
    let mains: Vec<(u16, f64)> = pieces.iter().map(|&o| main_instance(&of, o)).collect();
    for (&o, &(id, share)) in pieces.iter().zip(&mains) {
        assert!(id != 0 && share > 0.9, "object {o}: {:?}", of[&o]);
    }
    let ids: std::collections::BTreeSet<u16> = mains.iter().map(|m| m.0).collect();
    assert_eq!(ids.len(), pieces.len(), "joined: {mains:?}");
    let (wall, _) = main_instance(&of, 1);
    assert!(!ids.contains(&wall), "{of:?}");
    assert_eq!(
        map.instance_count(),
        pieces.len() + 1,
        "{:?}",
        map.instances()
    );
}

const WALL: u32 = 1;
const DOOR: u32 = 13;
const CABINET: u32 = 20;

/// Door `id`: a leaf 2 cm proud of the long wall, centred at `x`.
fn door(id: u16, x: f64) -> Object {
    object(
        id,
        DOOR,
        false,
        vec![cuboid([x, 2.88, -0.5], [0.45, 0.02, 1.0])],
    )
}

#[test]
fn two_doors_metres_apart_stay_two() {
    // Two door leaves 2 cm proud of a long wall, 5 m apart; the camera slides along the wall,
    // seeing one door, then plain wall, then the other. One instance per stuff class joined
    // them (flat's two doors 4.5 m apart as one `door` instance).
    let scene = wall_scene(vec![door(2, -2.5), door(3, 2.5)]);
    let poses: Vec<_> = (0..13)
        .map(|i| look_along(Point3::new(-3.0 + 0.5 * i as f64, 1.5, 0.0), Vector3::y()))
        .collect();
    assert_stuff_pieces_apart(&scene, &poses, &[(WALL, "wall"), (DOOR, "door")], &[2, 3]);
}

/// Doors 2 and 3 (stuff), 3 m apart on a long wall, seen from `poses`; in the frames
/// `one_segment` lists the network gives both one `door` segment, in two pieces. Checks that
/// each door is one instance of its own (see [`assert_stuff_pieces_apart`]).
fn assert_doors_in_one_segment_stay_two(poses: &[voxpan_core::Pose], one_segment: &[usize]) {
    let scene = wall_scene(vec![door(2, -1.5), door(3, 1.5)]);
    assert_stuff_pieces_apart_edited(
        &scene,
        poses,
        &[(WALL, "wall"), (DOOR, "door")],
        &[2, 3],
        |f, truth, masks| {
            if one_segment.contains(&f) {
                leave_inside(truth, masks, 3, 2);
            }
        },
    );
}

/// Looking at the wall from 1.9 m, centred on `x`: one door in view.
fn near_door(x: f64) -> voxpan_core::Pose {
    look_along(Point3::new(x, 1.0, -0.5), Vector3::y())
}

/// Looking at the wall from 2.6 m: both doors in view.
fn both_doors(x: f64) -> voxpan_core::Pose {
    look_along(Point3::new(x, 0.3, -0.3), Vector3::y())
}

#[test]
fn a_door_seen_first_in_another_doors_segment_stays_its_own() {
    // A panoptic network gives one segment per stuff class. Stepping back from the first
    // door, the camera sees both as one `door` segment, then the second door alone. Given
    // the first door's instance, the far piece made the second door's voxels vouch for it
    // (flat's two doors 4.5 m apart as one instance).
    let poses = [
        near_door(-1.6),
        near_door(-1.5),
        near_door(-1.4),
        both_doors(0.0),
        both_doors(0.1),
        near_door(1.4),
        near_door(1.5),
        near_door(1.6),
    ];
    assert_doors_in_one_segment_stay_two(&poses, &[3, 4]);
}

#[test]
fn two_doors_mapped_apart_then_seen_in_one_segment_stay_two() {
    // Each door mapped on its own, then both seen as one `door` segment in three frames:
    // the segment covering most of both instances in view voted to merge them.
    let poses = [
        near_door(-1.6),
        near_door(-1.5),
        near_door(1.5),
        near_door(1.6),
        both_doors(0.0),
        both_doors(0.1),
        both_doors(0.2),
    ];
    assert_doors_in_one_segment_stay_two(&poses, &[4, 5, 6]);
}

#[test]
fn a_cabinet_and_a_counter_in_two_rooms_stay_apart() {
    // Two rooms either side of a partition wall, each with a kitchen cabinet of one stuff
    // class against the back wall; the camera maps one room, then the other.
    let mut scene = Scene::empty(Vector3::new(20.0, 20.0, 10.0));
    scene.add(object(
        1,
        WALL,
        false,
        vec![
            cuboid([0.0, 3.0, 0.0], [8.0, 0.1, 2.0]),
            cuboid([0.0, 0.5, 0.0], [0.1, 2.4, 2.0]),
        ],
    ));
    for (id, x) in [(2, -2.0), (3, 2.0)] {
        scene.add(object(
            id,
            CABINET,
            false,
            vec![cuboid([x, 2.6, -1.2], [0.8, 0.3, 0.8])],
        ));
    }
    let poses: Vec<_> = [-2.3, -2.0, -1.7, 1.7, 2.0, 2.3]
        .iter()
        .map(|&x| {
            let p = Point3::new(x, 0.6, 0.2);
            look_along(p, Point3::new(x.signum() * 2.0, 2.6, -1.0) - p)
        })
        .collect();
    assert_stuff_pieces_apart(
        &scene,
        &poses,
        &[(WALL, "wall"), (CABINET, "cabinet")],
        &[2, 3],
    );
}

#[test]
fn a_refrigerator_seen_in_three_partial_views_is_one() {
    // Close up, each view sees a third of a 1.8 m refrigerator, with a little of the one
    // before (flat's refrigerator: three instances side by side).
    let scene = wall_scene(vec![object(
        2,
        30,
        true,
        vec![cuboid([0.0, 2.5, -0.9], [0.4, 0.35, 0.9])],
    )]);
    let poses: Vec<_> = [-0.3, -0.9, -1.5]
        .iter()
        .map(|&z| {
            let p = Point3::new(0.05, 1.45, -0.9);
            look_along(p, Point3::new(0.0, 2.15, z) - p)
        })
        .collect();
    assert_one_thing_through_every_view(&scene, &poses, 0.95);
}

/// A table (object 2, class 7) in front of the wall.
fn table_before_wall() -> Scene {
    wall_scene(vec![object(
        2,
        7,
        true,
        vec![cuboid([0.0, 2.0, -0.5], [0.6, 0.3, 0.4])],
    )])
}

/// Checks that true object `object` is the map's one thing instance, holding over 90 % of the
/// object's voxels.
fn assert_the_only_thing(map: &PanopticMap, reference: &PanopticMap, object: u16) {
    let of = instances_of_objects(map, reference);
    let (main, share) = main_instance(&of, object);
    assert!(share > 0.9, "{:?}", of[&object]);
    let things: Vec<u16> = map
        .instances()
        .iter()
        .filter(|i| i.is_thing)
        .map(|i| i.id)
        .collect();
    assert_eq!(things, [main]);
}

/// Checks that the first view founded `first` instances (`what` they are) and no later view
/// founded any.
fn assert_founded_in_the_first_view_only(reports: &[AssociationStats], first: usize, what: &str) {
    let created: Vec<usize> = reports.iter().map(|r| r.created).collect();
    assert_eq!(created[0], first, "{what}: {created:?}");
    assert!(created[1..].iter().all(|&n| n == 0), "{created:?}");
}

#[test]
fn a_table_first_segmented_in_parts_is_continued_whole() {
    // For the first 5 views the network cuts a table's mask across into three parts (each
    // founds an instance); then it segments the table whole. No part holds most of a whole segment, but together they do: the whole
    // table continues its parts instead of founding a fourth instance, and its votes join
    // them into one once they outweigh the views that told them apart.
    let scene = table_before_wall();
    let positions = (0..20).map(|i| Point3::new(-0.5 + 0.05 * i as f64, -0.2, 0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let (map, reference, reports) = fuse_reporting(&scene, &poses, &[], |f, truth, masks| {
        if f < 5 {
            split_across(truth, masks, 2, 3);
        }
    });
    assert_founded_in_the_first_view_only(&reports, 4, "the wall and three parts");
    assert_the_only_thing(&map, &reference, 2);
}

#[test]
fn a_table_cut_in_three_in_every_view_is_one_instance() {
    // The network cuts a table's mask across into three parts in every view, each part
    // founding an instance. The middle part meets both others across the table's own
    // surface, and the outer two never touch: read as two segments of one class in one
    // frame, they were told apart in every view, and once the map joined one of them to
    // the middle part the other stayed out. Linked through the middle part's cuts, they are
    // pieces of one object, and the map joins all three.
    let scene = table_before_wall();
    let positions = (0..12).map(|i| Point3::new(-0.3 + 0.05 * i as f64, -0.2, 0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let (mut map, reference) = fuse_edited(&scene, &poses, |_, truth, masks| {
        split_across(truth, masks, 2, 3);
    });
    assert_eq!(map.consolidate(), 2, "the two joins");
    assert_the_only_thing(&map, &reference, 2);
}

#[test]
fn a_piece_the_network_cuts_off_where_the_map_has_no_label_continues_its_object() {
    // For the first 5 views the network's mask covers only the left half of a table (its
    // right half is fused unlabelled); then it cuts the table at its middle. The right piece
    // lies where the map holds no instance, so nothing vouches for it, but it meets the left
    // piece across the table's own surface: it continues the table instead of founding a
    // second instance.
    let scene = table_before_wall();
    let positions = (0..10).map(|i| Point3::new(-0.25 + 0.05 * i as f64, -0.2, 0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let (map, reference, reports) = fuse_reporting(&scene, &poses, &[], |f, truth, masks| {
        if f < 5 {
            segment_half(truth, masks, 2, true);
        } else {
            split_across(truth, masks, 2, 2);
        }
    });
    assert_founded_in_the_first_view_only(&reports, 2, "the wall and the table");
    assert_the_only_thing(&map, &reference, 2);
}

/// Edits a frame's `masks` as a network that cuts true object `object`'s segment into
/// `parts` side by side (equal spans of its columns), each a segment of its class.
fn split_across(truth: &LabelImage, masks: &mut Segments, object: u16, parts: usize) {
    let w = truth.dims().0;
    let (left, right) = object_columns(truth, object);
    let span = (right - left + 1).div_ceil(parts);
    let pixel = truth.pixels().iter().position(|&t| t == object).unwrap();
    let id = masks.labels.pixels()[pixel];
    let whole = masks.segments.iter().find(|s| s.id == id).unwrap().clone();
    let first_new = masks.segments.iter().map(|s| s.id).max().unwrap() + 1;
    for k in 1..parts as u16 {
        masks.segments.push(voxpan_core::Segment {
            id: first_new + k - 1,
            ..whole.clone()
        });
    }
    for (i, l) in masks.labels.pixels_mut().iter_mut().enumerate() {
        if *l == id && truth.pixels()[i] == object {
            let part = ((i % w - left) / span) as u16;
            if part > 0 {
                *l = first_new + part - 1;
            }
        }
    }
}

#[test]
fn a_shelf_of_books_seen_once_each_leaves_no_swarm() {
    // Eight books on a shelf; in each view the network segments one of them and leaves the
    // others inside the shelf's segment (as networks do with rows of small things). A book
    // segmented once is no more an object than a fragment is: none is shown, the shelf is.
    let book = |k: u16| {
        object(
            3 + k,
            41,
            true,
            vec![cuboid(
                [-0.35 + 0.1 * k as f64, 2.6, 0.1],
                [0.04, 0.1, 0.12],
            )],
        )
    };
    let mut things = vec![object(
        2,
        40,
        true,
        vec![cuboid([0.0, 2.8, -0.4], [0.5, 0.1, 0.4])],
    )];
    things.extend((0..8).map(book));
    let scene = wall_scene(things);
    let positions = (0..8).map(|i| Point3::new(-0.2 + 0.05 * i as f64, 1.4, 0.3));
    let poses = looking_at(positions, Point3::new(0.0, 2.6, 0.0));
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        for k in (0..8).filter(|&k| k != f as u16) {
            leave_inside(truth, masks, 3 + k, 2);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let shelf = whole_thing(&of, 2, "shelf");
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 1, "a swarm: {things:?}");
    assert_eq!(things[0].id, shelf);
}

/// Two rows of eight books (objects 2-9 and 10-17, class 41) standing 5 mm apart with their
/// spines a few centimetres out of line, the rows 30 cm apart in front of a wall, seen by a
/// network that segments every book by itself in each of 8 views, passing each view's
/// masks through `edit(frame, masks)`. Returns, for each row, the map instances holding its
/// books' voxels (most first, with their voxels), and the things the map shows.
fn rows_of_books(
    names: &[(u32, &str)],
    mut edit: impl FnMut(usize, &mut Segments),
) -> (Vec<Vec<(u16, usize)>>, usize) {
    let book = |id: u16, x: f64, k: usize| {
        let spine = [0.0, 0.02, -0.01, 0.015, -0.02, 0.01, 0.0, -0.015][k];
        object(
            id,
            BOOK,
            true,
            vec![cuboid([x, 2.6 + spine, 0.1], [0.025, 0.1, 0.12])],
        )
    };
    let mut books = Vec::new();
    for (row, start) in [(0u16, -0.5), (1, 0.22)] {
        for k in 0..8 {
            books.push(book(2 + 8 * row + k as u16, start + 0.055 * k as f64, k));
        }
    }
    let scene = wall_scene(books);
    let positions = (0..8).map(|i| Point3::new(-0.2 + 0.05 * i as f64, 1.5, 0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.6, 0.1));
    let (map, reference) = fuse_named(&scene, &poses, names, |f, _, masks| edit(f, masks));
    let of = instances_of_objects(&map, &reference);
    let rows = [2u16..10, 10..18].map(|objects| {
        let mut held: BTreeMap<u16, usize> = BTreeMap::new();
        for o in objects {
            for (&i, &n) in &of[&o] {
                *held.entry(i).or_default() += n;
            }
        }
        let mut ids: Vec<(u16, usize)> = held.into_iter().filter(|&(i, _)| i != 0).collect();
        ids.sort_by_key(|&(i, n)| (std::cmp::Reverse(n), i));
        ids
    });
    let shown = map.instances().into_iter().filter(|i| i.is_thing).count();
    (rows.to_vec(), shown)
}

/// The class of the rows' books (see [`rows_of_books`]).
const BOOK: u32 = 41;

#[test]
fn a_row_of_books_segmented_book_by_book_is_one_instance() {
    // COCO names each `book`; the map, as the flat's ground truth (`SM_Stack_of_Books_*`),
    // holds a row as one object: the touching books of each view become one segment.
    let (rows, shown) = rows_of_books(&[(1, "wall"), (BOOK, "book")], |_, _| {});
    assert_eq!(rows[0].len(), 1, "the first row is split: {rows:?}");
    assert_eq!(rows[1].len(), 1, "the second row is split: {rows:?}");
    assert_ne!(rows[0][0].0, rows[1][0].0, "rows 30 cm apart are joined");
    assert_eq!(shown, 2);
    // Touching things of other classes are not groups: each keeps its own instance.
    let (rows, shown) = rows_of_books(&[(1, "wall"), (BOOK, "box")], |_, _| {});
    assert!(
        rows.iter().all(|r| r.len() == 8),
        "boxes side by side were joined: {rows:?}"
    );
    assert_eq!(shown, 16);
}

#[test]
fn a_row_of_books_first_named_box_book_by_book_is_one_instance() {
    // The first 3 views name every book `box` (a network's other name for them), so each
    // founds a `box` instance; the later views name them `book`, and the row's one segment
    // covers those instances: it gathers them into one.
    const BOX: u32 = 42;
    let names = [(1, "wall"), (BOOK, "book"), (BOX, "box")];
    let (rows, shown) = rows_of_books(&names, |f, masks| {
        for s in &mut masks.segments {
            if f < 3 && s.class_id == Some(BOOK) {
                s.class_id = Some(BOX);
            }
        }
    });
    for row in &rows {
        let total: usize = row.iter().map(|(_, n)| n).sum();
        assert!(
            row[0].1 as f64 > 0.9 * total as f64,
            "a row is split: {rows:?}"
        );
    }
    assert_ne!(rows[0][0].0, rows[1][0].0, "rows 30 cm apart are joined");
    assert_eq!(shown, 2, "{rows:?}");
}

#[test]
fn a_shelf_called_books_for_a_view_beside_its_book_stays_one_instance() {
    // A shelf with a book flush on its front. The first 5 views see the shelf's left end and
    // the book, each segmented as itself; one view from farther back sees the whole shelf but
    // calls it `books`, and that mask meets the book's across the shelf's continuous surface,
    // as a network cutting one object would; the last views see the right end, named a shelf
    // again. The renamed mask lies mostly on the shelf, so it is not a piece of the book: had
    // it continued the book, the right end would be the book's, and the shelf seen there
    // again a second shelf.
    let shelf = object(2, 40, true, vec![cuboid([0.0, 2.7, 0.0], [1.2, 0.1, 0.5])]);
    let book = object(
        3,
        41,
        true,
        vec![cuboid([-0.7, 2.59, 0.0], [0.15, 0.01, 0.2])],
    );
    let scene = wall_scene(vec![shelf, book]);
    let at = |x: f64, y: f64| look_along(Point3::new(x, y, 0.0), Vector3::new(0.0, 1.0, 0.0));
    let mut poses: Vec<_> = (0..5).map(|i| at(-0.9 + 0.1 * i as f64, 1.6)).collect();
    let renamed = poses.len();
    poses.push(at(0.0, 1.0));
    poses.extend((0..4).map(|i| at(0.6 + 0.1 * i as f64, 1.9)));
    let (mut map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        if f == renamed {
            rename(truth, masks, 2, 41);
        }
    });
    map.consolidate();
    let of = instances_of_objects(&map, &reference);
    let shelf = whole_thing(&of, 2, "shelf");
    let (book, _) = main_instance(&of, 3);
    assert!(book != 0 && book != shelf, "{:?}", of[&3]);
    let things: Vec<_> = map.instances().into_iter().filter(|i| i.is_thing).collect();
    assert_eq!(things.len(), 2, "{things:?}");
}

/// A floor (object 1) with a rug (object 2) on it, seen from above while the camera turns.
fn rug_on_floor() -> (Scene, Vec<voxpan_core::Pose>) {
    let mut scene = Scene::empty(Vector3::new(20.0, 20.0, 10.0));
    scene.add(object(
        1,
        FLOOR,
        false,
        vec![cuboid([0.0, 0.0, -1.1], [4.0, 4.0, 0.1])],
    ));
    scene.add(object(
        2,
        RUG,
        false,
        vec![cuboid([0.0, 1.5, -0.995], [0.6, 0.4, 0.005])],
    ));
    let positions = (0..10).map(|i| Point3::new(-0.5 + 0.1 * i as f64, 0.0, 0.4));
    let poses = looking_at(positions, Point3::new(0.0, 1.5, -1.0));
    (scene, poses)
}

const FLOOR: u32 = 2;
const RUG: u32 = 12;
const FLOOR_AND_RUG: [(u32, &str); 2] = [(FLOOR, "floor"), (RUG, "rug")];

#[test]
fn a_floor_the_network_calls_a_rug_for_a_while_stays_one_instance() {
    // Frames 3..6 name the whole floor segment `rug` (class flicker between frames): the
    // floor's instance continues, it does not found a rug instance covering the floor.
    let (scene, poses) = rug_on_floor();
    let (map, reference) = fuse_named(&scene, &poses, &FLOOR_AND_RUG, |f, truth, masks| {
        if (3..6).contains(&f) {
            rename(truth, masks, 1, RUG);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (floor, share) = main_instance(&of, 1);
    assert!(share > 0.95, "{:?}", of[&1]);
    let (rug, share) = main_instance(&of, 2);
    assert!(rug != floor && share > 0.8, "{:?}", of[&2]);
    assert_eq!(map.instance_count(), 2, "{:?}", map.instances());
    assert_eq!(map.class_of(floor), Some(FLOOR));
}

#[test]
fn a_floor_named_rug_by_most_frames_is_still_the_floor_in_the_next_room() {
    // The network calls the whole floor `rug` in 7 of the first 8 views, so its instance is
    // named `rug` by its votes; then the camera turns to a part of the floor no view has
    // mapped yet, segmented `floor` again. The floor is the building's shell: the segment
    // continues the instance seen most often as floor, whatever its name, and does not found
    // a second floor.
    let (scene, near) = rug_on_floor();
    let far = (0..4).map(|i| Point3::new(2.0 + 0.1 * i as f64, -1.5, 0.4));
    let poses: Vec<_> = near[..8]
        .iter()
        .copied()
        .chain(looking_at(far, Point3::new(3.0, -3.5, -1.0)))
        .collect();
    let (map, reference) = fuse_named(&scene, &poses, &FLOOR_AND_RUG, |f, truth, masks| {
        if (1..8).contains(&f) {
            rename(truth, masks, 1, RUG);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (floor, share) = main_instance(&of, 1);
    assert!(share > 0.95, "the floor is split: {:?}", of[&1]);
    assert_eq!(map.class_of(floor), Some(RUG), "the votes name it rug");
    assert_eq!(map.instance_count(), 2, "{:?}", map.instances());
}

#[test]
fn a_rug_first_mapped_as_the_floor_becomes_its_own_instance() {
    // The network sees no rug in the first 3 views (its pixels are in the floor's segment),
    // then segments it: a rug covers only part of the floor in view, so it is not the floor
    // renamed, and founds its own instance.
    let (scene, poses) = rug_on_floor();
    let (map, reference) = fuse_named(&scene, &poses, &FLOOR_AND_RUG, |f, truth, masks| {
        if f < 3 {
            leave_inside(truth, masks, 2, 1);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (floor, _) = main_instance(&of, 1);
    let (rug, share) = main_instance(&of, 2);
    assert!(rug != floor && share > 0.8, "{:?}", of[&2]);
    assert_eq!(map.class_of(rug), Some(RUG));
}

#[test]
fn a_rug_mapped_as_the_floor_separates_when_the_network_swaps_their_names() {
    // The first 3 views leave the rug inside the floor's segment, so the floor's instance
    // holds the rug. Later views segment the two apart but swap their names: the floor is
    // called `rug`, the rug `floor`. Both segments continue the floor's instance (the first
    // as the floor renamed, the second by its name and the voxels under it), though the
    // segmenter says these are two regions. The segment holding most of the instance keeps
    // it; the rug lets go and becomes an instance of its own.
    let (scene, poses) = rug_on_floor();
    let (map, reference) = fuse_named(&scene, &poses, &FLOOR_AND_RUG, |f, truth, masks| {
        if f < 3 {
            leave_inside(truth, masks, 2, 1);
        } else {
            rename(truth, masks, 1, RUG);
            rename(truth, masks, 2, FLOOR);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (floor, share) = main_instance(&of, 1);
    assert!(share > 0.95, "{:?}", of[&1]);
    let (rug, share) = main_instance(&of, 2);
    assert!(
        rug != floor && share > 0.8,
        "the rug is the floor's: {:?}",
        of[&2]
    );
    assert_eq!(map.instance_count(), 2, "{:?}", map.instances());
}

#[test]
fn a_floor_called_a_rug_where_the_camera_moves_on_to_new_floor_stays_the_floor() {
    // The first 5 views map the floor and the rug on it. Then the camera turns away to floor
    // no view has mapped, and the network calls the whole floor in view `rug` (the rug itself,
    // in the first of those views, is segmented apart as before). Most of each such segment
    // is new surface, so its measurements do not explain it as the floor renamed, and it
    // founded a rug instance that took the new floor. But what the map already holds under
    // it is floor, it covers all of the floor in view, and no segment of those frames says
    // `floor`: it is the floor under another name.
    let (scene, near) = rug_on_floor();
    let turning = (0..6).map(|i| Point3::new(-0.5 - 0.3 * i as f64, -0.3 * i as f64, 0.4));
    let targets = (0..6).map(|i| Point3::new(-(i as f64), 1.5 - 1.2 * i as f64, -1.0));
    let poses: Vec<_> = near[..4]
        .iter()
        .copied()
        .chain(turning.zip(targets).map(|(p, t)| look_along(p, t - p)))
        .collect();
    let (map, reference) = fuse_named(&scene, &poses, &FLOOR_AND_RUG, |f, truth, masks| {
        if f >= 5 {
            rename(truth, masks, 1, RUG);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (floor, share) = main_instance(&of, 1);
    assert!(share > 0.95, "the floor is split: {:?}", of[&1]);
    assert_eq!(map.class_of(floor), Some(FLOOR));
    let (rug, share) = main_instance(&of, 2);
    assert!(rug != floor && share > 0.8, "{:?}", of[&2]);
}

#[test]
fn a_wall_the_network_calls_a_door_for_a_while_stays_one_wall() {
    // In views 3..10 the network leaves the left 60 % of the wall in view unsegmented and
    // calls the rest `door`; from view 10 on it segments the whole wall as `wall` again. No
    // other segment continues the wall in those views, so the `door` is the wall renamed,
    // not a region beside it: it must not take the wall's voxels over (before, each `door`
    // view continued the first one's instance through the voxels' runner-up, which then led
    // that part of the wall and stayed a second instance).
    let scene = wall_scene(vec![]);
    let positions = (0..16).map(|i| Point3::new(-0.4 + 0.05 * i as f64, 1.5, 0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.9, 0.2));
    let names = [(WALL, "wall"), (DOOR, "door")];
    let (map, reference) = fuse_named(&scene, &poses, &names, |f, truth, masks| {
        if (3..10).contains(&f) {
            rename(truth, masks, 1, DOOR);
            void_left_of(truth, masks, 1, 0.6);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (wall, share) = main_instance(&of, 1);
    assert!(share > 0.95, "the wall is split: {:?}", of[&1]);
    assert_eq!(map.class_of(wall), Some(WALL));
    assert_eq!(map.instance_count(), 1, "{:?}", map.instances());
}

/// Edits a frame's `masks` as a network that leaves the left `share` of true object
/// `object`'s columns in view unsegmented.
fn void_left_of(truth: &LabelImage, masks: &mut Segments, object: u16, share: f64) {
    let (first, last) = object_columns(truth, object);
    let cut = first + ((last - first) as f64 * share) as usize;
    void_columns(truth, masks, object, |x| x < cut);
}

/// The first and last image columns true object `object` covers.
fn object_columns(truth: &LabelImage, object: u16) -> (usize, usize) {
    let w = truth.dims().0;
    let columns = || {
        (0..truth.pixels().len())
            .filter(|&i| truth.pixels()[i] == object)
            .map(|i| i % w)
    };
    (columns().min().unwrap(), columns().max().unwrap())
}

/// Leaves the pixels of true object `object` in the columns `void` picks unsegmented.
fn void_columns(
    truth: &LabelImage,
    masks: &mut Segments,
    object: u16,
    void: impl Fn(usize) -> bool,
) {
    let w = truth.dims().0;
    for (i, l) in masks.labels.pixels_mut().iter_mut().enumerate() {
        if truth.pixels()[i] == object && void(i % w) {
            *l = 0;
        }
    }
}

#[test]
fn a_things_bleed_onto_its_wall_goes_back_to_the_wall() {
    // A lamp's masks bleed 10 pixels onto the wall to its right in the first 4 views (as
    // over-covering masks do, where refinement cannot cut them), then fit in 8 more. Where a
    // later segment of the lamp stops short of those voxels, the wall's segment takes them
    // back: the thing does not keep every wall voxel its masks once covered.
    let scene = wall_scene(vec![object(
        2,
        5,
        true,
        vec![cuboid([0.0, 2.88, 0.2], [0.15, 0.02, 0.3])],
    )]);
    let positions = (0..12).map(|i| Point3::new(-0.3 + 0.05 * i as f64, 1.5, 0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.9, 0.2));
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        if f < 4 {
            bleed_right(truth, masks, 2, 10);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (wall, share) = main_instance(&of, 1);
    let lamp = main_instance(&of, 2).0;
    assert!(lamp != wall);
    assert!(share > 0.995, "the lamp kept wall voxels: {:?}", of[&1]);
}

#[test]
fn a_wall_patch_the_table_was_mapped_into_goes_back_to_the_wall() {
    // The network calls a patch of wall (object 3, wall in the reference) a table in two
    // close views of the wall; from across the room its mask of the table in front of the
    // wall (object 2) then spreads over that patch, so the table is mapped into the
    // fragment's instance. Views of the wall alone, with the table out of view, segment the
    // patch as wall. The table stands 0.6 m clear of the wall, so refinement would cut a
    // wall mask off it: wall pixels on its instance's voxels there are what its masks spread
    // onto, and they go back to the wall (three rooms seed 1 kept 3,800 wall voxels in a
    // table this way, and the table fell under IoU 0.5). Fails while stuff never overwrites
    // any thing no segment of the frame continues.
    let mut scene = table_before_wall();
    scene.add(object(
        3,
        1,
        false,
        vec![cuboid([1.1, 2.89, -0.35], [0.2, 0.01, 0.15])],
    ));
    let near = |i: usize| look_along(Point3::new(0.9 + 0.05 * i as f64, 2.0, -0.35), Vector3::y());
    let fragment_views = 2;
    let table_views = 7;
    let poses: Vec<_> = (0..fragment_views)
        .map(near)
        .chain((0..table_views).map(|i| {
            let p = Point3::new(-0.3 + 0.1 * i as f64, -0.3, -0.2);
            look_along(p, Point3::new(0.5, 2.5, -0.4) - p)
        }))
        .chain((0..10).map(near))
        .collect();
    let (map, reference) = fuse_edited(&scene, &poses, |f, truth, masks| {
        if f < fragment_views {
            let pixel = truth.pixels().iter().position(|&t| t == 3).unwrap();
            let id = masks.labels.pixels()[pixel];
            for s in masks.segments.iter_mut().filter(|s| s.id == id) {
                (s.class_id, s.is_thing) = (Some(7), Some(true));
            }
        } else if f < fragment_views + table_views {
            leave_inside(truth, masks, 3, 2);
        } else {
            leave_inside(truth, masks, 3, 1);
        }
    });
    let of = instances_of_objects(&map, &reference);
    let (table, table_share) = main_instance(&of, 2);
    let (wall, _) = main_instance(&of, 1);
    let (patch, patch_share) = main_instance(&of, 3);
    assert!(table != wall && table_share > 0.9, "{:?}", of[&2]);
    assert!(
        patch == wall && patch_share > 0.9,
        "the table ({table}) kept the wall patch: {:?}",
        of[&3]
    );
}

/// Edits a frame's `masks` as a network whose mask of true object `object` spreads `pixels`
/// pixels to the right of it, over what lies there.
fn bleed_right(truth: &LabelImage, masks: &mut Segments, object: u16, pixels: usize) {
    let (w, h) = truth.dims();
    let pixel = truth.pixels().iter().position(|&t| t == object).unwrap();
    let id = masks.labels.pixels()[pixel];
    for y in 0..h {
        let Some(right) = (0..w).rev().find(|&x| *truth.get(x, y) == object) else {
            continue;
        };
        for x in right + 1..(right + 1 + pixels).min(w) {
            *masks.labels.get_mut(x, y) = id;
        }
    }
}

/// Edits a frame's `masks` as a network that segments only one half of true object
/// `object` (the `left` or the right half of its columns) and leaves the other half void.
fn segment_half(truth: &LabelImage, masks: &mut Segments, object: u16, left: bool) {
    let (first, last) = object_columns(truth, object);
    let middle = (first + last) / 2;
    void_columns(truth, masks, object, |x| (x < middle) != left);
}

/// A bench (object 2, class 30) fused from eight views at one viewpoint (so that both
/// halves' masks meet at the same place on it), segmented by its left half in the first four
/// and by its right half in the last four, the other half void; the right half is named
/// `right_class` when given. Returns the map and its reference.
fn bench_segmented_by_halves(right_class: Option<u32>) -> (PanopticMap, PanopticMap) {
    bench_segmented_by_halves_into(MapConfig::default(), right_class)
}

/// [`bench_segmented_by_halves`] into a map of `config`.
fn bench_segmented_by_halves_into(
    config: MapConfig,
    right_class: Option<u32>,
) -> (PanopticMap, PanopticMap) {
    let scene = wall_scene(vec![object(
        2,
        30,
        true,
        vec![cuboid([0.0, 2.0, -0.6], [0.8, 0.25, 0.3])],
    )]);
    let positions = (0..8).map(|_| Point3::new(0.0, 0.4, -0.3));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.6));
    let (map, reference, _) = fuse_configured(config, &scene, &poses, &[], |f, truth, masks| {
        if let Some(class) = right_class.filter(|_| f >= 4) {
            // Before the left half is voided: `rename` finds the segment by its first pixel.
            rename(truth, masks, 2, class);
        }
        segment_half(truth, masks, 2, f < 4);
    });
    (map, reference)
}

#[test]
fn an_object_segmented_one_half_at_a_time_is_one_after_consolidation() {
    // A bench the network segments by halves: its left half for four views, then its right
    // half for four more, the other half void. No segment covers both halves and no view
    // tells them apart, so frame by frame each half founds an instance; they meet along the
    // cut, a seam as long as the bench is high.
    let (mut map, reference) = bench_segmented_by_halves(None);
    let things = |map: &PanopticMap| map.instances().into_iter().filter(|i| i.is_thing).count();
    assert_eq!(
        things(&map),
        2,
        "a half an instance before: {:?}",
        map.instances()
    );
    assert_eq!(map.consolidate(), 1);
    let of = instances_of_objects(&map, &reference);
    whole_thing(&of, 2, "bench");
    assert_eq!(things(&map), 1, "{:?}", map.instances());
}

#[test]
fn a_map_consolidated_every_few_frames_joins_the_halves_while_it_is_live() {
    // The bench of the test above, in a map that consolidates after every fourth frame: the
    // pass after the last view (the eighth) joins the halves with no call after the run, the
    // pass after the fourth had only the left half to read. The reference, fused from the
    // ground truth's ids with the same configuration, keeps its bench apart from its wall:
    // identified ids are not consolidated.
    let mut config = MapConfig::default();
    config.tracking.consolidate_every = 4;
    let (mut map, reference) = bench_segmented_by_halves_into(config, None);
    let things = |map: &PanopticMap| map.instances().into_iter().filter(|i| i.is_thing).count();
    assert_eq!(things(&map), 1, "{:?}", map.instances());
    let of = instances_of_objects(&map, &reference);
    whole_thing(&of, 2, "bench");
    assert_eq!(map.consolidate(), 0, "nothing left to join");
}

#[test]
fn an_object_named_two_ways_by_halves_is_one_after_consolidation() {
    // The bench of the test above, its left half segmented as a bench (class 30) for four
    // views, then its right half as a table (class 31) for four more: a network renaming an
    // object between the windows in which it cuts it. Frame by frame each half founds an
    // instance of its own class; no view tells them apart, so consolidation joins them along
    // their seam whatever they were called.
    let (mut map, reference) = bench_segmented_by_halves(Some(31));
    let classes = |map: &PanopticMap| {
        let mut classes: Vec<_> = map
            .instances()
            .into_iter()
            .filter(|i| i.is_thing)
            .map(|i| i.class_id)
            .collect();
        classes.sort();
        classes
    };
    assert_eq!(classes(&map), [Some(30), Some(31)], "{:?}", map.instances());
    assert_eq!(map.consolidate(), 1);
    whole_thing(&instances_of_objects(&map, &reference), 2, "bench");
    assert_eq!(classes(&map).len(), 1, "{:?}", map.instances());
}

#[test]
fn a_box_on_a_table_segmented_apart_stays_apart_after_consolidation() {
    // A box (class 41) standing on a table (class 40): their surfaces meet along the box's
    // whole footprint, a seam longer than the box is wide, but every view segments them as
    // two touching segments, so consolidation keeps both whatever their classes.
    let scene = wall_scene(vec![
        object(
            2,
            40,
            true,
            vec![cuboid([0.0, 2.0, -0.9], [0.6, 0.4, 0.05])],
        ),
        object(
            3,
            41,
            true,
            vec![cuboid([0.0, 2.0, -0.7], [0.15, 0.15, 0.15])],
        ),
    ]);
    let positions = (0..6).map(|i| Point3::new(-0.2 + 0.08 * i as f64, 0.6, 0.0));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.8));
    let (mut map, reference) = fuse(&scene, &poses);
    assert_objects_meet_along_a_seam(&map, &reference);
    assert_consolidation_keeps_apart(&mut map, &reference, 0.9);
}

/// Consolidation joins nothing, and true objects 2 and 3 are each mostly (over `share` of
/// their voxels) in an instance of their own.
fn assert_consolidation_keeps_apart(map: &mut PanopticMap, reference: &PanopticMap, share: f64) {
    assert_eq!(map.consolidate(), 0);
    let of = instances_of_objects(map, reference);
    let (a, b) = (main_instance(&of, 2), main_instance(&of, 3));
    assert!(a.0 != b.0 && a.1 > share && b.1 > share, "{of:?}");
}

/// The instances holding most of true objects 2 and 3 meet along a seam, as consolidation's
/// seam rule weighs it: else a test that they stay apart says nothing.
fn assert_objects_meet_along_a_seam(map: &PanopticMap, reference: &PanopticMap) {
    let of = instances_of_objects(map, reference);
    let (a, b) = (main_instance(&of, 2).0, main_instance(&of, 3).0);
    let (seam, smaller) = seam_between(map, a, b);
    assert!(
        seam.pow(2) >= smaller,
        "they must meet along a seam for this test to say anything: {seam} faces, {smaller} voxels"
    );
}

/// The voxel faces where surface voxels of instances `a` and `b` meet, and the smaller one's
/// surface voxels: what consolidation's seam rule weighs.
fn seam_between(map: &PanopticMap, a: u16, b: u16) -> (usize, usize) {
    let of: BTreeMap<VoxelIndex, u16> = map
        .surface_voxels()
        .filter(|v| v.instance == a || v.instance == b)
        .map(|v| (v.index, v.instance))
        .collect();
    let mut faces = 0;
    for (v, &id) in of.iter().filter(|(_, id)| **id == a) {
        for axis in 0..3 {
            for step in [-1, 1] {
                let mut n = *v;
                n[axis] += step;
                faces += usize::from(of.get(&n).is_some_and(|&other| other != id));
            }
        }
    }
    let size = |id| of.values().filter(|&&i| i == id).count();
    (faces, size(a).min(size(b)))
}

#[test]
fn two_things_of_two_classes_flush_side_by_side_stay_two_after_consolidation() {
    // A cabinet and a refrigerator with their fronts flush: their masks meet across one
    // continuous surface, as a cut through one object would, and their seam is as long; but
    // every view names them two classes, which is the network seeing two objects.
    let cabinet = |id: u16, class: u32, x: f64| {
        object(
            id,
            class,
            true,
            vec![cuboid([x, 2.0, -0.5], [0.3, 0.3, 0.4])],
        )
    };
    let scene = wall_scene(vec![cabinet(2, 30, -0.3), cabinet(3, 31, 0.3)]);
    let positions = (0..6).map(|i| Point3::new(-0.1 + 0.04 * i as f64, 0.2, -0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let (mut map, reference) = fuse(&scene, &poses);
    assert_consolidation_keeps_apart(&mut map, &reference, 0.95);
    let things = map.instances().into_iter().filter(|i| i.is_thing).count();
    assert_eq!(things, 2);
}

#[test]
fn identified_ids_are_not_consolidated_however_often_it_is_asked() {
    // Two cabinets of one class flush side by side, fused from the ground truth's own ids
    // into a map asked to consolidate after every frame: their seam is long and no frame of
    // the tracker told them apart, but the ids are the segmenter's decision, not the map's.
    let cabinet =
        |id: u16, x: f64| object(id, 30, true, vec![cuboid([x, 2.0, -0.5], [0.3, 0.3, 0.4])]);
    let scene = wall_scene(vec![cabinet(2, -0.3), cabinet(3, 0.3)]);
    let positions = (0..4).map(|i| Point3::new(-0.1 + 0.05 * i as f64, 0.2, -0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let mut config = MapConfig::default();
    config.tracking.consolidate_every = 1;
    let (_, reference, _) = fuse_configured(config, &scene, &poses, &[], |_, _, _| {});
    let things = reference
        .instances()
        .into_iter()
        .filter(|i| i.is_thing)
        .count();
    assert_eq!(things, 2, "{:?}", reference.instances());
}

#[test]
fn a_small_cabinet_against_the_front_of_a_large_one_stays_apart_after_consolidation() {
    // One class, the small cabinet standing against the large one's front: they meet along
    // the small one's outline, a long seam, but in the image its front lies 30 cm nearer than
    // the large one's, a depth edge between two objects in every view.
    let scene = wall_scene(vec![
        object(2, 30, true, vec![cuboid([0.0, 2.0, -0.5], [0.6, 0.3, 0.4])]),
        object(
            3,
            30,
            true,
            vec![cuboid([0.0, 1.55, -0.6], [0.15, 0.15, 0.15])],
        ),
    ]);
    let positions = (0..6).map(|i| Point3::new(-0.2 + 0.08 * i as f64, 0.2, 0.0));
    let poses = looking_at(positions, Point3::new(0.0, 1.8, -0.55));
    let (mut map, reference) = fuse(&scene, &poses);
    assert_objects_meet_along_a_seam(&map, &reference);
    assert_consolidation_keeps_apart(&mut map, &reference, 0.9);
}

/// A cabinet (class 30, a thing or stuff) whose mask the network cuts in two side by side
/// in every view, fused: no segment ever covers it whole, so frame-by-frame matching keeps two
/// instances (checked), each holding one half.
fn cabinet_cut_in_two(thing: bool) -> (PanopticMap, PanopticMap) {
    let scene = wall_scene(vec![object(
        2,
        30,
        thing,
        vec![cuboid([0.0, 2.0, -0.5], [0.6, 0.3, 0.4])],
    )]);
    let positions = (0..6).map(|i| Point3::new(-0.1 + 0.04 * i as f64, 0.2, -0.2));
    let poses = looking_at(positions, Point3::new(0.0, 2.0, -0.5));
    let (map, reference) = fuse_edited(&scene, &poses, |_, truth, masks| {
        split_across(truth, masks, 2, 2);
    });
    let halves = map
        .instances()
        .into_iter()
        .filter(|i| i.class_id == Some(30))
        .count();
    assert_eq!(
        halves, 2,
        "the halves must be two before consolidation for this test to say anything"
    );
    (map, reference)
}

/// Consolidates `map` and checks that the cabinet of [`cabinet_cut_in_two`] is one instance.
fn assert_cabinet_joined(mut map: PanopticMap, reference: &PanopticMap) {
    assert!(map.consolidate() >= 1);
    let of = instances_of_objects(&map, reference);
    let (cabinet, share) = main_instance(&of, 2);
    assert!(cabinet != 0 && share > 0.95, "{:?}", of[&2]);
    let cabinets: Vec<_> = map
        .instances()
        .into_iter()
        .filter(|i| i.class_id == Some(30))
        .collect();
    assert_eq!(cabinets.len(), 1, "{cabinets:?}");
}

#[test]
fn a_thing_every_view_cuts_in_two_is_one_after_consolidation() {
    // The cut lies across one continuous surface, which tells no two objects apart:
    // consolidation joins the halves along their seam.
    let (map, reference) = cabinet_cut_in_two(true);
    assert_cabinet_joined(map, &reference);
}

#[test]
fn a_stuff_region_every_view_cuts_in_two_is_one_after_consolidation() {
    // Stuff as well: two regions of one class meeting across one continuous surface are one
    // region the network cut (a door flush with its wall is two classes, and stays apart).
    let (map, reference) = cabinet_cut_in_two(false);
    assert_cabinet_joined(map, &reference);
}
