//! Association: matching each frame's segments with the map's persistent instances.

mod claims;
mod groups;
mod observe;
mod tracker;

pub(crate) use claims::claiming_pixels;
pub(crate) use observe::{Surface, observe};
pub use tracker::AssociationStats;
pub(crate) use tracker::{InstanceInfo, InstanceTracker, class_families};
