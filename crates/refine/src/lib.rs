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

mod example;
mod frame;
mod interior;
mod interval;
mod rule;

pub use example::{example_scene, ExampleScene};
pub use frame::{MaskReport, MaskStatus, RefineConfig, Refiner};
pub use interior::interior_depth;
pub use interval::{DepthInterval, KeptReason, Side, FAR_LIMIT_M};
pub use rule::Rule;
