//! Protocols over maps: voxel panoptic quality of each rule's map, and a map against a
//! ground-truth mesh.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use voxpan_core::nalgebra::Point3;
use voxpan_core::{LabelImage, Mesh, Segments};
use voxpan_dataset::{FrameSource, stream, stream_with};
use voxpan_eval::surface::{TriangleIndex, surface_scores};
use voxpan_eval::volume::{PanopticScores, panoptic_comparison, panoptic_scores};
use voxpan_map::PanopticMap;
use voxpan_perception::{DatasetMasks, GroundTruthMasks, Perception, Segmenter};
use voxpan_refine::Rule;

use super::{EvalError, MaskEvaluation, MaskOptions, Predictions, score_masks};
use crate::{Association, Config, Ending, build_with};

/// Maps `selected` frames of `source` with `segmenter`, as `config` says, associated and
/// ended as `how` says; `progress(frames done)` after each frame.
fn map_frames(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    segmenter: Box<dyn Segmenter>,
    config: &Config,
    how: (Association, Ending),
    mut progress: impl FnMut(usize),
    stop: &AtomicBool,
) -> Result<PanopticMap, EvalError> {
    let (association, ending) = how;
    let names = match association {
        Association::Identified => source.ground_truth_class_names().cloned(),
        Association::Track if segmenter.name() == "ground truth" => {
            source.ground_truth_class_names().cloned()
        }
        Association::Track => source.network_classes().map(|t| t.names()),
    };
    let wanted = segmenter.reads();
    let perception = Perception::new(config.perception(), segmenter)?;
    let frames = stream_with(source.clone(), selected.to_vec(), wanted);
    let mut map = PanopticMap::new(config.map())?;
    map.set_class_names(names.unwrap_or_default());
    let mut done = 0;
    let on_frame = |_: crate::FrameEvent| {
        done += 1;
        progress(done);
        Ok(())
    };
    let mapped = build_with(frames, perception, map, association, ending, stop, on_frame)?;
    if mapped.report.stopped_early {
        // Part of the frames: no map to score against.
        return Err(crate::RunError::Interrupted.into());
    }
    Ok(mapped.map)
}

/// The map `voxpan run` builds with `config` (association by the tracker) from the dataset's
/// masks.
pub fn tracked_map(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
) -> Result<PanopticMap, EvalError> {
    tracked_map_ending(source, selected, config, Ending::Consolidated)
}

/// [`tracked_map`] as a live reader holds it when the stream stops: without the pass after
/// the last frame, with the passes `tracking.consolidate_every` made on the way.
pub fn live_map(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
) -> Result<PanopticMap, EvalError> {
    tracked_map_ending(source, selected, config, Ending::Live)
}

/// The dataset's masks mapped by the tracker, ended as `ending` says.
fn tracked_map_ending(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
    ending: Ending,
) -> Result<PanopticMap, EvalError> {
    map_frames(
        source,
        selected,
        Box::new(DatasetMasks),
        config,
        (Association::Track, ending),
        |_| {},
        &AtomicBool::new(false),
    )
}

/// The map the tracker builds from the ground-truth masks renumbered at random in every frame
/// (seed `seed`): association alone, with masks that are right.
pub fn random_id_map(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
    seed: u64,
) -> Result<PanopticMap, EvalError> {
    let random =
        GroundTruthMasks::new(source.ground_truth_classes().cloned()).with_random_ids(seed);
    map_frames(
        source,
        selected,
        Box::new(random),
        &with_rule(config, Rule::None),
        (Association::Track, Ending::Consolidated),
        |_| {},
        &AtomicBool::new(false),
    )
}

/// `config` with refinement rule `rule`.
fn with_rule(config: &Config, rule: Rule) -> Config {
    let mut c = *config;
    c.refine.rule = rule;
    c
}

/// `config` with no instance hidden for its size or for being seen in one frame only.
fn every_instance_shown(config: &Config) -> Config {
    let mut c = *config;
    c.tracking.min_voxels = 0;
    c.tracking.min_observations = 1;
    c
}

/// `config` segmenting every frame, in order: what the reference and the correct-association
/// ceiling are built with, whatever `[segment] every` and `own_thread` the maps under test use.
fn every_frame_segmented(config: &Config) -> Config {
    let mut c = *config;
    c.segment.every = Default::default();
    c.segment.own_thread = false;
    c
}

/// Masks rendered from maps, scored with the 2-D protocol: the default rule's map as the
/// tracker builds it, and with correct association. Each map is built from every selected
/// frame, then ray-cast into each of them.
pub fn score_from_maps(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
    options: MaskOptions,
    progress: impl Fn(&str),
) -> Result<MaskEvaluation, EvalError> {
    let config = with_rule(config, Rule::Default);
    progress("map: default");
    let tracked = tracked_map(source, selected, &config)?;
    progress("map: default, correct association");
    let oracle = correctly_associated_map(source, selected, &config)?;
    let mut out: Option<MaskEvaluation> = None;
    for (name, map) in [
        ("map: default", tracked),
        ("map: default, correct assoc.", oracle),
    ] {
        progress(&format!("rendering {name} into every frame"));
        let predictions = Predictions::Map {
            name: name.into(),
            map: Arc::new(map),
        };
        let scored = score_masks(source.as_ref(), selected, &predictions, options, || {})?;
        match &mut out {
            None => out = Some(scored),
            Some(all) => all.append(scored),
        }
    }
    Ok(out.expect("two maps"))
}

/// The tracker-free reference: every frame's ground-truth segmentation fused with its ids as
/// instance ids (every id, 0 included where the label table lists it), so each surface voxel
/// holds the ground-truth object most of its observations saw. No association is involved:
/// a better tracker can only score higher against it. Every object is kept, however small
/// (`tracking.min_voxels` is a map's display choice, not the truth's).
pub fn reference_map(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
) -> Result<PanopticMap, EvalError> {
    reference_map_with_progress(source, selected, config, |_| {}, &AtomicBool::new(false))
}

/// [`reference_map`], calling `progress(frames done)` after each frame; ends with
/// `RunError::Interrupted` once `stop` is set.
fn reference_map_with_progress(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
    progress: impl FnMut(usize),
    stop: &AtomicBool,
) -> Result<PanopticMap, EvalError> {
    let truth = GroundTruthMasks::new(source.ground_truth_classes().cloned());
    map_frames(
        source,
        selected,
        Box::new(truth),
        &every_frame_segmented(&every_instance_shown(&with_rule(config, Rule::None))),
        (Association::Identified, Ending::Consolidated),
        progress,
        stop,
    )
}

/// A map's instances against the tracker-free reference: the scores, and the reference object
/// each matched instance is (the voxel PQ's true positives, IoU > 0.5).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ReferenceComparison {
    pub scores: PanopticScores,
    /// In map instance order; instances that matched nothing are absent.
    pub matches: Vec<ObjectMatch>,
    /// The true objects no instance matched (the false negatives), and where their surface
    /// voxels went: into which instances, or into none shown.
    pub missed: Vec<MissedObject>,
}

impl ReferenceComparison {
    /// The object map instance `id` matched, if any.
    pub fn match_of(&self, id: u16) -> Option<&ObjectMatch> {
        self.matches.iter().find(|m| m.instance == id)
    }
}

/// A map instance and the true object it matched.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ObjectMatch {
    pub instance: u16,
    /// The object's id in the ground-truth segmentation images (`None` only for a reference
    /// id no ground-truth id maps to, which the reference never makes).
    pub truth_id: Option<u16>,
    /// The object's class name from the ground truth's label table, when it has one.
    pub class: Option<String>,
    /// Voxel IoU, above 0.5.
    pub iou: f64,
}

/// A true object no map instance matched.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MissedObject {
    /// Its id in the ground-truth segmentation images (see [`ObjectMatch::truth_id`]).
    pub truth_id: Option<u16>,
    pub class: Option<String>,
    /// Its surface voxels in the reference.
    pub voxels: usize,
    /// The map instances holding most of those voxels, with how many each holds (largest
    /// first, at most three).
    pub holders: Vec<(u16, usize)>,
    /// Those of its voxels no shown instance leads (never labelled, or led by an instance
    /// still hidden).
    pub unlabelled: usize,
}

/// `map` (built from `selected` frames of `source` as `config` says) against the tracker-free
/// reference of the same frames; `None` when the dataset has no ground-truth segmentation.
/// Building the reference maps every frame again: `progress(frames done)` follows it, and
/// `stop` ends it (`RunError::Interrupted`) within a frame.
pub fn panoptic_against_reference(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
    map: &PanopticMap,
    progress: impl FnMut(usize),
    stop: &AtomicBool,
) -> Result<Option<ReferenceComparison>, EvalError> {
    let has_truth = selected
        .iter()
        .find_map(|&i| source.load(i).ok())
        .is_some_and(|f| f.ground_truth.is_some());
    if !has_truth {
        return Ok(None);
    }
    let reference = reference_map_with_progress(source, selected, config, progress, stop)?;
    let comparison = panoptic_comparison(map, &reference);
    // The reference's instance ids are its segment ids: turn them back into ground-truth ids.
    let ids = GroundTruthMasks::new(source.ground_truth_classes().cloned());
    let class = |object: u16| {
        reference
            .class_of(object)
            .and_then(|c| reference.class_name(c))
            .map(str::to_owned)
    };
    let matches = comparison
        .matches
        .into_iter()
        .map(|m| ObjectMatch {
            instance: m.instance,
            truth_id: ids.truth_id(m.object),
            class: class(m.object),
            iou: m.iou,
        })
        .collect();
    let missed = comparison
        .unmatched
        .into_iter()
        .map(|o| MissedObject {
            truth_id: ids.truth_id(o.object),
            class: class(o.object),
            voxels: o.voxels,
            holders: o.holders,
            unlabelled: o.unlabelled,
        })
        .collect();
    Ok(Some(ReferenceComparison {
        scores: comparison.scores,
        matches,
        missed,
    }))
}

/// The name of [`voxel_rows`]' live row.
pub const LIVE_ROW: &str = "default, live";

/// One kind of map scored against the reference.
#[derive(Clone, Debug, serde::Serialize)]
pub struct VoxelRow {
    /// `gt random ids`, a rule name, [`LIVE_ROW`], or `default, correct association`.
    pub name: String,
    pub scores: PanopticScores,
}

/// `segments` relabelled as a perfect tracker would: each segment takes the id of the
/// ground-truth object it covers most (segments on the same object share its id).
fn correctly_associated(
    segments: &Segments,
    truth: &LabelImage,
    ids: &GroundTruthMasks,
) -> Segments {
    let mut votes: BTreeMap<(u16, u16), usize> = BTreeMap::new();
    for (&l, &g) in segments.labels.pixels().iter().zip(truth.pixels()) {
        if l != 0 {
            *votes.entry((l, g)).or_default() += 1;
        }
    }
    let mut best: BTreeMap<u16, (usize, u16)> = BTreeMap::new();
    for (&(l, g), &n) in &votes {
        let e = best.entry(l).or_insert((0, 0));
        if n > e.0 {
            *e = (n, g);
        }
    }
    let mut relabel = vec![0u16; u16::MAX as usize + 1];
    let mut out = Segments {
        labels: segments.labels.clone(),
        segments: Vec::new(),
    };
    for s in &segments.segments {
        if let Some(id) = best.get(&s.id).and_then(|&(_, g)| ids.segment_id(g)) {
            relabel[s.id as usize] = id;
            if out.get(id).is_none() {
                out.segments.push(voxpan_core::Segment { id, ..s.clone() });
            }
        }
    }
    out.labels = segments.labels.map(|&l| relabel[l as usize]);
    out
}

/// The dataset's masks perceived as `config` says, associated correctly (see
/// [`correctly_associated`]): what association could reach with these masks, every frame
/// segmented.
pub fn correctly_associated_map(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    config: &Config,
) -> Result<PanopticMap, EvalError> {
    let config = every_frame_segmented(config);
    let mut perception = Perception::new(config.perception(), Box::new(DatasetMasks))?;
    let ids = GroundTruthMasks::new(source.ground_truth_classes().cloned());
    let mut map = PanopticMap::new(config.map())?;
    map.set_class_names(
        source
            .network_classes()
            .map(|t| t.names())
            .unwrap_or_default(),
    );
    for frame in stream(source.clone(), selected.to_vec()).flatten() {
        let perceived = perception.process(frame)?;
        let (Some(segments), Some(truth)) = (&perceived.segments, &perceived.frame.ground_truth)
        else {
            continue;
        };
        let segments = correctly_associated(segments, truth, &ids);
        map.integrate_identified(perceived.frame.view(), &segments)?;
    }
    // Shown as the tracker's map is after its last pass.
    map.judge_instances();
    Ok(map)
}

/// The maps `voxpan eval --3d` compares, each against the tracker-free reference: ground-truth
/// masks with per-frame random ids (association alone), the dataset's masks under each rule,
/// and the default rule's masks with correct association (association's ceiling for them);
/// with `live`, also the default rule's tracked map as a live reader holds it when the stream
/// stops ([`live_map`]). `progress(name)` is called before each map is built.
pub fn voxel_rows(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    rules: &[Rule],
    config: &Config,
    live: bool,
    progress: impl Fn(&str),
) -> Result<Vec<VoxelRow>, EvalError> {
    progress("reference (ground truth, no association)");
    let reference = reference_map(source, selected, config)?;
    let mut rows = Vec::new();
    let mut add = |name: String, map: PanopticMap| {
        rows.push(VoxelRow {
            name,
            scores: panoptic_scores(&map, &reference),
        });
    };
    progress("gt random ids");
    add(
        "gt random ids".into(),
        random_id_map(source, selected, config, 7)?,
    );
    for &rule in rules {
        progress(rule.name());
        add(
            rule.name().into(),
            tracked_map(source, selected, &with_rule(config, rule))?,
        );
    }
    if live {
        progress(LIVE_ROW);
        add(
            LIVE_ROW.into(),
            live_map(source, selected, &with_rule(config, Rule::Default))?,
        );
    }
    progress("default, correct association");
    add(
        "default, correct association".into(),
        correctly_associated_map(source, selected, &with_rule(config, Rule::Default))?,
    );
    Ok(rows)
}

/// A map against a ground-truth mesh; distances within one voxel count as hits.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct SurfaceReport {
    /// Distance from every mesh vertex to the true surface, metres.
    pub accuracy_mean_m: f64,
    pub accuracy_median_m: f64,
    pub accuracy_p95_m: f64,
    /// Percent of mesh vertices within a voxel of the true surface.
    pub accuracy_within: f64,
    /// Percent of the observed true surface within a voxel of the mesh.
    pub completeness_within: f64,
    /// Percent of labelled surface voxels whose map instance's majority true instance is
    /// their own true instance.
    pub label_agreement: f64,
}

/// Accuracy, completeness and label agreement of `map` (whose mesh is `mesh`) against
/// `truth`, a mesh whose vertices carry true instance ids.
pub fn surface_report(map: &PanopticMap, mesh: &Mesh, truth: &Mesh) -> SurfaceReport {
    let voxel = map.voxel_size();
    let vertices: Vec<Point3<f64>> = mesh
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let triangles = truth.triangle_points();
    // Completeness counts the truth the cameras saw: samples inside the observed band.
    let seen = |p: &Point3<f64>| {
        map.voxel(p)
            .is_some_and(|v| (v.distance.abs() as f64) < voxel)
    };
    let scores = surface_scores(&vertices, triangles.clone(), voxel, voxel / 2.0, seen);
    // Each labelled surface voxel: its map instance and the true instance of the nearest
    // true triangle.
    let index = TriangleIndex::new(triangles, 2.0 * voxel);
    let mut pairs: Vec<(u16, u16)> = Vec::new();
    for v in map.surface_voxels().filter(|v| v.instance != 0) {
        if let Some((_, t)) = index.nearest(&v.position) {
            let truth_id = truth
                .instances
                .get(truth.triangles[t][0] as usize)
                .copied()
                .unwrap_or(0);
            pairs.push((v.instance, truth_id));
        }
    }
    let mut votes: BTreeMap<u16, BTreeMap<u16, usize>> = BTreeMap::new();
    for &(m, t) in &pairs {
        *votes.entry(m).or_default().entry(t).or_default() += 1;
    }
    let majority: BTreeMap<u16, u16> = votes
        .iter()
        .map(|(&m, v)| {
            let best = v.iter().max_by_key(|&(_, &n)| n).map_or(0, |(&t, _)| t);
            (m, best)
        })
        .collect();
    let agree = pairs.iter().filter(|(m, t)| majority[m] == *t).count();
    SurfaceReport {
        accuracy_mean_m: scores.accuracy_mean,
        accuracy_median_m: scores.accuracy_median,
        accuracy_p95_m: scores.accuracy_p95,
        accuracy_within: scores.accuracy_within,
        completeness_within: scores.completeness_within,
        label_agreement: if pairs.is_empty() {
            0.0
        } else {
            100.0 * agree as f64 / pairs.len() as f64
        },
    }
}
