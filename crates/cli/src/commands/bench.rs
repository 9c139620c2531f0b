use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::{Result, bail};
use voxpan_dataset::{FrameSource, open_dataset};
use voxpan_io::flat_sample_dir;
use voxpan_pipeline::{Config, RunFolder, run_dataset};
use voxpan_refine::Rule;

use super::frames::FrameRange;
use super::run::{dataset_or_synthetic, select, set_threads};

#[derive(clap::Args)]
pub struct Args {
    /// Dataset to time [default: the flat sample in ../shared/data/flat, else the built-in
    /// synthetic world].
    dataset: Option<PathBuf>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Frame ids START:END[:STEP] (inclusive), as for `voxpan run`.
    #[arg(long)]
    frames: Option<FrameRange>,
}

/// End-to-end throughput: the pipeline with the default refinement, and without refinement as
/// the baseline measured in the same run.
pub fn run(args: Args) -> Result<()> {
    set_threads(args.threads)?;
    let scratch = std::env::temp_dir().join(format!("voxpan-bench-{}", std::process::id()));
    let dataset = dataset_or_synthetic(
        args.dataset.or_else(flat_sample_dir).as_ref(),
        &scratch.join("synthetic"),
    )?;
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(&dataset)?);
    if source.is_empty() {
        bail!("{} has no frames", dataset.display());
    }
    let indices = select(source.as_ref(), args.frames);
    if indices.is_empty() {
        bail!("no frame of {} in the selected range", dataset.display());
    }
    println!(
        "{} frames of {} ({} worker threads)",
        indices.len(),
        dataset.display(),
        rayon::current_num_threads()
    );
    let mut fps = Vec::new();
    for rule in [Rule::Default, Rule::None] {
        let mut config = Config::default();
        config.refine.rule = rule;
        config.output.instance_meshes = false;
        let mut folder = RunFolder::open(&scratch.join(rule.name()))?;
        let (mapped, _) = run_dataset(
            source.clone(),
            indices.clone(),
            &config,
            &mut folder,
            &AtomicBool::new(false),
            |_| {},
        )?;
        let report = mapped.report;
        let stages: Vec<String> = report
            .stage_ms
            .iter()
            .filter(|(k, _)| k.as_str() != "mesh")
            .map(|(k, v)| format!("{k} {v:.2}"))
            .collect();
        println!(
            "refinement {rule}: {:.1} frames/s; median ms per frame: {}; final mesh {:.0} ms",
            report.fps,
            stages.join(", "),
            report.stage_ms.get("mesh").copied().unwrap_or(0.0)
        );
        fps.push(report.fps);
    }
    println!(
        "with refinement: {:.2}x the frame rate of the no-refinement baseline",
        fps[0] / fps[1]
    );
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
