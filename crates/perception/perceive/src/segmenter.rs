use voxpan_core::{Annotations, ClassTable, Frame, Segment, Segments};

/// Why a segmenter could not segment a frame.
pub type SegmentError = Box<dyn std::error::Error + Send + Sync>;

/// Where a frame's instance masks come from: a network, a dataset's stored masks, a ROS topic.
pub trait Segmenter: Send {
    /// A short name for messages and reports ("dataset masks", "yolov5s-seg", ...).
    fn name(&self) -> &str;
    /// The frame's segments, or `None` when there are none for this frame (a dataset frame
    /// without masks): the frame is then mapped without instances.
    fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError>;
    /// The label table of the segments' class ids, when the segmenter has its own (a network's
    /// categories); `None` when they index a table the source provides (a dataset's).
    fn classes(&self) -> Option<&ClassTable> {
        None
    }
    /// The frame annotations [`Segmenter::segment`] reads; a source need not decode the
    /// others. Everything unless the segmenter says less.
    fn reads(&self) -> Annotations {
        Annotations::ALL
    }
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

    fn reads(&self) -> Annotations {
        Annotations {
            segments: true,
            ground_truth: false,
        }
    }
}

/// The frame's ground-truth instances as segments, for reference maps and upper bounds. Class
/// and kind come from the ground truth's label table when given. Where that table lists id 0
/// (flat's ceiling), 0 is an object like any other and every id is shifted up by one, so that
/// segment 0 stays void; otherwise ground-truth 0 is void.
///
/// By default a segment's id is its object's (shifted) id in every frame: ids that already
/// identify objects across frames. [`with_random_ids`](Self::with_random_ids) renumbers them
/// at random in each frame, as a network does, to measure association on perfect masks.
#[derive(Clone, Debug, Default)]
pub struct GroundTruthMasks {
    classes: Option<ClassTable>,
    random_ids: Option<u64>,
    frames: u64,
}

impl GroundTruthMasks {
    /// `classes`: ground-truth instance id → class and thing/stuff (flat's
    /// `groundtruth_labels.csv`), when known.
    pub fn new(classes: Option<ClassTable>) -> Self {
        Self {
            classes,
            random_ids: None,
            frames: 0,
        }
    }

    /// Segment ids drawn afresh in every frame (a seeded permutation per frame).
    pub fn with_random_ids(mut self, seed: u64) -> Self {
        self.random_ids = Some(seed);
        self
    }

    /// Whether ground-truth id 0 is an object (the label table lists it).
    fn zero_is_object(&self) -> bool {
        self.classes.as_ref().is_some_and(|t| t.get(0).is_some())
    }

    /// The segment id of ground-truth object `id` (`None`: void, or no id left).
    pub fn segment_id(&self, id: u16) -> Option<u16> {
        if self.zero_is_object() {
            id.checked_add(1)
        } else {
            (id != 0).then_some(id)
        }
    }

    /// The ground-truth object of segment id `segment`: the inverse of
    /// [`segment_id`](Self::segment_id) (`None` for void).
    pub fn truth_id(&self, segment: u16) -> Option<u16> {
        if self.zero_is_object() {
            segment.checked_sub(1)
        } else {
            (segment != 0).then_some(segment)
        }
    }
}

/// A permutation of `0..n` from `seed` (splitmix64 + Fisher-Yates: no dependency for a shuffle).
fn permutation(n: usize, seed: u64) -> Vec<usize> {
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (next() % (i as u64 + 1)) as usize;
        p.swap(i, j);
    }
    p
}

impl Segmenter for GroundTruthMasks {
    fn name(&self) -> &str {
        "ground truth"
    }

    fn reads(&self) -> Annotations {
        Annotations {
            segments: false,
            ground_truth: true,
        }
    }

    fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError> {
        let Some(truth) = &frame.ground_truth else {
            return Ok(None);
        };
        let mut present = vec![false; u16::MAX as usize + 1];
        for &g in truth.pixels() {
            present[g as usize] = true;
        }
        let objects: Vec<u16> = (0..=u16::MAX).filter(|&g| present[g as usize]).collect();
        // Ground-truth id → segment id, for this frame.
        let mut to_segment = vec![0u16; u16::MAX as usize + 1];
        let mut ids: Vec<u16> = Vec::new();
        for &g in &objects {
            match self.segment_id(g) {
                Some(id) => ids.push(id),
                None if g == u16::MAX => {
                    return Err(format!(
                        "ground-truth id {g} cannot be shifted past 0 (ids stop at 65535)"
                    )
                    .into());
                }
                None => ids.push(0),
            }
        }
        if let Some(seed) = self.random_ids {
            // Renumber the non-void segments 1..=n in a random order.
            let real: Vec<usize> = (0..ids.len()).filter(|&k| ids[k] != 0).collect();
            let order = permutation(real.len(), seed ^ self.frames.wrapping_mul(0x2545_f491));
            for (rank, &k) in order.iter().zip(&real) {
                ids[k] = *rank as u16 + 1;
            }
        }
        self.frames += 1;
        let mut segments = Vec::new();
        for (&g, &id) in objects.iter().zip(&ids) {
            to_segment[g as usize] = id;
            if id == 0 {
                continue;
            }
            let class = self.classes.as_ref().and_then(|t| t.get(g as u32));
            segments.push(Segment {
                id,
                class_id: class.map(|c| c.class_id),
                is_thing: class.map(|c| c.is_thing),
                score: None,
            });
        }
        segments.sort_by_key(|s| s.id);
        Ok(Some(Segments {
            labels: truth.map(|&g| to_segment[g as usize]),
            segments,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxpan_core::{ClassInfo, Image, Intrinsics, Pose};

    fn frame(truth: Vec<u16>) -> Frame {
        let k = Intrinsics {
            width: 3,
            height: 2,
            fx: 1.0,
            fy: 1.0,
            cx: 1.0,
            cy: 1.0,
        };
        Frame {
            id: "0".into(),
            timestamp: 0.0,
            color: Image::filled(3, 2, [0; 3]),
            depth: Image::filled(3, 2, 1.0),
            pose: Pose::identity(),
            intrinsics: k,
            segments: None,
            ground_truth: Some(Image::from_vec(3, 2, truth).unwrap()),
        }
    }

    fn table(ids: &[u32]) -> ClassTable {
        ClassTable {
            entries: ids
                .iter()
                .map(|&id| {
                    let info = ClassInfo {
                        class_id: id * 10,
                        is_thing: id % 2 == 1,
                        name: format!("c{id}"),
                        color: [0; 3],
                    };
                    (id, info)
                })
                .collect(),
        }
    }

    #[test]
    fn zero_is_an_object_when_the_table_lists_it() {
        let f = frame(vec![0, 0, 1, 1, 7, 7]);
        let s = GroundTruthMasks::new(Some(table(&[0, 1, 7])))
            .segment(&f)
            .unwrap()
            .unwrap();
        assert_eq!(s.labels.pixels(), &[1, 1, 2, 2, 8, 8]);
        assert_eq!(s.segments.len(), 3);
        assert_eq!(s.get(8).unwrap().class_id, Some(70));
        assert_eq!(s.get(8).unwrap().is_thing, Some(true));
        // Without 0 in the table (the synthetic world), 0 is void.
        let s = GroundTruthMasks::new(Some(table(&[1, 7])))
            .segment(&f)
            .unwrap()
            .unwrap();
        assert_eq!(s.labels.pixels(), &[0, 0, 1, 1, 7, 7]);
        assert_eq!(s.segments.len(), 2);
    }

    #[test]
    fn truth_id_inverts_segment_id() {
        for classes in [table(&[0, 1, 7]), table(&[1, 7])] {
            let gt = GroundTruthMasks::new(Some(classes));
            for id in [0u16, 1, 7, 65534] {
                if let Some(segment) = gt.segment_id(id) {
                    assert_eq!(gt.truth_id(segment), Some(id));
                }
            }
            assert_eq!(gt.truth_id(0), None, "segment 0 is void");
        }
    }

    #[test]
    fn random_ids_renumber_every_frame_but_keep_the_partition() {
        let f = frame(vec![0, 3, 3, 5, 9, 9]);
        let mut gt = GroundTruthMasks::new(Some(table(&[0, 3, 5, 9]))).with_random_ids(4);
        let mut seen = Vec::new();
        for _ in 0..8 {
            let s = gt.segment(&f).unwrap().unwrap();
            let l = s.labels.pixels().to_vec();
            // Same partition: equal pixels stay equal, different ones different.
            assert!(l[1] == l[2] && l[4] == l[5] && l[0] != l[1] && l[3] != l[4]);
            let mut ids: Vec<u16> = s.segments.iter().map(|s| s.id).collect();
            ids.sort();
            assert_eq!(ids, vec![1, 2, 3, 4]);
            // Class information follows the object, not the id.
            let kind_of_nine = s.get(l[4]).unwrap().class_id;
            assert_eq!(kind_of_nine, Some(90));
            seen.push(l);
        }
        seen.dedup();
        assert!(seen.len() > 3, "ids must change between frames");
    }
}
