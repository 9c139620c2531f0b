use std::path::PathBuf;

use anyhow::{Context, Result};
use voxpan_map::{Coloring, PanopticMap};
use voxpan_pipeline::instance_file_name;

#[derive(clap::Args)]
pub struct Args {
    /// A map written by voxpan (map.voxpan).
    map: PathBuf,
    /// Vertex colours: rgb, instance or class.
    #[arg(long, default_value = "rgb")]
    by: Coloring,
    /// Output PLY (binary).
    #[arg(long)]
    out: PathBuf,
    /// Also write one PLY per instance, as `NNNN_<class>.ply`, into this folder.
    #[arg(long)]
    instances: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    crate::paths::refuse_overwriting("--out", &args.out, &[&args.map])?;
    if let Some(dir) = &args.instances {
        crate::paths::refuse_file_as_folder("--instances", dir)?;
    }
    let mut map = PanopticMap::load(&args.map)?;
    let mesh = map.mesh(args.by);
    voxpan_io::write_ply(&args.out, &mesh, "voxpan TSDF mesh")?;
    println!(
        "{}: {} triangles, {} vertices from {} blocks, {} instances",
        args.out.display(),
        mesh.triangles.len(),
        mesh.vertices.len(),
        map.block_count(),
        map.instance_count()
    );
    if let Some(dir) = args.instances {
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        for (id, part) in mesh.split_by_instance() {
            let path = dir.join(instance_file_name(&map, id));
            voxpan_io::write_ply(&path, &part, "voxpan instance")?;
        }
    }
    Ok(())
}
