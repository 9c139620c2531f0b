//! Maps a flat-format dataset through `PanopticMap`, the way a robot program would: frames in,
//! masks refined, map updated, mesh and map file out.
//!
//! `cargo run --release -p voxpan-map --example map_flat -- [DATASET] [OUT_DIR]`
//! (default: the shared flat sample, `voxpan-out/example`).

use std::path::PathBuf;

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_map::{Coloring, MapConfig, PanopticMap};
use voxpan_perception::{DatasetMasks, Perception, PerceptionConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1).map(PathBuf::from);
    let dataset = FlatDataset::open(
        &args
            .next()
            .or_else(voxpan_io::flat_sample_dir)
            .ok_or("no dataset")?,
    )?;
    let out = args.next().unwrap_or_else(|| "voxpan-out/example".into());
    let mut perception = Perception::new(PerceptionConfig::default(), Box::new(DatasetMasks))?;
    let mut map = PanopticMap::new(MapConfig::default())?;
    map.set_class_names(
        dataset
            .network_classes()
            .map(|t| t.names())
            .unwrap_or_default(),
    );
    for i in 0..dataset.len() {
        // Segment (here: the dataset's masks), refine on measured depth, fill depth holes.
        let perceived = perception.process(dataset.load(i)?)?;
        // Match the segments with map instances; fuse depth, colour and instances.
        map.integrate(perceived.frame.view(), perceived.segments.as_ref())?;
    }
    std::fs::create_dir_all(&out)?;
    voxpan_io::write_ply(
        &out.join("mesh.ply"),
        &map.mesh(Coloring::Instance),
        "example",
    )?;
    map.save(&out.join("map.voxpan"))?;
    for i in map.instances().iter().filter(|i| i.voxels > 20_000) {
        println!(
            "instance {:>3} {:<12} {:>6} voxels",
            i.id,
            i.class_name.as_deref().unwrap_or("?"),
            i.voxels
        );
    }
    println!(
        "{} instances; wrote {}",
        map.instance_count(),
        out.display()
    );
    Ok(())
}
