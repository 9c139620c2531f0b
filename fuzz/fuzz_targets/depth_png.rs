//! 16-bit PNG depth decoding.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = voxpan_io::decode_depth_png(data, 1000.0, std::path::Path::new("fuzz.png"));
});
