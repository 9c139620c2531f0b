//! A small built-in RGB-D frame with over-covering masks: what `voxpan refine` runs on when no
//! files are given, and a fixture for tests. (The full synthetic world lives in its own crate.)

use voxpan_core::{DepthImage, LabelImage, Segment};

/// A frame, its predicted segments (which bleed onto the background) and the truth.
pub struct ExampleScene {
    pub depth: DepthImage,
    pub predicted: LabelImage,
    pub ground_truth: LabelImage,
    pub segments: Vec<Segment>,
}

const WIDTH: usize = 320;
const HEIGHT: usize = 240;
/// Focal length in pixels (90° horizontal field of view).
const FOCAL: f64 = 160.0;
const CAMERA_HEIGHT: f64 = 1.0;

/// Ids: 1 a box (thing), 2 a ball (thing), 3 the wall (stuff), 4 the floor (stuff).
pub fn example_scene() -> ExampleScene {
    let cy = HEIGHT as f64 / 2.0;
    let mut depth = DepthImage::filled(WIDTH, HEIGHT, 0.0);
    let mut truth = LabelImage::filled(WIDTH, HEIGHT, 0);
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            // A slightly slanted wall 3.2-3.6 m away.
            let mut z = 3.2 + 0.4 * x as f64 / WIDTH as f64;
            let mut id = 3;
            // The floor, 1 m below the camera, until it meets the wall.
            let v = y as f64 - cy;
            if v > 0.0 && FOCAL * CAMERA_HEIGHT / v < z {
                z = FOCAL * CAMERA_HEIGHT / v;
                id = 4;
            }
            // A box whose front face is turned a little: 1.20-1.25 m.
            if (70..150).contains(&x) && (90..190).contains(&y) {
                z = 1.2 + 0.05 * (x - 70) as f64 / 80.0;
                id = 1;
            }
            // A ball of radius 0.4 m centred 2 m away.
            let (bx, by, r_px) = (230.0, 120.0, 0.4 * FOCAL / 2.0);
            let d2 = (x as f64 - bx).powi(2) + (y as f64 - by).powi(2);
            if d2 < r_px * r_px {
                z = 2.0 - 0.4 * (1.0 - d2 / (r_px * r_px)).sqrt();
                id = 2;
            }
            // A little sensor noise, deterministic, growing with z².
            let noise = ((x * 7919 + y * 104_729) % 1000) as f64 / 1000.0 - 0.5;
            *depth.get_mut(x, y) = (z + 0.01 * z * z * noise) as f32;
            *truth.get_mut(x, y) = id;
        }
    }

    // Predicted things bleed 5 px (box) and 4 px (ball) onto their surroundings, like a
    // lightweight network's masks; stuff gets what is left.
    let grow = |id: u16, by: usize| {
        let mut out = vec![false; WIDTH * HEIGHT];
        for y in 0..HEIGHT {
            for x in 0..WIDTH {
                if *truth.get(x, y) != id {
                    continue;
                }
                for yy in y.saturating_sub(by)..(y + by + 1).min(HEIGHT) {
                    for xx in x.saturating_sub(by)..(x + by + 1).min(WIDTH) {
                        out[yy * WIDTH + xx] = true;
                    }
                }
            }
        }
        out
    };
    let (box_mask, ball_mask) = (grow(1, 5), grow(2, 4));
    let predicted = LabelImage::from_fn(WIDTH, HEIGHT, |x, y| {
        let i = y * WIDTH + x;
        if ball_mask[i] {
            2
        } else if box_mask[i] {
            1
        } else {
            match *truth.get(x, y) {
                4 => 4,
                _ => 3,
            }
        }
    });
    let segment = |id, is_thing| Segment {
        id,
        class_id: None,
        is_thing: Some(is_thing),
        score: None,
    };
    ExampleScene {
        depth,
        predicted,
        ground_truth: truth,
        segments: vec![
            segment(1, true),
            segment(2, true),
            segment(3, false),
            segment(4, false),
        ],
    }
}
