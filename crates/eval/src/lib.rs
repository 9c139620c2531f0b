//! Evaluation metrics (the last step of the pipeline): 2-D mask metrics, 3-D surface metrics
//! ([`surface`]) and panoptic quality over voxels ([`volume`]). They need only masks and maps;
//! the protocols that run the pipeline over datasets to compute them (what `voxpan eval`
//! prints) are `voxpan_pipeline::protocols`.
//!
//! The protocol (the paper gives none; this one is voxpan's): per frame, predicted segments are
//! the non-zero ids of the label image and ground-truth segments every id of the ground-truth
//! image (id 0 is a real class there). Their IoU matrix is matched by the Hungarian algorithm,
//! maximising total IoU. Pooled over frames:
//! - mean matched IoU: mean IoU over assigned pairs with IoU > 0;
//! - TP: assigned pairs with IoU > 0.5; FP = predicted − TP; FN = ground truth − TP
//!   (class-agnostic);
//! - SQ = mean IoU of TPs, RQ = TP / (TP + FP/2 + FN/2), PQ = SQ × RQ (Kirillov et al.);
//! - pixel precision: of all predicted pixels, the share inside their assigned ground-truth
//!   segment; pixel recall: of all ground-truth pixels, the share inside their assigned
//!   prediction.
//!
//! ```
//! use voxpan_core::Image;
//! use voxpan_eval::{match_frame, MaskScores};
//!
//! let gt = Image::from_fn(8, 8, |x, _| (x / 4) as u16);
//! // The same partition under other ids: a perfect prediction.
//! let pred = gt.map(|&g| g + 5);
//! let mut scores = MaskScores::default();
//! scores.add(&match_frame(&pred, &gt));
//! assert_eq!(scores.summary().pq, 100.0);
//! ```

mod masks;
pub mod surface;
pub mod volume;

pub use masks::{FrameMatch, MaskScores, MaskSummary, match_frame, match_frame_subset};
