use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use voxpan_core::{LabelImage, Segment, segment_ids};
use voxpan_io::{read_depth, read_label_png, read_segments_json, write_label_png};
use voxpan_kde::KdeMethod;
use voxpan_refine::{MaskReport, MaskStatus, RefineConfig, Refiner, Rule, example_scene};

#[derive(clap::Args)]
pub struct Args {
    /// Depth map: float32 TIFF in metres, or 16-bit PNG (see --depth-scale).
    /// Without --depth and --segments, a built-in example frame is refined.
    #[arg(long, requires = "segments")]
    depth: Option<PathBuf>,
    /// Predicted segment-id image (PNG, 0 = void).
    #[arg(long, requires = "depth")]
    segments: Option<PathBuf>,
    /// Segment list (panoptic_mapping labels.json): which ids are things.
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Refinement rule: none, paper, release or default.
    #[arg(long, default_value_t = Rule::Default)]
    rule: Rule,
    /// Refine only "thing" segments (needs --labels).
    #[arg(long)]
    things_only: bool,
    /// KDE to use, isj or kdepy; default: kdepy for the paper/release rules, isj for the
    /// default rule.
    #[arg(long)]
    kde: Option<KdeMethod>,
    /// Units per metre of a 16-bit PNG depth map (1000 = millimetres, 5000 = TUM).
    #[arg(long, default_value_t = 1000.0, allow_negative_numbers = true)]
    depth_scale: f32,
    /// Where to write the refined label image (PNG).
    #[arg(long, default_value = "voxpan-out/refined.png")]
    out: PathBuf,
    /// Print the per-segment results as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<()> {
    let inputs: Vec<&Path> = [&args.depth, &args.segments, &args.labels]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    crate::paths::refuse_overwriting("--out", &args.out, &inputs)?;
    if !(args.depth_scale.is_finite() && args.depth_scale > 0.0) {
        bail!(
            "--depth-scale must be a positive number of depth units per metre (found {})",
            args.depth_scale
        );
    }
    let rule = args.rule;
    let mut config = RefineConfig::new(rule);
    config.kde = args.kde;
    config.things_only = args.things_only;
    if args.things_only && args.labels.is_none() && args.depth.is_some() {
        bail!(
            "--things-only needs --labels: which segments are things is only in the segment list"
        );
    }

    let (depth, mut labels, segments, truth) = match (&args.depth, &args.segments) {
        (Some(depth_path), Some(seg_path)) => {
            let depth = read_depth(depth_path, args.depth_scale)?;
            let labels = read_label_png(seg_path)?;
            let segments = match &args.labels {
                Some(p) => read_segments_json(p)?,
                None => segment_ids(&labels)
                    .into_iter()
                    .map(Segment::bare)
                    .collect(),
            };
            (depth, labels, segments, None)
        }
        _ => {
            eprintln!("no --depth/--segments given: refining the built-in example frame");
            let scene = example_scene();
            (
                scene.depth,
                scene.predicted,
                scene.segments,
                Some(scene.ground_truth),
            )
        }
    };
    let before = labels.clone();
    let mut refiner = Refiner::new(config);
    let reports = refiner
        .refine_frame(&depth, &mut labels, &segments)
        .with_context(|| match (&args.depth, &args.segments) {
            (Some(d), Some(s)) => format!("{} and {}", d.display(), s.display()),
            _ => "built-in example".to_owned(),
        })?;

    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
    }
    write_label_png(&args.out, &labels)?;

    let mut out = std::io::stdout().lock();
    let printed = if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&reports)?)
    } else {
        print_table(&mut out, &reports, rule, refiner.config().kde_method()).and_then(|()| {
            match truth {
                Some(truth) => print_example_iou(&mut out, &before, &labels, &truth, &segments),
                None => Ok(()),
            }
        })
    };
    ignore_broken_pipe(printed)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

/// A closed pipe (`voxpan refine | head`) is the reader's choice, not an error.
fn ignore_broken_pipe(result: std::io::Result<()>) -> std::io::Result<()> {
    match result {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

fn print_table(
    out: &mut impl Write,
    reports: &[MaskReport],
    rule: Rule,
    kde: KdeMethod,
) -> std::io::Result<()> {
    writeln!(out, "rule {rule} (kde {kde})")?;
    writeln!(
        out,
        "{:>5} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9}  status",
        "id", "pixels", "kept", "removed", "low [m]", "high [m]", "bw [m]"
    )?;
    let num = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.4}"));
    for r in reports {
        let status = match r.status {
            MaskStatus::Refined => "refined".to_owned(),
            MaskStatus::Kept(reason) => format!("kept: {reason}"),
        };
        let fallback = r
            .bandwidth_fallback
            .map_or(String::new(), |f| format!(" (bandwidth: {f})"));
        writeln!(
            out,
            "{:>5} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9}  {status}{fallback}",
            r.id,
            r.pixels,
            r.kept,
            r.removed,
            num(r.low),
            num(r.high),
            num(r.bandwidth)
        )?;
    }
    Ok(())
}

fn print_example_iou(
    out: &mut impl Write,
    before: &LabelImage,
    after: &LabelImage,
    truth: &LabelImage,
    segments: &[Segment],
) -> std::io::Result<()> {
    let iou = |pred: &LabelImage, id: u16| {
        let (mut inter, mut union) = (0usize, 0usize);
        for (&p, &t) in pred.pixels().iter().zip(truth.pixels()) {
            inter += (p == id && t == id) as usize;
            union += (p == id || t == id) as usize;
        }
        inter as f64 / union.max(1) as f64
    };
    writeln!(
        out,
        "IoU with the example's ground truth (before -> after):"
    )?;
    for s in segments {
        writeln!(
            out,
            "{:>5}  {:.3} -> {:.3}",
            s.id,
            iou(before, s.id),
            iou(after, s.id)
        )?;
    }
    Ok(())
}
