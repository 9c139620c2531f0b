//! `voxpan info MAP.voxpan`: what a saved map holds.

use std::path::Path;

use anyhow::{Context, Result};
use voxpan_map::{PanopticMap, human_bytes};

/// Prints the map file's format, voxels, blocks, extent and instances.
pub fn describe(path: &Path, version: u32) -> Result<()> {
    let map = PanopticMap::load(path).with_context(|| format!("reading {}", path.display()))?;
    let config = map.config();
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    println!("path:      {}", path.display());
    println!(
        "format:    voxpan map, version {version} ({})",
        human_bytes(bytes)
    );
    println!(
        "voxels:    {} m, truncation {} voxels",
        map.voxel_size(),
        config.tsdf.truncation_voxels
    );
    println!(
        "blocks:    {} ({} voxels each; {} in memory{})",
        map.block_count(),
        voxpan_map::BLOCK_SIDE.pow(3),
        human_bytes(map.memory_bytes()),
        if config.esdf.enabled {
            ", distance field on"
        } else {
            ""
        }
    );
    let indices = map.block_indices();
    if let Some(first) = indices.first() {
        let block = map.voxel_size() * voxpan_map::BLOCK_SIDE as f64;
        let (mut lo, mut hi) = (*first, *first);
        for b in &indices {
            for a in 0..3 {
                lo[a] = lo[a].min(b[a]);
                hi[a] = hi[a].max(b[a]);
            }
        }
        let span = |a: usize| {
            format!(
                "{:.2} .. {:.2}",
                lo[a] as f64 * block,
                (hi[a] + 1) as f64 * block
            )
        };
        println!("extent:    x {}, y {}, z {} m", span(0), span(1), span(2));
    }
    let instances = map.instances();
    let things = instances.iter().filter(|i| i.is_thing).count();
    println!(
        "instances: {} shown ({things} things, {} stuff)",
        instances.len(),
        instances.len() - things
    );
    if !instances.is_empty() {
        println!(
            "  {:>5}  {:<20}  {:<5}  {:>8}  {:>6}  size (m)",
            "id", "class", "kind", "voxels", "frames"
        );
    }
    for i in &instances {
        let class = match (&i.class_name, i.class_id) {
            (Some(name), _) => name.clone(),
            (None, Some(id)) => format!("class {id}"),
            (None, None) => "-".into(),
        };
        let size = i.bounds.map_or("-".into(), |b| {
            format!(
                "{:.2} x {:.2} x {:.2}",
                b.max[0] - b.min[0],
                b.max[1] - b.min[1],
                b.max[2] - b.min[2]
            )
        });
        println!(
            "  {:>5}  {:<20}  {:<5}  {:>8}  {:>6}  {size}",
            i.id,
            class,
            if i.is_thing { "thing" } else { "stuff" },
            i.voxels,
            i.frames_seen
        );
    }
    Ok(())
}
