use std::sync::Arc;

use voxpan_core::{Annotations, ClassTable, Frame, FrameError, FrameStream};

use crate::DatasetError;

/// A recorded sequence whose frames can be decoded in any order, from any thread: what a
/// dataset on disk is. [`stream`] turns one into the [`FrameStream`] the pipeline consumes.
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
    /// Decodes frame `index` for a consumer that reads only the annotations `wanted`. A source
    /// that can skip decoding the others does, and leaves them `None`; the default decodes
    /// everything, as [`FrameSource::load`].
    fn load_with(&self, index: usize, _wanted: Annotations) -> Result<Frame, DatasetError> {
        self.load(index)
    }
    /// Frames left out when the dataset was opened, with the reason.
    fn skipped(&self) -> &[(String, String)];
    /// What the user should know about the data before trusting the map (a distorted
    /// camera, say), found when the dataset was opened.
    fn warnings(&self) -> &[String] {
        &[]
    }
    /// The network's label table (class ids of predicted segments), when the dataset has one.
    fn network_classes(&self) -> Option<&ClassTable> {
        None
    }
    /// The ground truth's label table (ground-truth instance id → class), when it has one.
    fn ground_truth_classes(&self) -> Option<&ClassTable> {
        None
    }
    /// Names of the ground truth's semantic classes (`ClassID → name`), when the dataset has
    /// them.
    fn ground_truth_class_names(&self) -> Option<&std::collections::BTreeMap<u32, String>> {
        None
    }
    /// Whether ground-truth instance `id` is a thing, when the dataset says.
    fn ground_truth_is_thing(&self, id: u16) -> Option<bool> {
        self.ground_truth_classes()?
            .get(id as u32)
            .map(|c| c.is_thing)
    }
}

/// The frames `indices` of `source` as a stream. Decoding happens lazily, on whichever thread
/// pulls the next frame (the pipeline's decode thread, one frame ahead of perception). A frame
/// that fails to decode is an error item naming it; the stream goes on.
pub fn stream(source: Arc<dyn FrameSource>, indices: Vec<usize>) -> FrameStream {
    stream_with(source, indices, Annotations::ALL)
}

/// [`stream`], decoding only the annotations `wanted` where the source can skip the others
/// (what the consumer's segmenter [reads](voxpan_core::Annotations)).
pub fn stream_with(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    wanted: Annotations,
) -> FrameStream {
    Box::new(indices.into_iter().map(move |i| {
        source
            .load_with(i, wanted)
            .map_err(|e| FrameError::new(source.frame_id(i), e.without_frame()))
    }))
}
