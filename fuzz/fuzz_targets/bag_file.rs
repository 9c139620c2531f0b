//! Bag files from anywhere (ROS 1 `.bag`, MCAP, ROS 2 SQLite `.db3`): any bytes are
//! summarised (`voxpan info`) and opened for mapping (`voxpan run`), or refused with an error;
//! a bag that opens loads its first frame or says why not.
#![no_main]
use libfuzzer_sys::fuzz_target;
use voxpan_bag::{BagDataset, BagOptions, summarize};
use voxpan_dataset::FrameSource;

fuzz_target!(|data: &[u8]| {
    // The readers map files: the input goes to a file of this process's own, in memory.
    let dir = std::env::temp_dir();
    let path = dir.join(format!("voxpan-fuzz-{}.bag", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let _ = summarize(&path);
    if let Ok(bag) = BagDataset::open(&path, BagOptions::default()) {
        if !bag.is_empty() {
            let _ = bag.load(0);
        }
    }
});
