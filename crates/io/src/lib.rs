//! Files on disk: depth maps, colour and label images, segment lists, label tables, PLY
//! meshes, and atomic writes.
//!
//! Every error names the file and says what is wrong with it; nothing here panics on data.
//!
//! ```
//! use voxpan_core::Image;
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("labels.png");
//! let labels = Image::from_fn(8, 4, |x, _| x as u16);
//! voxpan_io::write_label_png(&path, &labels).unwrap();
//! assert_eq!(voxpan_io::read_label_png(&path).unwrap(), labels);
//! ```

mod atomic;
mod classes;
mod color;
mod depth;
mod error;
mod labels;
mod ply;
mod sample;
mod segments;

pub use atomic::write_atomically;
pub use classes::{read_class_csv, write_class_csv};
pub use color::{read_color_png, write_color_png};
pub use depth::{read_depth, read_depth_png, read_depth_tiff, write_depth_tiff};
pub use error::IoError;
pub use labels::{read_label_png, write_label_png};
pub use ply::{read_ply, write_ply, write_ply_to};
pub use sample::{
    ALLOW_MISSING_ENV, FLAT_DIR_ENV, MODELS_DIR_ENV, ORT_LIBRARY_ENV, flat_sample_dir, models_dir,
    onnxruntime_library, require_flat_sample, require_model, require_onnxruntime,
};
pub use segments::{read_segments_json, write_segments_json};
