//! Label PNG decoding (grey, palette, 1 to 16 bits, several channels).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = voxpan_io::decode_label_png(data, std::path::Path::new("fuzz.png"));
});
