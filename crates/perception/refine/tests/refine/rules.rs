//! Behaviour of the refinement rules on constructed cases.

use proptest::prelude::*;
use voxpan_core::{DepthImage, LabelImage, Segment};
use voxpan_refine::{
    FAR_LIMIT_M, KeptReason, MaskStatus, RefineConfig, Refiner, Rule, Side, example_scene,
};

fn iou(pred: &LabelImage, truth: &LabelImage, id: u16) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&p, &t) in pred.pixels().iter().zip(truth.pixels()) {
        inter += (p == id && t == id) as usize;
        union += (p == id || t == id) as usize;
    }
    inter as f64 / union as f64
}

#[test]
fn over_covering_masks_lose_their_background() {
    let scene = example_scene();
    for rule in [Rule::Default, Rule::Paper, Rule::Release] {
        let mut labels = scene.predicted.clone();
        Refiner::new(RefineConfig::new(rule))
            .refine_frame(&scene.depth, &mut labels, &scene.segments)
            .unwrap();
        for thing in [1, 2] {
            let before = iou(&scene.predicted, &scene.ground_truth, thing);
            let after = iou(&labels, &scene.ground_truth, thing);
            assert!(before < 0.85, "the example must over-cover ({before})");
            assert!(
                after > 0.98,
                "rule {}: segment {thing} IoU {before:.3} -> {after:.3}",
                rule.name()
            );
        }
    }
}

#[test]
fn default_rule_keeps_a_slanted_floor() {
    // The floor spans 1.3-3.5 m under one mask: refined as stuff, or of unknown kind, the
    // default rule must not chop it.
    let scene = example_scene();
    let bare: Vec<Segment> = scene.segments.iter().map(|s| Segment::bare(s.id)).collect();
    for segments in [&scene.segments, &bare] {
        let mut labels = scene.predicted.clone();
        let reports = Refiner::new(RefineConfig::new(Rule::Default))
            .refine_frame(&scene.depth, &mut labels, segments)
            .unwrap();
        let floor = reports.iter().find(|r| r.id == 4).unwrap();
        assert_eq!(floor.status, MaskStatus::Refined);
        assert!(floor.removed * 100 < floor.pixels, "{floor:?}");
    }
}

/// Depths on a half-float-like grid (2^-10 m steps, like the flat dataset's).
fn quantised(values: impl Iterator<Item = f64>) -> Vec<f32> {
    values
        .map(|v| ((v * 1024.0).round() / 1024.0) as f32)
        .collect()
}

#[test]
fn default_rule_keeps_a_quantised_compact_object_whole() {
    // 4000 pixels within 4 cm at 1.9 m: ~40 representable values. A bandwidth below the
    // quantisation step would make a comb of spikes and cut between them.
    let object = quantised((0..4000).map(|i| 1.90 + 0.04 * ((i * 7919) % 4000) as f64 / 4000.0));
    let interval = Refiner::new(RefineConfig::default())
        .interval(&object)
        .unwrap();
    assert!(object.iter().all(|&d| interval.contains(d)), "{interval:?}");
}

#[test]
fn default_rule_follows_the_majority_not_the_sharpest_peak() {
    // A slanted object spread over 1.6-2.0 m (3000 px) and its bleed onto a wall at 3.2 m
    // facing the camera (1200 px, a much sharper peak). The paper rule follows the peak; the
    // default rule keeps the object.
    let mut depths = quantised((0..3000).map(|i| 1.6 + 0.4 * i as f64 / 3000.0));
    depths.extend(quantised((0..1200).map(|i| 3.2 + 0.002 * (i % 3) as f64)));
    let interval = Refiner::new(RefineConfig::default())
        .interval(&depths)
        .unwrap();
    assert!(
        interval.low <= 1.6 && (2.0..3.0).contains(&interval.high),
        "{interval:?}"
    );
    let paper = Refiner::new(RefineConfig::new(Rule::Paper))
        .interval(&depths)
        .unwrap();
    assert!(
        paper.low > 3.0,
        "the published rule keeps the wall: {paper:?}"
    );
}

#[test]
fn a_correct_mask_stays_nearly_intact() {
    let scene = example_scene();
    let mut labels = scene.ground_truth.clone();
    let segments: Vec<Segment> = (1..=4).map(Segment::bare).collect();
    let reports = Refiner::new(RefineConfig::default())
        .refine_frame(&scene.depth, &mut labels, &segments)
        .unwrap();
    for r in &reports {
        assert!(
            r.removed * 100 <= r.pixels,
            "segment {} lost {} of {}",
            r.id,
            r.removed,
            r.pixels
        );
    }
}

#[test]
fn default_rule_is_unit_invariant_and_paper_rule_is_not() {
    let scene = example_scene();
    let millimetres = scene.depth.map(|&d| d * 1000.0);
    // `unit` = depth units per metre; the far limit is the only metric setting.
    let refine = |rule: Rule, depth: &DepthImage, unit: f64| {
        let mut labels = scene.predicted.clone();
        let config = RefineConfig {
            far_limit: FAR_LIMIT_M * unit,
            ..RefineConfig::new(rule)
        };
        Refiner::new(config)
            .refine_frame(depth, &mut labels, &scene.segments)
            .unwrap();
        labels
    };
    for rule in [Rule::Default, Rule::Release] {
        assert_eq!(
            refine(rule, &scene.depth, 1.0),
            refine(rule, &millimetres, 1000.0),
            "rule {}",
            rule.name()
        );
    }
    // The paper's absolute cut-off (1e-6 per unit) moves the bounds with the unit.
    let ball: Vec<f32> = scene
        .depth
        .pixels()
        .iter()
        .zip(scene.predicted.pixels())
        .filter(|&(_, &l)| l == 2)
        .map(|(&d, _)| d)
        .collect();
    let ball_mm: Vec<f32> = ball.iter().map(|d| d * 1000.0).collect();
    let mut paper = Refiner::new(RefineConfig::new(Rule::Paper));
    let (m, mm) = (
        paper.interval(&ball).unwrap(),
        paper.interval(&ball_mm).unwrap(),
    );
    assert!((mm.low / 1000.0 - m.low).abs() > 1e-3, "{m:?} vs {mm:?}");
}

#[test]
fn guards_keep_the_mask_and_say_why() {
    let mut refiner = Refiner::new(RefineConfig::default());
    assert_eq!(
        refiner.interval(&[1.0; 5]).unwrap_err(),
        KeptReason::TooFewPixels { valid: 5, min: 16 }
    );
    assert_eq!(
        refiner.interval(&[2.0; 100]).unwrap_err(),
        KeptReason::ConstantDepth
    );
    let mut with_holes = vec![0.0; 100];
    with_holes.extend([f32::NAN; 10]);
    assert_eq!(
        refiner.interval(&with_holes).unwrap_err(),
        KeptReason::TooFewPixels { valid: 0, min: 16 }
    );
    // A density that never falls to 1e-6 per metre near the peak: the paper rule's grid is
    // padded by at least 6 m, so a crossing always exists; the KDEpy grid cannot lack one.
    let spread: Vec<f32> = (0..200).map(|i| 1.0 + i as f32 * 0.01).collect();
    assert!(
        Refiner::new(RefineConfig::new(Rule::Paper))
            .interval(&spread)
            .is_ok()
    );
    let _ = Side::Near;
}

#[test]
fn things_only_leaves_stuff_and_unknown_segments() {
    let scene = example_scene();
    let mut segments = scene.segments.clone();
    segments[1].is_thing = None;
    let config = RefineConfig {
        things_only: true,
        ..RefineConfig::default()
    };
    let mut labels = scene.predicted.clone();
    let reports = Refiner::new(config)
        .refine_frame(&scene.depth, &mut labels, &segments)
        .unwrap();
    assert_eq!(reports[0].status, MaskStatus::Refined);
    assert_eq!(reports[1].status, MaskStatus::Kept(KeptReason::UnknownKind));
    assert_eq!(reports[2].status, MaskStatus::Kept(KeptReason::NotAThing));
    assert_eq!(reports[3].removed, 0);
}

#[test]
fn mismatched_shapes_are_an_error() {
    let depth = DepthImage::filled(4, 4, 1.0);
    let mut labels = LabelImage::filled(4, 3, 1);
    let err = Refiner::new(RefineConfig::default())
        .refine_frame(&depth, &mut labels, &[Segment::bare(1)])
        .unwrap_err();
    assert_eq!(err.to_string(), "depth is 4x4 but the label image is 4x3");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Whatever the data: no panic, pixels only ever turn void, unlisted ids are untouched,
    /// invalid depth never stays in a refined mask, and the counts add up.
    #[test]
    fn refinement_only_removes(
        w in 1usize..40, h in 1usize..40, seed in any::<u64>(), rule_index in 0usize..3,
    ) {
        let mut state = seed | 1;
        let mut next = move || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state };
        let depth = DepthImage::from_fn(w, h, |_, _| match next() % 20 {
            0 => 0.0,
            1 => f32::NAN,
            2 => f32::INFINITY,
            k => 0.5 + (k as f32) * 0.3 + (next() % 100) as f32 * 1e-3,
        });
        let labels = LabelImage::from_fn(w, h, |_, _| (next() % 5) as u16);
        let rule = [Rule::Default, Rule::Paper, Rule::Release][rule_index];
        let mut config = RefineConfig::new(rule);
        config.min_pixels = 3;
        let listed: Vec<Segment> = [1u16, 2, 3].into_iter().map(Segment::bare).collect();
        let mut refined = labels.clone();
        let reports = Refiner::new(config).refine_frame(&depth, &mut refined, &listed).unwrap();
        for ((&a, &b), &d) in labels.pixels().iter().zip(refined.pixels()).zip(depth.pixels()) {
            prop_assert!(b == a || b == 0);
            if a == 4 { prop_assert_eq!(b, 4); }
            // Published rules drop pixels without depth from refined masks; the default keeps them.
            if b != 0 && b != 4 && reports[(b - 1) as usize].status == MaskStatus::Refined && rule.drops_pixels_without_depth() {
                prop_assert!(d.is_finite() && d > 0.0);
            }
            if a != 0 && a != 4 && b == 0 && !rule.drops_pixels_without_depth() {
                prop_assert!(d.is_finite() && d > 0.0, "the default rule removed a pixel without depth");
            }
        }
        for r in &reports {
            prop_assert_eq!(r.kept + r.removed, r.pixels);
            let count = refined.pixels().iter().filter(|&&l| l == r.id).count();
            prop_assert_eq!(count, r.kept);
        }
    }
}

/// A disc-shaped object at 1.5 m whose mask bleeds onto the wall behind (3 m) in a ring around
/// it; `ring` is the bleed's width in pixels.
fn bleeding_disc(radius: f64, ring: f64) -> (DepthImage, LabelImage, LabelImage) {
    let (w, h) = (160, 160);
    let r = |x: usize, y: usize| ((x as f64 - 80.0).powi(2) + (y as f64 - 80.0).powi(2)).sqrt();
    // Both surfaces slightly slanted, so the depths take many values as in real data.
    let depth = DepthImage::from_fn(w, h, |x, y| {
        let base = if r(x, y) <= radius { 1.5 } else { 3.0 };
        base + 0.001 * x as f32 + 0.0005 * y as f32
    });
    let truth = LabelImage::from_fn(w, h, |x, y| (r(x, y) <= radius) as u16);
    let predicted = LabelImage::from_fn(w, h, |x, y| (r(x, y) <= radius + ring) as u16);
    (depth, predicted, truth)
}

#[test]
fn a_bleed_larger_than_the_object_still_leaves_the_mask() {
    // Disc of radius 20 px (1257 px) with a 14 px ring of bleed (2376 px): the wall holds
    // most of the mask's pixels, but only its rim. Weighting clusters by depth inside the mask
    // keeps the object.
    let (depth, predicted, truth) = bleeding_disc(20.0, 14.0);
    let wall_pixels = predicted.pixels().iter().filter(|&&l| l == 1).count()
        - truth.pixels().iter().filter(|&&l| l == 1).count();
    assert!(
        wall_pixels > 1257 * 3 / 2,
        "the bleed must outweigh the disc"
    );
    let mut labels = predicted.clone();
    Refiner::new(RefineConfig::default())
        .refine_frame(&depth, &mut labels, &[Segment::bare(1)])
        .unwrap();
    let after = iou(&labels, &truth, 1);
    assert!(
        after == 1.0,
        "IoU {:.3} -> {after:.3}",
        iou(&predicted, &truth, 1)
    );
    // Counted without the image, every depth weighs the same and the wall wins.
    let depths: Vec<f32> = depth
        .pixels()
        .iter()
        .zip(predicted.pixels())
        .filter(|&(_, &l)| l == 1)
        .map(|(&d, _)| d)
        .collect();
    let by_count = Refiner::new(RefineConfig::default())
        .interval(&depths)
        .unwrap();
    assert!(by_count.low > 2.0, "{by_count:?}");
}

#[test]
fn depths_beyond_the_far_limit_leave_the_mask() {
    // A window: its frame at 5.5-5.6 m (a fifth of the mask) and the sky through it, rendered
    // at 16 km (the rest). Stuff keeps the frame only.
    let depth = DepthImage::from_fn(100, 100, |x, _| {
        if x < 20 {
            5.5 + 0.005 * x as f32
        } else {
            16_000.0
        }
    });
    let mut labels = LabelImage::filled(100, 100, 7);
    let window = Segment {
        is_thing: Some(false),
        ..Segment::bare(7)
    };
    let reports = Refiner::new(RefineConfig::default())
        .refine_frame(&depth, &mut labels, std::slice::from_ref(&window))
        .unwrap();
    assert_eq!(reports[0].status, MaskStatus::Refined);
    assert_eq!(reports[0].kept, 2000);
    assert!(
        labels
            .pixels()
            .iter()
            .enumerate()
            .all(|(i, &l)| (l == 7) == (i % 100 < 20))
    );
    // Nothing but sky: no surface to judge, the mask stays and says why.
    let sky = DepthImage::filled(100, 100, 16_000.0);
    let mut labels = LabelImage::filled(100, 100, 7);
    let reports = Refiner::new(RefineConfig::default())
        .refine_frame(&sky, &mut labels, &[window])
        .unwrap();
    assert_eq!(
        reports[0].status,
        MaskStatus::Kept(KeptReason::AllBeyondFarLimit)
    );
    assert_eq!(reports[0].removed, 0);
}
