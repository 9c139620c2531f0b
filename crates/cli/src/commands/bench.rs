use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use voxpan_dataset::{FrameSource, open_dataset};
use voxpan_io::flat_sample_dir;
use voxpan_map::{BLOCK_BYTES, BLOCK_VOXELS, VOXEL_BYTES, human_bytes};
use voxpan_perception::{Keyframes, Segmenter};
use voxpan_pipeline::{
    Config, RunFolder, RunProgress, dataset_segmenter, median, run_dataset_with,
};
use voxpan_refine::Rule;
use voxpan_yolo::{BackendKind, YoloOptions, YoloSegmenter};

use super::frames::FrameRange;
use super::network::ort_library;
use super::run::{dataset_or_synthetic, select, set_threads};

#[derive(clap::Args)]
pub struct Args {
    /// Dataset to time [default: the flat sample in ../shared/data/flat, else the built-in
    /// synthetic world].
    dataset: Option<PathBuf>,
    /// Worker threads for decoding, refinement, integration and meshing [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Frame ids START:END[:STEP] (inclusive), as for `voxpan run`.
    #[arg(long)]
    frames: Option<FrameRange>,
    /// Voxel size in metres [tsdf.voxel_size, default 0.02]; 0.01 gives the 1 cm figures.
    #[arg(long, allow_negative_numbers = true)]
    voxel_size: Option<f64>,
    /// Truncation distance in voxels [tsdf.truncation_voxels, default 3]; 2 is the original
    /// stack's (tools/original_stack_bench.py compares at both).
    #[arg(long, allow_negative_numbers = true)]
    truncation: Option<f64>,
    /// Also time this segmentation network (ONNX; repeatable), on every backend given by
    /// --backend, and map with the first one instead of the dataset's masks.
    #[arg(long, value_name = "M.onnx")]
    model: Vec<PathBuf>,
    /// Backends to time the networks on (repeatable: ort, tract) [default: every one built in].
    #[arg(long, requires = "model")]
    backend: Vec<BackendKind>,
    /// Frames the networks are timed on (spread over the selected frames).
    #[arg(long, default_value_t = 20, requires = "model")]
    network_frames: usize,
    /// Also time the pipeline with the distance field on (`[esdf] enabled`), its rebuild
    /// from the final map, and batched distance queries.
    #[arg(long)]
    esdf: bool,
    /// Also time the pipeline segmenting only keyframes (every Nth frame, or "auto";
    /// repeatable), against segmenting every frame in the same run.
    #[arg(long, value_name = "N|auto")]
    segment_every: Vec<Keyframes>,
    /// Also time each --segment-every schedule with the segmenter on a thread of its own
    /// (`[segment] own_thread`).
    #[arg(long, requires = "segment_every")]
    segmenter_thread: bool,
    /// Play the frames at this many per second, as a camera would deliver them (every
    /// variant) [default: as fast as each maps them].
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    rate: Option<f64>,
}

/// End-to-end throughput: the pipeline with the default refinement, and without refinement as
/// the baseline measured in the same run.
pub fn run(args: Args) -> Result<()> {
    set_threads(args.threads)?;
    // Checked before any frame is read.
    let mut base = Config::default();
    // Each option checked on its own, so that the error names it (the defaults are valid).
    if let Some(v) = args.voxel_size {
        base.tsdf.voxel_size = v;
        base.validate()
            .map_err(|e| anyhow::anyhow!("invalid option --voxel-size: {e}"))?;
    }
    if let Some(t) = args.truncation {
        base.tsdf.truncation_voxels = t;
        base.validate()
            .map_err(|e| anyhow::anyhow!("invalid option --truncation: {e}"))?;
    }
    if let Some(rate) = args.rate {
        base.source.rate = rate;
        base.validate()
            .map_err(|e| anyhow::anyhow!("invalid option --rate: {e}"))?;
    }
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
    let backends = if args.backend.is_empty() {
        BackendKind::built()
    } else {
        args.backend.clone()
    };
    if !args.model.is_empty() {
        time_networks(
            &args.model,
            args.network_frames,
            &backends,
            source.as_ref(),
            &indices,
        )?;
    }
    let network = |model: &PathBuf| -> Result<Box<dyn Segmenter>> {
        let options = YoloOptions {
            backend: backends.first().copied().unwrap_or_default(),
            ort_library: ort_library(),
            ..YoloOptions::default()
        };
        let segmenter =
            YoloSegmenter::open(model, &options, &[]).with_context(|| "--model".to_string())?;
        Ok(Box::new(segmenter))
    };
    if let Some(model) = args.model.first() {
        println!(
            "pipeline with {} on {} instead of the dataset's masks:",
            model.display(),
            backends.first().copied().unwrap_or_default()
        );
    }
    let mut fps = Vec::new();
    let every_frame = Keyframes::default();
    let mut variants = vec![
        (Rule::Default, false, every_frame, false),
        (Rule::None, false, every_frame, false),
    ];
    if args.esdf {
        variants.push((Rule::Default, true, every_frame, false));
    }
    for &keyframes in &args.segment_every {
        variants.push((Rule::Default, false, keyframes, false));
        if args.segmenter_thread {
            variants.push((Rule::Default, false, keyframes, true));
        }
    }
    for &(rule, esdf, keyframes, own_thread) in &variants {
        let mut config = base;
        config.refine.rule = rule;
        config.output.instance_meshes = false;
        config.esdf.enabled = esdf;
        config.segment.every = keyframes;
        config.segment.own_thread = own_thread;
        let thread = if own_thread { " on its own thread" } else { "" };
        let name = if esdf {
            format!("{rule} with the distance field")
        } else if keyframes != every_frame || own_thread {
            format!("{rule}, segmenting every {keyframes}{thread}")
        } else {
            rule.to_string()
        };
        let mut folder = RunFolder::open(&scratch.join(name.replace(' ', "-")))?;
        let segmenter = match args.model.first() {
            Some(model) => network(model)?,
            None => dataset_segmenter(&config, &source),
        };
        // CPU time of every thread while mapping (until the outputs begin): how the stages
        // share the cores.
        let (cpu_start, wall_start) = (process_cpu_seconds(), Instant::now());
        let mut mapping: Option<(Option<f64>, f64)> = None;
        let (mapped, _) = run_dataset_with(
            source.clone(),
            indices.clone(),
            &config,
            segmenter,
            &mut folder,
            &AtomicBool::new(false),
            |progress| {
                if matches!(progress, RunProgress::Output(_)) && mapping.is_none() {
                    mapping = Some((process_cpu_seconds(), wall_start.elapsed().as_secs_f64()));
                }
            },
        )?;
        let report = mapped.report;
        if esdf {
            time_esdf(&mapped.map)?;
        }
        // Measured heaps (nothing else runs now): the map's blocks and instances as a loaded
        // map holds them, against the computed figure the memory limit uses; then the whole
        // map with its meshes and buffers, as what dropping it frees.
        let saved = mapped.map.to_bytes();
        let before = crate::heap::in_use();
        let loaded = voxpan_map::PanopticMap::from_bytes(&saved, "memory".as_ref())?;
        let loaded_heap = crate::heap::in_use().saturating_sub(before);
        drop((loaded, saved));
        let held = crate::heap::in_use();
        drop(mapped.map);
        let map_heap = held.saturating_sub(crate::heap::in_use());
        let cpu = match (cpu_start, mapping) {
            (Some(start), Some((Some(end), wall))) if report.frames > 0 && wall > 0.0 => format!(
                "; CPU {:.1} ms a frame, {:.2} of {} cores busy",
                (end - start) * 1e3 / report.frames as f64,
                (end - start) / wall,
                std::thread::available_parallelism().map_or(1, |n| n.get()),
            ),
            _ => String::new(),
        };
        let (per_frame, per_run) = report.stage_summary();
        let rate = frames_per_second(&report);
        let segmented = if args.segment_every.is_empty() {
            String::new()
        } else {
            format!(
                "; segmented {} of {} frames",
                report.keyframes, report.frames
            )
        };
        println!(
            "refinement {name}: {rate:.1} frames/s (median frame interval {:.2} ms; {:.1} over \
             the whole run, start-up included{segmented}); median ms per frame: {per_frame}; \
             {per_run}{cpu}",
            report.frame_interval_ms, report.fps,
        );
        let bytes = report.blocks as u64 * BLOCK_BYTES;
        println!(
            "  map: {} blocks of {BLOCK_VOXELS} voxels at {} m, {} ({bytes} bytes; {VOXEL_BYTES} a \
             voxel); measured heap: {} ({loaded_heap} bytes) for the blocks and instances as \
             loaded, {} with meshes and buffers, {} at the process's peak",
            report.blocks,
            config.tsdf.voxel_size,
            human_bytes(bytes),
            human_bytes(loaded_heap as u64),
            human_bytes(map_heap as u64),
            human_bytes(crate::heap::peak() as u64),
        );
        fps.push(rate);
    }
    println!(
        "with refinement: {:.2}x the frame rate of the no-refinement baseline",
        fps[0] / fps[1]
    );
    for (&(_, esdf, keyframes, own_thread), rate) in variants.iter().zip(&fps).skip(2) {
        if esdf {
            println!(
                "with the distance field: {:.2}x the frame rate without it",
                rate / fps[0]
            );
        } else {
            let thread = if own_thread { " on its own thread" } else { "" };
            println!(
                "segmenting every {keyframes}{thread}: {:.2}x the frame rate of segmenting \
                 every frame",
                rate / fps[0]
            );
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Times a rebuild of `map`'s distance field from its saved form, and distance queries at a
/// million points spread over the map's bounds (one batch, every thread).
fn time_esdf(map: &voxpan_map::PanopticMap) -> Result<()> {
    let mut fresh = voxpan_map::PanopticMap::from_bytes(&map.to_bytes(), "memory".as_ref())?;
    let t = Instant::now();
    let stats = fresh.update_esdf();
    let rebuild_ms = t.elapsed().as_secs_f64() * 1e3;
    let voxels = fresh.esdf_voxels();
    let (low, high) = voxels
        .iter()
        .fold(([i32::MAX; 3], [i32::MIN; 3]), |(lo, hi), (v, _)| {
            (
                std::array::from_fn(|a| lo[a].min(v[a])),
                std::array::from_fn(|a| hi[a].max(v[a])),
            )
        });
    let s = fresh.voxel_size();
    // A fixed low-discrepancy spread (the golden ratio's fractions): no random source needed.
    let points: Vec<voxpan_core::nalgebra::Point3<f64>> = (0..1_000_000u64)
        .map(|i| {
            let f = |k: f64| (i as f64 * k).fract();
            let at = [f(0.618_033_988_7), f(0.754_877_666_2), f(0.569_840_290_9)];
            voxpan_core::nalgebra::Point3::from(std::array::from_fn::<f64, 3, _>(|a| {
                (low[a] as f64 + at[a] * (high[a] - low[a] + 1) as f64) * s
            }))
        })
        .collect();
    let t = Instant::now();
    let answered = fresh.distances(&points).iter().flatten().count();
    let query_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    fresh.distances_and_gradients(&points);
    let gradient_s = t.elapsed().as_secs_f64();
    println!(
        "  distance field: rebuilt from the saved map in {rebuild_ms:.0} ms ({} blocks, {} \
         relaxations in {} rounds); {:.1} M distance queries/s ({} of 1 M points observed), {:.1} \
         M with gradients/s",
        stats.changed_blocks,
        stats.relaxed_blocks,
        stats.rounds,
        1e-6 * points.len() as f64 / query_s,
        answered,
        1e-6 * points.len() as f64 / gradient_s,
    );
    Ok(())
}

/// The steady rate: from the median interval between mapped frames (a median, as the stages'
/// figures are) where every frame was segmented; the whole run's rate where fewer than two
/// frames were mapped. With keyframes the intervals alternate between a keyframe's and the
/// rest's, and a median would pick the short ones: the rate is then the frames after the
/// first over the time from the first to the last.
fn frames_per_second(report: &voxpan_pipeline::RunReport) -> f64 {
    let (first, last) = match (report.timeline.first(), report.timeline.last()) {
        (Some(first), Some(last)) if last.at_s > first.at_s => (first.at_s, last.at_s),
        _ => return report.fps,
    };
    if report.keyframes < report.frames {
        (report.timeline.len() - 1) as f64 / (last - first)
    } else if report.frame_interval_ms > 0.0 {
        1e3 / report.frame_interval_ms
    } else {
        report.fps
    }
}

/// Times each network on each backend on the same frames, interleaved (frame by frame, every
/// model and backend in turn) so that a change in the machine's load touches them alike.
fn time_networks(
    models: &[PathBuf],
    frames: usize,
    backends: &[BackendKind],
    source: &dyn FrameSource,
    indices: &[usize],
) -> Result<()> {
    if backends.is_empty() {
        // Opening says which feature to build with.
        YoloSegmenter::open(&models[0], &YoloOptions::default(), &[]).context("--model")?;
    }
    let mut runs = Vec::new();
    for model in models {
        for &backend in backends {
            let options = YoloOptions {
                backend,
                ort_library: ort_library(),
                ..YoloOptions::default()
            };
            let yolo = voxpan_yolo::Yolo::open(model, &options)
                .with_context(|| format!("--model on {backend}"))?;
            runs.push((model, backend, yolo, Vec::new()));
        }
    }
    let n = frames.clamp(1, indices.len());
    // Evenly spread, so that busy and empty views are both in.
    let picked: Vec<usize> = (0..n).map(|k| indices[k * indices.len() / n]).collect();
    println!(
        "networks on {n} frames, interleaved (median ms per frame; ONNX Runtime with its default \
         threads, one per core; tract on one thread):"
    );
    for &i in &picked {
        let frame = source
            .load(i)
            .context("loading a frame to time the networks on")?;
        for (model, _, yolo, times) in &mut runs {
            yolo.instances(&frame.color)
                .with_context(|| format!("--model {}", model.display()))?;
            times.push(yolo.times());
        }
    }
    println!(
        "{:<28} {:>7} {:>6} {:>10} {:>10} {:>8} {:>8}",
        "model", "backend", "input", "letterbox", "inference", "masks", "total"
    );
    for (model, backend, yolo, times) in &runs {
        let med = |f: fn(&voxpan_yolo::YoloTimes) -> f64| median(times.iter().map(f).collect());
        let name = model.file_name().map_or_else(
            || model.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        println!(
            "{:<28} {:>7} {:>6} {:>10.1} {:>10.1} {:>8.1} {:>8.1}",
            name,
            backend.name(),
            format!("{}", yolo.info().input.0),
            med(|t| t.preprocess),
            med(|t| t.inference),
            med(|t| t.postprocess),
            med(|t| t.preprocess + t.inference + t.postprocess)
        );
    }
    Ok(())
}

/// User plus system CPU time of the whole process so far, all threads, in seconds (`None`
/// where the platform does not say).
fn process_cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes only into the struct it is given, which is plain data.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } != 0 {
            return None;
        }
        let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        Some(seconds(usage.ru_utime) + seconds(usage.ru_stime))
    }
    #[cfg(not(unix))]
    {
        None
    }
}
