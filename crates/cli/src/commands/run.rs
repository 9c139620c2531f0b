use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use voxpan_dataset::{open_dataset, FrameSource};
use voxpan_pipeline::{run as run_pipeline, Refinement, RunConfig, SegmentSource};
use voxpan_sim::{generate, SynthConfig};

use super::frames::FrameRange;

#[derive(clap::Args)]
pub struct Args {
    /// Dataset folder (flat or TUM RGB-D). Without it, the built-in synthetic world (60 frames
    /// of 320x240) is generated into OUT/synthetic and mapped.
    dataset: Option<PathBuf>,
    /// Output folder: map.voxpan, mesh_rgb.ply, mesh_instance.ply, mesh_class.ply,
    /// instances/, metrics.json, config.toml (and refined/ with --save-refined).
    #[arg(long, default_value = "voxpan-out")]
    out: PathBuf,
    /// TOML file with any of: voxel_size, truncation_voxels, max_range, refine, things_only,
    /// segments, save_refined. Options given on the command line override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Voxel size in metres [default: 0.02].
    #[arg(long)]
    voxel_size: Option<f64>,
    /// Truncation distance in voxels [default: 3].
    #[arg(long)]
    truncation: Option<f64>,
    /// Depth beyond this (metres) is not integrated [default: 5].
    #[arg(long)]
    max_range: Option<f64>,
    /// Frame ids START:END[:STEP] (inclusive).
    #[arg(long)]
    frames: Option<FrameRange>,
    /// Mask refinement rule [default: default].
    #[arg(long, value_enum)]
    refine: Option<RefineArg>,
    /// Refine only thing segments.
    #[arg(long)]
    things_only: bool,
    /// Map the network's segments or the ground truth [default: predicted].
    #[arg(long, value_enum)]
    segments: Option<SegmentsArg>,
    /// Write the refined label images as refined/NNNNNN.png.
    #[arg(long)]
    save_refined: bool,
    /// Worker threads for integration and meshing [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum RefineArg {
    None,
    Paper,
    Release,
    Default,
}

#[derive(Clone, Copy, ValueEnum)]
enum SegmentsArg {
    Predicted,
    Gt,
}

impl From<RefineArg> for Refinement {
    fn from(r: RefineArg) -> Self {
        match r {
            RefineArg::None => Refinement::None,
            RefineArg::Paper => Refinement::Paper,
            RefineArg::Release => Refinement::Release,
            RefineArg::Default => Refinement::Default,
        }
    }
}

/// The configuration file (or the defaults) with the command line's options on top.
fn effective_config(args: &Args) -> Result<RunConfig> {
    let mut config = match &args.config {
        Some(path) => RunConfig::from_toml_file(path)?,
        None => RunConfig::default(),
    };
    if let Some(v) = args.voxel_size {
        config.voxel_size = v;
    }
    if let Some(v) = args.truncation {
        config.truncation_voxels = v;
    }
    if let Some(v) = args.max_range {
        config.max_range = v;
    }
    if let Some(r) = args.refine {
        config.refine = r.into();
    }
    config.things_only |= args.things_only;
    if let Some(s) = args.segments {
        config.segments = match s {
            SegmentsArg::Predicted => SegmentSource::Predicted,
            SegmentsArg::Gt => SegmentSource::Gt,
        };
    }
    config.save_refined |= args.save_refined;
    if !(config.voxel_size > 0.0 && config.truncation_voxels > 0.0 && config.max_range > 0.0) {
        bail!("voxel size, truncation and max range must be positive");
    }
    Ok(config)
}

/// Sets the worker pool size (once per process).
pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot size the worker pool")?;
    }
    Ok(())
}

/// The dataset to map: the given folder, or the built-in synthetic world generated into `dir`.
pub fn dataset_or_synthetic(dataset: Option<&PathBuf>, dir: &std::path::Path) -> Result<PathBuf> {
    match dataset {
        Some(d) => Ok(d.clone()),
        None => {
            eprintln!(
                "no dataset given: generating the built-in synthetic world into {}",
                dir.display()
            );
            let config = SynthConfig {
                frames: 60,
                width: 320,
                height: 240,
                ..SynthConfig::default()
            };
            generate(dir, &config, |_| {})
                .with_context(|| format!("generating {}", dir.display()))?;
            Ok(dir.to_owned())
        }
    }
}

/// The selected frame indices of a dataset.
pub fn select(source: &dyn FrameSource, frames: Option<FrameRange>) -> Vec<usize> {
    (0..source.len())
        .filter(|&i| frames.is_none_or(|r| r.contains(source.frame_id(i))))
        .collect()
}

pub fn run(args: Args) -> Result<()> {
    set_threads(args.threads)?;
    let config = effective_config(&args)?;
    let dataset = dataset_or_synthetic(args.dataset.as_ref(), &args.out.join("synthetic"))?;
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(&dataset)?);
    let mut config = config;
    // The synthetic world ships its ground-truth mesh: score the map against it.
    config.ground_truth_mesh = Some(dataset.join("groundtruth_mesh.ply")).filter(|p| p.is_file());
    let indices = select(source.as_ref(), args.frames);
    if indices.is_empty() {
        bail!("no frame of {} in the selected range", dataset.display());
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // Failing to install the handler only loses clean Ctrl-C handling.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let bar = ProgressBar::new(indices.len() as u64).with_style(
        ProgressStyle::with_template("mapping [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta}")
            .expect("static template"),
    );
    let report = run_pipeline(source, indices, &config, &args.out, &stop, |_| bar.inc(1))?;
    bar.finish_and_clear();
    for (id, why) in &report.skipped {
        eprintln!("warning: frame {id} skipped: {why}");
    }
    if report.stopped_early {
        eprintln!("stopped early: wrote what was built");
    }
    println!(
        "{} frames at {:.1} frames/s; {} instances, {} blocks, {} triangles; outputs in {}",
        report.frames,
        report.fps,
        report.instances,
        report.blocks,
        report.triangles,
        args.out.display()
    );
    let stages: Vec<String> = report
        .stage_ms
        .iter()
        .map(|(k, v)| format!("{k} {v:.2}"))
        .collect();
    write_run_report(&args.out, &dataset, &report)?;
    println!("median ms per frame: {}", stages.join(", "));
    if let Some(s) = report.surface {
        println!(
            "against the ground-truth mesh: accuracy {:.1} mm ({:.1} % within a voxel), \
             completeness {:.1} %, label agreement {:.1} %",
            1000.0 * s.accuracy_mean_m,
            s.accuracy_within,
            s.completeness_within,
            s.label_agreement
        );
    }
    Ok(())
}

/// report.md and report.html next to the outputs: what was mapped, how fast, how well.
fn write_run_report(
    out: &std::path::Path,
    dataset: &std::path::Path,
    report: &voxpan_pipeline::RunReport,
) -> Result<()> {
    let mut rows = vec![
        ("frames".to_owned(), report.frames.to_string()),
        ("frames/s".to_owned(), format!("{:.1}", report.fps)),
        ("map instances".to_owned(), report.instances.to_string()),
        ("allocated blocks".to_owned(), report.blocks.to_string()),
        ("mesh triangles".to_owned(), report.triangles.to_string()),
        (
            "skipped frames".to_owned(),
            report.skipped.len().to_string(),
        ),
    ];
    rows.extend(
        report
            .stage_ms
            .iter()
            .map(|(k, v)| (format!("{k} (median ms)"), format!("{v:.2}"))),
    );
    if let Some(s) = report.surface {
        rows.push((
            "accuracy vs ground-truth mesh".to_owned(),
            format!(
                "{:.1} mm ({:.1} % within a voxel)",
                1000.0 * s.accuracy_mean_m,
                s.accuracy_within
            ),
        ));
        rows.push((
            "completeness (observed truth within a voxel)".to_owned(),
            format!("{:.1} %", s.completeness_within),
        ));
        rows.push((
            "label agreement (surface voxels)".to_owned(),
            format!("{:.1} %", s.label_agreement),
        ));
    }
    let mut md = format!(
        "# voxpan run on {}\n\n| | |\n|---|---|\n",
        dataset.display()
    );
    let mut html = format!(
        "<!doctype html><meta charset=utf-8><title>voxpan run</title><style>body{{font-family:sans-serif}}\
         td{{border:1px solid #999;padding:2px 8px}}</style><h1>voxpan run on {}</h1><table>",
        dataset.display()
    );
    for (k, v) in &rows {
        md += &format!("| {k} | {v} |\n");
        html += &format!("<tr><td>{k}<td>{v}</tr>");
    }
    html += "</table>";
    if !report.skipped.is_empty() {
        md += "\n## Skipped frames\n\n";
        html += "<h2>Skipped frames</h2><ul>";
        for (id, why) in &report.skipped {
            md += &format!("- {id}: {why}\n");
            html += &format!("<li>{id}: {why}</li>");
        }
        html += "</ul>";
    }
    md += "\nMeshes: `mesh_rgb.ply`, `mesh_instance.ply`, `mesh_class.ply`, `instances/`. Mask scores: `voxpan eval DATASET --report DIR`.\n";
    std::fs::write(out.join("report.md"), md).context("cannot write report.md")?;
    std::fs::write(out.join("report.html"), html).context("cannot write report.html")?;
    Ok(())
}
