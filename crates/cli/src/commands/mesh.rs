use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::ValueEnum;
use voxpan_map::{id_color, io, MeshLayer};

#[derive(clap::Args)]
pub struct Args {
    /// A map written by voxpan (map.voxpan).
    map: PathBuf,
    /// Vertex colours.
    #[arg(long, value_enum, default_value_t = Coloring::Rgb)]
    by: Coloring,
    /// Output PLY (binary).
    #[arg(long)]
    out: PathBuf,
    /// Also write one PLY per instance, as `<id>_<class>.ply`, into this folder.
    #[arg(long)]
    instances: Option<PathBuf>,
}

#[derive(Clone, Copy, ValueEnum)]
enum Coloring {
    Rgb,
    Instance,
    Class,
}

pub fn run(args: Args) -> Result<()> {
    let mut map = io::load(&args.map)?;
    let mut meshes = MeshLayer::default();
    map.layer.blocks.values_mut().for_each(|b| b.updated = true);
    meshes.update(&mut map.layer);
    let mesh = meshes.combined();
    let class_of = |id: u16| map.instances.get(&id).and_then(|i| i.class());
    let colored = match args.by {
        Coloring::Rgb => mesh.clone(),
        Coloring::Instance => mesh.colored_by(|id| id_color(id as u32)),
        Coloring::Class => mesh.colored_by(|id| id_color(class_of(id).map_or(0, |c| c + 1))),
    };
    colored
        .write_ply(&args.out)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    println!(
        "{}: {} triangles from {} blocks, {} instances",
        args.out.display(),
        colored.triangles(),
        map.layer.blocks.len(),
        map.instances.len()
    );
    if let Some(dir) = args.instances {
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        for (id, part) in mesh.split_by_instance() {
            let class = class_of(id).map_or_else(|| "unknown".to_owned(), |c| c.to_string());
            let path = dir.join(format!("{id}_{class}.ply"));
            part.write_ply(&path)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    Ok(())
}
