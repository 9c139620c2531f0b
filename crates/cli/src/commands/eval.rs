use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use voxpan_core::LabelImage;
use voxpan_dataset::{open_dataset, FrameSource};
use voxpan_eval::{match_frame, match_frame_subset, MaskScores, MaskSummary};
use voxpan_fill::{FillParams, HoleFiller};
use voxpan_io::read_label_png;
use voxpan_refine::{RefineConfig, Refiner, Rule};
use voxpan_sim::{generate, MaskErrors, SynthConfig};

use super::frames::FrameRange;

#[derive(clap::Args)]
pub struct Args {
    /// Dataset folder (flat format, with ground-truth segmentation).
    #[arg(required_unless_present = "sweep")]
    dataset: Option<PathBuf>,
    /// Instead of a dataset, score the synthetic sweep: sequences of 320x240 frames (seed 11)
    /// whose masks over-cover only, and with the full error mix, at error strengths 0.5, 1,
    /// 1.5 and 2, generated into a temporary folder and removed afterwards.
    #[arg(long, conflicts_with_all = ["dataset", "pred", "three_d", "report", "frames"])]
    sweep: bool,
    /// Frames per sequence of the synthetic sweep.
    #[arg(long, default_value_t = 40, requires = "sweep")]
    sweep_frames: usize,
    /// Frame ids to score, START:END[:STEP] (inclusive).
    #[arg(long)]
    frames: Option<FrameRange>,
    /// Score the label images in this folder (NNNNNN.png or NNNNNN_predicted.png) instead of
    /// the dataset's predictions under each rule.
    #[arg(long)]
    pred: Option<PathBuf>,
    /// Refine only thing segments (the rules leave stuff alone).
    #[arg(long)]
    things_only: bool,
    /// Fill depth holes before refining. Off by default: refinement estimates densities from
    /// measured depth, since filled values interpolate across silhouettes and bridge exactly
    /// the depth gaps that separate an object from its background.
    #[arg(long)]
    fill: bool,
    /// Also build a map per row and one from the ground-truth segmentation, and score each
    /// against the latter: panoptic quality over voxels (2 cm voxels).
    #[arg(long = "3d")]
    three_d: bool,
    /// Also write report.md and report.html with plots into this folder.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Print JSON: per rule, mean_matched_iou, pq, sq, rq, precision, recall (percent).
    #[arg(long)]
    json: bool,
}

const ROWS: [(&str, Option<Rule>); 4] = [
    ("none", None),
    ("paper", Some(Rule::Paper)),
    ("release", Some(Rule::Release)),
    ("default", Some(Rule::Default)),
];

pub fn run(args: Args) -> Result<()> {
    if args.sweep {
        return sweep(&args);
    }
    let dataset = args
        .dataset
        .clone()
        .expect("clap requires a dataset without --sweep");
    let source = open_dataset(&dataset)?;
    for (id, why) in source.skipped() {
        eprintln!("warning: frame {id} skipped: {why}");
    }
    let selected: Vec<usize> = (0..source.len())
        .filter(|&i| args.frames.is_none_or(|r| r.contains(source.frame_id(i))))
        .collect();
    if selected.is_empty() {
        bail!("no frame of {} in the selected range", dataset.display());
    }
    let rows: Vec<(&str, Option<Rule>)> = match &args.pred {
        Some(_) => vec![("pred", None)],
        None => ROWS.to_vec(),
    };
    let scored = score_masks(
        source.as_ref(),
        &selected,
        &rows,
        args.things_only,
        args.fill,
        args.pred.as_ref(),
    )?;
    let (totals, per_frame) = (scored.totals, scored.per_frame);
    let things_only = args.things_only;
    let summaries: Vec<(&str, [MaskSummary; 3])> = rows
        .iter()
        .map(|r| r.0)
        .zip(
            totals
                .iter()
                .map(|t| [t[0].summary(), t[1].summary(), t[2].summary()]),
        )
        .collect();
    let voxel_rows = if args.three_d && args.pred.is_none() {
        Some(voxel_scores(&dataset, &selected, &rows, things_only)?)
    } else {
        None
    };
    if args.json {
        let map: serde_json::Map<String, serde_json::Value> = summaries
            .iter()
            .map(|(name, s)| {
                // The whole-image scores at the top, things and stuff nested.
                let mut v = serde_json::to_value(s[0]).expect("plain numbers");
                v["things"] = serde_json::to_value(s[1]).expect("plain numbers");
                v["stuff"] = serde_json::to_value(s[2]).expect("plain numbers");
                if let Some(vr) = voxel_rows
                    .as_ref()
                    .and_then(|v| v.iter().find(|r| r.0 == *name))
                {
                    v["voxel"] = serde_json::to_value(vr.1).expect("plain numbers");
                }
                (name.to_string(), v)
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&map)?);
    } else {
        println!(
            "{} frames of {}{}",
            summaries[0].1[0].frames,
            dataset.display(),
            if things_only {
                " (rules refine things only)"
            } else {
                ""
            }
        );
        for (k, part) in ["all segments", "things", "stuff"].iter().enumerate() {
            println!("{part}:");
            println!(
                "{:<9} {:>9} {:>7} {:>7} {:>7} {:>9} {:>7}",
                "masks", "mIoU", "PQ", "SQ", "RQ", "precision", "recall"
            );
            for (name, s) in &summaries {
                let s = &s[k];
                println!(
                    "{:<9} {:>9.2} {:>7.2} {:>7.2} {:>7.2} {:>9.2} {:>7.2}",
                    name, s.mean_matched_iou, s.pq, s.sq, s.rq, s.precision, s.recall
                );
            }
        }
    }
    if let (Some(v), false) = (&voxel_rows, args.json) {
        println!("maps against the map of the ground-truth segmentation (voxels):");
        println!(
            "{:<9} {:>7} {:>7} {:>7} {:>5} {:>5} {:>5}",
            "masks", "PQ", "SQ", "RQ", "TP", "FP", "FN"
        );
        for (name, s) in v {
            println!(
                "{:<9} {:>7.2} {:>7.2} {:>7.2} {:>5} {:>5} {:>5}",
                name, s.pq, s.sq, s.rq, s.tp, s.fp, s.fn_
            );
        }
    }
    if let Some(dir) = &args.report {
        // Illustrate refinement on the first selected frame with a thing segment.
        let sample = selected.iter().find_map(|&i| {
            let f = source.load(i).ok()?;
            let s = f.segments?;
            s.segments
                .iter()
                .any(|seg| seg.is_thing == Some(true))
                .then_some((f.id, f.depth, s.labels, s.segments))
        });
        let data = super::report::ReportData {
            dataset: &dataset,
            rows: &summaries,
            per_frame: &per_frame,
            sample,
            voxel: voxel_rows.as_deref(),
        };
        super::report::write_report(dir, &data)?;
        eprintln!("wrote {}", dir.join("report.html").display());
    }
    Ok(())
}

/// A kind of mask error: the model that makes it at a given strength.
type ErrorModel = fn(f64) -> MaskErrors;

/// `voxpan eval --sweep`: the synthetic benchmark of the refinement rules.
fn sweep(args: &Args) -> Result<()> {
    if args.sweep_frames == 0 {
        bail!("--sweep-frames must be at least 1");
    }
    let root = std::env::temp_dir().join(format!("voxpan-sweep-{}", std::process::id()));
    let kinds: [(&str, ErrorModel); 2] = [
        ("over-cover", MaskErrors::over_cover_only),
        ("mix", MaskErrors::new),
    ];
    let sequences: Vec<(&str, ErrorModel, f64)> = kinds
        .iter()
        .flat_map(|&(mode, errors)| [0.5, 1.0, 1.5, 2.0].map(|s| (mode, errors, s)))
        .collect();
    let mut results = Vec::new();
    for (k, &(mode, errors, strength)) in sequences.iter().enumerate() {
        eprintln!("sequence {}/{}: {mode} {strength}", k + 1, sequences.len());
        let dir = root.join(format!("{mode}-{strength}"));
        let config = SynthConfig {
            frames: args.sweep_frames,
            width: 320,
            height: 240,
            seed: 11,
            masks: errors(strength),
            ..SynthConfig::default()
        };
        let scored = generate(&dir, &config, |_| {})
            .with_context(|| format!("generating into {}", dir.display()))
            .and_then(|_| {
                let source = open_dataset(&dir)?;
                let selected: Vec<usize> = (0..source.len()).collect();
                score_masks(
                    source.as_ref(),
                    &selected,
                    &ROWS,
                    args.things_only,
                    args.fill,
                    None,
                )
            });
        // The sequences are large and reproducible from the seed: never leave them behind.
        let _ = std::fs::remove_dir_all(&dir);
        let scored = scored?;
        let summaries: Vec<MaskSummary> = scored.totals.iter().map(|t| t[0].summary()).collect();
        results.push((mode, strength, summaries));
    }
    let _ = std::fs::remove_dir_all(&root);
    if args.json {
        let list: Vec<serde_json::Value> = results
            .iter()
            .map(|(mode, strength, summaries)| {
                let mut v = serde_json::json!({ "errors": mode, "strength": strength });
                for ((name, _), s) in ROWS.iter().zip(summaries) {
                    v[*name] = serde_json::to_value(s).expect("plain numbers");
                }
                v
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&list)?);
        return Ok(());
    }
    println!(
        "synthetic sweep ({} frames of 320x240 per sequence, seed 11): mean matched IoU / PQ",
        args.sweep_frames
    );
    print!("{:<16}", "errors");
    for (name, _) in ROWS {
        print!(" {name:>15}");
    }
    println!();
    for (mode, strength, summaries) in &results {
        print!("{:<16}", format!("{mode} {strength}"));
        for s in summaries {
            print!(
                " {:>15}",
                format!("{:.2} / {:.2}", s.mean_matched_iou, s.pq)
            );
        }
        println!();
    }
    Ok(())
}

/// Pooled scores per row ([all, things, stuff]) and each frame's mean matched IoU per row.
struct Scored {
    totals: Vec<[MaskScores; 3]>,
    per_frame: Vec<(String, Vec<f64>)>,
}

/// Scores every selected frame under every row (in parallel); frames that fail are skipped
/// with a warning naming them.
fn score_masks(
    source: &dyn FrameSource,
    selected: &[usize],
    rows: &[(&str, Option<Rule>)],
    things_only: bool,
    fill: bool,
    pred: Option<&PathBuf>,
) -> Result<Scored> {
    let bar = ProgressBar::new(selected.len() as u64).with_style(
        ProgressStyle::with_template("scoring [{bar:40}] {pos}/{len} frames, {per_sec}")
            .expect("static template"),
    );
    let per_thread = || {
        let filler = fill.then(|| HoleFiller::new(FillParams::default()));
        let refiners = rows
            .iter()
            .map(|(_, rule)| {
                rule.map(|r| {
                    Refiner::new(RefineConfig {
                        things_only,
                        ..RefineConfig::new(r)
                    })
                })
            })
            .collect::<Vec<_>>();
        (filler, refiners)
    };
    let results: Vec<Result<Vec<[MaskScores; 3]>>> = selected
        .par_iter()
        .map_init(per_thread, |(filler, refiners), &i| {
            let scores = score_frame(source, i, filler.as_mut(), refiners, pred);
            bar.inc(1);
            scores
        })
        .collect();
    bar.finish_and_clear();

    let mut totals = vec![
        [
            MaskScores::default(),
            MaskScores::default(),
            MaskScores::default()
        ];
        rows.len()
    ];
    let mut failed = 0;
    let mut per_frame: Vec<(String, Vec<f64>)> = Vec::new();
    for (r, &i) in results.into_iter().zip(selected) {
        match r {
            Ok(scores) => {
                per_frame.push((
                    source.frame_id(i).to_owned(),
                    scores
                        .iter()
                        .map(|s| s[0].summary().mean_matched_iou)
                        .collect(),
                ));
                for (t, s) in totals.iter_mut().zip(&scores) {
                    for k in 0..3 {
                        t[k].merge(&s[k]);
                    }
                }
            }
            Err(e) => {
                failed += 1;
                eprintln!("warning: frame {} skipped: {e:#}", source.frame_id(i));
            }
        }
    }
    if failed == selected.len() {
        bail!("no frame could be scored");
    }
    Ok(Scored { totals, per_frame })
}

/// Voxel panoptic quality of the map of each row against the map of the ground truth.
fn voxel_scores(
    dataset: &std::path::Path,
    selected: &[usize],
    rows: &[(&'static str, Option<Rule>)],
    things_only: bool,
) -> Result<Vec<(&'static str, voxpan_eval::volume::VoxelPq)>> {
    use std::sync::atomic::AtomicBool;
    use voxpan_pipeline::{build_map, Refinement, RunConfig, SegmentSource};
    let source: std::sync::Arc<dyn FrameSource> = std::sync::Arc::from(open_dataset(dataset)?);
    let stop = AtomicBool::new(false);
    let build = |config: RunConfig| {
        build_map(
            source.clone(),
            selected.to_vec(),
            &config,
            None,
            &stop,
            |_| {},
        )
    };
    eprintln!("building the ground-truth map");
    let truth = build(RunConfig {
        segments: SegmentSource::Gt,
        refine: Refinement::None,
        ..RunConfig::default()
    })?;
    let mut out = Vec::new();
    for (name, rule) in rows {
        eprintln!("building the {name} map");
        let refine = match rule {
            None => Refinement::None,
            Some(Rule::Paper) => Refinement::Paper,
            Some(Rule::Release) => Refinement::Release,
            Some(Rule::Default) => Refinement::Default,
        };
        let map = build(RunConfig {
            refine,
            things_only,
            ..RunConfig::default()
        })?;
        out.push((
            *name,
            voxpan_eval::volume::voxel_pq(&map.layer, &truth.layer),
        ));
    }
    Ok(out)
}

/// One frame's matching for every row.
fn score_frame(
    source: &dyn FrameSource,
    index: usize,
    filler: Option<&mut HoleFiller>,
    refiners: &mut [Option<Refiner>],
    pred_dir: Option<&PathBuf>,
) -> Result<Vec<[MaskScores; 3]>> {
    let mut frame = source.load(index)?;
    if let Some(filler) = filler {
        filler.fill(&mut frame.depth);
    }
    let gt = frame
        .ground_truth
        .as_ref()
        .with_context(|| format!("frame {} has no ground-truth segmentation", frame.id))?;
    let mut out = Vec::with_capacity(refiners.len());
    if let Some(dir) = pred_dir {
        let path = [
            format!("{}.png", frame.id),
            format!("{}_predicted.png", frame.id),
        ]
        .into_iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file())
        .with_context(|| format!("no {}.png in {}", frame.id, dir.display()))?;
        let labels = read_label_png(&path)?;
        if labels.dims() != gt.dims() {
            bail!("{}: size differs from the ground truth", path.display());
        }
        // Without a segment list, predicted ids are of unknown kind: scored in "all" only.
        out.push(score_parts(
            &labels,
            gt,
            |_| None,
            |id| source.ground_truth_is_thing(id),
        ));
        return Ok(out);
    }
    let segments = frame
        .segments
        .as_ref()
        .with_context(|| format!("frame {} has no predicted segments", frame.id))?;
    for refiner in refiners.iter_mut() {
        let mut labels = segments.labels.clone();
        if let Some(refiner) = refiner {
            refiner.refine_frame(&frame.depth, &mut labels, &segments.segments)?;
        }
        let kind = |id: u16| {
            segments
                .segments
                .iter()
                .find(|s| s.id == id)
                .and_then(|s| s.is_thing)
        };
        out.push(score_parts(&labels, gt, kind, |id| {
            source.ground_truth_is_thing(id)
        }));
    }
    Ok(out)
}

/// All segments, things only, stuff only.
fn score_parts(
    pred: &LabelImage,
    gt: &LabelImage,
    pred_thing: impl Fn(u16) -> Option<bool>,
    gt_thing: impl Fn(u16) -> Option<bool>,
) -> [MaskScores; 3] {
    let mut out = [
        MaskScores::default(),
        MaskScores::default(),
        MaskScores::default(),
    ];
    out[0].add(&match_frame(pred, gt));
    out[1].add(&match_frame_subset(
        pred,
        gt,
        |id| pred_thing(id) == Some(true),
        |id| gt_thing(id) == Some(true),
    ));
    out[2].add(&match_frame_subset(
        pred,
        gt,
        |id| pred_thing(id) == Some(false),
        |id| gt_thing(id) == Some(false),
    ));
    out
}
