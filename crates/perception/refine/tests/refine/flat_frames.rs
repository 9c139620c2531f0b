//! `paper` and `release` reproduce the original KDEpy-based code on real flat frames.
//!
//! The reference masks in `golden/flat/` were written by `tools/kdepy_reference.py refine`
//! (the released code's rules on KDEpy 1.1.12) for six frames of the shared sample.

use std::path::Path;

use voxpan_core::{Segment, segment_ids};
use voxpan_io::{read_depth_tiff, read_label_png};
use voxpan_refine::{FAR_LIMIT_M, RefineConfig, Refiner, Rule};
use voxpan_test_support::require_flat_sample;

#[test]
fn published_rules_match_the_original_per_pixel() {
    let Some(flat) = require_flat_sample("published_rules_match_the_original_per_pixel") else {
        return;
    };
    let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/flat");
    for id in ["000000", "000040", "000080", "000120", "000160", "000198"] {
        let depth = read_depth_tiff(&flat.join(format!("run1/{id}_depth.tiff"))).unwrap();
        let predicted = read_label_png(&flat.join(format!("run1/{id}_predicted.png"))).unwrap();
        let segments: Vec<Segment> = segment_ids(&predicted)
            .into_iter()
            .map(Segment::bare)
            .collect();
        for rule in [Rule::Paper, Rule::Release] {
            let reference =
                read_label_png(&golden.join(format!("{id}_{}.png", rule.name()))).unwrap();
            let mut labels = predicted.clone();
            Refiner::new(RefineConfig::new(rule))
                .refine_frame(&depth, &mut labels, &segments)
                .unwrap();
            let same = labels
                .pixels()
                .iter()
                .zip(reference.pixels())
                .filter(|(a, b)| a == b)
                .count();
            let agreement = same as f64 / labels.pixels().len() as f64;
            // Measured: 100 % on every frame of the sample; the issue asks for >= 99.5 %.
            assert!(
                agreement >= 0.9995,
                "frame {id}, rule {}: {:.4} %",
                rule.name(),
                100.0 * agreement
            );
        }
    }
}

#[test]
fn default_rule_gives_the_same_masks_in_metres_and_millimetres() {
    let Some(flat) =
        require_flat_sample("default_rule_gives_the_same_masks_in_metres_and_millimetres")
    else {
        return;
    };
    for id in ["000000", "000060", "000130", "000190"] {
        let depth = read_depth_tiff(&flat.join(format!("run1/{id}_depth.tiff"))).unwrap();
        let millimetres = depth.map(|&d| d * 1000.0);
        let predicted = read_label_png(&flat.join(format!("run1/{id}_predicted.png"))).unwrap();
        let segments: Vec<Segment> = segment_ids(&predicted)
            .into_iter()
            .map(Segment::bare)
            .collect();
        // Every metric setting scales with the unit: the far limit is the only one.
        let mut in_metres = Refiner::new(RefineConfig::new(Rule::Default));
        let mut in_millimetres = Refiner::new(RefineConfig {
            far_limit: FAR_LIMIT_M * 1000.0,
            ..RefineConfig::new(Rule::Default)
        });
        let (mut a, mut b) = (predicted.clone(), predicted.clone());
        let ra = in_metres.refine_frame(&depth, &mut a, &segments).unwrap();
        let rb = in_millimetres
            .refine_frame(&millimetres, &mut b, &segments)
            .unwrap();
        assert_eq!(a, b, "frame {id}");
        for (x, y) in ra.iter().zip(&rb) {
            if let (Some(bm), Some(bmm)) = (x.bandwidth, y.bandwidth) {
                assert!(
                    (bmm / (1000.0 * bm) - 1.0).abs() < 1e-6,
                    "frame {id} segment {}",
                    x.id
                );
            }
        }
    }
}
