//! The 2-D mask protocol over a dataset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use voxpan_core::LabelImage;
use voxpan_dataset::FrameSource;
use voxpan_eval::{MaskScores, MaskSummary, match_frame, match_frame_subset};
use voxpan_fill::{FillConfig, HoleFiller};
use voxpan_map::PanopticMap;
use voxpan_refine::{RefineConfig, Refiner, Rule};

use super::EvalError;
use crate::SkippedFrame;

/// What is scored.
#[derive(Clone, Debug)]
pub enum Predictions {
    /// The dataset's own predicted masks, refined by each rule (`Rule::None` = as given).
    Rules(Vec<Rule>),
    /// Label images `DIR/NNNNNN.png` (or `NNNNNN_predicted.png`), scored as they are.
    Folder(PathBuf),
    /// A map's instances seen from each frame's camera (the map ray-cast into the frame):
    /// what the map says about every frame once it has seen them all.
    Map {
        name: String,
        map: std::sync::Arc<PanopticMap>,
    },
}

/// How masks are prepared before scoring.
#[derive(Clone, Copy, Debug, Default)]
pub struct MaskOptions {
    /// Refine only segments the segment list marks as things.
    pub things_only: bool,
    /// Fill depth holes before refining (off by default: refinement reads measured depth).
    pub fill: bool,
}

/// One row of the table: a rule (or the folder), scored over all segments, things and stuff.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MaskRow {
    pub name: String,
    pub all: MaskSummary,
    pub things: MaskSummary,
    pub stuff: MaskSummary,
}

/// The table, each frame's mean matched IoU per row, and the frames that failed.
#[derive(Clone, Debug)]
pub struct MaskEvaluation {
    pub rows: Vec<MaskRow>,
    /// `(frame id, mean matched IoU per row)`.
    pub per_frame: Vec<(String, Vec<f64>)>,
    pub skipped: Vec<SkippedFrame>,
}

impl MaskEvaluation {
    /// Adds `other`'s rows (of the same frames) after this one's.
    pub fn append(&mut self, other: MaskEvaluation) {
        self.rows.extend(other.rows);
        let mut by_frame: BTreeMap<String, Vec<f64>> = other.per_frame.into_iter().collect();
        let width = self.rows.len();
        for (frame, values) in &mut self.per_frame {
            values.extend(by_frame.remove(frame).unwrap_or_default());
            values.resize(width, f64::NAN);
        }
        self.skipped.extend(other.skipped);
    }
}

/// Scores the `selected` frames of `source` (in parallel; `progress` is called per frame).
/// Frames that fail are skipped and listed; if all fail, the error says why the first did.
pub fn score_masks(
    source: &dyn FrameSource,
    selected: &[usize],
    predictions: &Predictions,
    options: MaskOptions,
    progress: impl Fn() + Sync,
) -> Result<MaskEvaluation, EvalError> {
    let names: Vec<String> = match predictions {
        Predictions::Rules(rules) => rules.iter().map(|r| r.name().to_owned()).collect(),
        Predictions::Folder(_) => vec!["pred".to_owned()],
        Predictions::Map { name, .. } => vec![name.clone()],
    };
    let per_thread = || {
        let filler = options
            .fill
            .then(|| HoleFiller::new(FillConfig::default().params()));
        let refiners: Vec<Refiner> = match predictions {
            Predictions::Rules(rules) => rules
                .iter()
                .map(|&rule| {
                    Refiner::new(RefineConfig {
                        things_only: options.things_only,
                        ..RefineConfig::new(rule)
                    })
                })
                .collect(),
            Predictions::Folder(_) | Predictions::Map { .. } => Vec::new(),
        };
        (filler, refiners)
    };
    // Kinds of a map's instances, once (each lookup walks the map's surface).
    let map_kinds: BTreeMap<u16, bool> = match predictions {
        Predictions::Map { map, .. } => {
            map.instances().iter().map(|i| (i.id, i.is_thing)).collect()
        }
        _ => BTreeMap::new(),
    };
    let results: Vec<Result<Vec<[MaskScores; 3]>, String>> = selected
        .par_iter()
        .map_init(per_thread, |(filler, refiners), &i| {
            let scores = score_frame(
                source,
                i,
                filler.as_mut(),
                refiners,
                predictions,
                &map_kinds,
            );
            progress();
            scores
        })
        .collect();
    let mut totals = vec![
        [
            MaskScores::default(),
            MaskScores::default(),
            MaskScores::default()
        ];
        names.len()
    ];
    let mut per_frame = Vec::new();
    let mut skipped = Vec::new();
    for (result, &i) in results.into_iter().zip(selected) {
        let frame = source.frame_id(i).to_owned();
        match result {
            Ok(scores) => {
                per_frame.push((
                    frame,
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
            Err(reason) => skipped.push(SkippedFrame { frame, reason }),
        }
    }
    if per_frame.is_empty() {
        let first = skipped
            .first()
            .map_or("no frames selected".to_owned(), |s| {
                format!("frame {}: {}", s.frame, s.reason)
            });
        return Err(EvalError::NoFrames(first));
    }
    let rows = names
        .into_iter()
        .zip(totals)
        .map(|(name, t)| MaskRow {
            name,
            all: t[0].summary(),
            things: t[1].summary(),
            stuff: t[2].summary(),
        })
        .collect();
    Ok(MaskEvaluation {
        rows,
        per_frame,
        skipped,
    })
}

/// The prediction file for a frame in a folder.
fn prediction_file(dir: &Path, frame: &str) -> Option<PathBuf> {
    [format!("{frame}.png"), format!("{frame}_predicted.png")]
        .into_iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file())
}

/// One frame's scores for every row.
fn score_frame(
    source: &dyn FrameSource,
    index: usize,
    filler: Option<&mut HoleFiller>,
    refiners: &mut [Refiner],
    predictions: &Predictions,
    map_kinds: &BTreeMap<u16, bool>,
) -> Result<Vec<[MaskScores; 3]>, String> {
    let mut frame = source
        .load(index)
        .map_err(|e| e.without_frame().to_string())?;
    if let Some(filler) = filler {
        filler.fill(&mut frame.depth);
    }
    let gt = frame
        .ground_truth
        .as_ref()
        .ok_or("no ground-truth segmentation")?;
    let gt_thing = |id: u16| source.ground_truth_is_thing(id);
    if let Predictions::Map { map, .. } = predictions {
        let view = map.render(&frame.intrinsics, &frame.pose);
        let kind = |id: u16| map_kinds.get(&id).copied();
        return Ok(vec![score_parts(&view.instances, gt, kind, gt_thing)]);
    }
    if let Predictions::Folder(dir) = predictions {
        let path = prediction_file(dir, &frame.id)
            .ok_or_else(|| format!("no {}.png in {}", frame.id, dir.display()))?;
        let labels = voxpan_io::read_label_png(&path).map_err(|e| e.to_string())?;
        if labels.dims() != gt.dims() {
            return Err(format!(
                "{}: {}x{}, but the ground truth is {}x{}",
                path.display(),
                labels.width(),
                labels.height(),
                gt.width(),
                gt.height()
            ));
        }
        // The segment list beside the image says each id's kind; without one, predicted ids
        // are of unknown kind and scored in "all" only.
        let listed = [
            format!("{}_labels.json", frame.id),
            format!("{}.json", frame.id),
        ]
        .into_iter()
        .map(|name| dir.join(name))
        .find(|p| p.is_file());
        let kinds: BTreeMap<u16, bool> = match listed {
            Some(p) => voxpan_io::read_segments_json(&p)
                .map_err(|e| e.to_string())?
                .into_iter()
                .filter_map(|s| Some((s.id, s.is_thing?)))
                .collect(),
            None => BTreeMap::new(),
        };
        let kind = |id: u16| kinds.get(&id).copied();
        return Ok(vec![score_parts(&labels, gt, kind, gt_thing)]);
    }
    let segments = frame.segments.as_ref().ok_or("no predicted segments")?;
    let mut out = Vec::with_capacity(refiners.len());
    for refiner in refiners.iter_mut() {
        let mut labels = segments.labels.clone();
        refiner
            .refine_frame(&frame.depth, &mut labels, &segments.segments)
            .map_err(|e| e.to_string())?;
        let kind = |id: u16| segments.get(id).and_then(|s| s.is_thing);
        out.push(score_parts(&labels, gt, kind, gt_thing));
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
