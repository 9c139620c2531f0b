//! Frame files on disk: depth maps, label images and segment descriptions.
//!
//! Every error names the file and says what is wrong with it; nothing here panics on data.

mod color;
mod depth;
mod error;
mod labels;
mod sample;
mod segments;

pub use color::{read_color_png, write_color_png};
pub use depth::{read_depth, read_depth_png, read_depth_tiff, write_depth_tiff};
pub use error::IoError;
pub use labels::{read_label_png, write_label_png};
pub use sample::{flat_sample_dir, require_flat_sample, ALLOW_MISSING_ENV, FLAT_DIR_ENV};
pub use segments::{read_segments_json, write_segments_json};
