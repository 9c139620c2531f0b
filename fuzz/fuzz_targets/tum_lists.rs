//! TUM RGB-D lists (`rgb.txt`, `depth.txt`) and trajectories (`groundtruth.txt`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let path = std::path::Path::new("fuzz.txt");
        let _ = voxpan_dataset::tum::parse_list(text, path, 1);
        if let Ok(poses) = voxpan_dataset::tum::parse_trajectory(text, path) {
            for (t, pose) in poses {
                assert!(t.is_finite());
                assert!(pose.translation.vector.iter().all(|v| v.is_finite()));
            }
        }
    }
});
