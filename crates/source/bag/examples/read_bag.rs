//! Opens a bag as voxpan maps it and decodes every frame, timing both:
//! `cargo run --release -p voxpan-bag --example read_bag -- BAG`.

use std::time::Instant;

use voxpan_bag::{BagDataset, BagOptions};
use voxpan_dataset::FrameSource;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: read_bag BAG")?;
    let t = Instant::now();
    let bag = BagDataset::open(path.as_ref(), BagOptions::default())?;
    let open = t.elapsed().as_secs_f64();
    let t = Instant::now();
    for i in 0..bag.len() {
        bag.load(i)?;
    }
    let per_frame = t.elapsed().as_secs_f64() / bag.len().max(1) as f64;
    println!(
        "{path}: {} frames ({} skipped); open {:.0} ms, {:.1} ms per frame",
        bag.len(),
        bag.skipped().len(),
        open * 1e3,
        per_frame * 1e3
    );
    Ok(())
}
