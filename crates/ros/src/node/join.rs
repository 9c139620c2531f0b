//! The mapping node's inputs joined by stamp into frames.

use voxpan_bag::assemble::{MAX_WAIT_S, Unpaired};
use voxpan_bag::live::Wire;
use voxpan_core::{Frame, Segments};

use super::{Carry, ToMap};
use crate::inbound;

/// Partial frames of the mapping node, by stamp.
#[derive(Default)]
struct Partial {
    depth: Option<voxpan_core::DepthImage>,
    color: Option<voxpan_core::ColorImage>,
    intrinsics: Option<voxpan_core::Intrinsics>,
    pose: Option<(String, voxpan_core::Pose)>,
    labels: Option<voxpan_core::LabelImage>,
    /// `Some(None)`: the frame has no masks.
    list: Option<inbound::SegmentList>,
}

/// The inputs a frame is joined from.
const INPUTS: usize = 6;

impl Partial {
    /// Which inputs arrived, in [`MapInput`]'s order.
    fn present(&self) -> [bool; INPUTS] {
        [
            self.depth.is_some(),
            self.color.is_some(),
            self.intrinsics.is_some(),
            self.pose.is_some(),
            self.labels.is_some(),
            self.list.is_some(),
        ]
    }

    /// Which inputs the frame still needs: every one, except the label image of a frame
    /// whose segment list says it has no masks (none, or between keyframes).
    fn missing(&self) -> [bool; INPUTS] {
        let no_masks = self.list.as_ref().is_some_and(|l| l.segments.is_none());
        let mut missing = self.present().map(|present| !present);
        missing[MapInput::Labels as usize] &= !no_masks;
        missing
    }

    fn complete(&self) -> bool {
        !self.missing().contains(&true)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum MapInput {
    Depth,
    Color,
    CameraInfo,
    Pose,
    Labels,
    Segments,
}

/// Frames the perception node's messages make, joined by stamp.
pub(super) struct Joiner {
    partial: std::collections::BTreeMap<i64, Partial>,
    next_id: usize,
    wire: Wire,
}

/// Partial frames kept at most; the oldest is given up first.
const MAX_PARTIAL: usize = 64;

impl Joiner {
    pub(super) fn new(wire: Wire) -> Self {
        Self {
            partial: Default::default(),
            next_id: 0,
            wire,
        }
    }

    pub(super) fn add(&mut self, input: MapInput, data: &[u8]) -> Result<(), String> {
        match input {
            MapInput::Depth => {
                let (h, d) = voxpan_bag::live::depth_image(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().depth = Some(d);
            }
            MapInput::Color => {
                let (h, c) = voxpan_bag::live::color_image(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().color = Some(c);
            }
            MapInput::CameraInfo => {
                let (h, k, _) = voxpan_bag::live::camera_info(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().intrinsics = Some(k);
            }
            MapInput::Pose => {
                let (h, p) = voxpan_bag::live::pose_stamped(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().pose = Some((h.frame_id, p));
            }
            MapInput::Labels => {
                let (h, l) = voxpan_bag::live::label_image(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().labels = Some(l);
            }
            MapInput::Segments => {
                let list = inbound::segment_list(self.wire, data)?;
                let t = list.stamp_ns;
                self.partial.entry(t).or_default().list = Some(list);
            }
        }
        Ok(())
    }

    /// Complete frames in stamp order (with the world frame's name and the perception node's
    /// arrival time), and stamps given up.
    ///
    /// Each topic's messages arrive in stamp order, so a frame still missing a message that a
    /// newer frame already has on that topic never completes: it is given up. So is one more
    /// than [`MAX_WAIT_S`] older than the newest complete frame. A complete frame waits behind
    /// an older one that may still complete: a frame between keyframes has no label image, so
    /// it can arrive whole before the keyframe just before it, whose large label image is
    /// still on its way, and its masks must come from a map that holds that keyframe.
    pub(super) fn take_ready(&mut self) -> (Vec<(ToMap, String)>, Vec<Unpaired>) {
        let mut ready = Vec::new();
        let mut given_up = Vec::new();
        let newest_complete = self
            .partial
            .iter()
            .rev()
            .find(|(_, p)| p.complete())
            .map(|(t, _)| *t);
        let mut newer_has = [false; INPUTS];
        let mut hopeless = Vec::new();
        for (&t, p) in self.partial.iter().rev() {
            let lost = p
                .missing()
                .iter()
                .zip(newer_has)
                .any(|(&missing, newer)| missing && newer);
            let stale =
                !p.complete() && newest_complete.is_some_and(|n| (n - t) as f64 > MAX_WAIT_S * 1e9);
            if lost {
                hopeless.push((t, "some of its messages never arrived".to_owned()));
            } else if stale {
                let reason = format!("incomplete {MAX_WAIT_S} s after a newer frame completed");
                hopeless.push((t, reason));
            }
            for (has, &present) in newer_has.iter_mut().zip(&p.present()) {
                *has |= present;
            }
        }
        for (stamp_ns, reason) in hopeless.into_iter().rev() {
            self.partial.remove(&stamp_ns);
            given_up.push(Unpaired { stamp_ns, reason });
        }
        while self.partial.len() > MAX_PARTIAL {
            let (s, _) = self.partial.pop_first().expect("non-empty");
            given_up.push(Unpaired {
                stamp_ns: s,
                reason: format!("more than {MAX_PARTIAL} frames incomplete"),
            });
        }
        while let Some(entry) = self.partial.first_entry() {
            if !entry.get().complete() {
                break;
            }
            let (t, p) = entry.remove_entry();
            ready.push(self.frame(t, p));
        }
        (ready, given_up)
    }

    /// The complete partial frame `p` at stamp `t`.
    fn frame(&mut self, t: i64, p: Partial) -> (ToMap, String) {
        let list = p.list.expect("complete");
        let (world, pose) = p.pose.expect("complete");
        let segments = list.segments.map(|segments| Segments {
            labels: p.labels.expect("complete"),
            segments,
        });
        // Between keyframes the depth came as measured: it is the frame's until the mapping
        // thread has refined the map's masks on it and filled it.
        let carry = list.carry.map(|config| Carry {
            config,
            measured: None,
        });
        let frame = Frame {
            id: format!("{:06}", self.next_id),
            timestamp: t as f64 / 1e9,
            color: p.color.expect("complete"),
            depth: p.depth.expect("complete"),
            pose,
            intrinsics: p.intrinsics.expect("complete"),
            segments: None,
            ground_truth: None,
        };
        self.next_id += 1;
        let item = ToMap {
            frame,
            segments,
            carry,
            received_unix_ns: list.received_unix_ns,
            class_names: list.class_names,
        };
        (item, world)
    }
}

#[cfg(test)]
mod tests {
    use voxpan_core::{Image, Intrinsics, Pose, Segment};

    use super::*;
    use crate::cdr::Ros2Message;
    use crate::encode;

    const KEYFRAME: i64 = 1_000_000_000;
    const BETWEEN: i64 = 1_033_000_000;

    /// Sends frame `t`'s messages (CDR, as ROS 2 carries them) but its label image, and its
    /// segment list last: a keyframe's masks, or a frame between keyframes.
    fn send_all_but_labels(joiner: &mut Joiner, t: i64, keyframe: bool) {
        let header = || encode::header(t, "camera");
        let depth = Image::filled(2, 1, 1.5f32);
        let k = Intrinsics {
            width: 2,
            height: 1,
            fx: 1.0,
            fy: 1.0,
            cx: 1.0,
            cy: 0.5,
        };
        let sent = [
            (
                MapInput::Depth,
                encode::depth_image(header(), &depth).to_cdr(),
            ),
            (
                MapInput::Color,
                encode::color_image(header(), &Image::filled(2, 1, [9u8; 3])).to_cdr(),
            ),
            (
                MapInput::CameraInfo,
                encode::camera_info(header(), &k).to_cdr(),
            ),
            (
                MapInput::Pose,
                encode::pose_stamped(encode::header(t, "world"), &Pose::identity()).to_cdr(),
            ),
        ];
        for (input, data) in sent {
            joiner.add(input, &data).unwrap();
        }
        let segments = [Segment::bare(1)];
        let carry = voxpan_perception::PerceptionConfig::default();
        let list = match keyframe {
            true => {
                encode::segment_list(t, "camera", Some(&segments), 0, &Default::default(), None)
            }
            false => encode::segment_list(t, "camera", None, 0, &Default::default(), Some(&carry)),
        };
        joiner.add(MapInput::Segments, &list.to_cdr()).unwrap();
    }

    fn send_labels(joiner: &mut Joiner, t: i64) {
        let labels = encode::label_image(encode::header(t, "camera"), &Image::filled(2, 1, 1u16));
        joiner.add(MapInput::Labels, &labels.to_cdr()).unwrap();
    }

    fn stamps(ready: &[(ToMap, String)]) -> Vec<i64> {
        ready
            .iter()
            .map(|(m, _)| (m.frame.timestamp * 1e9).round() as i64)
            .collect()
    }

    /// A frame between keyframes arrives whole before the keyframe just before it, whose
    /// label image is still on its way: it waits, and both come out in stamp order once the
    /// label image is in, the keyframe with its masks and the other to be carried.
    #[test]
    fn a_frame_between_keyframes_waits_for_the_keyframe_before_it() {
        let mut joiner = Joiner::new(Wire::Cdr);
        send_all_but_labels(&mut joiner, KEYFRAME, true);
        send_all_but_labels(&mut joiner, BETWEEN, false);
        let (ready, given_up) = joiner.take_ready();
        assert!(ready.is_empty() && given_up.is_empty());
        send_labels(&mut joiner, KEYFRAME);
        let (ready, given_up) = joiner.take_ready();
        assert!(given_up.is_empty());
        assert_eq!(stamps(&ready), [KEYFRAME, BETWEEN]);
        assert!(ready[0].0.segments.is_some() && ready[0].0.carry.is_none());
        assert!(ready[1].0.segments.is_none() && ready[1].0.carry.is_some());
    }

    /// A keyframe whose label image never comes is given up once a newer frame's label image
    /// has arrived (each topic arrives in order), and the frames behind it come out.
    #[test]
    fn a_keyframe_whose_labels_were_lost_is_given_up_by_the_next_keyframe() {
        let mut joiner = Joiner::new(Wire::Cdr);
        let next_keyframe = BETWEEN + 33_000_000;
        send_all_but_labels(&mut joiner, KEYFRAME, true);
        send_all_but_labels(&mut joiner, BETWEEN, false);
        send_all_but_labels(&mut joiner, next_keyframe, true);
        send_labels(&mut joiner, next_keyframe);
        let (ready, given_up) = joiner.take_ready();
        assert_eq!(stamps(&ready), [BETWEEN, next_keyframe]);
        assert_eq!(given_up.len(), 1);
        assert_eq!(given_up[0].stamp_ns, KEYFRAME);
    }

    /// Nor does a keyframe wait longer than a second of stamps for its label image.
    #[test]
    fn a_keyframe_without_labels_is_given_up_a_second_later() {
        let mut joiner = Joiner::new(Wire::Cdr);
        send_all_but_labels(&mut joiner, KEYFRAME, true);
        send_all_but_labels(&mut joiner, BETWEEN, false);
        assert_eq!(joiner.take_ready().0.len(), 0);
        let late = KEYFRAME + (MAX_WAIT_S * 1e9) as i64 + 1;
        send_all_but_labels(&mut joiner, late, false);
        let (ready, given_up) = joiner.take_ready();
        assert_eq!(stamps(&ready), [BETWEEN, late]);
        assert_eq!(given_up.len(), 1);
        assert!(given_up[0].reason.contains("after a newer frame completed"));
    }
}
