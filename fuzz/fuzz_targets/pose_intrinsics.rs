//! Flat-dataset poses (`_pose.txt`) and `Intrinsics.txt`: the same text through both.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let path = std::path::Path::new("fuzz.txt");
        let _ = voxpan_dataset::flat::parse_pose(text, path);
        if let Ok(k) = voxpan_dataset::flat::parse_intrinsics(text, path) {
            // Accepted intrinsics are usable: projection of the image centre is finite.
            assert!(k.check().is_ok());
        }
    }
});
