//! voxpan's simulation world (like voxblox's, but full RGB-D): a procedural room with
//! furniture-like instances, a camera trajectory, ray-cast colour / depth / instance ids, a
//! switchable sensor model, and predicted masks with the errors a lightweight CNN makes.
//! Written in the flat format, so the same reader handles real and synthetic data; the
//! ground-truth mesh goes to a PLY with per-vertex instance ids.
//!
//! Everything is deterministic for a given seed (each frame draws from its own seeded stream,
//! so frames can be rendered in parallel).
//!
//! ```
//! use voxpan_sim::{generate, SynthConfig};
//!
//! let dir = tempfile::tempdir()?;
//! let config = SynthConfig { frames: 3, ..SynthConfig::tiny() };
//! let summary = generate(dir.path(), &config, |_| {})?;
//! assert_eq!(summary.frames, 3);
//! assert!(dir.path().join("run1/000002_depth.tiff").is_file());
//! assert!(dir.path().join("groundtruth_mesh.ply").is_file());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod masks;
mod mesh;
mod random;
mod render;
mod scene;
mod sensor;
mod shape;
pub mod trajectory;
mod world;

pub use masks::{MaskErrors, PERSIST, SequenceFrame, TrueView};
pub use mesh::scene_mesh;
pub use random::Rand;
pub use render::{Rendered, render};
pub use scene::{Object, Room, Scene, Surface};
pub use sensor::SensorModel;
pub use shape::{Hit, Shape};
pub use trajectory::trajectory;
pub use world::{SynthConfig, SynthSummary, World, generate, synth_frame};
