//! Mask refinement (step 2 of the pipeline; the paper's Algorithm 1).
//!
//! For each mask: take the valid depths under it, estimate their density with the ISJ KDE, find
//! the global peak, walk left and right to the first grid point whose density is below the
//! rule's cut-off, and keep the pixels with `low <= depth <= high`. Removed pixels become void
//! (0), never another segment.
//!
//! Rules ([`Rule`]): `paper` and `release` reproduce the published method; `default` is
//! voxpan's rule (cuts at depth gaps, weighs clusters by depth inside the mask with
//! [`interior_depth`]). A mask the rule cannot judge (too few pixels, constant depth, a peak on
//! the grid edge, no crossing on one side, nothing within the far limit) is kept unchanged, and
//! its [`MaskReport`] says why.
//!
//! ```
//! use voxpan_refine::{example_scene, RefineConfig, Refiner, Rule};
//!
//! // A box and a ball whose predicted masks bleed onto the wall and floor behind them.
//! let scene = example_scene();
//! let mut labels = scene.predicted.clone();
//! let mut refiner = Refiner::new(RefineConfig::new(Rule::Default));
//! let reports = refiner.refine_frame(&scene.depth, &mut labels, &scene.segments).unwrap();
//! // Masks lose pixels, and only pixels the ground truth does not give them.
//! assert!(reports.iter().map(|r| r.removed).sum::<usize>() > 1000);
//! let wrongly_removed = labels
//!     .pixels()
//!     .iter()
//!     .zip(scene.predicted.pixels())
//!     .zip(scene.ground_truth.pixels())
//!     .filter(|&((&after, &before), &truth)| after == 0 && before != 0 && truth == before)
//!     .count();
//! assert_eq!(wrongly_removed, 0);
//! ```

mod example;
mod frame;
mod interior;
mod interval;
mod planes;
mod rule;

pub use example::{ExampleScene, example_scene};
pub use frame::{MaskReport, MaskStatus, RefineConfig, Refiner, ShapeMismatch};
pub use interior::interior_depth;
pub use interval::{DepthInterval, FAR_LIMIT_M, KeptReason, Side};
pub use planes::{PlaneTrimmer, StuffPlane, TrimReport};
pub use rule::Rule;
