//! Refinement speed on real frames of the flat sample (`../shared/data/flat`).
//!
//! - `frame`: all segments of a frame (10 frames, spread over the run), per rule.
//! - `mask_50k`: the frame segment nearest 50 000 pixels, per rule.
//! - `interior`: the default rule's per-frame distance-to-outline map (part of `frame`).
//! - `trim_stuff_planes`: thing masks trimmed off the frame's stuff planes, after the default
//!   rule (the pipeline's step after `frame`).
//!
//! The paper/release rules run the KDEpy-compatible KDE; `default` runs Botev's ISJ. The
//! original Python refinement (KDEpy) is timed by `tools/kdepy_reference.py eval`.

use voxpan_core::{DepthImage, LabelImage, Segment, segment_ids};
use voxpan_io::{flat_sample_dir, read_depth_tiff, read_label_png, read_segments_json};
use voxpan_refine::{PlaneTrimmer, RefineConfig, Refiner, Rule, interior_depth};

fn main() {
    if flat_sample_dir().is_none() {
        eprintln!(
            "refine bench: the flat sample (../shared/data/flat) is missing; nothing to measure"
        );
        return;
    }
    divan::main();
}

const RULES: [Rule; 3] = [Rule::Default, Rule::Paper, Rule::Release];

fn frames() -> Vec<(DepthImage, LabelImage)> {
    let dir = flat_sample_dir().expect("checked in main").join("run1");
    (0..10)
        .map(|i| {
            let id = format!("{:06}", i * 20);
            let depth = read_depth_tiff(&dir.join(format!("{id}_depth.tiff"))).unwrap();
            let labels = read_label_png(&dir.join(format!("{id}_predicted.png"))).unwrap();
            (depth, labels)
        })
        .collect()
}

fn segments_of(labels: &LabelImage) -> Vec<Segment> {
    segment_ids(labels).into_iter().map(Segment::bare).collect()
}

#[divan::bench(args = RULES)]
fn frame(bencher: divan::Bencher, rule: Rule) {
    let frames = frames();
    let segments: Vec<Vec<Segment>> = frames.iter().map(|(_, l)| segments_of(l)).collect();
    let mut refiner = Refiner::new(RefineConfig::new(rule));
    let mut next = 0;
    bencher
        .with_inputs(|| {
            next = (next + 1) % frames.len();
            (next, frames[next].1.clone())
        })
        .bench_local_values(|(i, mut labels)| {
            refiner
                .refine_frame(&frames[i].0, &mut labels, &segments[i])
                .unwrap()
        });
}

#[divan::bench]
fn interior(bencher: divan::Bencher) {
    let frames = frames();
    let mut out = Vec::new();
    let mut next = 0;
    bencher.bench_local(|| {
        next = (next + 1) % frames.len();
        interior_depth(&frames[next].1, &mut out);
    });
}

#[divan::bench]
fn trim_stuff_planes(bencher: divan::Bencher) {
    let dir = flat_sample_dir().expect("checked in main").join("run1");
    let mut refiner = Refiner::new(RefineConfig::default());
    let frames: Vec<(DepthImage, LabelImage, Vec<Segment>)> = frames()
        .into_iter()
        .enumerate()
        .map(|(i, (depth, mut labels))| {
            let json = dir.join(format!("{:06}_labels.json", i * 20));
            let segments = read_segments_json(&json).unwrap();
            refiner
                .refine_frame(&depth, &mut labels, &segments)
                .unwrap();
            (depth, labels, segments)
        })
        .collect();
    let mut trimmer = PlaneTrimmer::new();
    let mut next = 0;
    bencher
        .with_inputs(|| {
            next = (next + 1) % frames.len();
            (next, frames[next].1.clone())
        })
        .bench_local_values(|(i, mut labels)| {
            trimmer.trim(&frames[i].0, &mut labels, &frames[i].2)
        });
}

#[divan::bench(args = RULES)]
fn mask_50k(bencher: divan::Bencher, rule: Rule) {
    let depths = mask_near_50k(&frames());
    let mut refiner = Refiner::new(RefineConfig::new(rule));
    bencher.bench_local(|| refiner.interval(divan::black_box(&depths)));
}

/// Depths under the segment whose size is nearest 50 000 pixels.
fn mask_near_50k(frames: &[(DepthImage, LabelImage)]) -> Vec<f32> {
    let mut best: Option<(usize, Vec<f32>)> = None;
    for (depth, labels) in frames {
        for id in segment_ids(labels) {
            let d: Vec<f32> = labels
                .pixels()
                .iter()
                .zip(depth.pixels())
                .filter(|&(&l, _)| l == id)
                .map(|(_, &d)| d)
                .collect();
            let gap = d.len().abs_diff(50_000);
            if best.as_ref().is_none_or(|(g, _)| gap < *g) {
                best = Some((gap, d));
            }
        }
    }
    best.expect("frames have segments").1
}
