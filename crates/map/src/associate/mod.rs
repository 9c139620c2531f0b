//! Association: matching each frame's segments with the map's persistent instances.

mod splat;
mod tracker;

pub use splat::downscaled;
pub(crate) use splat::render_instances;
pub use tracker::AssociationStats;
pub(crate) use tracker::{InstanceInfo, InstanceTracker};
