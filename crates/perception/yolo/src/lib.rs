//! YOLO instance segmentation (ONNX) inside voxpan: the network as a
//! [`Segmenter`](voxpan_perception::Segmenter).
//!
//! - [`letterbox`]: the image scaled into the network input (aspect kept, gray padding) and
//!   the map between image and input pixels;
//! - [`model`]: the head layout (YOLOv5-seg with objectness, or anchor-free YOLOv8/11-seg),
//!   detected from the output shapes and the model's metadata, and its class names;
//! - [`postprocess`]: confidence threshold, class-aware NMS, masks
//!   (`sigmoid(coefficients · prototypes)`, upsampled through the letterbox, > 0.5, cut to the
//!   box) and one label image where the higher score wins;
//! - [`Backend`]: what runs the graph. ONNX Runtime (cargo feature `ort`, the fast path,
//!   loaded at run time from `$ORT_DYLIB_PATH`) and tract (feature `tract`, pure Rust); both
//!   are optional and neither is in the workspace's default build;
//! - [`Yolo`]: a model on a backend, image in, instances out; [`YoloSegmenter`]: the same as
//!   voxpan's `Segmenter`.
//!
//! Pre- and post-processing are plain Rust and always built; with no backend feature,
//! [`Yolo::open`] says how to build one in.
//!
//! ```
//! use voxpan_yolo::{Letterbox, Detection, nms};
//!
//! // A 640×480 frame in a 320×320 input: halved, 40 rows of gray above and below.
//! let lb = Letterbox::new(640, 480, 320, 320).unwrap();
//! assert_eq!((lb.resized, lb.top), ((320, 240), 40));
//! assert_eq!(lb.to_image(160.0, 40.0), (320.0, 0.0));
//!
//! // Class-aware NMS: the weaker chair goes, the table on the same box stays.
//! let d = |class, score, bbox| Detection { class, score, bbox, coefs: vec![] };
//! let kept = nms(vec![d(0, 0.9, [0., 0., 10., 10.]), d(0, 0.8, [1., 0., 11., 10.]),
//!                     d(1, 0.7, [0., 0., 10., 10.])], 0.45, 100);
//! assert_eq!(kept.iter().map(|d| d.score).collect::<Vec<_>>(), [0.9, 0.7]);
//! ```

mod backend;
pub mod letterbox;
pub mod model;
#[cfg(feature = "ort")]
mod ort_backend;
pub mod postprocess;
mod segmenter;
#[cfg(feature = "tract")]
mod tract_backend;
mod yolo;

use std::path::PathBuf;

pub use backend::{Backend, BackendError, BackendKind, BackendOptions, Tensor, open_backend};
pub use letterbox::Letterbox;
pub use model::{Layout, ModelInfo, parse_names};
pub use postprocess::{
    Detection, Grid, Protos, candidates, for_each_mask_pixel, iou, label_image, nms,
};
pub use segmenter::YoloSegmenter;
pub use yolo::{ImageInstances, RawOutputs, Yolo, YoloOptions, YoloTimes};

/// Why a model cannot be used. Every message names the file (model or library) it is about.
#[derive(Debug, thiserror::Error)]
pub enum YoloError {
    /// The model file is missing, malformed, or not a YOLO segmentation model.
    #[error("{}: {message}", path.display())]
    Model { path: PathBuf, message: String },
    /// The ONNX Runtime shared library cannot be loaded.
    #[error("cannot load ONNX Runtime from {}: {message}", path.display())]
    Library { path: PathBuf, message: String },
    /// The backend asked for is not in this build.
    #[error("this voxpan was built without {backend}; build with {build}")]
    NotBuilt {
        backend: String,
        /// How to build a voxpan that has it.
        build: String,
    },
    /// The backend failed on an input.
    #[error("{}: inference failed: {message}", path.display())]
    Inference { path: PathBuf, message: String },
    /// An unusable option.
    #[error("{0}")]
    Options(String),
}
