//! `NNNNNN_labels.json` segment lists.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = voxpan_io::parse_segments_json(text, std::path::Path::new("fuzz.json"));
    }
});
