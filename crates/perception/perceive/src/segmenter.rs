use voxpan_core::{ClassTable, Frame, Segment, Segments, segment_ids};

/// Why a segmenter could not segment a frame.
pub type SegmentError = Box<dyn std::error::Error + Send + Sync>;

/// Where a frame's instance masks come from: a network, a dataset's stored masks, a ROS topic.
pub trait Segmenter: Send {
    /// A short name for messages and reports ("dataset masks", "yolov5s-seg", ...).
    fn name(&self) -> &str;
    /// The frame's segments, or `None` when there are none for this frame (a dataset frame
    /// without masks): the frame is then mapped without instances.
    fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError>;
}

/// The masks the frame came with (a dataset's precomputed network output).
#[derive(Clone, Copy, Debug, Default)]
pub struct DatasetMasks;

impl Segmenter for DatasetMasks {
    fn name(&self) -> &str {
        "dataset masks"
    }

    fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError> {
        Ok(frame.segments.clone())
    }
}

/// The frame's ground-truth instances as segments (for reference maps and upper bounds):
/// every non-zero ground-truth id becomes a segment of the same id, with class and kind from
/// the ground truth's label table when given.
#[derive(Clone, Debug, Default)]
pub struct GroundTruthMasks {
    classes: Option<ClassTable>,
}

impl GroundTruthMasks {
    /// `classes`: ground-truth instance id → class and thing/stuff (flat's
    /// `groundtruth_labels.csv`), when known.
    pub fn new(classes: Option<ClassTable>) -> Self {
        Self { classes }
    }
}

impl Segmenter for GroundTruthMasks {
    fn name(&self) -> &str {
        "ground truth"
    }

    fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError> {
        let Some(labels) = &frame.ground_truth else {
            return Ok(None);
        };
        let segments = segment_ids(labels)
            .into_iter()
            .map(|id| {
                let class = self.classes.as_ref().and_then(|t| t.get(id as u32));
                Segment {
                    id,
                    class_id: class.map(|c| c.class_id),
                    is_thing: class.map(|c| c.is_thing),
                    score: None,
                }
            })
            .collect();
        Ok(Some(Segments {
            labels: labels.clone(),
            segments,
        }))
    }
}
