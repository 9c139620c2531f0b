//! What a person sees of a run: the progress `voxpan run` writes into a log, the instance
//! table's true objects, and report.html as a browser draws it (headless Chromium).

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Output;

use super::common::{voxpan, voxpan_ok};

/// A short run on a tiny synthetic world (which has ground truth): the run folder and what
/// `voxpan run` wrote.
fn short_run(dir: &Path) -> (PathBuf, Output) {
    let data = dir.join("data");
    let out = dir.join("out");
    voxpan_ok(
        ["synth", "--preset", "tiny", "--frames", "6", "--out"]
            .map(OsStr::new)
            .into_iter()
            .chain([data.as_os_str()]),
    );
    // A coarse map: the run is about the report, not the map.
    let run = voxpan(
        [OsStr::new("run"), data.as_os_str(), OsStr::new("--out")]
            .into_iter()
            .chain([out.as_os_str()])
            .chain(["--voxel-size", "0.05"].map(OsStr::new)),
    );
    assert!(
        run.status.success(),
        "voxpan run failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    (out, run)
}

#[test]
fn a_run_in_a_log_says_each_phase_and_the_table_names_true_objects() {
    let dir = tempfile::tempdir().unwrap();
    let (out, run) = short_run(dir.path());
    // Standard error is a pipe here, as in a log: every phase has its line, in order.
    let log = String::from_utf8_lossy(&run.stderr);
    let phases = [
        "mapping: 6 frames",
        "extracting the mesh",
        "writing the meshes",
        "saving the map",
        "scoring the map against the ground-truth mesh",
        "mapping the ground truth for the voxel PQ: 6 frames",
        "matching the map's instances to the true objects",
        "writing the report",
        "putting the outputs in place",
    ];
    let mut from = 0;
    for phase in phases {
        let at = log[from..]
            .find(phase)
            .unwrap_or_else(|| panic!("no {phase:?} after byte {from} of the log:\n{log}"));
        from += at + phase.len();
    }
    // Human words only: no Rust debug output.
    for debug in ["Some(", "None", "::", "{ "] {
        assert!(!log.contains(debug), "{debug:?} in the log:\n{log}");
    }
    // The synthetic world has ground truth: the table has the column, and the walls and floor
    // (large, seen in every frame) are matched.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| true object (voxel IoU) |"), "{md}");
    let rows: Vec<&str> = md
        .lines()
        .skip_while(|l| !l.starts_with("| id |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .collect();
    assert!(!rows.is_empty(), "{md}");
    for row in &rows {
        let last = row.trim_end_matches('|').rsplit('|').next().unwrap().trim();
        assert!(
            last == "—" || (last.ends_with(')') && last.contains(" (0.")),
            "{row}"
        );
    }
    assert!(rows.iter().any(|r| r.contains(" floor (0.")), "{md}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<th>true object (voxel IoU)"));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let matches = metrics["instance_matches"].as_array().unwrap();
    assert_eq!(
        matches.len() as u64,
        metrics["panoptic"]["all"]["tp"].as_u64().unwrap()
    );
    // Every true object is matched or listed as missed, with where its voxels went.
    let missed = metrics["missed_objects"].as_array().unwrap();
    assert_eq!(
        missed.len() as u64,
        metrics["panoptic"]["all"]["fn_"].as_u64().unwrap()
    );
    assert_eq!(
        (matches.len() + missed.len()) as u64,
        metrics["panoptic"]["objects"].as_u64().unwrap()
    );
    let heading = format!(
        "{} of {} true objects matched no instance",
        missed.len(),
        metrics["panoptic"]["objects"]
    );
    assert!(
        md.contains("## Missed objects") && md.contains(&heading),
        "{md}"
    );
    assert!(html.contains("<h2>Missed objects</h2>"));
    for m in missed {
        let held: u64 = m["holders"]
            .as_array()
            .unwrap()
            .iter()
            .map(|h| h[1].as_u64().unwrap())
            .sum();
        let voxels = m["voxels"].as_u64().unwrap();
        assert!(held + m["unlabelled"].as_u64().unwrap() <= voxels, "{m}");
        assert!(voxels > 0, "{m}");
    }
}

#[test]
fn headless_chromium_draws_the_report() {
    let test = "headless_chromium_draws_the_report";
    let Some(_) =
        voxpan_test_support::require_program("chromium", "run tools/report/setup.sh", test)
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (out, _) = short_run(dir.path());
    let png = dir.path().join("report.png");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/report/screenshot.sh");
    let shot = std::process::Command::new("bash")
        .arg(&script)
        .arg(out.join("report.html"))
        .arg(&png)
        .arg("1000x3000")
        .output()
        .unwrap();
    assert!(
        shot.status.success(),
        "{}: {}",
        script.display(),
        String::from_utf8_lossy(&shot.stderr)
    );
    let image = image::open(&png)
        .unwrap_or_else(|e| panic!("{}: {e}", png.display()))
        .to_rgb8();
    assert_eq!(image.dimensions(), (1000, 3000));
    let pixels: Vec<[u8; 3]> = image.pixels().map(|p| p.0).collect();
    let colors: std::collections::HashSet<[u8; 3]> = pixels.iter().copied().collect();
    let inked = pixels.iter().filter(|&&p| p != [255; 3]).count() as f64 / pixels.len() as f64;
    // Text alone gives a few grey levels; the embedded pictures (the map from above, the ray
    // casts) give thousands of colours and cover much of the page. A page whose pictures did
    // not load, or a blank page, has neither.
    eprintln!("{} colours, {:.1} % not white", colors.len(), 100.0 * inked);
    assert!(colors.len() > 1000, "{} colours", colors.len());
    assert!(inked > 0.15, "{:.1} % not white", 100.0 * inked);
    // The header's text is on the page: dark pixels in the first rows.
    let dark_on_top = (0..1000)
        .flat_map(|x| (0..80).map(move |y| (x, y)))
        .filter(|&(x, y)| image.get_pixel(x, y).0.iter().all(|&c| c < 64))
        .count();
    assert!(
        dark_on_top > 200,
        "no heading drawn ({dark_on_top} dark pixels)"
    );
}
