//! Times the distance field on a flat-format dataset: per frame (incremental, after each
//! integration) and once from scratch, with what each update did.
//!
//! `cargo run --release -p voxpan-map --example esdf_flat -- [VOXEL_SIZE] [DATASET]`
//! (defaults: 0.05, the shared flat sample).

use std::path::PathBuf;
use std::time::Instant;

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_map::{MapConfig, PanopticMap};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let voxel: f64 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(0.05);
    let dataset = FlatDataset::open(
        &args
            .next()
            .map(PathBuf::from)
            .or_else(voxpan_io::flat_sample_dir)
            .ok_or("no dataset")?,
    )?;
    let mut config = MapConfig::default();
    config.tsdf.voxel_size = voxel;
    config.esdf.enabled = true;
    let mut map = PanopticMap::new(config)?;
    let (mut integrate, mut esdf) = (Vec::new(), Vec::new());
    let mut totals = voxpan_map::EsdfStats::default();
    for i in 0..dataset.len() {
        let frame = dataset.load(i)?;
        let t = Instant::now();
        map.integrate(frame.view(), None)?;
        integrate.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let s = map.update_esdf();
        esdf.push(t.elapsed().as_secs_f64() * 1e3);
        totals.changed_blocks += s.changed_blocks;
        totals.marked_blocks += s.marked_blocks;
        totals.raised_voxels += s.raised_voxels;
        totals.relaxed_blocks += s.relaxed_blocks;
        totals.rounds += s.rounds;
        totals.sites_added += s.sites_added;
        totals.sites_removed += s.sites_removed;
        totals.mark_ms += s.mark_ms;
        totals.raise_ms += s.raise_ms;
        totals.lower_ms += s.lower_ms;
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{} frames at {voxel} m: integrate {:.2} ms, esdf {:.2} ms (medians); {} blocks",
        dataset.len(),
        median(integrate),
        median(esdf),
        map.block_count()
    );
    println!("per-frame totals: {totals:?}");
    let mut fresh = PanopticMap::from_bytes(&map.to_bytes(), "memory".as_ref())?;
    let t = Instant::now();
    let s = fresh.update_esdf();
    println!(
        "from scratch: {:.0} ms, {s:?}",
        t.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}
