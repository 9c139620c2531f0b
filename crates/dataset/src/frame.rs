use voxpan_core::{ColorImage, DepthImage, Intrinsics, LabelImage, Pose, Segment};

use crate::DatasetError;

/// A network's segmentation of a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSegments {
    pub labels: LabelImage,
    pub segments: Vec<Segment>,
}

/// One RGB-D frame and what is known about it.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The dataset's name for the frame (flat: `000042`; TUM: the depth timestamp).
    pub id: String,
    /// Seconds.
    pub timestamp: f64,
    pub color: ColorImage,
    /// Planar depth in metres; 0 = invalid.
    pub depth: DepthImage,
    /// Predicted segments, when the dataset has them.
    pub segments: Option<FrameSegments>,
    /// Ground-truth instance ids, when the dataset has them.
    pub ground_truth: Option<LabelImage>,
    /// `T_world_camera`.
    pub pose: Pose,
    pub intrinsics: Intrinsics,
}

/// A sequence of frames that can be decoded in any order, from any thread.
pub trait FrameSource: Send + Sync {
    /// What kind of dataset, for messages ("flat", "tum").
    fn kind(&self) -> &'static str;
    /// Usable frames.
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The id of frame `index` (`0..len()`).
    fn frame_id(&self, index: usize) -> &str;
    /// Decodes frame `index`.
    fn load(&self, index: usize) -> Result<Frame, DatasetError>;
    /// Frames left out when the dataset was opened, with the reason.
    fn skipped(&self) -> &[(String, String)];
    /// Whether ground-truth instance `id` is a thing, when the dataset says.
    fn ground_truth_is_thing(&self, _id: u16) -> Option<bool> {
        None
    }
}
