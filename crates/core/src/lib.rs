//! The types every voxpan stage shares: a dense row-major [`Image`], the per-frame
//! [`Segment`] description, and the depth validity rule.
//!
//! Kept tiny and dependency-free so that each stage crate (fill, refine, io, ...) can depend on
//! it without pulling in the others.

mod image;
mod segment;

pub use image::{is_valid_depth, DepthImage, Image, LabelImage};
pub use segment::{segment_ids, Segment};
