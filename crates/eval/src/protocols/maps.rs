//! Protocols over maps: voxel panoptic quality of each rule's map, and a map against a
//! ground-truth mesh.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use voxpan_core::Mesh;
use voxpan_core::nalgebra::Point3;
use voxpan_dataset::{FrameSource, stream};
use voxpan_map::{MapConfig, PanopticMap};
use voxpan_perception::{DatasetMasks, GroundTruthMasks, Perception, PerceptionConfig, Segmenter};
use voxpan_pipeline::build;
use voxpan_refine::{RefineConfig, Rule};

use super::EvalError;
use crate::surface::{TriangleIndex, surface_scores};
use crate::volume::{VoxelPq, voxel_pq};

/// Maps `selected` frames of `source` with `segmenter` and `refine`, default map settings.
fn map_frames(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    segmenter: Box<dyn Segmenter>,
    refine: RefineConfig,
) -> Result<PanopticMap, EvalError> {
    let perception = Perception::new(
        PerceptionConfig {
            refine,
            ..PerceptionConfig::default()
        },
        segmenter,
    )?;
    let frames = stream(source.clone(), selected.to_vec());
    let map = PanopticMap::new(MapConfig::default())?;
    Ok(build(frames, perception, map, &AtomicBool::new(false), |_| Ok(()))?.map)
}

/// For each rule, the map of the dataset's refined masks scored against the map of its
/// ground-truth segmentation (panoptic quality over surface voxels, 2 cm voxels).
/// `progress(name)` is called before each map is built.
pub fn voxel_rows(
    source: &Arc<dyn FrameSource>,
    selected: &[usize],
    rules: &[Rule],
    things_only: bool,
    progress: impl Fn(&str),
) -> Result<Vec<(Rule, VoxelPq)>, EvalError> {
    progress("ground truth");
    let truth = map_frames(
        source,
        selected,
        Box::new(GroundTruthMasks::new(
            source.ground_truth_classes().cloned(),
        )),
        RefineConfig::new(Rule::None),
    )?;
    let mut rows = Vec::new();
    for &rule in rules {
        progress(rule.name());
        let refine = RefineConfig {
            things_only,
            ..RefineConfig::new(rule)
        };
        let map = map_frames(source, selected, Box::new(DatasetMasks), refine)?;
        rows.push((rule, voxel_pq(&map, &truth)));
    }
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
