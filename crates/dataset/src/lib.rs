//! Where frames come from: datasets on disk, decoded in the background.
//!
//! - [`FlatDataset`]: the panoptic_mapping "flat" format (colour PNG, float depth TIFF,
//!   predicted segments + labels.json, ground-truth segmentation, 4×4 poses, timestamps,
//!   intrinsics and label CSVs). [`flat::write_frame`] writes it (the synthetic world uses it).
//! - [`TumDataset`]: the TUM RGB-D layout (rgb.txt, depth.txt, groundtruth.txt, 16-bit PNG depth
//!   / 5000), associated by timestamp.
//! - [`open_dataset`] detects the format; [`prefetch`] decodes frames on a background thread
//!   while the caller works on the previous ones.
//!
//! A frame with a missing file is reported and skipped when the dataset is opened; one that
//! fails to decode is an error for that frame only. Errors name the file.

mod classes;
mod error;
pub mod flat;
mod frame;
mod prefetch;
mod tum;

pub use classes::{ClassInfo, ClassTable};
pub use error::DatasetError;
pub use flat::FlatDataset;
pub use frame::{Frame, FrameSegments, FrameSource};
pub use prefetch::prefetch;
pub use tum::TumDataset;

use std::path::Path;

/// Opens a flat or TUM RGB-D directory, whichever it is.
pub fn open_dataset(path: &Path) -> Result<Box<dyn FrameSource>, DatasetError> {
    if TumDataset::looks_like(path) {
        return Ok(Box::new(TumDataset::open(path)?));
    }
    if FlatDataset::looks_like(path) {
        return Ok(Box::new(FlatDataset::open(path)?));
    }
    Err(DatasetError::Unrecognised(path.to_owned()))
}
