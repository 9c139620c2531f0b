//! `voxpan synth` writes a flat dataset the reader accepts, deterministically; `voxpan run` and
//! `voxpan mesh` work on it.

use std::ffi::OsStr;
use std::path::Path;

use super::common::{voxpan, voxpan_ok};
use voxpan_dataset::{FlatDataset, FrameSource};

fn synth(out: &Path, seed: &str) {
    synth_with(out, seed, &[]);
}

fn synth_with(out: &Path, seed: &str, options: &[&str]) {
    let stdout = voxpan_ok(
        [
            "synth", "--preset", "tiny", "--frames", "3", "--seed", seed, "--out",
        ]
        .map(OsStr::new)
        .into_iter()
        .chain([out.as_os_str()])
        .chain(options.iter().map(OsStr::new)),
    );
    assert!(stdout.contains("wrote 3 frames (160x120"), "{stdout}");
}

#[test]
fn tiny_preset_round_trips_through_the_reader() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    synth(a.path(), "9");
    synth(b.path(), "9");
    let dataset = FlatDataset::open(a.path()).unwrap();
    assert_eq!(dataset.len(), 3);
    let frame = dataset.load(2).unwrap();
    assert!(frame.segments.is_some() && frame.ground_truth.is_some());
    // Same seed, same bytes.
    for name in [
        "run1/000002_depth.tiff",
        "run1/000002_predicted.png",
        "groundtruth_mesh.ply",
    ] {
        assert_eq!(
            std::fs::read(a.path().join(name)).unwrap(),
            std::fs::read(b.path().join(name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn a_mask_seed_changes_the_masks_and_nothing_else() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    synth(a.path(), "9");
    synth_with(b.path(), "9", &["--mask-seed", "4"]);
    let read = |dir: &Path, name: &str| std::fs::read(dir.join(name)).unwrap();
    for name in [
        "run1/000002_depth.tiff",
        "run1/000002_color.png",
        "run1/000002_segmentation.png",
        "groundtruth_mesh.ply",
    ] {
        assert_eq!(read(a.path(), name), read(b.path(), name), "{name}");
    }
    assert_ne!(
        read(a.path(), "run1/000002_predicted.png"),
        read(b.path(), "run1/000002_predicted.png")
    );
}

#[test]
fn rejects_nonsense_options() {
    let dir = tempfile::tempdir().unwrap();
    let result = voxpan([
        OsStr::new("synth"),
        OsStr::new("--frames"),
        OsStr::new("0"),
        OsStr::new("--out"),
        dir.path().as_os_str(),
    ]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("at least one frame"));
}

#[test]
fn refinement_raises_iou_on_over_covering_synthetic_masks() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("oc");
    voxpan_ok(
        [
            "synth",
            "--preset",
            "tiny",
            "--over-cover-only",
            "--mask-error",
            "1",
            "--out",
        ]
        .map(OsStr::new)
        .into_iter()
        .chain([data.as_os_str()]),
    );
    let stdout = voxpan_ok([OsStr::new("eval"), data.as_os_str(), OsStr::new("--json")]);
    let table: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let get = |rule: &str, key: &str| table[rule][key].as_f64().unwrap();
    // Measured: none 54.21 / 40.77, default 55.08 / 43.15 (mean matched IoU / PQ).
    assert!(get("default", "mean_matched_iou") > get("none", "mean_matched_iou") + 0.5);
    assert!(get("default", "pq") > get("none", "pq") + 1.5);
}

#[test]
fn run_writes_its_outputs_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    synth(&data, "3");
    let out = dir.path().join("out");
    let stdout = voxpan_ok(
        [OsStr::new("run"), data.as_os_str()]
            .into_iter()
            .chain(["--voxel-size", "0.05", "--threads", "1", "--out"].map(OsStr::new))
            .chain([out.as_os_str()]),
    );
    assert!(
        stdout.contains("3 frames at") && stdout.contains("against the ground-truth mesh"),
        "{stdout}"
    );
    for f in [
        "map.voxpan",
        "mesh_rgb.ply",
        "mesh_instance.ply",
        "mesh_class.ply",
        "metrics.json",
        "config.toml",
        "report.md",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let config = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(config.contains("voxel_size = 0.05"), "{config}");
    // The report shows the map: pictures that decode and are not blank, embedded in the page,
    // the instance table and the configuration.
    for by in ["rgb", "instance", "class"] {
        for view in ["top", "view1", "view2"] {
            let path = out.join(format!("report/{view}_{by}.png"));
            let picture = image::open(&path).unwrap().to_rgb8();
            let drawn = picture.pixels().filter(|p| p.0 != [255, 255, 255]).count();
            let share = drawn as f64 / (picture.width() * picture.height()) as f64;
            assert!(
                share > 0.05,
                "{}: {:.1} % drawn",
                path.display(),
                100.0 * share
            );
        }
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    // 9 views, the timeline, and the sample frame's densities, depth and mask before/after.
    assert_eq!(html.matches("data:image/png;base64,").count(), 13);
    assert!(out.join("report/mask_on_color.png").is_file());
    assert!(html.contains("<h2>Instances</h2>") && html.contains("voxel_size = 0.05"));
    // The saved map meshes again, by class.
    let mesh = dir.path().join("class.ply");
    let map = out.join("map.voxpan");
    voxpan_ok([
        OsStr::new("mesh"),
        map.as_os_str(),
        OsStr::new("--by"),
        OsStr::new("class"),
        OsStr::new("--out"),
        mesh.as_os_str(),
    ]);
    assert!(std::fs::metadata(&mesh).unwrap().len() > 1000);
}

/// `--keep-radius R --save-dropped`: the blocks the bounded run drops are written as map
/// files under `dropped/` (listed in the manifest); with the bounded map they hold every
/// block the unbounded run allocates; `voxpan info` describes each. Without a radius the
/// option is refused by name.
#[test]
fn a_bounded_run_writes_the_blocks_it_drops() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    voxpan_ok(
        [
            "synth", "--world", "flat", "--frames", "40", "--width", "160", "--height", "120",
            "--out",
        ]
        .map(OsStr::new)
        .into_iter()
        .chain([d.join("world").as_os_str()]),
    );
    let run = |out: &str, extra: &[&str]| {
        let world = d.join("world");
        let out_dir = d.join(out);
        let mut args = vec![OsStr::new("run"), world.as_os_str(), OsStr::new("--out")];
        args.push(out_dir.as_os_str());
        args.extend(["--voxel-size", "0.05"].map(OsStr::new));
        args.extend(extra.iter().map(OsStr::new));
        voxpan_ok(args);
        voxpan_map::PanopticMap::load(&d.join(out).join("map.voxpan")).unwrap()
    };
    let unbounded = run("unbounded", &[]);
    let bounded = run("bounded", &["--keep-radius", "5", "--save-dropped"]);
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("bounded/manifest.json")).unwrap()).unwrap();
    let dropped: Vec<&str> = manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f.as_str())
        .filter(|f| f.starts_with("dropped/"))
        .collect();
    assert!(dropped.len() > 1, "{dropped:?}");
    let mut blocks: std::collections::HashSet<_> = bounded.block_indices().into_iter().collect();
    assert!(blocks.len() < unbounded.block_count());
    for name in &dropped {
        assert!(name.ends_with(".voxpan"), "{name}");
        let part = voxpan_map::PanopticMap::load(&d.join("bounded").join(name)).unwrap();
        assert_eq!(part.config(), bounded.config());
        blocks.extend(part.block_indices());
    }
    let missing = unbounded
        .block_indices()
        .into_iter()
        .filter(|b| !blocks.contains(b))
        .count();
    assert_eq!(
        missing,
        0,
        "{missing} of {} blocks in no file",
        unbounded.block_count()
    );

    // `voxpan info` describes a map file: the main map and a dropped part alike.
    let part = d.join("bounded").join(dropped[0]);
    for (path, map) in [
        (d.join("bounded/map.voxpan"), bounded),
        (part.clone(), voxpan_map::PanopticMap::load(&part).unwrap()),
    ] {
        let info = voxpan_ok([OsStr::new("info"), path.as_os_str()]);
        assert!(info.contains("voxpan map, version 4"), "{info}");
        assert!(
            info.contains(&format!(
                "blocks:    {} (512 voxels each",
                map.block_count()
            )),
            "{info}"
        );
        let instances = map.instances();
        assert!(
            info.contains(&format!("instances: {} shown", instances.len())),
            "{info}"
        );
        for i in &instances {
            let row = format!("{:>5}  {:<20}", i.id, i.class_name.clone().unwrap());
            assert!(info.contains(&row), "{row} not in {info}");
        }
    }
    // A damaged map is named as one, not as a bag.
    let mut bytes = std::fs::read(d.join("bounded/map.voxpan")).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0xff;
    std::fs::write(d.join("damaged.voxpan"), bytes).unwrap();
    let damaged = voxpan([OsStr::new("info"), d.join("damaged.voxpan").as_os_str()]);
    let err = String::from_utf8_lossy(&damaged.stderr);
    assert!(!damaged.status.success());
    assert!(
        err.contains("damaged.voxpan") && err.contains("checksum"),
        "{err}"
    );

    let refused = voxpan(
        [
            OsStr::new("run"),
            d.join("world").as_os_str(),
            OsStr::new("--save-dropped"),
        ]
        .into_iter()
        .chain([OsStr::new("--out"), d.join("refused").as_os_str()]),
    );
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("output.dropped_blocks") && err.contains("--keep-radius"),
        "{err}"
    );
    assert!(!d.join("refused/map.voxpan").exists());
}
