//! The types every voxpan stage shares: a dense row-major [`Image`], the per-frame
//! [`Segment`] description, camera [`Intrinsics`] and [`Pose`], and the depth validity rule.
//!
//! Kept tiny (serde and nalgebra only) so that each stage crate (fill, refine, io, ...) can depend on
//! it without pulling in the others.

mod camera;
mod image;
mod segment;

pub use camera::{pose_from_matrix, Intrinsics, Pose, PoseError};
pub use image::{is_valid_depth, ColorImage, DepthImage, Image, LabelImage};
pub use nalgebra;
pub use segment::{segment_ids, Segment};
