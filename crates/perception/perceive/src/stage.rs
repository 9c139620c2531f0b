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
    /// Run the segmenter on a thread of its own in [`Perception::spawn`] (`[segment]
    /// own_thread`): frames never wait for it. A keyframe is a frame the schedule asks for
    /// while the segmenter is free; it comes out when its masks are ready, after the frames
    /// that went on meanwhile, and those frames carry the map's masks.
    pub own_thread: bool,
}

impl PerceptionConfig {
    /// Refuses `[fill]` and `[refine]` values perception cannot run with.
    pub fn validate(&self) -> Result<(), PerceptionError> {
        self.fill.validate().map_err(PerceptionError::Config)?;
        let far = self.refine.far_limit;
        if far.is_nan() || far <= 0.0 {
            return Err(PerceptionError::Config(format!(
                "refine.far_limit = {far}: expected a positive number"
            )));
        }
        Ok(())
    }
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

/// Segment → trim things off stuff planes → refine (on measured depth) → fill, one frame at a
/// time. Keeps its buffers between frames: one per thread.
pub struct Perception {
    config: PerceptionConfig,
    segmenter: Box<dyn Segmenter>,
    refiner: MaskRefiner,
    filler: HoleFiller,
    keyframes: KeyframeScheduler,
}

/// Trimming things off stuff planes, then refinement by the depths under each mask: what
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
        // Planes first: they say for sure which pixels are floor or wall. Left in, a thin
        // thing's bleed onto the wall can outweigh the thing in the rule's depth clusters,
        // and what the rule keeps then lies flat on the wall, as a picture would.
        if self.config.trim_stuff_planes {
            let t = Instant::now();
            self.trimmer
                .trim(depth, &mut segments.labels, &segments.segments)
                .expect("shapes checked above");
            times.trim += ms(t);
        }
        let t = Instant::now();
        let reports = self
            .refiner
            .refine_frame(depth, &mut segments.labels, &segments.segments)
            .expect("shapes checked above");
        times.refine += ms(t);
        Ok(reports)
    }
}

impl Perception {
    pub fn new(
        config: PerceptionConfig,
        segmenter: Box<dyn Segmenter>,
    ) -> Result<Self, PerceptionError> {
        config.validate()?;
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

    /// [`Self::process`] with trimming, refinement and filling run on rayon's pool (one
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

    /// What [`Self::process`] does after segmenting: trim, refine, fill.
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
                if self.config.own_thread {
                    return self.spawn_with_segmenter_thread(decoded_rx, tx);
                }
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

    /// [`Self::spawn`] with the segmenter on a thread of its own (`own_thread`): the
    /// perception thread hands a keyframe to it when the schedule asks for one and it is
    /// free, and goes on with the next frames (carried: their masks come from the map). A
    /// keyframe comes out once its masks are back and refined, after the frames that passed
    /// it: the map integrates it late, each frame still once. A schedule of every frame then
    /// means "whenever the segmenter is free".
    fn spawn_with_segmenter_thread(
        mut self,
        decoded: std::sync::mpsc::Receiver<(Result<Frame, FrameError>, f64)>,
        tx: std::sync::mpsc::SyncSender<Result<Perceived, FrameError>>,
    ) {
        type Segmented = (Frame, f64, Result<Option<Segments>, PerceptionError>, f64);
        let (request_tx, request_rx) = std::sync::mpsc::sync_channel::<(Frame, f64)>(1);
        let (done_tx, done_rx) = std::sync::mpsc::channel::<Segmented>();
        let name = self.segmenter.name().to_owned();
        let mut segmenter = std::mem::replace(&mut self.segmenter, Box::new(Lent { name }));
        std::thread::Builder::new()
            .name("voxpan-segmenter".into())
            .spawn(move || {
                for (frame, decode) in request_rx {
                    let t = Instant::now();
                    let segments =
                        segmenter
                            .segment(&frame)
                            .map_err(|source| PerceptionError::Segment {
                                segmenter: segmenter.name().to_owned(),
                                source,
                            });
                    let ms = t.elapsed().as_secs_f64() * 1e3;
                    if done_tx.send((frame, decode, segments, ms)).is_err() {
                        break;
                    }
                }
            })
            .expect("a thread can be spawned");
        // A keyframe back from the segmenter, refined and filled.
        let finish = |perception: &mut Self, (frame, decode, segments, ms): Segmented| {
            let id = frame.id.clone();
            let mut perceived = segments
                .and_then(|s| rayon::scope(|_| perception.refine_and_fill(frame, Some((s, ms)))))
                .map_err(|e| FrameError::new(id, e))?;
            perceived.times.decode = decode;
            Ok(perceived)
        };
        let mut in_flight = false;
        for (item, decode) in decoded {
            if in_flight && let Ok(done) = done_rx.try_recv() {
                in_flight = false;
                if tx.send(finish(&mut self, done)).is_err() {
                    return;
                }
            }
            let result = match item {
                Err(e) => Err(e),
                Ok(frame) => {
                    let keyframe = if in_flight {
                        self.keyframes.pass();
                        false
                    } else {
                        self.keyframes.is_keyframe(&frame)
                    };
                    if keyframe {
                        in_flight = true;
                        if request_tx.send((frame, decode)).is_err() {
                            return;
                        }
                        continue;
                    }
                    let id = frame.id.clone();
                    rayon::scope(|_| self.refine_and_fill(frame, None))
                        .map(|mut perceived| {
                            perceived.times.decode = decode;
                            perceived
                        })
                        .map_err(|e| FrameError::new(id, e))
                }
            };
            if tx.send(result).is_err() {
                return;
            }
        }
        drop(request_tx);
        if in_flight && let Ok(done) = done_rx.recv() {
            let _ = tx.send(finish(&mut self, done));
        }
    }
}

/// Stands in for a segmenter lent to its own thread (see
/// [`Perception::spawn_with_segmenter_thread`]), which alone calls it.
struct Lent {
    name: String,
}

impl Segmenter for Lent {
    fn name(&self) -> &str {
        &self.name
    }

    fn segment(&mut self, _: &Frame) -> Result<Option<Segments>, SegmentError> {
        Err(format!("{} runs on a thread of its own", self.name).into())
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

    /// A pole 2 px wide at 2 m before a wall at 4 m (with a camera's noise), its mask 6 px
    /// too wide on each side. By the rule's weights (distance to the mask's outline) the
    /// bleed outweighs the pole: refined first, the mask keeps the wall and then lies flat on
    /// it, as a picture would. Trimmed first, the bleed goes to the wall and the pole stays.
    #[test]
    fn a_thin_things_bleed_onto_the_wall_goes_and_the_thing_stays() {
        use voxpan_core::{DepthImage, LabelImage, Segment};
        let (width, height) = (160, 120);
        let pole = |x: usize, y: usize| (79..81).contains(&x) && (20..100).contains(&y);
        let mask = |x: usize, y: usize| (73..87).contains(&x) && (14..106).contains(&y);
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut depth = DepthImage::filled(width, height, 0.0);
        let mut labels = LabelImage::filled(width, height, 1);
        for y in 0..height {
            for x in 0..width {
                let z: f64 = if pole(x, y) { 2.0 } else { 4.0 };
                // Gaussian noise of 0.002 /m in inverse depth (Box-Muller).
                let (a, b) = (uniform(), uniform());
                let noise = (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos();
                *depth.get_mut(x, y) = (1.0 / (1.0 / z + 0.002 * noise)) as f32;
                if mask(x, y) {
                    *labels.get_mut(x, y) = 2;
                }
            }
        }
        let segments = vec![
            Segment {
                is_thing: Some(false),
                ..Segment::bare(1)
            },
            Segment {
                is_thing: Some(true),
                ..Segment::bare(2)
            },
        ];
        let mut segments = Segments { labels, segments };
        let mut refiner = MaskRefiner::new(RefineConfig::default());
        refiner
            .refine(&depth, &mut segments, &mut StageTimes::default())
            .unwrap();
        let (mut pole_kept, mut bleed_kept, mut bleed) = (0, 0, 0);
        for y in 0..height {
            for x in 0..width {
                let kept = *segments.labels.get(x, y) == 2;
                if pole(x, y) {
                    pole_kept += usize::from(kept);
                } else if mask(x, y) {
                    bleed += 1;
                    bleed_kept += usize::from(kept);
                }
            }
        }
        assert_eq!(pole_kept, 160, "of the pole's 160 pixels");
        assert!(
            bleed_kept * 100 <= bleed * 3,
            "{bleed_kept} of {bleed} left"
        );
    }

    /// A segmenter on its own thread never holds frames up: this one returns the first
    /// keyframe's masks only once ten frames have come out past it (and fails after a minute,
    /// which is what waiting for it would come to). Every frame comes out once, the keyframe
    /// after the ten. (Which frames come after it are keyframes depends on the timing.)
    #[test]
    fn frames_do_not_wait_for_a_segmenter_on_its_own_thread() {
        use std::sync::Arc;
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::time::Duration;

        struct Slow {
            passed: Arc<AtomicUsize>,
            calls: usize,
        }
        impl Segmenter for Slow {
            fn name(&self) -> &str {
                "slow"
            }
            fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError> {
                self.calls += 1;
                let start = Instant::now();
                while self.calls == 1 && self.passed.load(Ordering::SeqCst) < 10 {
                    if start.elapsed() > Duration::from_secs(60) {
                        return Err("the frames waited for the segmenter".into());
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                Ok(frame.segments.clone())
            }
        }

        let config = SynthConfig {
            frames: 16,
            ..SynthConfig::tiny()
        };
        let scene = Scene::generate(config.seed);
        let frames: Vec<_> = trajectory(&scene, config.frames)
            .iter()
            .enumerate()
            .map(|(i, pose)| Ok(synth_frame(&scene, &config, i, pose)))
            .collect();
        let passed = Arc::new(AtomicUsize::new(0));
        let segmenter = Slow {
            passed: passed.clone(),
            calls: 0,
        };
        let perception_config = PerceptionConfig {
            own_thread: true,
            ..PerceptionConfig::default()
        };
        let perception = Perception::new(perception_config, Box::new(segmenter)).unwrap();
        let mut out = Vec::new();
        for item in perception.spawn(Box::new(frames.into_iter())) {
            let perceived = item.unwrap();
            if !perceived.keyframe {
                assert!(perceived.segments.is_none() && perceived.measured_depth.is_some());
                passed.fetch_add(1, Ordering::SeqCst);
            } else {
                assert!(perceived.segments.is_some() && perceived.measured_depth.is_none());
            }
            out.push((perceived.frame.id.clone(), perceived.keyframe));
        }
        let first_keyframe = out.iter().position(|(_, k)| *k).unwrap();
        assert_eq!(out[first_keyframe].0, frames_id(0), "{out:?}");
        assert!(first_keyframe >= 10, "{out:?}");
        let mut ids: Vec<&String> = out.iter().map(|(id, _)| id).collect();
        ids.sort();
        ids.dedup();
        assert_eq!((ids.len(), out.len()), (16, 16), "{out:?}");
    }

    fn frames_id(i: usize) -> String {
        format!("{i:06}")
    }
}
