//! Bounded resources: the memory limit refuses a frame before anything changes, re-seen
//! surface allocates nothing, and running out of instance ids is reported.

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{Image, Segment, Segments};
use voxpan_map::{BLOCK_BYTES, MapConfig, MapError, PanopticMap};
use voxpan_sim::Shape;
use voxpan_sim::trajectory::look_along;

use super::{camera, scene_with, view};

fn ball() -> voxpan_sim::Scene {
    scene_with(Shape::Sphere {
        center: Point3::new(0.0, 2.0, 0.0),
        radius: 0.4,
    })
}

#[test]
fn a_frame_past_the_memory_limit_is_refused_before_anything_changes() {
    let k = camera();
    let pose = look_along(Point3::origin(), Vector3::y());
    let frame = view(&ball(), &pose, &k);
    // With a segment, so that a refused frame must leave the tracker untouched too.
    let ball_pixels = frame.ground_truth.clone().unwrap();
    let segments = Segments {
        labels: Image::from_fn(k.width, k.height, |x, y| {
            if *ball_pixels.get(x, y) != 0 { 5 } else { 0 }
        }),
        segments: vec![Segment::bare(5)],
    };
    let mut free = PanopticMap::new(MapConfig::default()).unwrap();
    free.integrate(frame.view(), Some(&segments)).unwrap();
    let blocks = free.block_count();
    assert!(blocks > 10);
    assert_eq!(free.memory_bytes(), blocks as u64 * BLOCK_BYTES);
    // The single-frame bound holds what the frame really took.
    assert!(free.frame_memory_bound(&k) >= free.memory_bytes());

    let mut tight = PanopticMap::new(MapConfig::default()).unwrap();
    tight.set_memory_limit(Some((blocks as u64 - 1) * BLOCK_BYTES));
    let err = tight.integrate(frame.view(), Some(&segments)).unwrap_err();
    assert!(
        matches!(err, MapError::MemoryLimit { blocks: b, .. } if b == blocks),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(message.contains("voxel_size"), "{message}");
    assert_eq!(tight.block_count(), 0);
    tight.set_memory_limit(Some(blocks as u64 * BLOCK_BYTES));
    tight.integrate(frame.view(), Some(&segments)).unwrap();
    // Equal maps, their trackers included: the refused frame was no sighting.
    assert_eq!(tight, free);
    // Far from its limit a map plans and associates side by side: the same map.
    let mut roomy = PanopticMap::new(MapConfig::default()).unwrap();
    roomy.set_memory_limit(Some(1 << 40));
    roomy.integrate(frame.view(), Some(&segments)).unwrap();
    assert_eq!(roomy, free);
}

#[test]
fn memory_grows_with_the_surface_not_with_frames() {
    let k = camera();
    let scene = ball();
    let poses: Vec<_> = (0..6)
        .map(|i| {
            let p = Point3::new(-0.5 + 0.2 * i as f64, 0.0, 0.1);
            look_along(p, Point3::new(0.0, 2.0, 0.0) - p)
        })
        .collect();
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let mut counts = Vec::new();
    for _ in 0..5 {
        for pose in &poses {
            map.integrate(view(&scene, pose, &k).view(), None).unwrap();
        }
        counts.push(map.block_count());
    }
    assert!(counts.windows(2).all(|w| w[0] == w[1]), "{counts:?}");
}

#[test]
fn running_out_of_instance_ids_is_counted() {
    let k = camera();
    let pose = look_along(Point3::origin(), Vector3::y());
    let frame = view(&ball(), &pose, &k);
    let ball_pixels = frame.ground_truth.clone().unwrap();
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    // An upstream tracker used the second-largest id: none is left for new objects.
    let as_id = |id: u16| Segments {
        labels: Image::from_fn(k.width, k.height, |x, y| {
            if *ball_pixels.get(x, y) != 0 { id } else { 0 }
        }),
        segments: vec![Segment::bare(id)],
    };
    map.integrate_identified(frame.view(), &as_id(u16::MAX - 1))
        .unwrap();
    // Seen elsewhere in the room: a new object for the tracker.
    let other = look_along(Point3::new(0.0, 0.0, 0.0), -Vector3::y());
    let mut elsewhere = view(
        &scene_with(Shape::Sphere {
            center: Point3::new(0.0, -2.0, 0.0),
            radius: 0.4,
        }),
        &other,
        &k,
    );
    elsewhere.id = "elsewhere".into();
    let report = map.integrate(elsewhere.view(), Some(&as_id(3))).unwrap();
    let stats = report.association.unwrap();
    assert_eq!((stats.out_of_ids, stats.created), (1, 0), "{stats:?}");
    // The geometry is still mapped.
    assert!(report.integration.updated_voxels > 0);
}

/// A floor 80 m long with a ball every 5 m beside it.
fn corridor() -> voxpan_sim::Scene {
    use voxpan_sim::{Object, Scene, Surface};
    let mut scene = Scene::empty(Vector3::new(100.0, 10.0, 10.0));
    let mut add = |id: u16, class_id: u32, shape: Shape| {
        scene.add(Object {
            instance_id: id,
            class_id,
            is_thing: id > 1,
            color: [120, 120, 120],
            surface: Surface::Plain,
            specular: false,
            shapes: vec![shape],
        })
    };
    add(
        1,
        0,
        Shape::Cuboid {
            center: Point3::new(30.0, 0.0, -1.05),
            half: Vector3::new(40.0, 4.0, 0.05),
            yaw: 0.0,
        },
    );
    for k in 0..14 {
        add(
            2 + k,
            9,
            Shape::Sphere {
                center: Point3::new(5.0 * k as f64, 1.5, -0.6),
                radius: 0.4,
            },
        );
    }
    scene
}

#[test]
fn a_bounded_map_keeps_its_memory_on_a_long_drive() {
    let k = camera();
    let scene = corridor();
    let mut config = MapConfig::default();
    config.tsdf.voxel_size = 0.05;
    config.tracking.min_voxels = 0;
    config.esdf.enabled = true;
    let mut bounded_config = config;
    bounded_config.tsdf.keep_radius = 6.0;
    let mut bounded = PanopticMap::new(bounded_config).unwrap();
    let mut unbounded = PanopticMap::new(config).unwrap();
    let mut memory = Vec::new();
    // 60 m at half a metre a frame, looking ahead and down.
    for step in 0..=120 {
        let x = 0.5 * step as f64;
        let pose = look_along(Point3::new(x, 0.0, 0.3), Vector3::new(1.0, 0.3, -0.5));
        let mut frame = view(&scene, &pose, &k);
        frame.id = format!("{step}");
        let truth = frame.ground_truth.clone().unwrap();
        let mut ids: Vec<u16> = truth.pixels().iter().copied().filter(|&i| i != 0).collect();
        ids.sort_unstable();
        ids.dedup();
        let segments = Segments {
            labels: truth,
            segments: ids.into_iter().map(Segment::bare).collect(),
        };
        bounded
            .integrate_identified(frame.view(), &segments)
            .unwrap();
        bounded.update_esdf();
        unbounded
            .integrate_identified(frame.view(), &segments)
            .unwrap();
        memory.push(bounded.memory_bytes());
        if step == 0 {
            // Free space allocated: the single-frame bound still holds what the frame took,
            // and is not the sampled rays' bound (gigabytes).
            let bound = bounded.frame_memory_bound(&k);
            assert!(bound >= memory[0] && bound < 2_000_000_000, "{bound}");
        }
    }
    // Flat once the first radius is driven out of: the last half of the drive holds no more
    // than the stretch after the first 10 m, while the unbounded map grows on.
    let settled = *memory[20..40].iter().max().unwrap();
    let late = *memory[60..].iter().max().unwrap();
    assert!(late as f64 <= 1.2 * settled as f64, "{late} vs {settled}");
    assert!(unbounded.block_count() > 4 * bounded.block_count());
    // What was dropped is gone from the distance field and the mesh; what is near is there.
    assert_eq!(bounded.distance(&Point3::new(5.0, 0.0, -0.5)), None);
    assert!(bounded.distance(&Point3::new(59.0, 0.0, -0.5)).is_some());
    let mesh = bounded.mesh(voxpan_map::Coloring::Rgb);
    assert!(mesh.vertices.iter().all(|v| v[0] > 50.0));
    // The balls passed long ago keep their summaries.
    let first = bounded.instances().into_iter().find(|i| i.id == 3).unwrap();
    assert!(first.voxels > 20, "{first:?}");
    let bounds = first.bounds.unwrap();
    assert!((bounds.min[0] - 4.6).abs() < 0.2 && (bounds.max[0] - 5.4).abs() < 0.2);
}

#[test]
fn a_keep_radius_inside_the_range_is_refused() {
    let mut config = MapConfig::default();
    config.tsdf.keep_radius = 3.0;
    let Err(MapError::Config(e)) = PanopticMap::new(config) else {
        panic!("accepted");
    };
    assert_eq!(e.key, "tsdf.keep_radius");
}

/// A bounded map keeping what it drops writes each block out as it was when dropped: every
/// surface voxel of a block written once and not seen again (in no later file, not in the
/// map) is the unbounded map's, and the files with the bounded map hold every surface voxel
/// the unbounded map has.
#[test]
fn dropped_blocks_are_written_out_as_they_were() {
    let k = camera();
    let scene = corridor();
    let mut config = MapConfig::default();
    config.tsdf.voxel_size = 0.05;
    config.tracking.min_voxels = 0;
    let mut bounded_config = config;
    bounded_config.tsdf.keep_radius = 6.0;
    let mut bounded = PanopticMap::new(bounded_config).unwrap();
    bounded.keep_dropped_blocks(true);
    let mut unbounded = PanopticMap::new(config).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    let mut write = |map: &mut PanopticMap| {
        let path = dir.path().join(format!("dropped-{}.voxpan", files.len()));
        if map.save_dropped_blocks(&path).unwrap() > 0 {
            files.push(path);
        }
        assert_eq!(map.dropped_block_count(), 0);
    };
    for step in 0..=60 {
        let pose = look_along(
            Point3::new(0.5 * step as f64, 0.0, 0.3),
            Vector3::new(1.0, 0.3, -0.5),
        );
        let mut frame = view(&scene, &pose, &k);
        frame.id = format!("{step}");
        let truth = frame.ground_truth.clone().unwrap();
        let segments = Segments {
            labels: truth,
            segments: vec![Segment::bare(3)],
        };
        bounded
            .integrate_identified(frame.view(), &segments)
            .unwrap();
        unbounded
            .integrate_identified(frame.view(), &segments)
            .unwrap();
        if bounded.dropped_block_count() >= 40 {
            write(&mut bounded);
        }
    }
    write(&mut bounded);
    assert!(files.len() > 3, "{} files", files.len());

    let block = |v: &voxpan_map::ObservedVoxel| v.index.map(|c| c.div_euclid(8));
    let parts: Vec<PanopticMap> = files
        .iter()
        .map(|p| PanopticMap::load(p).unwrap())
        .collect();
    let mut copies = std::collections::HashMap::new();
    for map in parts.iter().chain([&bounded]) {
        for b in map.block_indices() {
            *copies.entry(b).or_insert(0) += 1;
        }
    }
    let (mut compared, mut covered) = (0, std::collections::HashSet::new());
    for part in &parts {
        assert_eq!(part.config(), bounded.config());
        for v in part.surface_voxels() {
            covered.insert(v.index);
            if copies[&block(&v)] == 1 {
                let there = unbounded.voxel(&v.position).expect("in the unbounded map");
                let seen = |v: &voxpan_map::ObservedVoxel| (v.distance, v.weight, v.color);
                assert_eq!(seen(&v), seen(&there), "{:?}", v.index);
                compared += 1;
            }
        }
    }
    assert!(compared > 10_000, "{compared} voxels compared");
    covered.extend(bounded.surface_voxels().map(|v| v.index));
    let all: Vec<_> = unbounded.surface_voxels().map(|v| v.index).collect();
    let missing = all.iter().filter(|i| !covered.contains(*i)).count();
    assert_eq!(
        missing,
        0,
        "{missing} of {} surface voxels in no file nor the map",
        all.len()
    );
}
