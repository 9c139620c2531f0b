//! The mapping node's inputs joined by stamp into frames.

use voxpan_bag::assemble::Unpaired;
use voxpan_bag::live::Wire;
use voxpan_core::{Frame, Segments};

use super::ToMap;
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
    pub(super) fn take_ready(&mut self) -> (Vec<(ToMap, String)>, Vec<Unpaired>) {
        let mut ready = Vec::new();
        let mut given_up = Vec::new();
        let complete: Vec<i64> = self
            .partial
            .iter()
            .filter(|(_, p)| {
                let masks_ok = match &p.list {
                    Some(l) => l.segments.is_none() || p.labels.is_some(),
                    None => false,
                };
                masks_ok
                    && p.depth.is_some()
                    && p.color.is_some()
                    && p.intrinsics.is_some()
                    && p.pose.is_some()
            })
            .map(|(t, _)| *t)
            .collect();
        for t in complete {
            // Older incomplete frames will not complete now that a newer one has.
            let older: Vec<i64> = self.partial.range(..t).map(|(s, _)| *s).collect();
            for s in older {
                self.partial.remove(&s);
                given_up.push(Unpaired {
                    stamp_ns: s,
                    reason: "some of its messages never arrived".into(),
                });
            }
            let p = self.partial.remove(&t).expect("listed");
            let list = p.list.expect("complete");
            let (world, pose) = p.pose.expect("complete");
            let segments = list.segments.map(|segments| Segments {
                labels: p.labels.expect("complete"),
                segments,
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
            ready.push((
                ToMap {
                    frame,
                    segments,
                    received_unix_ns: list.received_unix_ns,
                    class_names: list.class_names,
                },
                world,
            ));
        }
        while self.partial.len() > MAX_PARTIAL {
            let (s, _) = self.partial.pop_first().expect("non-empty");
            given_up.push(Unpaired {
                stamp_ns: s,
                reason: format!("more than {MAX_PARTIAL} frames incomplete"),
            });
        }
        (ready, given_up)
    }
}
