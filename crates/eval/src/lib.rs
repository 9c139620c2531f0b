//! Evaluation (the last step of the pipeline): 2-D mask metrics, 3-D surface metrics
//! ([`surface`]) and panoptic quality over voxels ([`volume`]).
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

mod masks;
pub mod surface;
pub mod volume;

pub use masks::{match_frame, match_frame_subset, FrameMatch, MaskScores, MaskSummary};
