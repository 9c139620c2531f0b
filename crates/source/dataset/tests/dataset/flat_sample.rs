//! The real flat sample reads correctly, and broken frames are reported, not fatal.

use std::path::Path;
use std::sync::Arc;

use voxpan_core::{Annotations, is_valid_depth};
use voxpan_dataset::{FlatDataset, FrameSource, open_dataset, stream, stream_with};
use voxpan_test_support::require_flat_sample;

#[test]
fn reads_the_shared_sample() {
    let Some(flat) = require_flat_sample("reads_the_shared_sample") else {
        return;
    };
    let dataset = FlatDataset::open(&flat).unwrap();
    assert_eq!(dataset.len(), 100);
    assert!(dataset.skipped().is_empty());
    // timestamps.csv is unsorted; frames come out in time order, which here is id order.
    let ids: Vec<&str> = (0..dataset.len()).map(|i| dataset.frame_id(i)).collect();
    let mut sorted = ids.clone();
    sorted.sort();
    assert_eq!(ids, sorted);
    let k = dataset.intrinsics();
    assert_eq!(
        (k.width, k.height, k.fx, k.cx, k.cy),
        (640, 480, 320.0, 320.0, 240.0)
    );

    let network = dataset.network_classes.as_ref().unwrap();
    let truth = dataset.ground_truth_classes.as_ref().unwrap();
    for i in [0, 37, 99] {
        let frame = dataset.load(i).unwrap();
        let r = frame.pose.rotation.to_rotation_matrix();
        let orthonormality = (r.matrix().transpose() * r.matrix()
            - voxpan_core::nalgebra::Matrix3::identity())
        .abs()
        .max();
        assert!(orthonormality < 1e-9);
        let valid: Vec<f32> = frame
            .depth
            .pixels()
            .iter()
            .copied()
            .filter(|&d| is_valid_depth(d))
            .collect();
        assert!(
            valid.len() > 300_000,
            "frame {i}: {} valid depths",
            valid.len()
        );
        // AirSim writes ~13 km through windows; the bulk is indoor range.
        assert!(valid.iter().all(|&d| d >= 0.05));
        let mut sorted = valid.clone();
        sorted.sort_by(f32::total_cmp);
        assert!(
            (0.3..8.0).contains(&sorted[sorted.len() / 2]),
            "frame {i}: median depth"
        );
        let segments = frame.segments.unwrap();
        assert!(!segments.segments.is_empty());
        assert!(
            segments
                .segments
                .iter()
                .all(|s| network.get(s.class_id.unwrap()).is_some())
        );
        let gt = frame.ground_truth.unwrap();
        assert!(gt.pixels().iter().all(|&id| truth.get(id as u32).is_some()));
    }
    // The camera moves between the first and the last frame.
    let (a, b) = (dataset.load(0).unwrap(), dataset.load(99).unwrap());
    assert!((a.pose.translation.vector - b.pose.translation.vector).norm() > 0.1);
}

#[test]
fn a_stream_delivers_the_selected_frames_in_order_and_names_failures() {
    let Some(flat) = require_flat_sample("a_stream_delivers_the_selected_frames_in_order") else {
        return;
    };
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(&flat).unwrap());
    let got: Vec<String> = stream(source, vec![5, 2, 9, 3])
        .map(|f| f.unwrap().id)
        .collect();
    assert_eq!(got, ["000010", "000004", "000018", "000006"]);
    // A frame whose depth file is corrupt is an error item naming frame and file; the stream
    // goes on.
    let dir = tempfile::tempdir().unwrap();
    copy_frames(&flat, dir.path(), &["000000", "000002"]);
    std::fs::write(dir.path().join("run1/000000_depth.tiff"), b"garbage").unwrap();
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(dir.path()).unwrap());
    let items: Vec<_> = stream(source, vec![0, 1]).collect();
    let err = items[0].as_ref().unwrap_err();
    assert_eq!(err.frame, "000000");
    assert!(err.to_string().contains("000000_depth.tiff"), "{err}");
    assert_eq!(items[1].as_ref().unwrap().id, "000002");
}

fn copy_frames(flat: &Path, to: &Path, ids: &[&str]) {
    std::fs::create_dir_all(to.join("run1")).unwrap();
    for f in [
        "Intrinsics.txt",
        "detectron_labels.csv",
        "groundtruth_labels.csv",
    ] {
        std::fs::copy(flat.join(f), to.join(f)).unwrap();
    }
    for id in ids {
        for s in [
            "color.png",
            "depth.tiff",
            "pose.txt",
            "predicted.png",
            "labels.json",
            "segmentation.png",
        ] {
            let name = format!("{id}_{s}");
            std::fs::copy(flat.join("run1").join(&name), to.join("run1").join(&name)).unwrap();
        }
    }
}

#[test]
fn missing_and_broken_files_are_reported_with_their_names() {
    let Some(flat) = require_flat_sample("missing_and_broken_files_are_reported_with_their_names")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    copy_frames(&flat, dir.path(), &["000000", "000002", "000004"]);
    let run = dir.path().join("run1");
    std::fs::remove_file(run.join("000002_depth.tiff")).unwrap();
    std::fs::write(run.join("000004_pose.txt"), "1 0 0\n0 1 0\n").unwrap();

    // No timestamps.csv here: frames come from the depth files, at 30 Hz.
    let dataset = FlatDataset::open(dir.path()).unwrap();
    assert_eq!(dataset.len(), 2);
    assert_eq!(
        dataset.skipped().len(),
        0,
        "a missing depth file means no frame at all"
    );
    std::fs::write(
        run.join("timestamps.csv"),
        "ImageID,TimeStamp\n000004,300\n000002,200\n000000,100\n",
    )
    .unwrap();
    let dataset = FlatDataset::open(&run).unwrap();
    assert_eq!(dataset.len(), 2);
    assert_eq!(
        dataset.skipped(),
        &[("000002".to_owned(), "missing 000002_depth.tiff".to_owned())]
    );
    assert!(dataset.load(0).is_ok());
    let err = dataset.load(1).unwrap_err().to_string();
    assert!(
        err.contains("frame 000004") && err.contains("000004_pose.txt") && err.contains("4x4"),
        "{err}"
    );

    // An unknown network category.
    std::fs::write(
        run.join("000000_labels.json"),
        r#"[{"id": 1, "isthing": true, "category_id": 999}]"#,
    )
    .unwrap();
    let err = dataset.load(0).unwrap_err().to_string();
    assert!(
        err.contains("000000_labels.json") && err.contains("unknown label id 999"),
        "{err}"
    );
}

#[test]
fn annotations_left_out_are_not_decoded() {
    let Some(flat) = require_flat_sample("annotations_left_out_are_not_decoded") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    copy_frames(&flat, dir.path(), &["000000", "000002"]);
    let run = dir.path().join("run1");
    let dataset = Arc::new(FlatDataset::open(&run).unwrap());
    let full = dataset.load(0).unwrap();
    assert!(full.segments.is_some() && full.ground_truth.is_some());
    let masks_only = Annotations {
        segments: true,
        ground_truth: false,
    };
    let frame = dataset.load_with(0, masks_only).unwrap();
    assert_eq!(frame.ground_truth, None);
    assert_eq!(frame.segments, full.segments);
    assert_eq!((&frame.color, &frame.depth), (&full.color, &full.depth));
    let frame = dataset.load_with(0, Annotations::NONE).unwrap();
    assert_eq!((frame.segments, frame.ground_truth), (None, None));
    assert_eq!(dataset.load_with(0, Annotations::ALL).unwrap(), full);

    // A broken ground-truth file: an error only for readers that want it.
    std::fs::write(run.join("000002_segmentation.png"), "not a png").unwrap();
    let source: Arc<dyn FrameSource> = dataset.clone();
    let frames: Vec<_> = stream_with(source.clone(), vec![0, 1], masks_only).collect();
    assert!(frames.iter().all(Result::is_ok));
    let err = stream(source, vec![1])
        .next()
        .unwrap()
        .unwrap_err()
        .to_string();
    assert!(err.contains("000002_segmentation.png"), "{err}");
}

#[test]
fn a_run_without_usable_frames_is_an_error() {
    let Some(flat) = require_flat_sample("a_run_without_usable_frames_is_an_error") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    copy_frames(&flat, dir.path(), &["000000"]);
    std::fs::remove_file(dir.path().join("run1/000000_color.png")).unwrap();
    std::fs::write(
        dir.path().join("run1/timestamps.csv"),
        "ImageID,TimeStamp\n000000,1\n",
    )
    .unwrap();
    let err = FlatDataset::open(dir.path()).err().unwrap().to_string();
    assert!(err.contains("no usable frame"), "{err}");
}

/// The silent-wrong-data cases of the robustness issue: each is an error naming the file.
#[test]
fn inputs_that_would_map_wrong_data_are_refused_by_name() {
    let Some(flat) = require_flat_sample("inputs_that_would_map_wrong_data_are_refused_by_name")
    else {
        return;
    };
    let missing = tempfile::tempdir().unwrap();
    let err = voxpan_dataset::open_dataset(&missing.path().join("nowhere"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("nowhere") && err.contains("does not exist"),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    copy_frames(&flat, dir.path(), &["000000"]);
    let run = dir.path().join("run1");
    let dataset = FlatDataset::open(dir.path()).unwrap();

    // A label image holding an id its labels.json does not list.
    let good_labels = std::fs::read_to_string(run.join("000000_labels.json")).unwrap();
    std::fs::write(
        run.join("000000_labels.json"),
        r#"[{"id": 1, "isthing": false, "category_id": 8}]"#,
    )
    .unwrap();
    let err = dataset.load(0).unwrap_err().to_string();
    assert!(
        err.contains("000000_labels.json") && err.contains("does not describe segment id"),
        "{err}"
    );
    std::fs::write(run.join("000000_labels.json"), good_labels).unwrap();

    // A pose with a NaN says where.
    let good_pose = std::fs::read_to_string(run.join("000000_pose.txt")).unwrap();
    std::fs::write(
        run.join("000000_pose.txt"),
        good_pose.replacen("1.000000", "nan", 1),
    )
    .unwrap();
    let err = dataset.load(0).unwrap_err().to_string();
    assert!(
        err.contains("000000_pose.txt") && err.to_lowercase().contains("nan"),
        "{err}"
    );
    std::fs::write(run.join("000000_pose.txt"), good_pose).unwrap();
    assert!(dataset.load(0).is_ok());

    // A zero focal length.
    let intrinsics = std::fs::read_to_string(dir.path().join("Intrinsics.txt")).unwrap();
    std::fs::write(
        dir.path().join("Intrinsics.txt"),
        intrinsics.replace("f_x: 320", "f_x: 0"),
    )
    .unwrap();
    let err = FlatDataset::open(dir.path()).err().unwrap().to_string();
    assert!(err.contains("Intrinsics.txt") && err.contains("f"), "{err}");
}
