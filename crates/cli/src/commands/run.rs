use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use voxpan_dataset::{open_dataset, FrameSource};
use voxpan_pipeline::{run as run_pipeline, RunConfig, SegmentSource};
use voxpan_refine::Rule;
use voxpan_sim::{generate, SynthConfig};

use super::frames::FrameRange;

#[derive(clap::Args)]
pub struct Args {
    /// Dataset folder (flat or TUM RGB-D). Without it, the built-in synthetic world (60 frames
    /// of 320x240) is generated into OUT/synthetic and mapped.
    dataset: Option<PathBuf>,
    /// Output folder: map.voxpan, mesh_rgb.ply, mesh_instance.ply, mesh_class.ply,
    /// instances/, metrics.json (and refined/ with --save-refined).
    #[arg(long, default_value = "voxpan-out")]
    out: PathBuf,
    /// Voxel size in metres.
    #[arg(long, default_value_t = 0.02)]
    voxel_size: f64,
    /// Truncation distance in voxels.
    #[arg(long, default_value_t = 3.0)]
    truncation: f64,
    /// Depth beyond this (metres) is not integrated.
    #[arg(long, default_value_t = 5.0)]
    max_range: f64,
    /// Frame ids START:END[:STEP] (inclusive).
    #[arg(long)]
    frames: Option<FrameRange>,
    /// Mask refinement rule.
    #[arg(long, value_enum, default_value_t = RefineArg::Default)]
    refine: RefineArg,
    /// Refine only thing segments.
    #[arg(long)]
    things_only: bool,
    /// Map the network's segments or the ground truth.
    #[arg(long, value_enum, default_value_t = SegmentsArg::Predicted)]
    segments: SegmentsArg,
    /// Write the refined label images as refined/NNNNNN.png.
    #[arg(long)]
    save_refined: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum RefineArg {
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

pub fn run(args: Args) -> Result<()> {
    if !(args.voxel_size > 0.0 && args.truncation > 0.0 && args.max_range > 0.0) {
        bail!("--voxel-size, --truncation and --max-range must be positive");
    }
    let dataset = match &args.dataset {
        Some(d) => d.clone(),
        None => {
            let dir = args.out.join("synthetic");
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
            generate(&dir, &config, |_| {})
                .with_context(|| format!("generating {}", dir.display()))?;
            dir
        }
    };
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(&dataset)?);
    let indices: Vec<usize> = (0..source.len())
        .filter(|&i| args.frames.is_none_or(|r| r.contains(source.frame_id(i))))
        .collect();
    if indices.is_empty() {
        bail!("no frame of {} in the selected range", dataset.display());
    }
    let config = RunConfig {
        voxel_size: args.voxel_size,
        truncation_voxels: args.truncation,
        max_range: args.max_range,
        refine: match args.refine {
            RefineArg::None => None,
            RefineArg::Paper => Some(Rule::Paper),
            RefineArg::Release => Some(Rule::Release),
            RefineArg::Default => Some(Rule::Default),
        },
        things_only: args.things_only,
        segments: match args.segments {
            SegmentsArg::Predicted => SegmentSource::Predicted,
            SegmentsArg::Gt => SegmentSource::Gt,
        },
        save_refined: args.save_refined,
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second handler cannot be installed (tests run several commands in one process is
        // not a case here); failing to install only loses clean Ctrl-C handling.
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
    println!("median ms per frame: {}", stages.join(", "));
    Ok(())
}
