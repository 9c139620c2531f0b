use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};
use voxpan_dataset::{FrameSource, open_dataset};
use voxpan_pipeline::Config;
use voxpan_pipeline::protocols::{
    MaskEvaluation, MaskOptions, Predictions, VoxelRow, score_from_maps, score_masks, sweep,
    voxel_rows,
};
use voxpan_refine::Rule;
use voxpan_report::{
    EvalReport, SampleFrame, VOXEL_COLUMNS, VOXEL_LEGEND, voxel_table, write_eval_report,
};

use super::frames::FrameRange;
use super::run::select;

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
    /// Also build maps (2 cm voxels) and score them against a tracker-free reference (the
    /// ground-truth segmentation fused with its own ids): ground-truth masks with per-frame
    /// random ids, the dataset's masks under each rule, and the default rule's masks with
    /// correct association. Panoptic quality over voxels, things and stuff, split and merged
    /// objects.
    #[arg(long = "3d", conflicts_with = "pred")]
    three_d: bool,
    /// With --3d, also score the default rule's map as a live reader (a mapping node, a
    /// viewer) holds it when the stream stops: without the consolidation after the last frame,
    /// with the passes `[tracking] consolidate_every` in --config makes on the way.
    #[arg(long, requires = "three_d")]
    live: bool,
    /// Also build the default rule's map (with the tracker, and with correct association),
    /// ray-cast it into every frame and score those masks beside the per-frame rows.
    #[arg(long, conflicts_with = "pred")]
    from_map: bool,
    /// The refinement rules to score (comma-separated; default all: none, paper, release,
    /// default).
    #[arg(long, value_delimiter = ',', conflicts_with = "pred")]
    rules: Vec<Rule>,
    /// Configuration for the maps of --3d and --from-map (TOML, as for `voxpan run`; its
    /// [refine] rule is replaced by each row's).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Also write report.md and report.html with plots into this folder.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Print JSON: per row, mean_matched_iou, pq, sq, rq, precision, recall (percent).
    #[arg(long)]
    json: bool,
}

fn progress_bar(len: usize, what: &str) -> ProgressBar {
    ProgressBar::new(len as u64).with_style(
        ProgressStyle::with_template(&format!(
            "{what} [{{bar:40}}] {{pos}}/{{len}} frames, {{per_sec}}"
        ))
        .expect("static template"),
    )
}

pub fn run(args: Args) -> Result<()> {
    let options = MaskOptions {
        things_only: args.things_only,
        fill: args.fill,
    };
    let Some(dataset) = args.dataset.clone() else {
        return run_sweep(&args, options);
    };
    let mut map_config = match &args.config {
        Some(path) => Config::from_toml_file(path)?,
        None => Config::default(),
    };
    map_config.refine.things_only |= args.things_only;
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(&dataset)?);
    super::warn_skipped(
        source
            .skipped()
            .iter()
            .map(|(f, r)| (f.as_str(), r.as_str())),
    );
    let selected = select(source.as_ref(), args.frames);
    if selected.is_empty() {
        anyhow::bail!("no frame of {} in the selected range", dataset.display());
    }
    let predictions = match &args.pred {
        Some(dir) => {
            let has_lists = std::fs::read_dir(dir).is_ok_and(|entries| {
                entries
                    .flatten()
                    .any(|e| e.path().extension().is_some_and(|x| x == "json"))
            });
            if !has_lists {
                eprintln!(
                    "note: {} has no NNNNNN_labels.json: without segment lists the predicted \
                     ids have no thing/stuff kind, so only the \"all\" scores mean anything",
                    dir.display()
                );
            }
            Predictions::Folder(dir.clone())
        }
        None if args.rules.is_empty() => Predictions::Rules(Rule::ALL.to_vec()),
        None => Predictions::Rules(args.rules.clone()),
    };
    let bar = progress_bar(selected.len(), "scoring");
    let mut evaluation = score_masks(source.as_ref(), &selected, &predictions, options, || {
        bar.inc(1)
    })?;
    bar.finish_and_clear();
    if args.from_map {
        let rendered = score_from_maps(&source, &selected, &map_config, options, |what| {
            eprintln!("{what}")
        })?;
        evaluation.append(rendered);
    }
    super::warn_skipped(
        evaluation
            .skipped
            .iter()
            .map(|s| (s.frame.as_str(), s.reason.as_str())),
    );
    let voxel = match (&predictions, args.three_d) {
        (Predictions::Rules(rules), true) => Some(voxel_rows(
            &source,
            &selected,
            rules,
            &map_config,
            args.live,
            |name| eprintln!("building the {name} map"),
        )?),
        _ => None,
    };
    if args.json {
        print_json(&evaluation, voxel.as_deref())?;
    } else {
        print_tables(&evaluation, &dataset, args.things_only);
        if let Some(rows) = &voxel {
            println!("maps against the tracker-free reference (panoptic quality over voxels):");
            let print = |cells: &[String]| {
                println!(
                    "{:<30}{}",
                    cells[0],
                    cells[1..]
                        .iter()
                        .map(|c| format!(" {c:>9}"))
                        .collect::<String>()
                )
            };
            print(&VOXEL_COLUMNS.map(str::to_owned));
            for cells in voxel_table(rows) {
                print(&cells);
            }
            println!("{VOXEL_LEGEND}");
        }
    }
    if let Some(dir) = &args.report {
        // Illustrate refinement on the first selected frame with a thing segment.
        let sample = selected
            .iter()
            .find_map(|&i| SampleFrame::from_frame(source.load(i).ok()?));
        write_eval_report(
            dir,
            &EvalReport {
                dataset: &dataset,
                evaluation: &evaluation,
                sample,
                voxel: voxel.as_deref(),
            },
        )?;
        eprintln!("wrote {}", dir.join("report.html").display());
    }
    Ok(())
}

fn print_json(evaluation: &MaskEvaluation, voxel: Option<&[VoxelRow]>) -> Result<()> {
    let mut map: serde_json::Map<String, serde_json::Value> = evaluation
        .rows
        .iter()
        .map(|row| {
            // The whole-image scores at the top, things and stuff nested.
            let mut v = serde_json::to_value(row.all).expect("plain numbers");
            v["things"] = serde_json::to_value(row.things).expect("plain numbers");
            v["stuff"] = serde_json::to_value(row.stuff).expect("plain numbers");
            (row.name.clone(), v)
        })
        .collect();
    if let Some(rows) = voxel {
        // Maps, by name, against the tracker-free reference.
        let maps: serde_json::Map<String, serde_json::Value> = rows
            .iter()
            .map(|r| {
                (
                    r.name.clone(),
                    serde_json::to_value(r.scores).expect("plain numbers"),
                )
            })
            .collect();
        map.insert("voxel".into(), maps.into());
    }
    println!("{}", serde_json::to_string_pretty(&map)?);
    Ok(())
}

fn print_tables(evaluation: &MaskEvaluation, dataset: &std::path::Path, things_only: bool) {
    println!(
        "{} frames of {}{}",
        evaluation.rows[0].all.frames,
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
        for row in &evaluation.rows {
            let s = [&row.all, &row.things, &row.stuff][k];
            println!(
                "{:<9} {:>9.2} {:>7.2} {:>7.2} {:>7.2} {:>9.2} {:>7.2}",
                row.name, s.mean_matched_iou, s.pq, s.sq, s.rq, s.precision, s.recall
            );
        }
    }
}

/// `voxpan eval --sweep`: the synthetic benchmark of the refinement rules.
fn run_sweep(args: &Args, options: MaskOptions) -> Result<()> {
    let results = sweep(args.sweep_frames, options, |k, n, errors, strength| {
        eprintln!("sequence {k}/{n}: {errors} {strength}")
    })?;
    if args.json {
        let list: Vec<serde_json::Value> = results
            .iter()
            .map(|r| {
                let mut v = serde_json::json!({ "errors": r.errors, "strength": r.strength });
                for row in &r.rows {
                    v[row.name.as_str()] = serde_json::to_value(row.all).expect("plain numbers");
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
    for rule in Rule::ALL {
        print!(" {:>15}", rule.name());
    }
    println!();
    for r in &results {
        print!("{:<16}", format!("{} {}", r.errors, r.strength));
        for row in &r.rows {
            print!(
                " {:>15}",
                format!("{:.2} / {:.2}", row.all.mean_matched_iou, row.all.pq)
            );
        }
        println!();
    }
    Ok(())
}
