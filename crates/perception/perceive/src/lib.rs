//! The perception stage (step 1 and 2 of the pipeline), frame by frame: segment the colour
//! image, refine each mask by the depths under it, fill the depth holes. On a robot this runs
//! on the camera's computer; the map runs on another.
//!
//! - [`Segmenter`]: where masks come from. [`DatasetMasks`] takes the masks a dataset ships
//!   (precomputed network output), [`GroundTruthMasks`] the dataset's ground truth; a network
//!   is one more implementation.
//! - [`Keyframes`]: which frames the segmenter runs on; between keyframes the map renders
//!   the masks and [`MaskRefiner`] refines them on the frame's measured depth.
//! - [`Perception`]: segment → trim → refine (on measured depth) → fill, with timings and per-mask
//!   reports; [`Perception::spawn`] runs it on its own thread one frame ahead of the consumer,
//!   its work on rayon's pool ([`Perception::process_on_workers`]).
//!
//! ```
//! use voxpan_perception::{DatasetMasks, Perception, PerceptionConfig};
//! use voxpan_sim::{synth_frame, trajectory, Scene, SynthConfig};
//!
//! let config = SynthConfig::tiny();
//! let scene = Scene::generate(config.seed);
//! let pose = trajectory(&scene, 1)[0];
//! let frame = synth_frame(&scene, &config, 0, &pose);
//! let mut perception = Perception::new(PerceptionConfig::default(), Box::new(DatasetMasks))?;
//! let perceived = perception.process(frame)?;
//! let segments = perceived.segments.expect("the synthetic frame has masks");
//! assert!(!segments.segments.is_empty());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod keyframes;
mod segmenter;
mod stage;

pub use keyframes::{Keyframes, shared_view};
pub use segmenter::{DatasetMasks, GroundTruthMasks, SegmentError, Segmenter};
pub use stage::{
    MaskRefiner, Perceived, Perception, PerceptionConfig, PerceptionError, StageTimes,
};
