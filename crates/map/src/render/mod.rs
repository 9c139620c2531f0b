//! The map seen from a camera: a ray cast of the TSDF's zero crossing (Open3D's `RayCast`,
//! nvblox's sphere tracer), giving depth, colour, instance and normal images.

mod raycast;

pub use raycast::RenderedView;
pub(crate) use raycast::{RaySpan, instances_at_depth, raycast};
