//! Maps a flat-format dataset through `PanopticMap`, the way a robot program would: frames in,
//! masks refined, map updated, mesh and map file out.
//!
//! `cargo run --release -p voxpan-map --example map_flat -- [DATASET] [OUT_DIR]`
//! (default: the shared flat sample, `voxpan-out/example`).

use std::error::Error;
use std::path::PathBuf;

use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_map::{Coloring, MapConfig, PanopticMap};
use voxpan_perception::{DatasetMasks, Perception, PerceptionConfig};

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1).map(PathBuf::from);
    let dataset = args
        .next()
        .or_else(voxpan_io::flat_sample_dir)
        .ok_or("no dataset given")?;
    let out = args.next().unwrap_or_else(|| "voxpan-out/example".into());
    let frames = FlatDataset::open(&dataset)?;
    let mut perception = Perception::new(PerceptionConfig::default(), Box::new(DatasetMasks))?;
    let mut map = PanopticMap::new(MapConfig::default())?;
    for i in 0..frames.len() {
        // Segment (here: the dataset's masks), refine them on measured depth, fill holes.
        let perceived = perception.process(frames.load(i)?)?;
        // Associate the segments with map instances and fuse depth, colour and instances.
        let report = map.integrate(&perceived.frame, perceived.segments.as_ref())?;
        if i % 20 == 0 {
            println!("frame {}: {:?}", perceived.frame.id, report.association);
        }
    }
    std::fs::create_dir_all(&out)?;
    voxpan_io::write_ply(
        &out.join("mesh.ply"),
        &map.mesh(Coloring::Instance),
        "example",
    )?;
    map.save(&out.join("map.voxpan"))?;
    for instance in map.instances().iter().filter(|i| i.voxels > 2000) {
        println!(
            "instance {} (class {:?}): {} voxels",
            instance.id, instance.class_id, instance.voxels
        );
    }
    println!(
        "{} instances; wrote {}",
        map.instance_count(),
        out.display()
    );
    Ok(())
}
