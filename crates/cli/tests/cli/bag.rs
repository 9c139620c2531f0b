//! `voxpan info BAG` and `voxpan run BAG` on bags written by PyPI rosbags
//! (tools/ros/make_test_bags.py): the run's map equals the run on the same frames as a folder.

use std::path::{Path, PathBuf};

use crate::common::{tiny_world_bags, voxpan, voxpan_ok};
use voxpan_map::PanopticMap;

/// The Python with PyPI rosbags (target/ros-venv or $VOXPAN_ROS_PYTHON); `None` (skipped)
/// only with VOXPAN_ALLOW_MISSING_DATA=1.
fn python(test: &str) -> Option<PathBuf> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/ros-venv/bin/python");
    match std::env::var_os("VOXPAN_ROS_PYTHON").map(PathBuf::from) {
        Some(p) => return Some(p),
        None if venv.is_file() => return Some(venv),
        None => {}
    }
    if voxpan_test_support::missing_data_allowed() {
        eprintln!("SKIPPED {test}: no target/ros-venv (tools/ros/setup.sh) to write bags");
        return None;
    }
    panic!(
        "{test}: no Python with PyPI rosbags: run tools/ros/setup.sh or set VOXPAN_ALLOW_MISSING_DATA=1"
    );
}

/// The tiny world's bags in a new folder, written in `formats_then_options[0]` (the bag
/// writer's `--formats`) with the writer's other options; `None`: skipped (no rosbags).
fn written_bags(test: &str, formats_then_options: &[&str]) -> Option<tempfile::TempDir> {
    let py = python(test)?;
    let dir = tempfile::tempdir().unwrap();
    let (formats, options) = formats_then_options.split_first().expect("formats");
    let mut args: Vec<&std::ffi::OsStr> = vec!["--formats".as_ref(), formats.as_ref()];
    args.push("--no-verify".as_ref());
    args.extend(options.iter().map(|o| std::ffi::OsStr::new(*o)));
    tiny_world_bags(&py, dir.path(), &args);
    Some(dir)
}

#[test]
fn info_and_run_read_bags_like_folders() {
    let Some(py) = python("info_and_run_read_bags_like_folders") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let flat = d.join("flat");
    tiny_world_bags(
        &py,
        d,
        &[
            "--formats".as_ref(),
            "ros1-bz2,mcap,db3".as_ref(),
            "--no-verify".as_ref(),
            "--export-flat".as_ref(),
            flat.as_os_str(),
        ],
    );

    let info = voxpan_ok([
        "info".as_ref(),
        d.join("bags/s-bz2.bag").as_os_str(),
        "--frames".as_ref(),
    ]);
    for needle in [
        "format:   ROS 1",
        "duration: 0.636 s",
        "frames:   20 (skipped 0)",
        "30.00 Hz",
    ] {
        assert!(info.contains(needle), "{needle:?} not in\n{info}");
    }
    assert!(
        info.lines().any(
            |l| l.starts_with("/camera/aligned_depth_to_color/image_raw ")
                && l.contains(" sensor_msgs/Image ")
                && l.contains(" 20 ")
        ),
        "{info}"
    );
    let info = voxpan_ok(["info".as_ref(), d.join("bags/s-mcap").as_os_str()]);
    assert!(
        info.contains("format:   MCAP") && info.contains("/tf_static"),
        "{info}"
    );
    let info = voxpan_ok(["info".as_ref(), d.join("bags/s-db3").as_os_str()]);
    assert!(
        info.contains("format:   SQLite") && info.contains("/tf_static"),
        "{info}"
    );

    let classes = d.join("flat/detectron_labels.csv");
    let run = |input: &Path, out: &str| {
        voxpan_ok([
            "run".as_ref(),
            input.as_os_str(),
            "--out".as_ref(),
            d.join(out).as_os_str(),
            "--classes".as_ref(),
            classes.as_os_str(),
        ]);
        PanopticMap::load(&d.join(out).join("map.voxpan")).unwrap()
    };
    let folder = run(&d.join("flat"), "out-flat");
    assert!(
        run(&d.join("bags/s-bz2.bag"), "out-bz2") == folder,
        "ROS 1 map differs"
    );
    assert!(
        run(&d.join("bags/s-mcap"), "out-mcap") == folder,
        "MCAP map differs"
    );
    assert!(
        run(&d.join("bags/s-db3"), "out-db3") == folder,
        "SQLite (.db3) map differs"
    );

    // A wrong topic is named, with what the bag has.
    let bad = voxpan([
        "run".as_ref(),
        d.join("bags/s-mcap").as_os_str(),
        "--out".as_ref(),
        d.join("o").as_os_str(),
        "--depth-topic".as_ref(),
        "/depth".as_ref(),
    ]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("no topic /depth (--depth-topic)"),
        "{err}"
    );
}

/// A camera_info with non-zero distortion is warned about (voxpan maps rectified images with K
/// alone), on ROS 1 and in CDR; rectified images get no warning.
#[test]
fn distorted_camera_info_is_warned_about() {
    let Some(py) = python("distorted_camera_info_is_warned_about") else {
        return;
    };
    // `voxpan run` of each bag in `dir` written with the bag writer's `options`: its stderr.
    let warnings = |options: &[&str], bags: &[&str]| {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let options: Vec<&std::ffi::OsStr> = options.iter().map(|o| o.as_ref()).collect();
        tiny_world_bags(&py, d, &options);
        bags.iter()
            .map(|bag| {
                let o = voxpan([
                    "run".as_ref(),
                    d.join(bag).as_os_str(),
                    "--out".as_ref(),
                    d.join("out").join(bag).as_os_str(),
                    "--voxel-size".as_ref(),
                    "0.05".as_ref(),
                ]);
                let err = String::from_utf8_lossy(&o.stderr).into_owned();
                assert!(o.status.success(), "{err}");
                err
            })
            .collect::<Vec<_>>()
    };
    let distorted = [
        "--formats",
        "ros1,mcap",
        "--no-verify",
        "--distortion",
        "0.1",
        "-0.05",
    ];
    let bags = ["bags/s.bag", "bags/s-mcap"];
    for (bag, err) in bags.iter().zip(warnings(&distorted, &bags)) {
        assert!(
            err.contains("warning: /camera/color/camera_info at ")
                && err.contains("distorted (plumb_bob model, D = [0.1, -0.05, 0.0, 0.0, 0.0])")
                && err.contains("rectify"),
            "{bag}: {err}"
        );
    }
    let plain = warnings(&["--formats", "ros1", "--no-verify"], &["bags/s.bag"]);
    assert!(!plain[0].contains("distorted"), "{}", plain[0]);
}

/// Two depth images with one stamp (each with its own /tf sample there) cannot be told apart:
/// the second is skipped, saying why and naming the first.
#[test]
fn frames_sharing_a_stamp_are_skipped_by_name() {
    let test = "frames_sharing_a_stamp_are_skipped_by_name";
    let Some(dir) = written_bags(test, &["ros1", "--malform", "duplicate-stamp"]) else {
        return;
    };
    let d = dir.path();
    let bag = std::fs::read_dir(d.join("bags"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "bag"))
        .expect("the bag written");
    let info = voxpan_ok(["info".as_ref(), bag.as_os_str(), "--frames".as_ref()]);
    assert!(info.contains("frames:   19 (skipped 1)"), "{info}");
    assert!(
        info.contains("000010") && info.contains("is frame 000009's too"),
        "{info}"
    );
}

/// A stretch of a bag without poses skips many frames for one reason: said once, with the
/// count and the frames, not once per frame (the reasons differ only in their stamps).
#[test]
fn frames_skipped_for_one_reason_are_one_line() {
    let test = "frames_skipped_for_one_reason_are_one_line";
    let Some(dir) = written_bags(test, &["ros1", "--malform", "tf-gap"]) else {
        return;
    };
    let bag = std::fs::read_dir(dir.path().join("bags"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "bag"))
        .expect("the bag written");
    let info = voxpan_ok(["info".as_ref(), bag.as_os_str(), "--frames".as_ref()]);
    let count: usize = info
        .split("(skipped ")
        .nth(1)
        .and_then(|rest| rest.split(')').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no skip count: {info}"));
    assert!(count > 3, "the gap skips several frames: {info}");
    let lines: Vec<&str> = info.lines().filter(|l| l.contains(" skipped")).collect();
    assert_eq!(lines.len(), 1, "{info}");
    assert!(
        lines[0].starts_with(&format!("  {count} frames (")) && lines[0].contains("gap"),
        "{info}"
    );
}
