//! Building a map from a frame stream: perception on its own thread one frame ahead,
//! association and integration on the caller's thread.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use voxpan_core::FrameStream;
use voxpan_map::{FrameReport, MapError, PanopticMap, human_bytes};
use voxpan_perception::{MaskRefiner, Perceived, Perception};

/// A frame that was not mapped, and why.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct SkippedFrame {
    pub frame: String,
    pub reason: String,
}

/// What a run did and how fast.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RunReport {
    /// Frames mapped.
    pub frames: usize,
    /// Mapped frames the segmenter ran on (`[segment] every`); the others were mapped with
    /// the masks the map rendered at their pose.
    pub keyframes: usize,
    pub skipped: Vec<SkippedFrame>,
    /// Frames mapped per second of wall time, start-up included.
    pub fps: f64,
    /// Median milliseconds between consecutive mapped frames (0 with fewer than two): the
    /// pipeline's steady period, as a median like the stages' figures. Unlike `fps` it leaves
    /// out the start-up (the first frame crosses every stage alone) and the odd frame a busy
    /// machine holds back.
    pub frame_interval_ms: f64,
    /// Median milliseconds per frame of each stage (`decode`, `segment`, `carry`, `refine`,
    /// `fill`, `track`, `integrate`, and `esdf` with `[esdf] enabled`), and of the final `mesh`
    /// extraction and, with the tracker, the final `consolidate` (once per run); with
    /// `tracking.consolidate_every`, `consolidate_every` is the median of its passes.
    pub stage_ms: BTreeMap<String, f64>,
    /// Map instances, allocated blocks and mesh triangles at the end.
    pub instances: usize,
    pub blocks: usize,
    pub triangles: usize,
    /// A stop was requested before the stream ended.
    pub stopped_early: bool,
    /// Things the user should know that did not stop the run (each said once).
    pub warnings: Vec<String>,
    /// One record per mapped frame, in order.
    pub timeline: Vec<FrameRecord>,
    /// The camera pose of each mapped frame (`T_world_camera`), in order.
    #[serde(skip)]
    pub poses: Vec<voxpan_core::Pose>,
}

/// The [`RunReport::stage_ms`] entries measured once per run, not per frame, with what to
/// call them.
pub const ONCE_PER_RUN: [(&str, &str); 2] =
    [("mesh", "final mesh"), ("consolidate", "consolidation")];

impl RunReport {
    /// The stage figures as a line's two halves: the per-frame medians (`decode 1.70, ...`)
    /// and the once-per-run figures (`final mesh 83 ms, consolidation 17 ms`).
    pub fn stage_summary(&self) -> (String, String) {
        let once = |k: &str| ONCE_PER_RUN.iter().any(|(key, _)| *key == k);
        let per_frame: Vec<String> = self
            .stage_ms
            .iter()
            .filter(|(k, _)| !once(k))
            .map(|(k, v)| format!("{k} {v:.2}"))
            .collect();
        let per_run: Vec<String> = ONCE_PER_RUN
            .iter()
            .filter_map(|(key, name)| self.stage_ms.get(*key).map(|v| format!("{name} {v:.0} ms")))
            .collect();
        (per_frame.join(", "), per_run.join(", "))
    }
}

/// When a frame was mapped, what it cost and how many instances the map then held.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct FrameRecord {
    pub frame: String,
    /// Seconds since the run started, when the frame was done.
    pub at_s: f64,
    /// Milliseconds of each stage, in [`STAGES`] order (`esdf` 0 when the field is off).
    pub stage_ms: [f64; 9],
    pub instances: usize,
    /// The segmenter ran on this frame (else its masks are the map's, `carry`).
    pub keyframe: bool,
}

/// The per-frame stages, in the order [`FrameRecord::stage_ms`] lists them. `carry` is the
/// rendering of the map's instances as masks for a frame between keyframes.
pub const STAGES: [&str; 9] = [
    "decode",
    "segment",
    "carry",
    "refine",
    "trim",
    "fill",
    "track",
    "integrate",
    "esdf",
];

/// What the pipeline tells its caller after each frame.
pub enum FrameEvent<'a> {
    Mapped {
        perceived: &'a Perceived,
        report: &'a FrameReport,
        /// The map with this frame in it: observers may read it and re-mesh it (a live view
        /// sends the changed blocks), not integrate into it.
        map: &'a mut PanopticMap,
    },
    Skipped(&'a SkippedFrame),
}

/// Why a run failed as a whole (single bad frames are skipped and reported instead).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("no frame could be mapped{}", summarise(.0))]
    NoFrames(Vec<SkippedFrame>),
    /// A stop was requested before any frame was mapped.
    #[error("interrupted before any frame was mapped")]
    Interrupted,
    #[error("{0}")]
    Callback(Box<dyn std::error::Error + Send + Sync>),
    /// The map would outgrow its memory limit at `frame` (mapping on would only fail every
    /// frame).
    #[error("frame {frame}: {source}")]
    Memory {
        frame: String,
        #[source]
        source: MapError,
    },
    #[error(
        "one frame of {width}x{height} may add {} to the map (voxel size {voxel} m, truncation \
         {truncation} voxels, range {range} m), more than the memory limit of {}; use a coarser \
         tsdf.voxel_size or a shorter tsdf.max_range, or raise the limit (--max-memory)",
        human_bytes(*needed), human_bytes(*limit)
    )]
    FrameTooLarge {
        width: usize,
        height: usize,
        voxel: f64,
        truncation: f64,
        range: f64,
        needed: u64,
        limit: u64,
    },
}

/// The reasons frames were skipped, most frequent first (so "no frame could be mapped" says
/// why).
fn summarise(skipped: &[SkippedFrame]) -> String {
    if skipped.is_empty() {
        return String::new();
    }
    let mut counts: BTreeMap<&str, (usize, &str)> = BTreeMap::new();
    for s in skipped {
        // Frames fail for the same reason with different file names: group by the message
        // after the file.
        let key = s.reason.rsplit(": ").next().unwrap_or(&s.reason);
        let e = counts.entry(key).or_insert((0, &s.frame));
        e.0 += 1;
    }
    let mut list: Vec<(&str, (usize, &str))> = counts.into_iter().collect();
    list.sort_by_key(|e| std::cmp::Reverse(e.1.0));
    let lines: Vec<String> = list
        .iter()
        .take(5)
        .map(|(why, (n, first))| format!("\n  {n} frame(s), e.g. {first}: {why}"))
        .collect();
    format!(": {} skipped{}", skipped.len(), lines.concat())
}

/// A map and how it was built.
pub struct Mapped {
    pub map: PanopticMap,
    pub report: RunReport,
}

/// How each frame's segments become map instances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Association {
    /// Matched with the map's instances ([`PanopticMap::integrate`]): a network's per-frame ids.
    Track,
    /// Segment ids are instance ids ([`PanopticMap::integrate_identified`]): ground truth, or
    /// ids an upstream tracker keeps.
    Identified,
}

/// What the map goes through once the stream ends.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Ending {
    /// With the tracker, consolidated ([`PanopticMap::consolidate`]): the map `voxpan run`
    /// writes.
    #[default]
    Consolidated,
    /// Left as its last frame left it: the map a live reader (a mapping node, a viewer) holds
    /// when the stream stops, with the passes `tracking.consolidate_every` made on the way.
    Live,
}

/// Maps `frames`: each is perceived (on a worker thread, one frame ahead), then its segments
/// are associated with the map's instances and it is integrated. `stop` ends the run early
/// with what was built; `on_frame` hears of every frame (progress bars, refined-mask writers)
/// and may abort the run by returning an error.
pub fn build(
    frames: FrameStream,
    perception: Perception,
    map: PanopticMap,
    stop: &AtomicBool,
    on_frame: impl FnMut(FrameEvent) -> Result<(), Box<dyn std::error::Error + Send + Sync>>,
) -> Result<Mapped, RunError> {
    build_with(
        frames,
        perception,
        map,
        Association::Track,
        Ending::Consolidated,
        stop,
        on_frame,
    )
}

/// [`build`] with the association and the ending chosen.
pub fn build_with(
    frames: FrameStream,
    perception: Perception,
    mut map: PanopticMap,
    association: Association,
    ending: Ending,
    stop: &AtomicBool,
    mut on_frame: impl FnMut(FrameEvent) -> Result<(), Box<dyn std::error::Error + Send + Sync>>,
) -> Result<Mapped, RunError> {
    let mut report = RunReport::default();
    let mut times: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    // Refines the masks the map renders for frames between keyframes, as perception refines
    // a segmenter's.
    let mut carried_refiner = MaskRefiner::new(perception.config().refine);
    let start = Instant::now();
    let mut first = true;
    for item in perception.spawn(frames) {
        if stop.load(Ordering::Relaxed) {
            report.stopped_early = true;
            break;
        }
        if let (Ok(p), Some(limit), true) = (&item, map.memory_limit(), first) {
            first = false;
            let k = &p.frame.intrinsics;
            let needed = map.frame_memory_bound(k);
            if needed > limit {
                let tsdf = map.config().tsdf;
                return Err(RunError::FrameTooLarge {
                    width: k.width,
                    height: k.height,
                    voxel: tsdf.voxel_size,
                    truncation: tsdf.truncation_voxels,
                    range: tsdf.max_range,
                    needed,
                    limit,
                });
            }
        }
        let mut carry_ms = 0.0;
        let result =
            item.map_err(|e| (e.frame.clone(), e.source.to_string()))
                .and_then(|mut p| {
                    let (lo, hi) = (map.config().tsdf.min_range, map.config().tsdf.max_range);
                    let usable = p.frame.depth.pixels().iter().any(|&z| {
                        voxpan_core::is_valid_depth(z) && (lo..=hi).contains(&(z as f64))
                    });
                    if !usable {
                        let reason = format!(
                            "no depth between {lo} and {hi} m (every pixel NaN, infinite, zero, \
                         negative or out of range)"
                        );
                        return Err((p.frame.id.clone(), reason));
                    }
                    let integrated = if let Some(measured) = p.measured_depth.take() {
                        let t = Instant::now();
                        let k = &p.frame.intrinsics;
                        // Looked up at the depth integration fuses (filled): a pixel the
                        // sensor missed still lands on the surface it joins. Refined on the
                        // measured depth, as keyframes' masks are.
                        let mut carried = map.carried_segments(&p.frame.depth, k, &p.frame.pose);
                        carry_ms = t.elapsed().as_secs_f64() * 1e3;
                        p.refine_reports = carried_refiner
                            .refine(&measured, &mut carried, &mut p.times)
                            .map_err(|e| (p.frame.id.clone(), e.to_string()))?;
                        let integrated = map.integrate_carried(p.frame.view(), &carried);
                        p.segments = Some(carried);
                        integrated
                    } else {
                        match (association, p.segments.as_ref()) {
                            (Association::Identified, Some(s)) => {
                                map.integrate_identified(p.frame.view(), s)
                            }
                            (_, segments) => map.integrate(p.frame.view(), segments),
                        }
                    };
                    let frame_report = match integrated {
                        Err(e @ MapError::MemoryLimit { .. }) => {
                            return Ok(Err(RunError::Memory {
                                frame: p.frame.id.clone(),
                                source: e,
                            }));
                        }
                        other => other.map_err(|e| (p.frame.id.clone(), e.to_string()))?,
                    };
                    Ok(Ok((p, frame_report)))
                });
        let result = match result {
            Ok(Err(memory)) => return Err(memory),
            Ok(Ok(done)) => Ok(done),
            Err(skip) => Err(skip),
        };
        match result {
            Ok((perceived, frame_report)) => {
                let out_of_ids = frame_report.association.is_some_and(|a| a.out_of_ids > 0);
                if out_of_ids && !report.warnings.iter().any(|w| w.contains("instance id")) {
                    report.warnings.push(format!(
                        "from frame {} on, every 16-bit instance id is taken ({}): new objects \
                         are mapped as geometry without an instance",
                        perceived.frame.id,
                        u16::MAX - 1
                    ));
                }
                let esdf_on = map.config().esdf.enabled;
                let esdf_ms = if esdf_on {
                    let t = Instant::now();
                    map.update_esdf();
                    t.elapsed().as_secs_f64() * 1e3
                } else {
                    0.0
                };
                let t = perceived.times;
                let stage_ms = [
                    t.decode,
                    t.segment,
                    carry_ms,
                    t.refine,
                    t.trim,
                    t.fill,
                    frame_report.track_ms,
                    frame_report.integrate_ms,
                    esdf_ms,
                ];
                for (stage, ms) in STAGES.into_iter().zip(stage_ms) {
                    if stage != "esdf" || esdf_on {
                        times.entry(stage).or_default().push(ms);
                    }
                }
                if let Some(ms) = frame_report.consolidate_ms {
                    times.entry("consolidate_every").or_default().push(ms);
                }
                report.timeline.push(FrameRecord {
                    frame: perceived.frame.id.clone(),
                    at_s: start.elapsed().as_secs_f64(),
                    stage_ms,
                    instances: map.instance_count(),
                    keyframe: perceived.keyframe,
                });
                report.poses.push(perceived.frame.pose);
                report.frames += 1;
                report.keyframes += usize::from(perceived.keyframe);
                on_frame(FrameEvent::Mapped {
                    perceived: &perceived,
                    report: &frame_report,
                    map: &mut map,
                })
                .map_err(RunError::Callback)?;
            }
            Err((frame, reason)) => {
                let skipped = SkippedFrame { frame, reason };
                on_frame(FrameEvent::Skipped(&skipped)).map_err(RunError::Callback)?;
                report.skipped.push(skipped);
            }
        }
    }
    if report.frames == 0 && report.stopped_early {
        return Err(RunError::Interrupted);
    }
    if report.frames == 0 {
        return Err(RunError::NoFrames(report.skipped));
    }
    report.fps = report.frames as f64 / start.elapsed().as_secs_f64();
    report.frame_interval_ms = median(
        report
            .timeline
            .windows(2)
            .map(|pair| (pair[1].at_s - pair[0].at_s) * 1e3)
            .collect(),
    );
    report.stage_ms = times
        .into_iter()
        .map(|(k, v)| (k.to_owned(), median(v)))
        .collect();
    if (association, ending) == (Association::Track, Ending::Consolidated) {
        let t = Instant::now();
        map.consolidate();
        report
            .stage_ms
            .insert("consolidate".into(), t.elapsed().as_secs_f64() * 1e3);
    }
    report.instances = map.instance_count();
    report.blocks = map.block_count();
    Ok(Mapped { map, report })
}

/// The median (upper middle for an even count; 0 for none).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}
