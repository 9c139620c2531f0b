//! The whole data flow, frame by frame: decode → fill holes → refine the masks on *measured*
//! depth (these three on a worker thread, one frame ahead) → match segments to map instances →
//! integrate the filled depth, colour and instances → meshes, map file, metrics.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use voxpan_core::{segment_ids, Segment};
use voxpan_dataset::{DatasetError, Frame, FrameSegments, FrameSource};
use voxpan_fill::{FillParams, HoleFiller};
use voxpan_map::{
    downscaled, id_color, io, render_instances, InstanceInfo, InstanceTracker, Layer, MeshLayer,
    TrackingConfig, TsdfConfig, TsdfIntegrator,
};
use voxpan_refine::{RefineConfig, Refiner, Rule};

/// Which masks to map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentSource {
    /// The network's predictions (refined).
    Predicted,
    /// The dataset's ground truth (a reference map).
    Gt,
}

/// Which refinement, if any.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Refinement {
    None,
    Paper,
    Release,
    Default,
}

impl Refinement {
    pub fn rule(self) -> Option<Rule> {
        match self {
            Refinement::None => None,
            Refinement::Paper => Some(Rule::Paper),
            Refinement::Release => Some(Rule::Release),
            Refinement::Default => Some(Rule::Default),
        }
    }
}

/// Everything a run can be told; also the layout of a `--config` TOML file (every key
/// optional, unknown keys rejected).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    pub voxel_size: f64,
    pub truncation_voxels: f64,
    pub max_range: f64,
    pub refine: Refinement,
    pub things_only: bool,
    pub segments: SegmentSource,
    /// Write the refined label images as `refined/NNNNNN.png`.
    pub save_refined: bool,
    /// A ground-truth mesh (the synthetic world's `groundtruth_mesh.ply`) to score the map
    /// against; set from the dataset, not from configuration files.
    #[serde(skip)]
    pub ground_truth_mesh: Option<std::path::PathBuf>,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            voxel_size: 0.02,
            truncation_voxels: 3.0,
            max_range: 5.0,
            refine: Refinement::Default,
            things_only: false,
            segments: SegmentSource::Predicted,
            save_refined: false,
            ground_truth_mesh: None,
        }
    }
}

impl RunConfig {
    /// Reads a TOML file; errors name the file and the offending key.
    pub fn from_toml_file(path: &Path) -> Result<Self, RunError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RunError::Output(format!("{}: {e}", path.display())))?;
        toml::from_str(&text).map_err(|e| RunError::Output(format!("{}: {e}", path.display())))
    }
}

/// Why a run failed as a whole (single bad frames are skipped and reported instead).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    #[error("{0}")]
    Output(String),
    #[error("no frame could be processed")]
    NoFrames,
}

/// Per-stage timings and what happened.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RunReport {
    pub frames: usize,
    pub skipped: Vec<(String, String)>,
    pub fps: f64,
    /// Median milliseconds per frame of each stage.
    pub stage_ms: BTreeMap<String, f64>,
    pub instances: usize,
    pub blocks: usize,
    pub triangles: usize,
    pub stopped_early: bool,
    /// 3-D metrics against the ground-truth mesh, when there is one.
    pub surface: Option<SurfaceReport>,
}

/// The map against the ground-truth mesh (distances within one voxel count as hits).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct SurfaceReport {
    /// Mean distance from mesh vertices to the true surface, metres.
    pub accuracy_mean_m: f64,
    /// Percent of mesh vertices within a voxel of the true surface.
    pub accuracy_within: f64,
    /// Percent of the observed true surface within a voxel of the mesh.
    pub completeness_within: f64,
    /// Percent of labelled surface voxels whose map instance's majority true instance is
    /// their own true instance.
    pub label_agreement: f64,
}

/// Runs the pipeline over `indices` of `source`, writing everything into `out`. `stop` ends the
/// run early (Ctrl-C), still writing what was built; `progress(done)` is called per frame.
pub fn run(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    config: &RunConfig,
    out: &Path,
    stop: &AtomicBool,
    progress: impl Fn(usize),
) -> Result<RunReport, RunError> {
    let mkdir = |p: &Path| {
        std::fs::create_dir_all(p)
            .map_err(|e| RunError::Output(format!("cannot create {}: {e}", p.display())))
    };
    mkdir(out)?;
    let effective = toml::to_string(config).expect("plain data");
    std::fs::write(out.join("config.toml"), effective)
        .map_err(|e| RunError::Output(format!("cannot write config.toml: {e}")))?;
    if config.save_refined {
        mkdir(&out.join("refined"))?;
    }
    let refined_dir = out.join("refined");
    let built = build_map(
        source,
        indices,
        config,
        config.save_refined.then_some(refined_dir.as_path()),
        stop,
        progress,
    )?;
    let (mut layer, tracker_instances, mut report, mut times) =
        (built.layer, built.instances, built.report, built.times);

    let t = Instant::now();
    let mut meshes = MeshLayer::default();
    meshes.update(&mut layer);
    let mesh = meshes.combined();
    times
        .entry("mesh")
        .or_default()
        .push(t.elapsed().as_secs_f64() * 1e3);
    let class_of = |id: u16| tracker_instances.get(&id).and_then(|i| i.class());
    let write = |name: &str, m: &voxpan_map::Mesh| {
        m.write_ply(&out.join(name)).map_err(|e| {
            RunError::Output(format!("cannot write {}: {e}", out.join(name).display()))
        })
    };
    write("mesh_rgb.ply", &mesh)?;
    write(
        "mesh_instance.ply",
        &mesh.colored_by(|id| id_color(id as u32)),
    )?;
    write(
        "mesh_class.ply",
        &mesh.colored_by(|id| id_color(class_of(id).map_or(0, |c| c + 1))),
    )?;
    mkdir(&out.join("instances"))?;
    for (id, part) in mesh.split_by_instance() {
        let class = class_of(id).map_or_else(|| "unknown".to_owned(), |c| c.to_string());
        write(&format!("instances/{id}_{class}.ply"), &part)?;
    }
    io::save(&layer, &tracker_instances, &out.join("map.voxpan"))
        .map_err(|e| RunError::Output(e.to_string()))?;

    if let Some(path) = &config.ground_truth_mesh {
        let truth = voxpan_sim::read_ply(path).map_err(|e| RunError::Output(e.to_string()))?;
        report.surface = Some(surface_report(&layer, &mesh, &truth));
    }
    report.stage_ms = times
        .into_iter()
        .map(|(k, v)| (k.to_owned(), median(v)))
        .collect();
    report.instances = tracker_instances.len();
    report.blocks = layer.blocks.len();
    report.triangles = mesh.triangles();
    let metrics = serde_json::json!({ "config": config, "report": report });
    std::fs::write(
        out.join("metrics.json"),
        serde_json::to_string_pretty(&metrics).expect("plain data"),
    )
    .map_err(|e| RunError::Output(format!("cannot write metrics.json: {e}")))?;
    Ok(report)
}

/// The map a run builds, before anything is written.
pub struct BuiltMap {
    pub layer: Layer,
    pub instances: BTreeMap<u16, InstanceInfo>,
    pub report: RunReport,
    times: BTreeMap<&'static str, Vec<f64>>,
}

/// Fuses the frames `indices` of `source` into a map (no meshes, no files except refined label
/// images into `refined_dir` when given).
pub fn build_map(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    config: &RunConfig,
    refined_dir: Option<&Path>,
    stop: &AtomicBool,
    progress: impl Fn(usize),
) -> Result<BuiltMap, RunError> {
    let mut layer = Layer::new(config.voxel_size);
    let integrator = TsdfIntegrator::new(TsdfConfig {
        truncation_voxels: config.truncation_voxels,
        max_range: config.max_range,
        ..TsdfConfig::default()
    });
    let mut tracker = InstanceTracker::new(TrackingConfig::default());
    let mut report = RunReport {
        skipped: source.skipped().to_vec(),
        ..RunReport::default()
    };
    let mut times: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    let start = Instant::now();
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    // Decoding, hole filling and refinement do not depend on the map: a worker prepares frame
    // n + 1 while this thread tracks and integrates frame n.
    for (done, (index, prepared)) in
        prepare_frames(source.clone(), indices, config.clone()).enumerate()
    {
        if stop.load(Ordering::Relaxed) {
            report.stopped_early = true;
            break;
        }
        let prepared = match prepared {
            Ok(p) => p,
            Err(e) => {
                report
                    .skipped
                    .push((source.frame_id(index).to_owned(), e.to_string()));
                progress(done + 1);
                continue;
            }
        };
        for (stage, t) in prepared.stage_ms {
            times.entry(stage).or_default().push(t);
        }
        let frame = prepared.frame;
        if let (Some(dir), Some(m)) = (refined_dir, &prepared.masks) {
            let path = dir.join(format!("{}.png", frame.id));
            voxpan_io::write_label_png(&path, &m.labels)
                .map_err(|e| RunError::Output(e.to_string()))?;
        }

        let t = Instant::now();
        let instances = prepared.masks.map(|m| {
            let rendered = render_instances(&layer, &frame.pose, &downscaled(&frame.intrinsics, 4));
            tracker.assign(&m.labels, &m.segments, &rendered)
        });
        times.entry("track").or_default().push(ms(t));

        let t = Instant::now();
        integrator.integrate(
            &mut layer,
            &frame.depth,
            Some(&frame.color),
            instances.as_ref(),
            &frame.pose,
            &frame.intrinsics,
        );
        times.entry("integrate").or_default().push(ms(t));
        report.frames += 1;
        progress(done + 1);
    }
    if report.frames == 0 {
        return Err(RunError::NoFrames);
    }
    report.fps = report.frames as f64 / start.elapsed().as_secs_f64();
    Ok(BuiltMap {
        layer,
        instances: tracker.instances,
        report,
        times,
    })
}

/// A frame ready for tracking and integration: filled depth, the masks to map, stage timings.
struct Prepared {
    frame: Frame,
    masks: Option<FrameSegments>,
    stage_ms: Vec<(&'static str, f64)>,
}

/// Decodes, fills and refines frames on a worker thread, one frame ahead of the consumer.
/// Dropping the iterator stops the worker after its current frame.
fn prepare_frames(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    config: RunConfig,
) -> impl Iterator<Item = (usize, Result<Prepared, DatasetError>)> {
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    std::thread::spawn(move || {
        let mut filler = HoleFiller::new(FillParams::default());
        let mut refiner = config.refine.rule().map(|rule| {
            Refiner::new(RefineConfig {
                things_only: config.things_only,
                ..RefineConfig::new(rule)
            })
        });
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        for index in indices {
            let t = Instant::now();
            let result = source.load(index).map(|mut frame| {
                let mut stage_ms = vec![("decode", ms(t))];
                // Refinement reads measured depth; integration the filled depth.
                let measured = frame.depth.clone();
                let t = Instant::now();
                filler.fill(&mut frame.depth);
                stage_ms.push(("fill", ms(t)));
                let t = Instant::now();
                let masks = match config.segments {
                    SegmentSource::Predicted => frame.segments.take().map(|mut s| {
                        if let Some(refiner) = refiner.as_mut() {
                            // Shapes match: the reader checked every image against the
                            // intrinsics.
                            let _ = refiner.refine_frame(&measured, &mut s.labels, &s.segments);
                        }
                        s
                    }),
                    SegmentSource::Gt => frame.ground_truth.take().map(|labels| {
                        let segments = segment_ids(&labels)
                            .into_iter()
                            .map(Segment::bare)
                            .collect();
                        FrameSegments { labels, segments }
                    }),
                };
                stage_ms.push(("refine", ms(t)));
                Prepared {
                    frame,
                    masks,
                    stage_ms,
                }
            });
            if tx.send((index, result)).is_err() {
                break;
            }
        }
    });
    rx.into_iter()
}

/// Accuracy, completeness and label agreement of the map against a ground-truth mesh.
fn surface_report(
    layer: &Layer,
    mesh: &voxpan_map::Mesh,
    truth: &voxpan_sim::Mesh,
) -> SurfaceReport {
    use voxpan_core::nalgebra::Point3;
    use voxpan_eval::surface::{surface_scores, TriangleIndex};
    let voxel = layer.voxel_size();
    let vertices: Vec<Point3<f64>> = mesh
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let triangles = truth.triangle_points();
    let seen = |p: &Point3<f64>| {
        layer
            .voxel_at(p)
            .is_some_and(|v| v.observed() && (v.distance.abs() as f64) < voxel)
    };
    let scores = surface_scores(&vertices, triangles.clone(), voxel, voxel / 2.0, seen);
    // Each labelled surface voxel: its map instance and the true instance of the nearest
    // true triangle.
    let index = TriangleIndex::new(triangles, 2.0 * voxel);
    let mut pairs: Vec<(u16, u16)> = Vec::new();
    for (&block_index, block) in &layer.blocks {
        // Integration keeps each block's mask of labelled surface voxels current.
        for i in block.surface_voxels() {
            let l = &block.labels[i];
            let p = voxpan_map::Block::voxel_center(block_index, i, voxel);
            if let Some((_, t)) = index.nearest(&p) {
                let truth_id = truth.instances[truth.triangles[t][0] as usize];
                pairs.push((l.instance(), truth_id));
            }
        }
    }
    let mut votes: BTreeMap<u16, BTreeMap<u16, usize>> = BTreeMap::new();
    for &(m, t) in &pairs {
        *votes.entry(m).or_default().entry(t).or_default() += 1;
    }
    let majority: BTreeMap<u16, u16> = votes
        .iter()
        .map(|(&m, v)| {
            (
                m,
                *v.iter()
                    .max_by_key(|(_, &n)| n)
                    .map(|(t, _)| t)
                    .unwrap_or(&0),
            )
        })
        .collect();
    let agree = pairs.iter().filter(|(m, t)| majority[m] == *t).count();
    SurfaceReport {
        accuracy_mean_m: scores.accuracy_mean,
        accuracy_within: scores.accuracy_within,
        completeness_within: scores.completeness_within,
        label_agreement: if pairs.is_empty() {
            0.0
        } else {
            100.0 * agree as f64 / pairs.len() as f64
        },
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}
