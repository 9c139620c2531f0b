//! Trimming thing masks off the frame's stuff planes, on constructed rooms with exact geometry.

use voxpan_core::{DepthImage, LabelImage, Segment};
use voxpan_refine::PlaneTrimmer;

const W: usize = 160;
const H: usize = 120;
const F: f64 = 100.0;
const CY: f64 = 60.0;
/// Camera 1.2 m above the floor (y down), a wall 4 m ahead.
const FLOOR_Y: f64 = 1.2;
const WALL_Z: f64 = 4.0;
const FLOOR: u16 = 1;
const WALL: u16 = 2;

fn stuff(id: u16) -> Segment {
    Segment {
        is_thing: Some(false),
        ..Segment::bare(id)
    }
}

fn thing(id: u16) -> Segment {
    Segment {
        is_thing: Some(true),
        ..Segment::bare(id)
    }
}

/// Planar depth of the floor or the wall in row `y` (neither depends on the column), whichever
/// is nearer, and which.
fn room(y: usize) -> (f64, u16) {
    let ray_y = (y as f64 - CY) / F;
    let floor = (ray_y > 0.0).then(|| FLOOR_Y / ray_y);
    match floor {
        Some(z) if z < WALL_Z => (z, FLOOR),
        _ => (WALL_Z, WALL),
    }
}

/// A rectangle of pixels, `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy)]
struct Rect(usize, usize, usize, usize);

impl Rect {
    fn holds(&self, x: usize, y: usize) -> bool {
        x >= self.0 && x < self.1 && y >= self.2 && y < self.3
    }

    fn grown(&self, by: usize) -> Rect {
        Rect(
            self.0.saturating_sub(by),
            (self.1 + by).min(W),
            self.2.saturating_sub(by),
            (self.3 + by).min(H),
        )
    }
}

/// The room, a box face at `box_depth` over `body`, and the network's labels: stuff by
/// surface, the box's mask grown by `bleed` px over the floor and wall behind it.
struct Scene {
    depth: DepthImage,
    labels: LabelImage,
    /// Which pixels are truly the box.
    body: Rect,
}

fn scene(body: Rect, box_depth: f64, bleed: usize, noise: f64) -> Scene {
    let mut rng = 0x2545_f491_4f6c_dd1d_u64;
    let mut gaussian = move || {
        // Box-Muller from a xorshift stream: reproducible noise without a dependency.
        let mut uniform = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            ((rng >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (uniform(), uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    };
    let mask = body.grown(bleed);
    let mut depth = DepthImage::filled(W, H, 0.0);
    let mut labels = LabelImage::filled(W, H, 0);
    for y in 0..H {
        for x in 0..W {
            let (room_z, surface) = room(y);
            let z = if body.holds(x, y) { box_depth } else { room_z };
            // Noise in inverse depth, as a triangulating camera has it.
            *depth.get_mut(x, y) = (1.0 / (1.0 / z + noise * gaussian())) as f32;
            *labels.get_mut(x, y) = if mask.holds(x, y) { 3 } else { surface };
        }
    }
    Scene {
        depth,
        labels,
        body,
    }
}

fn segments() -> Vec<Segment> {
    vec![stuff(FLOOR), stuff(WALL), thing(3)]
}

/// (box pixels kept, bleed pixels kept) of segment 3.
fn kept(scene: &Scene, labels: &LabelImage) -> (usize, usize) {
    let (mut body, mut bleed) = (0, 0);
    for y in 0..H {
        for x in 0..W {
            if *labels.get(x, y) == 3 {
                if scene.body.holds(x, y) {
                    body += 1;
                } else {
                    bleed += 1;
                }
            }
        }
    }
    (body, bleed)
}

#[test]
fn bleed_onto_the_floor_and_wall_is_trimmed_and_the_thing_kept() {
    // A box face at 2.5 m, its mask 8 px too wide on every side: onto the wall above and
    // beside it, onto the floor below.
    let scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.0);
    let (body, bleed) = kept(&scene, &scene.labels);
    assert!(
        bleed > body / 2,
        "the constructed mask must bleed ({bleed} of {body})"
    );
    let mut labels = scene.labels.clone();
    let reports = PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    assert_eq!(kept(&scene, &labels), (body, 0));
    let report = reports.iter().find(|r| r.id == 3).unwrap();
    assert_eq!((report.removed, report.on_stuff), (bleed, bleed));
    // Nothing else changes: the stuff keeps its pixels and gets the bleed on its plane.
    for y in 0..H {
        for x in 0..W {
            let (before, after) = (*scene.labels.get(x, y), *labels.get(x, y));
            // The row where floor meets wall lies on both planes: either is right.
            let corner = y as f64 == CY + F * FLOOR_Y / WALL_Z;
            if before == 3 && !scene.body.holds(x, y) {
                assert!(
                    after == room(y).1 || (corner && after == FLOOR),
                    "pixel ({x}, {y})"
                );
            } else {
                assert_eq!(after, before, "pixel ({x}, {y})");
            }
        }
    }
}

#[test]
fn one_plane_per_surface_is_found_with_no_threshold() {
    let scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.0);
    let mut trimmer = PlaneTrimmer::new();
    trimmer
        .trim(&scene.depth, &mut scene.labels.clone(), &segments())
        .unwrap();
    let planes = trimmer.planes();
    assert_eq!(planes.len(), 2, "{planes:?}");
    // In inverse depth the wall is the constant 1/4 and the floor rises with the row:
    // 1/z = (v - cy) / (f · 1.2).
    let wall = planes.iter().find(|p| p.segment == WALL).unwrap();
    assert!(wall.a.abs() < 1e-9 && wall.b.abs() < 1e-9 && (wall.c - 0.25).abs() < 1e-7);
    let floor = planes.iter().find(|p| p.segment == FLOOR).unwrap();
    let slope = 1.0 / (F * FLOOR_Y);
    assert!(floor.a.abs() < 1e-9, "{floor:?}");
    assert!((floor.b - slope).abs() < 1e-7 * slope, "{floor:?}");
    assert!((floor.c + CY * slope).abs() < 1e-6, "{floor:?}");
}

#[test]
fn with_sensor_noise_nearly_all_bleed_goes_and_the_thing_stays() {
    // σ = 0.002 /m in 1/z: about 1.2 cm at 2.5 m, 3 cm at 4 m.
    let scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.002);
    let (body, bleed) = kept(&scene, &scene.labels);
    let mut labels = scene.labels.clone();
    PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    let (body_after, bleed_after) = kept(&scene, &labels);
    // 2.5 σ keeps 98.8 % of a plane's own pixels on it.
    assert!(
        bleed_after * 100 <= bleed * 3,
        "{bleed_after} of {bleed} left"
    );
    assert!(body_after * 100 >= body * 99, "{body_after} of {body}");
}

#[test]
fn a_thing_flat_on_the_wall_keeps_its_mask() {
    // A picture: the wall's own depths, its mask 2 px wider, with noise.
    let scene = scene(Rect(20, 50, 10, 30), WALL_Z, 2, 0.002);
    let mut labels = scene.labels.clone();
    let reports = PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    assert_eq!(labels, scene.labels);
    let report = reports.iter().find(|r| r.id == 3).unwrap();
    assert_eq!(report.removed, 0);
    assert!(report.on_stuff * 10 >= report.pixels * 9, "{report:?}");
}

#[test]
fn a_thin_thing_whose_bleed_is_most_of_its_mask_is_not_taken_for_flat() {
    // A pole 2 px wide at 2 m, its mask 12 px too wide on every side: 94 % of the mask's
    // pixels lie on the wall or floor, more than a thing flat on them shows. Its core is the
    // pole, though, and by depth inside the mask the bleed is the rim.
    let scene = scene(Rect(79, 81, 20, 100), 2.0, 12, 0.0);
    let (body, bleed) = kept(&scene, &scene.labels);
    assert!(
        bleed * 10 >= (body + bleed) * 9,
        "{bleed} of {}",
        body + bleed
    );
    let mut labels = scene.labels.clone();
    PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    assert_eq!(kept(&scene, &labels), (body, 0));
}

#[test]
fn stuff_that_is_no_plane_trims_nothing() {
    // The only stuff is clutter (depths scattered over 1-5 m): no plane, nothing trimmed.
    let mut scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.0);
    let mut state = 7u64;
    for (z, &l) in scene
        .depth
        .pixels_mut()
        .iter_mut()
        .zip(scene.labels.pixels())
    {
        if l != 3 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *z = 1.0 + 4.0 * ((state >> 33) as f32 / (1u64 << 31) as f32);
        }
    }
    let mut labels = scene.labels.clone();
    let mut trimmer = PlaneTrimmer::new();
    trimmer
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    assert!(trimmer.planes().is_empty(), "{:?}", trimmer.planes());
    assert_eq!(labels, scene.labels);
}

#[test]
fn segments_of_unknown_kind_are_neither_trimmed_nor_planes() {
    let scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.0);
    let unknown = [Segment::bare(FLOOR), Segment::bare(WALL), thing(3)];
    let mut labels = scene.labels.clone();
    let reports = PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &unknown)
        .unwrap();
    assert!(reports.is_empty());
    assert_eq!(labels, scene.labels);
    let unknown_thing = [stuff(FLOOR), stuff(WALL), Segment::bare(3)];
    PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &unknown_thing)
        .unwrap();
    assert_eq!(labels, scene.labels);
}

#[test]
fn pixels_without_depth_are_left_alone() {
    let mut scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.0);
    // Holes in a band through the box and its bleed.
    for x in 0..W {
        *scene.depth.get_mut(x, 45) = 0.0;
        *scene.depth.get_mut(x, 46) = f32::NAN;
    }
    let mut labels = scene.labels.clone();
    PlaneTrimmer::new()
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    for y in [45, 46] {
        assert_eq!(labels.row(y), scene.labels.row(y));
    }
    // The bleed left: 8 px either side of the box, in the two rows without depth.
    assert_eq!(kept(&scene, &labels).1, 2 * (8 + 8));
}

#[test]
fn a_surface_scattered_beyond_the_sensor_noise_is_no_plane() {
    // The wall is exact; the floor below the box is a rumpled rug: 1.5 % of its depth in
    // scatter (thin enough for a plane on its own, thousands of times the wall's). Bleed on the
    // wall goes; bleed on the rug stays.
    let mut scene = scene(Rect(60, 100, 40, 100), 2.5, 8, 0.0);
    let mut state = 11u64;
    for y in 0..H {
        for x in 0..W {
            if room(y).1 == FLOOR && !scene.body.holds(x, y) {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (state >> 33) as f32 / (1u64 << 31) as f32 - 0.5;
                *scene.depth.get_mut(x, y) *= 1.0 + 0.05 * u;
            }
        }
    }
    let mut labels = scene.labels.clone();
    let mut trimmer = PlaneTrimmer::new();
    trimmer
        .trim(&scene.depth, &mut labels, &segments())
        .unwrap();
    assert!(
        trimmer.planes().iter().all(|p| p.segment == WALL),
        "{:?}",
        trimmer.planes()
    );
    for y in 0..H {
        for x in 0..W {
            if *scene.labels.get(x, y) == 3 && !scene.body.holds(x, y) {
                let on_floor = room(y).1 == FLOOR;
                assert_eq!(*labels.get(x, y) == 3, on_floor, "pixel ({x}, {y})");
            }
        }
    }
}

#[test]
fn images_of_different_sizes_are_an_error() {
    let depth = DepthImage::filled(W, H, 1.0);
    let mut labels = LabelImage::filled(W, H + 1, 0);
    let err = PlaneTrimmer::new()
        .trim(&depth, &mut labels, &segments())
        .unwrap_err();
    assert_eq!((err.depth, err.labels), ((W, H), (W, H + 1)));
}
