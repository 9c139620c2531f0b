//! Map files (`.voxpan`, versions 2 and 3): any bytes load or fail with an error; a map that
//! loads saves and loads back equal.
#![no_main]
use libfuzzer_sys::fuzz_target;
use voxpan_map::PanopticMap;

fuzz_target!(|data: &[u8]| {
    let name = std::path::Path::new("fuzz.voxpan");
    if let Ok(map) = PanopticMap::from_bytes(data, name) {
        let again = PanopticMap::from_bytes(&map.to_bytes(), name).expect("own bytes load");
        assert!(again == map);
    }
});
