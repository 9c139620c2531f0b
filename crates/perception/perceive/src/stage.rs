use std::time::Instant;

use voxpan_core::{DepthImage, Frame, FrameError, FrameStream, Segments};
use voxpan_fill::{FillConfig, HoleFiller};
use voxpan_refine::{MaskReport, PlaneTrimmer, RefineConfig, Refiner, Rule};

use crate::keyframes::{KeyframeScheduler, Keyframes};
use crate::{SegmentError, Segmenter};

/// The perception stage's settings: the `[fill]` and `[refine]` sections, and which frames
/// are segmented (`[segment] every`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    pub fill: FillConfig,
    pub refine: RefineConfig,
    pub keyframes: Keyframes,
}

/// Why a frame could not be perceived.
#[derive(Debug, thiserror::Error)]
pub enum PerceptionError {
    #[error("segmentation ({segmenter}) failed: {source}")]
    Segment {
        segmenter: String,
        #[source]
        source: SegmentError,
    },
    #[error("the label image is {labels:?} but the depth image {depth:?}")]
    Shape {
        labels: (usize, usize),
        depth: (usize, usize),
    },
    #[error("invalid configuration: {0}")]
    Config(String),
}

/// Milliseconds each step took on one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Getting the frame from its stream (decoding, for a dataset); set by
    /// [`Perception::spawn`].
    pub decode: f64,
    pub segment: f64,
    pub refine: f64,
    /// Trimming things off stuff planes (0 when off).
    pub trim: f64,
    pub fill: f64,
}

/// A frame after perception: holes filled, segments refined.
#[derive(Clone, Debug)]
pub struct Perceived {
    /// The frame, its depth hole-filled (what integration reads).
    pub frame: Frame,
    /// The refined segments (`None` when the segmenter had none for this frame, or did not
    /// run on it).
    pub segments: Option<Segments>,
    /// Whether the segmenter ran on this frame (see [`Keyframes`]). A frame between
    /// keyframes takes its masks from the map instead, refined on [`Self::measured_depth`].
    pub keyframe: bool,
    /// The frame's depth as measured, before hole filling: kept for frames between
    /// keyframes, whose masks are refined once the map has rendered them.
    pub measured_depth: Option<DepthImage>,
    /// One line per refined segment, in segment order (empty without refinement).
    pub refine_reports: Vec<MaskReport>,
    pub times: StageTimes,
}

/// Segment → refine (on measured depth) → trim things off stuff planes → fill, one frame at a
/// time. Keeps its buffers between frames: one per thread.
pub struct Perception {
    config: PerceptionConfig,
    segmenter: Box<dyn Segmenter>,
    refiner: MaskRefiner,
    filler: HoleFiller,
    keyframes: KeyframeScheduler,
}

/// Refinement by the depths under each mask, then trimming things off stuff planes: what
/// perception does to a segmenter's masks, and to the masks a map renders between keyframes.
pub struct MaskRefiner {
    config: RefineConfig,
    refiner: Refiner,
    trimmer: PlaneTrimmer,
}

impl MaskRefiner {
    pub fn new(config: RefineConfig) -> Self {
        Self {
            config,
            refiner: Refiner::new(config),
            trimmer: PlaneTrimmer::new(),
        }
    }

    /// Refines `segments` on the measured `depth` as `[refine]` says; records the
    /// milliseconds in `times.refine` and `times.trim`. Returns one report per segment
    /// (none without refinement).
    pub fn refine(
        &mut self,
        depth: &DepthImage,
        segments: &mut Segments,
        times: &mut StageTimes,
    ) -> Result<Vec<MaskReport>, PerceptionError> {
        if segments.labels.dims() != depth.dims() {
            return Err(PerceptionError::Shape {
                labels: segments.labels.dims(),
                depth: depth.dims(),
            });
        }
        if self.config.rule == Rule::None {
            return Ok(Vec::new());
        }
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let reports = self
            .refiner
            .refine_frame(depth, &mut segments.labels, &segments.segments)
            .expect("shapes checked above");
        times.refine += ms(t);
        // After the rule: it removes the bleed at other depths, this the bleed at the
        // thing's own depths that lies on the floor or a wall.
        if self.config.trim_stuff_planes {
            let t = Instant::now();
            self.trimmer
                .trim(depth, &mut segments.labels, &segments.segments)
                .expect("shapes checked above");
            times.trim += ms(t);
        }
        Ok(reports)
    }
}

impl Perception {
    pub fn new(
        config: PerceptionConfig,
        segmenter: Box<dyn Segmenter>,
    ) -> Result<Self, PerceptionError> {
        config.fill.validate().map_err(PerceptionError::Config)?;
        let far = config.refine.far_limit;
        if far.is_nan() || far <= 0.0 {
            return Err(PerceptionError::Config(format!(
                "refine.far_limit = {}: expected a positive number",
                config.refine.far_limit
            )));
        }
        Ok(Self {
            refiner: MaskRefiner::new(config.refine),
            filler: HoleFiller::new(config.fill.params()),
            keyframes: KeyframeScheduler::new(config.keyframes),
            config,
            segmenter,
        })
    }

    pub fn config(&self) -> &PerceptionConfig {
        &self.config
    }

    pub fn segmenter_name(&self) -> &str {
        self.segmenter.name()
    }

    /// The segmenter's own label table (a network's categories), if it has one.
    pub fn segmenter_classes(&self) -> Option<&voxpan_core::ClassTable> {
        self.segmenter.classes()
    }

    /// Perceives one frame. Refinement reads the measured depth (filled values interpolate
    /// across silhouettes and bridge exactly the gaps that separate an object from what lies
    /// behind it); holes are filled afterwards, for integration.
    pub fn process(&mut self, frame: Frame) -> Result<Perceived, PerceptionError> {
        let segmented = self.segment(&frame)?;
        self.refine_and_fill(frame, segmented)
    }

    /// [`Self::process`] with refinement, trimming and filling run on rayon's pool (one
    /// worker per core, where the map integrates too) and the segmenter on this thread (a
    /// network's runtime brings its own threads): what a perception thread beside a mapping
    /// thread calls, so that the two take turns on the cores instead of time slices (see
    /// [`Self::spawn`]).
    pub fn process_on_workers(&mut self, frame: Frame) -> Result<Perceived, PerceptionError> {
        let segmented = self.segment(&frame)?;
        // A scope's body runs inside the global pool (queued there from outside it), and this
        // thread waits for it.
        rayon::scope(|_| self.refine_and_fill(frame, segmented))
    }

    /// The segmenter's masks for `frame`, and the milliseconds they took; `None` between
    /// keyframes, where the segmenter does not run.
    #[allow(clippy::type_complexity)] // a result of a pair of options, named by the doc
    fn segment(
        &mut self,
        frame: &Frame,
    ) -> Result<Option<(Option<Segments>, f64)>, PerceptionError> {
        if !self.keyframes.is_keyframe(frame) {
            return Ok(None);
        }
        let t = Instant::now();
        let segments =
            self.segmenter
                .segment(frame)
                .map_err(|source| PerceptionError::Segment {
                    segmenter: self.segmenter.name().to_owned(),
                    source,
                })?;
        Ok(Some((segments, t.elapsed().as_secs_f64() * 1e3)))
    }

    /// What [`Self::process`] does after segmenting: refine, trim, fill.
    fn refine_and_fill(
        &mut self,
        mut frame: Frame,
        segmented: Option<(Option<Segments>, f64)>,
    ) -> Result<Perceived, PerceptionError> {
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let keyframe = segmented.is_some();
        let (mut segments, segment_ms) = segmented.unwrap_or((None, 0.0));
        let mut times = StageTimes {
            segment: segment_ms,
            ..StageTimes::default()
        };
        let mut refine_reports = Vec::new();
        if let Some(s) = segments.as_mut() {
            refine_reports = self.refiner.refine(&frame.depth, s, &mut times)?;
        }
        let measured_depth = (!keyframe).then(|| frame.depth.clone());
        let t = Instant::now();
        if self.config.fill.enabled {
            self.filler.fill(&mut frame.depth);
        }
        times.fill = ms(t);
        Ok(Perceived {
            frame,
            segments,
            keyframe,
            measured_depth,
            refine_reports,
            times,
        })
    }

    /// Runs perception on its own thread, one frame ahead of the consumer (perception does not
    /// depend on the map, so it overlaps with integration), and decoding on another, one frame
    /// ahead of perception: decoding and refinement in turn on one thread left half a core idle
    /// on 2 cores (flat: 1.5 of 2 busy). Frames the stream could not deliver, and frames
    /// perception fails on, come out as errors naming the frame. Dropping the iterator stops
    /// both threads after their current frame.
    ///
    /// The two threads only hand frames on: the work runs on rayon's pool (one worker per
    /// core), where a dataset's decoding and the map's integration run too
    /// ([`Self::process_on_workers`]). Refinement on the perception thread itself made three
    /// compute threads share two cores, and the scheduler's time slices then stretched every
    /// stage (flat, `voxpan bench`: 108-121 against 124-132 frames/s; decode 3.0-5.0 against
    /// 2.7 ms, integrate 6.0-6.7 against 5.1-5.2). Segmentation stays on the perception
    /// thread: a network's runtime brings its own threads, and a worker blocked on it would be
    /// lost to integration.
    pub fn spawn(
        mut self,
        frames: FrameStream,
    ) -> impl Iterator<Item = Result<Perceived, FrameError>> {
        let (decoded_tx, decoded_rx) = std::sync::mpsc::sync_channel(1);
        std::thread::Builder::new()
            .name("voxpan-decode".into())
            .spawn(move || {
                let mut frames = frames;
                loop {
                    let t = Instant::now();
                    let Some(item) = frames.next() else {
                        break;
                    };
                    let decode = t.elapsed().as_secs_f64() * 1e3;
                    if decoded_tx.send((item, decode)).is_err() {
                        break;
                    }
                }
            })
            .expect("a thread can be spawned");
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        std::thread::Builder::new()
            .name("voxpan-perception".into())
            .spawn(move || {
                for (item, decode) in decoded_rx {
                    let result = item.and_then(|frame| {
                        let id = frame.id.clone();
                        let mut perceived = self
                            .process_on_workers(frame)
                            .map_err(|e| FrameError::new(id, e))?;
                        perceived.times.decode = decode;
                        Ok(perceived)
                    });
                    if tx.send(result).is_err() {
                        break;
                    }
                }
            })
            .expect("a thread can be spawned");
        rx.into_iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DatasetMasks;
    use voxpan_sim::{Scene, SynthConfig, synth_frame, trajectory};

    /// Perceives `config`'s synthetic frames two ways, each with a `Perception` of its own,
    /// asserts that both give the same masks, reports and filled depth, and returns the first
    /// way's results.
    fn perceived_alike(
        config: SynthConfig,
        mut one: impl FnMut(&mut Perception, Frame) -> Perceived,
        mut other: impl FnMut(&mut Perception, Frame) -> Perceived,
    ) -> Vec<Perceived> {
        let scene = Scene::generate(config.seed);
        let poses = trajectory(&scene, config.frames);
        let new = || Perception::new(PerceptionConfig::default(), Box::new(DatasetMasks)).unwrap();
        let (mut first, mut second) = (new(), new());
        let mut results = Vec::new();
        for (i, pose) in poses.iter().enumerate() {
            let frame = synth_frame(&scene, &config, i, pose);
            let a = one(&mut first, frame.clone());
            let b = other(&mut second, frame);
            assert_eq!(a.segments, b.segments, "frame {i}");
            assert_eq!(a.refine_reports, b.refine_reports, "frame {i}");
            assert_eq!(a.frame.depth, b.frame.depth, "frame {i}");
            results.push(a);
        }
        results
    }

    /// On the pool or on the calling thread, the same masks, reports and filled depth.
    #[test]
    fn perceiving_on_the_workers_gives_what_process_gives() {
        let config = SynthConfig {
            frames: 4,
            ..SynthConfig::tiny()
        };
        let perceived = perceived_alike(
            config,
            |p, frame| p.process(frame).unwrap(),
            |p, frame| p.process_on_workers(frame).unwrap(),
        );
        let refined: usize = perceived.iter().map(|p| p.refine_reports.len()).sum();
        assert!(refined > 0, "no mask was refined");
    }

    /// Refinement, trimming and filling on the AVX2 path (where the CPU has it) give the
    /// baseline path's masks, reports and depth bit for bit; masks do lose pixels here, so
    /// the passes that decide which are compared.
    #[test]
    fn the_avx2_path_perceives_what_the_baseline_perceives() {
        let config = SynthConfig {
            frames: 6,
            ..SynthConfig::default()
        };
        let perceived = perceived_alike(
            config,
            |p, frame| p.process(frame).unwrap(),
            |p, frame| voxpan_core::cpu::as_built(|| p.process(frame)).unwrap(),
        );
        let removed: usize = perceived
            .iter()
            .flat_map(|p| &p.refine_reports)
            .map(|r| r.removed)
            .sum();
        assert!(removed > 0, "refinement removed no pixel");
    }
}
