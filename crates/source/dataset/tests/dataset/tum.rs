//! TUM RGB-D layout: association by timestamp, depth scale, poses.

use voxpan_dataset::{TumDataset, open_dataset};

fn write_png16(path: &std::path::Path, value: u16) {
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, vec![value; 12])
        .unwrap()
        .save(path)
        .unwrap();
}

#[test]
fn associates_depth_colour_and_pose() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("rgbd_dataset_freiburg1_xyz");
    std::fs::create_dir_all(root.join("rgb")).unwrap();
    std::fs::create_dir_all(root.join("depth")).unwrap();
    let mut rgb = String::from("# color images\n# file: 'x.bag'\n# timestamp filename\n");
    let mut depth = String::from("# depth maps\n");
    for (i, t) in [10.0, 10.033, 10.5].iter().enumerate() {
        let d = format!("depth/{t:.6}.png");
        write_png16(&root.join(&d), 5000 * (i as u16 + 1));
        depth += &format!("{t:.6} {d}\n");
        if i < 2 {
            // colour 5 ms later; none for the last depth image
            let c = format!("rgb/{:.6}.png", t + 0.005);
            image::RgbImage::from_raw(4, 3, vec![i as u8; 36])
                .unwrap()
                .save(root.join(&c))
                .unwrap();
            rgb += &format!("{:.6} {c}\n", t + 0.005);
        }
    }
    std::fs::write(root.join("rgb.txt"), rgb).unwrap();
    std::fs::write(root.join("depth.txt"), depth).unwrap();
    let mut gt = String::from("# ground truth trajectory\n");
    for k in 0..100 {
        let t = 9.9 + k as f64 * 0.01;
        // 90° about z: q = (0, 0, sin 45°, cos 45°)
        gt += &format!(
            "{t:.4} {} 2 3 0 0 0.7071067811865476 0.7071067811865476\n",
            k as f64 * 0.01
        );
    }
    std::fs::write(root.join("groundtruth.txt"), gt).unwrap();

    let dataset = open_dataset(&root).unwrap();
    assert_eq!(dataset.kind(), "tum");
    assert_eq!(dataset.len(), 2);
    assert_eq!(dataset.skipped().len(), 1);
    assert!(dataset.skipped()[0].1.contains("colour"));
    let f = dataset.load(1).unwrap();
    assert_eq!(f.id, "10.033000");
    assert_eq!(f.depth.pixels()[0], 2.0);
    assert_eq!(f.color.pixels()[0], [1, 1, 1]);
    // Nearest pose to 10.033 is the one at 10.03 (x = 0.13).
    assert!((f.pose.translation.vector.x - 0.13).abs() < 1e-9);
    let x_axis = f.pose.rotation * voxpan_core::nalgebra::Vector3::x();
    assert!((x_axis.y - 1.0).abs() < 1e-9);
    // freiburg1 calibration, image size from the files.
    assert_eq!((f.intrinsics.fx, f.intrinsics.width), (517.3, 4));
    assert!(TumDataset::looks_like(&root));
}

#[test]
fn malformed_lists_name_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("rgb.txt"), "1.0 rgb/a.png\n").unwrap();
    std::fs::write(dir.path().join("depth.txt"), "1.0\n").unwrap();
    std::fs::write(dir.path().join("groundtruth.txt"), "").unwrap();
    let err = TumDataset::open(dir.path()).err().unwrap().to_string();
    assert!(err.contains("depth.txt") && err.contains("line 1"), "{err}");
}

#[test]
fn a_zero_quaternion_is_no_rotation() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("depth")).unwrap();
    std::fs::create_dir_all(dir.path().join("rgb")).unwrap();
    write_png16(&dir.path().join("depth/1.0.png"), 5000);
    std::fs::write(dir.path().join("depth.txt"), "1.0 depth/1.0.png\n").unwrap();
    std::fs::write(dir.path().join("rgb.txt"), "1.0 rgb/1.0.png\n").unwrap();
    std::fs::write(dir.path().join("groundtruth.txt"), "1.0 0 0 0 0 0 0 0\n").unwrap();
    let err = TumDataset::open(dir.path()).err().unwrap().to_string();
    assert!(
        err.contains("groundtruth.txt") && err.contains("quaternion") && err.contains("length 0"),
        "{err}"
    );
}
