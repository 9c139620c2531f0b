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
    let mut frame = view(&ball(), &pose, &k);
    frame.id = "000007".into();
    // With a segment, so that a refused frame must leave the tracker untouched too.
    let ball_pixels = frame.ground_truth.clone().unwrap();
    let segments = Segments {
        labels: Image::from_fn(k.width, k.height, |x, y| {
            if *ball_pixels.get(x, y) != 0 { 5 } else { 0 }
        }),
        segments: vec![Segment::bare(5)],
    };
    let mut free = PanopticMap::new(MapConfig::default()).unwrap();
    free.integrate(&frame, Some(&segments)).unwrap();
    let blocks = free.block_count();
    assert!(blocks > 10);
    assert_eq!(free.memory_bytes(), blocks as u64 * BLOCK_BYTES);
    // The single-frame bound holds what the frame really took.
    assert!(free.frame_memory_bound(&k) >= free.memory_bytes());

    let mut tight = PanopticMap::new(MapConfig::default()).unwrap();
    tight.set_memory_limit(Some((blocks as u64 - 1) * BLOCK_BYTES));
    let err = tight.integrate(&frame, Some(&segments)).unwrap_err();
    assert!(
        matches!(err, MapError::MemoryLimit { blocks: b, .. } if b == blocks),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(
        message.contains("000007") && message.contains("voxel_size"),
        "{message}"
    );
    assert_eq!(tight.block_count(), 0);
    tight.set_memory_limit(Some(blocks as u64 * BLOCK_BYTES));
    tight.integrate(&frame, Some(&segments)).unwrap();
    // Equal maps, their trackers included: the refused frame was no sighting.
    assert_eq!(tight, free);
    // Far from its limit a map plans and associates side by side: the same map.
    let mut roomy = PanopticMap::new(MapConfig::default()).unwrap();
    roomy.set_memory_limit(Some(1 << 40));
    roomy.integrate(&frame, Some(&segments)).unwrap();
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
            map.integrate(&view(&scene, pose, &k), None).unwrap();
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
    map.integrate_identified(&frame, &as_id(u16::MAX - 1))
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
    let report = map.integrate(&elsewhere, Some(&as_id(3))).unwrap();
    let stats = report.association.unwrap();
    assert_eq!((stats.out_of_ids, stats.created), (1, 0), "{stats:?}");
    // The geometry is still mapped.
    assert!(report.integration.updated_voxels > 0);
}
