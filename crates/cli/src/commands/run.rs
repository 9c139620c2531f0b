use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, bail};
use voxpan_dataset::{FrameSource, open_dataset};
use voxpan_map::Coloring;
use voxpan_perception::{Keyframes, Segmenter};
use voxpan_pipeline::{
    Config, Manifest, PipelineError, RunError, RunFolder, RunProgress, SegmentSource,
    dataset_segmenter, run_dataset_observed,
};
use voxpan_refine::Rule;
use voxpan_report::{RunSummary, SampleFrame, write_run_report};
use voxpan_sim::{SynthConfig, generate};

use super::frames::FrameRange;
use super::live::LiveArgs;
use super::network::NetworkArgs;
use crate::progress::{Counter, Phases};

#[derive(clap::Args)]
pub struct Args {
    /// Dataset folder (flat or TUM RGB-D) or ROS bag (.bag, .mcap, .db3, ROS 2 bag folder; topics
    /// below). Without it, the built-in synthetic world (60 frames
    /// of 320x240) is generated into OUT/synthetic and mapped.
    dataset: Option<PathBuf>,
    /// Output folder: map.voxpan, mesh_rgb.ply, mesh_instance.ply, mesh_class.ply,
    /// instances/, metrics.json, config.toml, report.md, report.html (and refined/ with
    /// --save-refined).
    #[arg(long, default_value = "voxpan-out")]
    out: PathBuf,
    /// Configuration file (TOML, sections [tsdf], [tracking], [fill], [refine], [segment],
    /// [output], [resources]; see docs/configuration.md). Options given on the command line override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Voxel size in metres [tsdf.voxel_size, default 0.02].
    #[arg(long, allow_negative_numbers = true)]
    voxel_size: Option<f64>,
    /// Truncation distance in voxels [tsdf.truncation_voxels, default 3].
    #[arg(long, allow_negative_numbers = true)]
    truncation: Option<f64>,
    /// Depth beyond this (metres) is not integrated [tsdf.max_range, default 5].
    #[arg(long, allow_negative_numbers = true)]
    max_range: Option<f64>,
    /// Drop the blocks farther than this from the camera after each frame, so that memory
    /// stays bounded on a long drive [tsdf.keep_radius, default 0: keep everything].
    #[arg(long)]
    keep_radius: Option<f64>,
    /// Write the blocks --keep-radius drops into dropped/blocks-NNNNNN.voxpan (map files of
    /// their own) instead of discarding them [output.dropped_blocks].
    #[arg(long)]
    save_dropped: bool,
    /// Frame ids START:END[:STEP] (inclusive).
    #[arg(long)]
    frames: Option<FrameRange>,
    /// Mask refinement rule: none, paper, release or default [refine.rule, default default].
    #[arg(long)]
    refine: Option<Rule>,
    /// Refine only thing segments [refine.things_only].
    #[arg(long)]
    things_only: bool,
    /// Keep thing masks whole where they lie on the frame's floor and wall planes
    /// [refine.trim_stuff_planes = false].
    #[arg(long)]
    no_trim_stuff_planes: bool,
    /// Map the dataset's predicted masks or its ground truth: predicted or gt
    /// [segment.source, default predicted].
    #[arg(long)]
    segments: Option<SegmentSource>,
    /// Segment only keyframes: every Nth frame, or "auto" (when the view has moved on from the
    /// last keyframe's); the frames between are mapped with the masks the map renders at their
    /// pose, refined on their own depth [segment.every, default 1].
    #[arg(long, value_name = "N|auto")]
    segment_every: Option<Keyframes>,
    /// Run the segmenter on a thread of its own: frames never wait for it, keyframes are the
    /// frames it is free for and are mapped when their masks are ready [segment.own_thread].
    #[arg(long)]
    segmenter_thread: bool,
    /// Play the recording at this many frames per second, as a camera would deliver them
    /// [source.rate, default 0: as fast as it maps].
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    rate: Option<f64>,
    /// Write the refined label images as refined/NNNNNN.png [output.save_refined].
    #[arg(long)]
    save_refined: bool,
    /// Worker threads for decoding, refinement, integration and meshing [default: all cores;
    /// more than the cores are capped]. A network's runtime has threads of its own.
    #[arg(long)]
    threads: Option<usize>,
    /// Most memory the map's voxel blocks may take, in GB [resources.max_memory_gb, default
    /// half the machine's memory]. A configuration that could need more for a single frame is
    /// refused before mapping.
    #[arg(long, allow_negative_numbers = true)]
    max_memory: Option<f64>,
    #[command(flatten)]
    bag: super::bag::BagArgs,
    /// Segment every frame with this network instead of reading the dataset's masks.
    #[command(flatten)]
    network: NetworkArgs,
    #[command(flatten)]
    live: LiveArgs,
}

/// The configuration file (or the defaults) with the command line's options on top.
fn effective_config(args: &Args) -> Result<Config> {
    let mut config = match &args.config {
        Some(path) => Config::from_toml_file(path)?,
        None => Config::default(),
    };
    if let Some(v) = args.voxel_size {
        config.tsdf.voxel_size = v;
    }
    if let Some(v) = args.truncation {
        config.tsdf.truncation_voxels = v;
    }
    if let Some(v) = args.max_range {
        config.tsdf.max_range = v;
    }
    if let Some(v) = args.keep_radius {
        config.tsdf.keep_radius = v;
    }
    if let Some(r) = args.refine {
        config.refine.rule = r;
    }
    config.refine.things_only |= args.things_only;
    config.refine.trim_stuff_planes &= !args.no_trim_stuff_planes;
    if let Some(s) = args.segments {
        config.segment.source = s;
    }
    if let Some(every) = args.segment_every {
        config.segment.every = every;
    }
    config.segment.own_thread |= args.segmenter_thread;
    if let Some(rate) = args.rate {
        config.source.rate = rate;
    }
    config.output.save_refined |= args.save_refined;
    config.output.dropped_blocks |= args.save_dropped;
    if let Some(gb) = args.max_memory {
        config.resources.max_memory_gb = Some(gb);
    }
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid option: {e}"))?;
    Ok(config)
}

/// Sets the worker pool size (once per process). More threads than cores only add switching
/// (the work is compute-bound), so the count is capped there.
pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(mut n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        if n > cores {
            eprintln!("note: --threads {n} capped at the {cores} cores this machine has");
            n = cores;
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot size the worker pool")?;
    }
    Ok(())
}

/// The dataset to map: the given folder, or the built-in synthetic world generated into `dir`.
pub fn dataset_or_synthetic(dataset: Option<&PathBuf>, dir: &Path) -> Result<PathBuf> {
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
            let counter = Counter::new("rendering", "rendering frame", config.frames);
            generate(dir, &config, |_| counter.inc())
                .with_context(|| format!("generating {}", dir.display()))?;
            counter.finish();
            Ok(dir.to_owned())
        }
    }
}

/// A dataset folder, or a ROS bag read with the bag options.
pub fn open_source(path: &Path, bag: &super::bag::BagArgs) -> Result<Arc<dyn FrameSource>> {
    if voxpan_bag::looks_like_bag(path) {
        return Ok(Arc::new(voxpan_bag::BagDataset::open(path, bag.options())?));
    }
    Ok(Arc::from(open_dataset(path)?))
}

/// The selected frame indices of a dataset.
pub fn select(source: &dyn FrameSource, frames: Option<FrameRange>) -> Vec<usize> {
    (0..source.len())
        .filter(|&i| frames.is_none_or(|r| r.contains(source.frame_id(i))))
        .collect()
}

/// Exit status of a run stopped by Ctrl-C (128 + SIGINT, the shell's convention).
pub const INTERRUPTED: u8 = 130;

pub fn run(args: Args) -> Result<std::process::ExitCode> {
    set_threads(args.threads)?;
    let config = effective_config(&args)?;
    if args.network.model.is_some() && config.segment.source == SegmentSource::Gt {
        bail!("--model and segment.source = gt (--segments gt) exclude each other");
    }
    // The network is loaded before the output folder is touched: a model that cannot be used
    // leaves no trace.
    let network = args.network.open()?;
    if let Some(n) = &network {
        let yolo = n.yolo();
        eprintln!(
            "segmenting with {} ({}, {} classes, {}x{} input, {})",
            yolo.path().display(),
            yolo.info().layout.name(),
            yolo.info().classes(),
            yolo.info().input.0,
            yolo.info().input.1,
            yolo.backend_name()
        );
    }
    crate::paths::refuse_file_as_folder("--out", &args.out)?;
    if let Some(dataset) = &args.dataset
        && crate::paths::same_file(dataset, &args.out)
    {
        bail!(
            "--out {} is the dataset itself: the outputs would mix with its frames; choose \
             another folder",
            args.out.display()
        );
    }
    args.live.check_record_path()?;
    // Locked next: a second run into the same folder is refused before any work.
    let mut folder = RunFolder::open(&args.out)?;
    let dataset = dataset_or_synthetic(args.dataset.as_ref(), &args.out.join("synthetic"))?;
    let source = open_source(&dataset, &args.bag)?;
    let segmenter: Box<dyn Segmenter> = match network {
        Some(n) => Box::new(n),
        None => dataset_segmenter(&config, &source),
    };
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
    let counter = Counter::new("mapping", "frame", indices.len());
    // What runs after mapping (meshing, saving, scoring, the report) takes a good part of a
    // run: each phase says itself.
    let mut phases = Phases::default();
    let mut live = args.live.start()?;
    let (mut mapped, outputs) = match run_dataset_observed(
        source.clone(),
        indices.clone(),
        &config,
        segmenter,
        &mut folder,
        &stop,
        |progress| match progress {
            RunProgress::Frames(done) => counter.set(done),
            RunProgress::Output(step) => {
                counter.finish();
                phases.start(&step.to_string());
            }
        },
        |perceived, map| live.show(perceived, map),
    ) {
        Err(PipelineError::Run(RunError::Interrupted)) => {
            counter.finish();
            eprintln!(
                "interrupted before any frame was mapped: {} is as it was",
                args.out.display()
            );
            return Ok(std::process::ExitCode::from(INTERRUPTED));
        }
        other => other?,
    };
    counter.finish();
    phases.end();
    // A side output that fails must not cost the run's outputs: reported after they are in.
    let recording = live.finish(&mut mapped.map);
    let report = &mapped.report;
    super::warn_skipped(
        report
            .skipped
            .iter()
            .map(|s| (s.frame.as_str(), s.reason.as_str())),
    );
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    // A Ctrl-C that ended mapping early is spent: what was built is scored and reported as
    // before. A Ctrl-C from now on skips what is left of scoring and the report; the map and
    // meshes are already written and go in place.
    stop.store(false, Ordering::Relaxed);
    let interrupted = || stop.load(Ordering::Relaxed);
    // The synthetic world ships its ground-truth mesh: score the map against it.
    let truth_path = dataset.join("groundtruth_mesh.ply");
    let surface = if truth_path.is_file() && !interrupted() {
        phases.start("scoring the map against the ground-truth mesh");
        let truth = voxpan_io::read_ply(&truth_path)?;
        let mesh = mapped.map.mesh(Coloring::Rgb);
        Some(voxpan_pipeline::protocols::surface_report(
            &mapped.map,
            &mesh,
            &truth,
        ))
    } else {
        None
    };
    phases.end();
    // The reference maps every frame again; only a dataset with ground truth builds it.
    let reference = Counter::new(
        "mapping the ground truth for the voxel PQ",
        "reference frame",
        indices.len(),
    );
    let panoptic = match voxpan_pipeline::protocols::panoptic_against_reference(
        &source,
        &indices,
        &config,
        &mapped.map,
        |done| {
            reference.set(done);
            if done == indices.len() {
                reference.finish();
                phases.start("matching the map's instances to the true objects");
            }
        },
        &stop,
    ) {
        Err(voxpan_pipeline::protocols::EvalError::Run(RunError::Interrupted)) => None,
        _ if interrupted() => None,
        other => other?,
    };
    reference.finish();
    phases.end();
    let report = &mapped.report;
    let segmented = if report.keyframes < report.frames {
        format!(
            " ({} segmented, {} with the map's masks)",
            report.keyframes,
            report.frames - report.keyframes
        )
    } else {
        String::new()
    };
    println!(
        "{} frames{segmented} at {:.1} frames/s; {} instances, {} blocks, {} triangles; outputs in {}",
        report.frames,
        report.fps,
        report.instances,
        report.blocks,
        report.triangles,
        args.out.display()
    );
    let (per_frame, per_run) = report.stage_summary();
    println!("median ms per frame: {per_frame}; {per_run}");
    if let Some(s) = surface {
        println!(
            "against the ground-truth mesh: accuracy {:.1} mm mean, {:.1} mm median, {:.1} mm \
             95th percentile ({:.1} % within a voxel), completeness {:.1} %, label agreement {:.1} %",
            1000.0 * s.accuracy_mean_m,
            1000.0 * s.accuracy_median_m,
            1000.0 * s.accuracy_p95_m,
            s.accuracy_within,
            s.completeness_within,
            s.label_agreement
        );
    }
    if let Some(p) = panoptic.as_ref().map(|p| p.scores) {
        println!(
            "against the ground-truth segmentation: voxel PQ {:.1} (things {:.1}, stuff {:.1}); \
             {} instances for {} objects ({} split, {} merged)",
            p.all.pq,
            p.things.pq,
            p.stuff.pq,
            p.instances,
            p.objects,
            p.over_segmented,
            p.under_segmenting
        );
    }
    let input = dataset.display().to_string();
    let scored = !interrupted();
    if scored {
        phases.start("writing the report (pictures of the map, plots)");
        // Refinement illustrated on the middle selected frame with a thing mask, if any.
        let middle = indices.len() / 2;
        let sample = indices[middle..]
            .iter()
            .chain(&indices[..middle])
            .take(20)
            .find_map(|&i| SampleFrame::from_frame(source.load(i).ok()?));
        write_run_report(
            &mut folder,
            &RunSummary {
                input: &input,
                config: &config,
                report,
                outputs: &outputs,
                surface,
                panoptic: panoptic.as_ref(),
                map: Some(&mapped.map),
                sample: sample.as_ref(),
            },
        )?;
    }
    let stopped = report.stopped_early;
    let completed = !stopped && scored && !interrupted();
    phases.start("putting the outputs in place");
    folder.commit(Manifest {
        voxpan: env!("CARGO_PKG_VERSION").into(),
        input,
        completed,
        frames: report.frames,
        skipped: report.skipped.len(),
        files: Vec::new(),
        config: toml::Value::try_from(config).expect("plain data"),
    })?;
    phases.end();
    if let Err(e) = recording {
        return Err(e.context(format!(
            "the live view or recording failed; the run's outputs are in {}",
            args.out.display()
        )));
    }
    if stopped {
        eprintln!(
            "interrupted: {} holds what was built from {} frames (manifest.json: completed false)",
            args.out.display(),
            report.frames
        );
        return Ok(std::process::ExitCode::from(INTERRUPTED));
    }
    if !completed {
        eprintln!(
            "interrupted after mapping: the map and meshes of all {} frames are in {}; the \
             scores and the report were not written",
            report.frames,
            args.out.display()
        );
        return Ok(std::process::ExitCode::from(INTERRUPTED));
    }
    Ok(std::process::ExitCode::SUCCESS)
}
