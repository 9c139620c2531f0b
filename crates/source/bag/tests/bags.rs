//! Bags written by an independent implementation (PyPI `rosbags`, through
//! tools/ros/make_test_bags.py) from the synthetic world and the flat sample: the frames and
//! the map read from each bag must equal those read from the same frames as a folder (the
//! script's `--export-flat`: depth quantised as the bag carries it, poses composed from the tf
//! chain); malformed bags give errors naming topic and time.
//!
//! The bags are generated here, with the Python in `target/ros-venv` (tools/ros/setup.sh, or
//! the CI's set-up) or `$VOXPAN_ROS_PYTHON`. Without it the tests fail saying so, unless
//! `VOXPAN_ALLOW_MISSING_DATA=1` (then they print SKIPPED).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex, OnceLock};

use voxpan_bag::{BagDataset, BagOptions, fmt_time, summarize};
use voxpan_core::Frame;
use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_map::{MapConfig, PanopticMap};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../..")
}

fn python() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("VOXPAN_ROS_PYTHON") {
        return Some(p.into());
    }
    let p = repo().join("target/ros-venv/bin/python");
    p.is_file().then_some(p)
}

/// The bag-writing Python, or `None` (test skipped) when allowed to be missing.
fn require_python(test: &str) -> Option<PathBuf> {
    match python() {
        Some(p) => Some(p),
        None if voxpan_test_support::missing_data_allowed() => {
            eprintln!("SKIPPED {test}: no target/ros-venv (tools/ros/setup.sh) to write bags");
            None
        }
        None => panic!(
            "{test}: no Python with PyPI rosbags to write the test bags: run tools/ros/setup.sh \
             (or set VOXPAN_ROS_PYTHON), or set {}=1 to skip",
            voxpan_test_support::ALLOW_MISSING_ENV
        ),
    }
}

fn workdir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bag-tests");
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    })
}

/// The tiny synthetic world (20 frames of 160x120), generated once.
fn synth() -> PathBuf {
    static ONCE: OnceLock<PathBuf> = OnceLock::new();
    ONCE.get_or_init(|| {
        let out = workdir().join("synth");
        voxpan_sim::generate(&out, &voxpan_sim::SynthConfig::tiny(), |_| ()).unwrap();
        out
    })
    .clone()
}

/// Runs make_test_bags.py once per `name` (serialised: the script is not cheap on 2 cores).
fn make_bags(py: &Path, src: &Path, name: &str, args: &[&str]) -> PathBuf {
    static LOCK: Mutex<()> = Mutex::new(());
    let _guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let out = workdir().join(name);
    if out.join("done").is_file() {
        return out;
    }
    let status = Command::new(py)
        .arg(repo().join("tools/ros/make_test_bags.py"))
        .arg(src)
        .arg(&out)
        .args(["--name", "b", "--no-verify", "--force", "--export-flat"])
        .arg(out.join("flat"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "make_test_bags.py {args:?} failed:\n{}{}",
        String::from_utf8_lossy(&status.stdout),
        String::from_utf8_lossy(&status.stderr)
    );
    std::fs::write(out.join("done"), "").unwrap();
    out
}

fn manifest(dir: &Path, name: &str) -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(dir.join(format!("{name}.manifest.json"))).unwrap(),
    )
    .unwrap()
}

fn frames(source: &dyn FrameSource) -> Vec<Frame> {
    (0..source.len()).map(|i| source.load(i).unwrap()).collect()
}

fn map_of(frames: &[Frame]) -> PanopticMap {
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    for f in frames {
        map.integrate(f.view(), f.segments.as_ref()).unwrap();
    }
    map
}

/// Every bag in `dir` gives the frames of its flat export, and the same map.
fn check_against_folder(dir: &Path, bags: &[&str], options: &BagOptions) {
    let folder = FlatDataset::open(&dir.join("flat")).unwrap();
    let expected = frames(&folder);
    let expected_map = map_of(&expected);
    for bag in bags {
        let path = dir.join(bag);
        let t = std::time::Instant::now();
        let source = Arc::new(BagDataset::open(&path, options.clone()).unwrap());
        let got = frames(source.as_ref());
        eprintln!(
            "{bag}: {} frames read in {:.1} ms/frame (open included)",
            got.len(),
            t.elapsed().as_secs_f64() * 1e3 / got.len() as f64
        );
        assert!(source.skipped().is_empty(), "{bag}: {:?}", source.skipped());
        assert_eq!(got.len(), expected.len(), "{bag}");
        for (g, e) in got.iter().zip(&expected) {
            assert_eq!(g.color, e.color, "{bag} frame {}: colour", g.id);
            assert_eq!(g.depth, e.depth, "{bag} frame {}: depth", g.id);
            assert_eq!(g.intrinsics, e.intrinsics, "{bag} frame {}", g.id);
            assert_eq!(g.segments, e.segments, "{bag} frame {}: segments", g.id);
            assert!(
                (g.timestamp - e.timestamp).abs() < 1e-6,
                "{bag} frame {}",
                g.id
            );
            let d = (g.pose.to_homogeneous() - e.pose.to_homogeneous())
                .abs()
                .max();
            assert!(d < 1e-12, "{bag} frame {}: pose differs by {d}", g.id);
        }
        assert!(
            map_of(&got) == expected_map,
            "{bag}: the map differs from the folder's"
        );
    }
}

const ALL: [&str; 5] = ["b.bag", "b-bz2.bag", "b-lz4.bag", "b-mcap", "b-db3"];

#[test]
fn synthetic_bags_map_like_the_folder() {
    let Some(py) = require_python("synthetic_bags_map_like_the_folder") else {
        return;
    };
    let dir = make_bags(
        &py,
        &synth(),
        "synth",
        &["--formats", "ros1,ros1-bz2,ros1-lz4,mcap,db3"],
    );
    check_against_folder(&dir, &ALL, &BagOptions::default());

    // voxpan info's numbers: every topic with the writer's message counts.
    let m = manifest(&dir, "b");
    for bag in ALL {
        let s = summarize(&dir.join(bag)).unwrap();
        for (topic, count) in m["expected_counts"].as_object().unwrap() {
            let t = s.topics.iter().find(|t| &t.topic == topic).unwrap();
            assert_eq!(t.count, count.as_u64().unwrap(), "{bag} {topic}");
        }
        assert!(
            (s.duration_s() - 19.0 / 30.0).abs() < 0.01,
            "{bag}: {}",
            s.duration_s()
        );
    }
}

#[test]
fn other_encodings_and_a_pose_topic() {
    let Some(py) = require_python("other_encodings_and_a_pose_topic") else {
        return;
    };
    let dir = make_bags(
        &py,
        &synth(),
        "synth-bgr-32f",
        &[
            "--formats",
            "ros1,mcap,db3",
            "--color-encoding",
            "bgr8",
            "--depth-encoding",
            "32FC1",
            "--label-encoding",
            "8UC1",
            "--pose",
            "posestamped",
        ],
    );
    let options = BagOptions {
        pose_topic: Some("/camera/pose".into()),
        ..BagOptions::default()
    };
    check_against_folder(&dir, &["b.bag", "b-mcap", "b-db3"], &options);
    // Without the pose topic there is no /tf: said so.
    let e = BagDataset::open(&dir.join("b.bag"), BagOptions::default())
        .err()
        .unwrap();
    assert!(e.to_string().contains("no topic /tf"), "{e}");

    let dir = make_bags(
        &py,
        &synth(),
        "synth-rgba",
        &[
            "--formats",
            "ros1-lz4,mcap",
            "--color-encoding",
            "rgba8",
            "--no-labels",
        ],
    );
    check_against_folder(&dir, &["b-lz4.bag", "b-mcap"], &BagOptions::default());
    let dir = make_bags(
        &py,
        &synth(),
        "synth-mono",
        &["--formats", "mcap", "--color-encoding", "mono8"],
    );
    check_against_folder(&dir, &["b-mcap"], &BagOptions::default());
}

#[test]
fn flat_sample_bags_map_like_the_folder() {
    let Some(flat) =
        voxpan_test_support::require_flat_sample("flat_sample_bags_map_like_the_folder")
    else {
        return;
    };
    let Some(py) = require_python("flat_sample_bags_map_like_the_folder") else {
        return;
    };
    let dir = make_bags(
        &py,
        &flat,
        "flat",
        &["--formats", "ros1-lz4,mcap", "--frames", "4"],
    );
    check_against_folder(&dir, &["b-lz4.bag", "b-mcap"], &BagOptions::default());
}

#[test]
fn malformed_bags_say_what_and_where() {
    let Some(py) = require_python("malformed_bags_say_what_and_where") else {
        return;
    };
    let src = synth();
    let formats = ["--formats", "ros1-bz2,mcap,db3", "--malform"];
    let bags = ["b-truncated-bz2.bag", "b-truncated-mcap", "b-truncated-db3"];

    let dir = make_bags(
        &py,
        &src,
        "truncated",
        &[&formats[..], &["truncated"]].concat(),
    );
    for bag in bags {
        let e = BagDataset::open(&dir.join(bag), BagOptions::default())
            .err()
            .unwrap();
        assert!(e.to_string().contains("truncated"), "{bag}: {e}");
        assert!(summarize(&dir.join(bag)).is_err());
    }

    let dir = make_bags(
        &py,
        &src,
        "encoding",
        &[&formats[..], &["unknown-encoding"]].concat(),
    );
    let facts = &manifest(&dir, "b-unknown-encoding")["facts"]["unknown_encoding"];
    let when = fmt_time(facts["stamp_ns"].as_i64().unwrap());
    for bag in [
        "b-unknown-encoding-bz2.bag",
        "b-unknown-encoding-mcap",
        "b-unknown-encoding-db3",
    ] {
        let source = BagDataset::open(&dir.join(bag), BagOptions::default()).unwrap();
        let bad: Vec<String> = (0..source.len())
            .filter_map(|i| source.load(i).err().map(|e| e.to_string()))
            .collect();
        assert_eq!(bad.len(), 1, "{bag}: {bad:?}");
        for needle in [
            "/camera/color/image_raw",
            "\"yuv422\"",
            &when,
            "frame 000001",
        ] {
            assert!(
                bad[0].contains(needle),
                "{bag}: {:?} lacks {needle}",
                bad[0]
            );
        }
    }

    let dir = make_bags(
        &py,
        &src,
        "noinfo",
        &[&formats[..], &["missing-camera-info"]].concat(),
    );
    for bag in [
        "b-missing-camera-info-bz2.bag",
        "b-missing-camera-info-mcap",
        "b-missing-camera-info-db3",
    ] {
        let e = BagDataset::open(&dir.join(bag), BagOptions::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("no camera_info") && e.contains("/camera/color/camera_info"),
            "{e}"
        );
    }

    let dir = make_bags(&py, &src, "tfgap", &[&formats[..], &["tf-gap"]].concat());
    let gap = &manifest(&dir, "b-tf-gap")["facts"]["tf_gap"];
    let stamps: Vec<i64> = gap["stamps_without_pose_ns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect();
    assert!(!stamps.is_empty());
    for bag in ["b-tf-gap-bz2.bag", "b-tf-gap-mcap", "b-tf-gap-db3"] {
        let source = BagDataset::open(&dir.join(bag), BagOptions::default()).unwrap();
        let skipped = source.skipped();
        assert_eq!(skipped.len(), stamps.len(), "{bag}: {skipped:?}");
        for ((_, reason), t) in skipped.iter().zip(&stamps) {
            for needle in [
                "/tf has no transform world -> base_link",
                &fmt_time(*t),
                "gap of",
            ] {
                assert!(reason.contains(needle), "{bag}: {reason:?} lacks {needle}");
            }
        }
        assert_eq!(source.len(), 20 - stamps.len());
        // The rest still load.
        for i in 0..source.len() {
            source.load(i).unwrap();
        }
    }
}

#[test]
fn a_sqlite_file_that_is_no_rosbag2_is_named() {
    let dir = tempfile::tempdir().unwrap();
    // A valid, empty SQLite database made by SQLite itself would need a writer; a header with
    // garbage after it is enough for "not a rosbag2 bag" (no topics table can be read).
    let path = dir.path().join("other.db3");
    let mut bytes = b"SQLite format 3\0".to_vec();
    bytes.resize(4096, 0);
    std::fs::write(&path, &bytes).unwrap();
    let e = BagDataset::open(&path, BagOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("other.db3") && e.contains("SQLite"), "{e}");
    assert!(summarize(&path).is_err());
}

#[test]
fn wrong_topics_are_named() {
    let Some(py) = require_python("wrong_topics_are_named") else {
        return;
    };
    let dir = make_bags(
        &py,
        &synth(),
        "synth",
        &["--formats", "ros1,ros1-bz2,ros1-lz4,mcap"],
    );
    let options = BagOptions {
        color_topic: "/rgb".into(),
        ..BagOptions::default()
    };
    let e = BagDataset::open(&dir.join("b-mcap"), options)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("no topic /rgb (--color-topic)") && e.contains("/camera/color/image_raw"),
        "{e}"
    );
    let options = BagOptions {
        depth_topic: "/camera/color/camera_info".into(),
        ..BagOptions::default()
    };
    let e = BagDataset::open(&dir.join("b.bag"), options)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("is sensor_msgs/CameraInfo, expected sensor_msgs/Image"),
        "{e}"
    );
}
