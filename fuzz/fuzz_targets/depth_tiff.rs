//! Depth TIFF decoding: any bytes give an image or an error, never a panic or a huge
//! allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = voxpan_io::decode_depth_tiff(data, std::path::Path::new("fuzz.tiff"));
});
