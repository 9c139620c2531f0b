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

/// `frames` delivered at `rate` frames per second at most, as a camera delivers them: frame
/// `i` no earlier than `i / rate` seconds after the first was asked for. None is dropped; a
/// consumer slower than the rate gets each as soon as it asks.
pub fn paced(frames: FrameStream, rate: f64) -> FrameStream {
    let period = std::time::Duration::from_secs_f64(1.0 / rate);
    let mut next: Option<std::time::Instant> = None;
    Box::new(frames.inspect(move |_| {
        let now = std::time::Instant::now();
        let due = *next.get_or_insert(now);
        if due > now {
            std::thread::sleep(due - now);
        }
        next = Some(due + period);
    }))
}

/// Skipped frames of one kind: the reasons are the same but for their numbers (stamps, frame
/// ids), as when a whole stretch of a bag has no pose.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SkipGroup {
    /// The first frame's reason, as given.
    pub reason: String,
    /// The frames, in the order given.
    pub frames: Vec<String>,
}

impl std::fmt::Display for SkipGroup {
    /// `frame 000010 skipped: REASON`, or for several `412 frames (000003, 000007, 000011,
    /// ..., 000998) skipped, the first: REASON`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        const LISTED: usize = 3;
        match self.frames.as_slice() {
            [one] => write!(f, "frame {one} skipped: {}", self.reason),
            frames => {
                let mut listed = frames[..frames.len().min(LISTED)].join(", ");
                if frames.len() > LISTED + 1 {
                    listed.push_str(", ...");
                }
                if frames.len() > LISTED {
                    listed.push_str(&format!(", {}", frames[frames.len() - 1]));
                }
                write!(
                    f,
                    "{} frames ({listed}) skipped, the first: {}",
                    frames.len(),
                    self.reason
                )
            }
        }
    }
}

/// Groups `(frame, reason)` pairs whose reasons differ only in their numbers, in the order
/// each kind first appears: one line per kind instead of one per frame.
pub fn group_skipped<'a>(skipped: impl IntoIterator<Item = (&'a str, &'a str)>) -> Vec<SkipGroup> {
    let mut groups: Vec<(String, SkipGroup)> = Vec::new();
    for (frame, reason) in skipped {
        let kind = without_numbers(reason);
        match groups.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, group)) => group.frames.push(frame.to_owned()),
            None => groups.push((
                kind,
                SkipGroup {
                    reason: reason.to_owned(),
                    frames: vec![frame.to_owned()],
                },
            )),
        }
    }
    groups.into_iter().map(|(_, g)| g).collect()
}

/// `text` with every run of digits (and the points between them) replaced by `#`.
fn without_numbers(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_number = false;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        let digit_point = c == '.' && in_number && chars.peek().is_some_and(char::is_ascii_digit);
        if c.is_ascii_digit() || digit_point {
            if !in_number {
                out.push('#');
            }
            in_number = true;
        } else {
            in_number = false;
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_differing_only_in_numbers_are_one_group() {
        let skipped = [
            ("000003", "no /tf pose at 12.5 s: gap of 0.30 s"),
            ("000004", "its depth stamp 13 s is frame 000003's too"),
            ("000005", "no /tf pose at 13.25 s: gap of 1.5 s"),
            ("000006", "no /tf pose at 14 s: gap of 2 s"),
            ("000007", "no /tf pose at 15 s: gap of 2 s"),
            ("000009", "no /tf pose at 16.75 s: gap of 3 s."),
        ];
        let groups = group_skipped(skipped.iter().map(|(f, r)| (*f, *r)));
        assert_eq!(groups.len(), 3, "{groups:?}");
        assert_eq!(groups[0].frames, ["000003", "000005", "000006", "000007"]);
        assert_eq!(groups[0].reason, skipped[0].1);
        assert_eq!(
            groups[0].to_string(),
            "4 frames (000003, 000005, 000006, 000007) skipped, the first: no /tf pose at 12.5 s: \
             gap of 0.30 s"
        );
        assert_eq!(
            groups[1].to_string(),
            "frame 000004 skipped: its depth stamp 13 s is frame 000003's too"
        );
        // A sentence's full stop after a number is not part of it: a kind of its own here.
        assert_eq!(groups[2].frames, ["000009"]);
        let many: Vec<(String, String)> = (0..412)
            .map(|k| {
                (
                    format!("{k:06}"),
                    format!("no colour image within 20 ms of {k}.5 s"),
                )
            })
            .collect();
        let groups = group_skipped(many.iter().map(|(f, r)| (f.as_str(), r.as_str())));
        assert_eq!(groups.len(), 1);
        assert!(
            groups[0].to_string().starts_with(
                "412 frames (000000, 000001, 000002, ..., 000411) skipped, the first:"
            ),
            "{}",
            groups[0]
        );
    }

    /// Paced frames come no faster than the rate (frame i at i / rate seconds at the
    /// earliest), all of them, in order.
    #[test]
    fn paced_frames_come_at_the_rate_at_most() {
        let frames: FrameStream =
            Box::new((0..5).map(|i| Err(FrameError::new(format!("{i}"), "placeholder"))));
        let start = std::time::Instant::now();
        let ids: Vec<String> = paced(frames, 100.0)
            .map(|item| item.unwrap_err().frame)
            .collect();
        assert!(start.elapsed() >= std::time::Duration::from_millis(40));
        assert_eq!(ids, ["0", "1", "2", "3", "4"]);
    }
}
