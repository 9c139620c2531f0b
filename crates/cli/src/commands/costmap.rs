use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use voxpan_map::{PanopticMap, UpAxis};
use voxpan_pipeline::write_costmap;

#[derive(clap::Args)]
pub struct Args {
    /// A map written by voxpan (map.voxpan).
    map: PathBuf,
    /// Folder to write `costmap.pgm` and `costmap.yaml` into (ROS map_server's format);
    /// created if missing.
    #[arg(long)]
    out: PathBuf,
    /// Obstacles are the surfaces between these heights, metres along the up axis (defaults:
    /// the map's `[esdf] slice_min_z` and `slice_max_z`).
    #[arg(long, allow_hyphen_values = true)]
    min_z: Option<f64>,
    #[arg(long, allow_hyphen_values = true)]
    max_z: Option<f64>,
    /// The world axis pointing up: x, y, z, -x, -y or -z (default: the map's, else z).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_up)]
    up: Option<UpAxis>,
    /// Inflate obstacles by this radius, metres (default: the map's `[esdf] robot_radius`).
    #[arg(long)]
    robot_radius: Option<f64>,
}

fn parse_up(text: &str) -> Result<UpAxis, String> {
    toml::Value::String(text.to_owned())
        .try_into()
        .map_err(|_| format!("expected x, y, z, -x, -y or -z, not {text:?}"))
}

pub fn run(args: Args) -> Result<()> {
    crate::paths::refuse_file_as_folder("--out", &args.out)?;
    for name in ["costmap.pgm", "costmap.yaml"] {
        crate::paths::refuse_overwriting("--out", &args.out.join(name), &[&args.map])?;
    }
    let mut map = PanopticMap::load(&args.map)?;
    let mut esdf = map.config().esdf;
    esdf.slice_min_z = args.min_z.unwrap_or(esdf.slice_min_z);
    esdf.slice_max_z = args.max_z.unwrap_or(esdf.slice_max_z);
    esdf.up_axis = args.up.unwrap_or(esdf.up_axis);
    esdf.robot_radius = args.robot_radius.unwrap_or(esdf.robot_radius);
    map.set_esdf_config(esdf)
        .map_err(|e| anyhow::anyhow!("{e}").context("bad --min-z, --max-z or --robot-radius"))?;
    if !map.config().esdf.enabled {
        eprintln!(
            "warning: {} was built without [esdf] enabled: free space is known only around \
             surfaces, so most of the costmap reads unknown",
            args.map.display()
        );
    }
    let t = Instant::now();
    let stats = map.update_esdf();
    let esdf_ms = t.elapsed().as_secs_f64() * 1e3;
    let Some(costmap) = map.costmap() else {
        bail!(
            "{}: no observed voxel lies between heights {} and {} m along {:?}; \
             choose --min-z and --max-z (and --up) where the map has surfaces",
            args.map.display(),
            esdf.slice_min_z,
            esdf.slice_max_z,
            esdf.up_axis
        );
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let (pgm, yaml) = (args.out.join("costmap.pgm"), args.out.join("costmap.yaml"));
    write_costmap(&costmap, &pgm, &yaml)?;
    let (unknown, free, occupied) = costmap.counts();
    println!(
        "{}: {} x {} cells of {} m ({occupied} occupied, {free} free, {unknown} unknown); \
         distance field of {} blocks built in {esdf_ms:.0} ms",
        yaml.display(),
        costmap.width,
        costmap.height,
        costmap.resolution,
        stats.changed_blocks,
    );
    Ok(())
}
