//! The robustness issue's acceptance list, through the binary: bad options are refused by
//! name before any work, the output folder is locked, committed with a manifest, and an
//! interrupted run exits 130 and says so.

use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::common::{voxpan, voxpan_ok};

fn tiny_dataset(out: &Path, frames: &str) {
    voxpan_ok(
        ["synth", "--preset", "tiny", "--frames", frames, "--out"]
            .map(OsStr::new)
            .into_iter()
            .chain([out.as_os_str()]),
    );
}

/// Runs `voxpan run data --out out extra...`; returns (success, stderr).
fn run(data: &Path, out: &Path, extra: &[&str]) -> (bool, String) {
    let result = voxpan(
        [OsStr::new("run"), data.as_os_str(), OsStr::new("--out")]
            .into_iter()
            .chain([out.as_os_str()])
            .chain(extra.iter().map(OsStr::new)),
    );
    (
        result.status.success(),
        String::from_utf8_lossy(&result.stderr).into_owned(),
    )
}

#[test]
fn absurd_options_are_refused_by_name_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_dataset(&data, "2");
    let out = dir.path().join("out");
    for (option, value, named) in [
        ("--voxel-size", "inf", "tsdf.voxel_size"),
        ("--voxel-size", "10", "tsdf.voxel_size"),
        ("--voxel-size", "1e-5", "tsdf.voxel_size"),
        ("--voxel-size", "-0.02", "tsdf.voxel_size"),
        ("--truncation", "1000", "tsdf.truncation_voxels"),
        ("--max-range", "nan", "tsdf.max_range"),
        ("--max-memory", "0", "resources.max_memory_gb"),
        ("--threads", "0", "--threads"),
        ("--sync-tolerance-ms", "nan", "--sync-tolerance-ms"),
        ("--sync-tolerance-ms", "-5", "--sync-tolerance-ms"),
        ("--rate", "-1", "source.rate"),
        ("--rate", "nan", "source.rate"),
    ] {
        let (ok, stderr) = run(&data, &out, &[option, value]);
        assert!(!ok, "{option} {value} accepted");
        assert!(stderr.contains(named), "{option} {value}: {stderr}");
        assert!(!out.join("manifest.json").exists());
    }
    // One millimetre voxels: one frame could need more than 0.05 GB; refused before mapping.
    let (ok, stderr) = run(
        &data,
        &out,
        &["--voxel-size", "0.001", "--max-memory", "0.05"],
    );
    assert!(!ok);
    assert!(
        stderr.contains("one frame of 160x120") && stderr.contains("--max-memory"),
        "{stderr}"
    );
    assert!(!out.join("manifest.json").exists());
    // Too many threads are capped, not a hang.
    let (ok, stderr) = run(
        &data,
        &out,
        &["--threads", "100000", "--voxel-size", "0.05"],
    );
    assert!(ok, "{stderr}");
    assert!(stderr.contains("capped"), "{stderr}");

    let synth_out = dir.path().join("s");
    let result = voxpan(
        [
            "synth",
            "--preset",
            "tiny",
            "--frames",
            "2",
            "--mask-error",
            "1000",
            "--out",
        ]
        .map(OsStr::new)
        .into_iter()
        .chain([synth_out.as_os_str()]),
    );
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("--mask-error"));
}

#[test]
fn the_output_folder_is_locked_committed_and_replaced_whole() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_dataset(&data, "2");
    let out = dir.path().join("out");
    let (ok, stderr) = run(&data, &out, &["--voxel-size", "0.05", "--save-refined"]);
    assert!(ok, "{stderr}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["completed"], true);
    assert_eq!(manifest["frames"], 2);
    let files: Vec<&str> = manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    for f in ["map.voxpan", "mesh_rgb.ply", "config.toml", "report.md"] {
        assert!(files.contains(&f), "{f} not in {files:?}");
    }
    assert!(files.iter().any(|f| f.starts_with("refined/")));
    for f in &files {
        assert!(out.join(f).is_file(), "{f}");
    }

    // A live process (this test) holds the folder's lock: refused, naming it.
    let held = std::fs::File::create(out.join(".voxpan.lock")).unwrap();
    held.try_lock().unwrap();
    std::fs::write(out.join(".voxpan.lock"), std::process::id().to_string()).unwrap();
    let (ok, stderr) = run(&data, &out, &["--voxel-size", "0.05"]);
    assert!(!ok);
    assert!(
        stderr.contains(&std::process::id().to_string()) && stderr.contains("out"),
        "{stderr}"
    );
    // Once its holder lets go (as the OS does for a killed one), the lock is taken over
    // whatever the file says; the new run replaces the old one's files whole (no refined/
    // this time).
    drop(held);
    let (ok, stderr) = run(
        &data,
        &out,
        &["--voxel-size", "0.04", "--no-trim-stuff-planes"],
    );
    assert!(ok, "{stderr}");
    assert!(!out.join("refined").exists());
    let config = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(config.contains("voxel_size = 0.04"), "{config}");
    assert!(config.contains("trim_stuff_planes = false"), "{config}");
    assert!(!out.join(".voxpan.lock").exists());
    assert!(!out.join(".voxpan-staging").exists());
}

#[test]
fn an_interrupted_run_exits_130_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_dataset(&data, "30");
    let out = dir.path().join("out");
    let child = Command::new(env!("CARGO_BIN_EXE_voxpan"))
        .args([OsStr::new("run"), data.as_os_str(), OsStr::new("--out")])
        .arg(&out)
        .args(["--voxel-size", "0.01", "--threads", "1", "--save-refined"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Refined masks are staged as frames are mapped: interrupt after the first.
    let start = Instant::now();
    let staged = out.join(".voxpan-staging/refined");
    while std::fs::read_dir(&staged).map_or(true, |mut d| d.next().is_none()) {
        assert!(start.elapsed() < Duration::from_secs(60), "never started");
        std::thread::sleep(Duration::from_millis(2));
    }
    // SAFETY: sending a signal to our own child process.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted"), "{stderr}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["completed"], false);
    assert!(manifest["frames"].as_u64().unwrap() < 30);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.to_lowercase().contains("stopped early"), "{report}");
}

/// An output that is one of a command's inputs (by any spelling), a folder option naming a
/// file, a run into its own dataset and a recording path that cannot be written are refused
/// by name before anything is read or written.
#[test]
fn outputs_that_would_destroy_inputs_or_fail_late_are_refused_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = d.join("data");
    tiny_dataset(&data, "2");
    let (ok, stderr) = run(&data, &d.join("out"), &["--voxel-size", "0.05"]);
    assert!(ok, "{stderr}");
    let map = d.join("out/map.voxpan");
    let before = std::fs::read(&map).unwrap();
    std::fs::write(d.join("file"), b"not a folder").unwrap();
    let spelled = d.join("out/../out/map.voxpan");
    let p = |p: &Path| p.to_str().unwrap().to_owned();
    let refused: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["mesh".into(), p(&map), "--out".into(), p(&map)],
            "would destroy",
        ),
        (
            vec!["mesh".into(), p(&map), "--out".into(), p(&spelled)],
            "would destroy",
        ),
        (
            vec![
                "mesh".into(),
                p(&map),
                "--out".into(),
                p(&d.join("m.ply")),
                "--instances".into(),
                p(&d.join("file")),
            ],
            "--instances",
        ),
        (
            vec![
                "costmap".into(),
                p(&map),
                "--out".into(),
                p(&d.join("file")),
            ],
            "is a file",
        ),
        (
            vec!["run".into(), p(&data), "--out".into(), p(&data)],
            "the dataset itself",
        ),
        (
            vec!["run".into(), p(&data), "--out".into(), p(&d.join("file"))],
            "is a file",
        ),
        (
            vec![
                "run".into(),
                p(&data),
                "--out".into(),
                p(&d.join("o2")),
                "--record".into(),
                p(d),
            ],
            "is a folder",
        ),
        (
            vec![
                "run".into(),
                p(&data),
                "--out".into(),
                p(&d.join("o3")),
                "--record".into(),
                p(&d.join("missing/r.mcap")),
            ],
            "does not exist",
        ),
    ];
    for (args, needle) in refused {
        let o = voxpan(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    assert_eq!(std::fs::read(&map).unwrap(), before, "the map was touched");
    for never in ["m.ply", "o2", "o3"] {
        assert!(!d.join(never).exists(), "{never} was written");
    }
}

/// Ctrl-C after mapping (here while the ground truth is mapped again for the voxel PQ) stops
/// the run at once: the map and meshes go in place with `completed: false`, no report, exit
/// 130.
#[test]
fn ctrl_c_while_scoring_keeps_the_map_and_exits_130() {
    use std::io::{BufRead, BufReader};
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_dataset(&data, "30");
    let out = dir.path().join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_voxpan"))
        .args([OsStr::new("run"), data.as_os_str(), OsStr::new("--out")])
        .arg(&out)
        .args(["--voxel-size", "0.02", "--threads", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = Vec::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        let scoring = line.starts_with("mapping the ground truth for the voxel PQ");
        seen.push(line);
        if scoring {
            break;
        }
    }
    assert!(
        seen.last().unwrap().starts_with("mapping the ground truth"),
        "{seen:#?}"
    );
    let signalled = Instant::now();
    // SAFETY: sending a signal to our own child process.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    seen.extend(lines.map(Result::unwrap));
    let status = child.wait().unwrap();
    let stderr = seen.join("\n");
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(signalled.elapsed() < Duration::from_secs(20), "{stderr}");
    assert!(stderr.contains("interrupted after mapping"), "{stderr}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["completed"], false);
    assert_eq!(manifest["frames"], 30);
    voxpan_map::PanopticMap::load(&out.join("map.voxpan")).unwrap();
    assert!(out.join("mesh_rgb.ply").is_file());
    assert!(!out.join("report.md").exists());
    eprintln!("stopped {:?} after SIGINT", signalled.elapsed());
}

/// An empty `.bag` and a ROS 2 bag folder without `metadata.yaml` get the bag reader's
/// errors, naming them, not "neither flat nor TUM".
#[test]
fn broken_bags_are_named_as_bags() {
    let dir = tempfile::tempdir().unwrap();
    let (empty, folder) = (
        dir.path().join("empty.bag"),
        dir.path().join("rosbag2_2026"),
    );
    std::fs::create_dir(&folder).unwrap();
    // A 0-byte bag; a folder holding only a storage file's first bytes.
    let db3 = folder.join("rosbag2_2026_0.db3");
    for (file, bytes) in [(&empty, &b""[..]), (&db3, b"SQLite format 3\0")] {
        std::fs::write(file, bytes).unwrap();
    }
    for input in [&empty, &folder] {
        let (ok, stderr) = run(input, &dir.path().join("out"), &[]);
        assert!(!ok);
        assert!(!stderr.contains("TUM"), "{stderr}");
        assert!(
            stderr.contains(input.file_name().unwrap().to_str().unwrap()),
            "{stderr}"
        );
    }
}
