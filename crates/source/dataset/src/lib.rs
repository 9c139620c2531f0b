//! Where frames come from: datasets on disk, decoded in the background.
//!
//! - [`FlatDataset`]: the panoptic_mapping "flat" format (colour PNG, float depth TIFF,
//!   predicted segments + labels.json, ground-truth segmentation, 4×4 poses, timestamps,
//!   intrinsics and label CSVs). [`flat::write_frame`] writes it (the synthetic world uses it).
//! - [`TumDataset`]: the TUM RGB-D layout (rgb.txt, depth.txt, groundtruth.txt, 16-bit PNG depth
//!   / 5000), associated by timestamp.
//! - [`open_dataset`] detects the format; [`stream`] turns a dataset into the
//!   [`FrameStream`](voxpan_core::FrameStream) the pipeline consumes, decoding on a background
//!   thread while the caller works on the previous frames.
//!
//! A frame with a missing file is reported and skipped when the dataset is opened; one that
//! fails to decode is an error for that frame only. Errors name the file.
//!
//! ```
//! use std::sync::Arc;
//! use voxpan_core::{Frame, Image, Intrinsics, Pose};
//! use voxpan_dataset::{flat, open_dataset, stream, FrameSource};
//!
//! // Write a two-frame flat dataset, open it, and stream it.
//! let dir = tempfile::tempdir()?;
//! let k = Intrinsics { width: 8, height: 6, fx: 4.0, fy: 4.0, cx: 4.0, cy: 3.0 };
//! std::fs::create_dir_all(dir.path().join("run1"))?;
//! flat::write_intrinsics(dir.path(), &k)?;
//! for i in 0..2 {
//!     let frame = Frame {
//!         id: format!("{i:06}"),
//!         timestamp: i as f64 / 30.0,
//!         color: Image::filled(8, 6, [90, 90, 90]),
//!         depth: Image::filled(8, 6, 1.5),
//!         pose: Pose::identity(),
//!         intrinsics: k,
//!         segments: None,
//!         ground_truth: None,
//!     };
//!     flat::write_frame(&dir.path().join("run1"), &frame)?;
//! }
//! let dataset: Arc<dyn FrameSource> = Arc::from(open_dataset(dir.path())?);
//! let ids: Vec<String> = stream(dataset, vec![0, 1]).map(|f| f.unwrap().id).collect();
//! assert_eq!(ids, ["000000", "000001"]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
pub mod flat;
mod frame;
pub mod tum;

pub use error::DatasetError;
pub use flat::FlatDataset;
pub use frame::{FrameSource, SkipGroup, group_skipped, paced, stream, stream_with};
pub use tum::TumDataset;

use std::path::Path;

/// Opens a flat or TUM RGB-D directory, whichever it is.
pub fn open_dataset(path: &Path) -> Result<Box<dyn FrameSource>, DatasetError> {
    if !path.exists() {
        return Err(DatasetError::Missing(path.to_owned()));
    }
    if TumDataset::looks_like(path) {
        return Ok(Box::new(TumDataset::open(path)?));
    }
    if FlatDataset::looks_like(path) {
        return Ok(Box::new(FlatDataset::open(path)?));
    }
    Err(DatasetError::Unrecognised(path.to_owned()))
}
