//! `voxpan bench` on a few flat frames: every stage timed with and without refinement, and the
//! map's memory at the voxel size asked for.

use super::common::{voxpan, voxpan_ok};

use voxpan_test_support::require_flat_sample;

/// The stages `voxpan bench` times per frame.
const STAGES: [&str; 7] = [
    "decode",
    "segment",
    "refine",
    "trim",
    "fill",
    "track",
    "integrate",
];

#[test]
fn times_every_stage_and_reports_memory_at_the_voxel_size_asked_for() {
    let Some(flat) =
        require_flat_sample("times_every_stage_and_reports_memory_at_the_voxel_size_asked_for")
    else {
        return;
    };
    let flat = flat.to_str().unwrap();
    let mut blocks_at = Vec::new();
    for voxel in ["0.04", "0.08"] {
        let out = voxpan_ok(["bench", flat, "--frames", "0:8", "--voxel-size", voxel]);
        assert!(out.starts_with("5 frames of "), "{out}");
        for rule in ["default", "none"] {
            let line = out
                .lines()
                .find(|l| l.starts_with(&format!("refinement {rule}: ")))
                .unwrap_or_else(|| panic!("no {rule} line: {out}"));
            assert!(
                line.contains("frames/s") && line.contains("final mesh"),
                "{line}"
            );
            // "R frames/s (median frame interval I ms; W over the whole run, ...)": the
            // headline rate is the median interval's, and both rates are positive.
            let words: Vec<&str> = line.split_whitespace().collect();
            let rate: f64 = words[2].parse().unwrap();
            assert_eq!(
                words[3..7],
                ["frames/s", "(median", "frame", "interval"],
                "{line}"
            );
            let interval: f64 = words[7].parse().unwrap();
            let whole_run: f64 = words[9].parse().unwrap();
            assert!(interval > 0.0 && whole_run > 0.0, "{line}");
            // Up to the printed digits: 0.005 ms of the interval, 0.05 of the rate.
            let rounding = rate * 0.005 / interval + 0.05;
            assert!((rate - 1e3 / interval).abs() <= rounding, "{line}");
            for stage in STAGES {
                assert!(
                    line.contains(&format!("{stage} ")),
                    "{stage} missing: {line}"
                );
            }
            // "CPU C ms a frame, B of N cores busy": busy cores at most the machine's (with a
            // tick of rounding in the process's CPU clock), CPU time per frame positive.
            let cpu = line
                .split("; CPU ")
                .nth(1)
                .unwrap_or_else(|| panic!("no CPU figures: {line}"));
            let words: Vec<&str> = cpu.split_whitespace().collect();
            let per_frame: f64 = words[0].parse().unwrap();
            let (busy, cores): (f64, f64) = (words[4].parse().unwrap(), words[6].parse().unwrap());
            assert_eq!(
                (words[1], words[7], words[8]),
                ("ms", "cores", "busy"),
                "{line}"
            );
            assert!(
                per_frame > 0.0 && busy > 0.0 && busy <= cores + 0.25,
                "{line}"
            );
        }
        // Both runs map the same frames at the same voxel size: the same blocks.
        let maps: Vec<&str> = out.lines().filter(|l| l.starts_with("  map: ")).collect();
        assert_eq!(maps.len(), 2, "{out}");
        // (The measured heaps may differ: the instances differ.)
        let computed = |m: &str| m.split("; measured").next().unwrap().to_owned();
        assert_eq!(computed(maps[0]), computed(maps[1]));
        let words: Vec<&str> = maps[0].split_whitespace().collect();
        // "map: N blocks of 512 voxels at V m, S MB (B bytes; b a voxel); measured heap: M MB
        // (H bytes) for the blocks and instances as loaded, ..."
        let blocks: u64 = words[1].parse().unwrap();
        assert_eq!((words[4], words[7]), ("512", voxel), "{}", maps[0]);
        let bytes: u64 = words[11].trim_start_matches('(').parse().unwrap();
        let voxel_bytes: u64 = words[13].parse().unwrap();
        // The speed issue's memory goal: distance, weight, colour and instance evidence
        // together in at most 12 bytes.
        assert!(voxel_bytes <= 12, "{voxel_bytes} bytes a voxel");
        // The computed figure (what the memory limit counts) against the heap the loaded map
        // was measured to hold by the counting allocator: at least the blocks, and no more
        // than 5 % beyond them plus 64 kB (the block table and the instances).
        let measured: u64 = maps[0]
            .split("measured heap: ")
            .nth(1)
            .and_then(|m| m.split(" bytes)").next())
            .and_then(|m| m.rsplit('(').next())
            .unwrap_or_else(|| panic!("no measured heap: {}", maps[0]))
            .parse()
            .unwrap();
        assert!(
            measured >= bytes && measured <= bytes + bytes / 20 + (64 << 10),
            "{}: measured {measured} bytes, computed {bytes}",
            maps[0]
        );
        blocks_at.push(blocks);
    }
    // Coarser voxels: fewer, larger blocks for the same surface.
    assert!(blocks_at[1] * 3 < blocks_at[0], "{blocks_at:?}");
    // A narrower band around the surface touches fewer blocks.
    let out = voxpan_ok([
        "bench",
        flat,
        "--frames",
        "0:8",
        "--voxel-size",
        "0.08",
        "--truncation",
        "1",
    ]);
    let map = out.lines().find(|l| l.starts_with("  map: ")).unwrap();
    let blocks: u64 = map.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(
        blocks < blocks_at[1],
        "{blocks} blocks at truncation 1, {blocks_at:?} at 3"
    );
}

#[test]
fn refuses_a_voxel_size_or_truncation_it_cannot_use_naming_the_option() {
    for (option, value) in [("--voxel-size", "-1"), ("--truncation", "0.5")] {
        let out = voxpan(["bench", option, value]);
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(option), "{stderr}");
        assert!(out.stdout.is_empty(), "nothing timed before the check");
    }
}
