//! Frames from live topics: the perception node's inputs (colour, depth, camera_info, /tf or a
//! pose topic, optionally a label image and its segment list) paired as the bag reader pairs
//! them, one message at a time; and the mapping node's inputs, which the perception node
//! stamps alike, joined by stamp.

use std::collections::VecDeque;

use crate::BagOptions;
use crate::live::{self, TfTree, Track, Wire};
use voxpan_core::{ColorImage, DepthImage, Frame, Intrinsics, LabelImage, Segment, Segments};

/// Which input a message came on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Input {
    Color,
    Depth,
    CameraInfo,
    Tf,
    TfStatic,
    Pose,
    Labels,
    Segments,
}

impl Input {
    /// Every input, in the order a node subscribes them.
    pub const ALL: [Input; 8] = [
        Input::Color,
        Input::Depth,
        Input::CameraInfo,
        Input::Tf,
        Input::TfStatic,
        Input::Pose,
        Input::Labels,
        Input::Segments,
    ];
}

/// A depth image that did not become a frame, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Unpaired {
    pub stamp_ns: i64,
    pub reason: String,
}

/// A frame ready for perception, with when its depth image arrived (Unix nanoseconds).
#[derive(Debug)]
pub struct Assembled {
    pub frame: Frame,
    pub stamp_ns: i64,
    pub received_unix_ns: i64,
    /// The camera's and the world's frame names (for the outputs' headers).
    pub camera_frame: String,
    pub world_frame: String,
}

/// Depth images waiting for their colour image, pose or masks are kept this long in stamp
/// time (a depth image this much newer arrived) before they are given up: a second covers
/// transform publishers that lag by a few frames, at 30 Hz 30 frames.
pub const MAX_WAIT_S: f64 = 1.0;
/// At most this many depth images wait; the oldest is given up first.
pub const MAX_PENDING: usize = 64;
/// At most this many messages of each other stream are held (oldest first out), and this
/// many samples per moving /tf edge or pose topic, so that a peer sending stamps that never
/// age (equal, or in the future) cannot grow the node's memory: four times a 60 Hz stream's
/// wait.
pub const MAX_HELD: usize = 4 * MAX_PENDING;
/// At most this many frames on /tf and /tf_static (a robot has tens).
pub const MAX_FRAMES: usize = 1024;

pub struct Assembler {
    options: BagOptions,
    masks: bool,
    colors: VecDeque<(i64, String, ColorImage)>,
    depths: VecDeque<(i64, DepthImage, i64)>,
    infos: VecDeque<(i64, Intrinsics)>,
    labels: VecDeque<(i64, LabelImage)>,
    lists: VecDeque<(i64, Vec<Segment>)>,
    tf: TfTree,
    poses: Track,
    next_id: usize,
    wire: Wire,
    /// The first distorted camera_info's warning: `Some(Some(_))` until taken, `Some(None)`
    /// after (said once).
    distortion: Option<Option<String>>,
}

fn within<T>(list: &VecDeque<(i64, T)>, t: i64, tolerance: i64) -> Option<&(i64, T)> {
    list.iter()
        .filter(|(s, _)| (s - t).abs() <= tolerance)
        .min_by_key(|(s, _)| (s - t).abs())
}

fn ns(seconds: f64) -> i64 {
    (seconds * 1e9).round() as i64
}

impl Assembler {
    /// `masks`: frames carry the label image and segment list of `options`' topics; `wire`:
    /// how the messages are serialised (ROS 1 or ROS 2's CDR).
    pub fn new(options: BagOptions, masks: bool, wire: Wire) -> Self {
        Self {
            tf: TfTree::new(&options.tf_topic),
            options,
            masks,
            colors: VecDeque::new(),
            depths: VecDeque::new(),
            infos: VecDeque::new(),
            labels: VecDeque::new(),
            lists: VecDeque::new(),
            poses: Track::default(),
            next_id: 0,
            wire,
            distortion: None,
        }
    }

    /// Why the camera's images are not pinhole images, once, when a camera_info said they
    /// are distorted (voxpan maps rectified images).
    pub fn take_warning(&mut self) -> Option<String> {
        match &mut self.distortion {
            Some(pending @ Some(_)) => pending.take(),
            _ => None,
        }
    }

    /// The topic an input is read from.
    pub fn topic(&self, input: Input) -> Option<&str> {
        let o = &self.options;
        Some(match input {
            Input::Color => &o.color_topic,
            Input::Depth => &o.depth_topic,
            Input::CameraInfo => &o.info_topic,
            Input::Tf if o.pose_topic.is_none() => &o.tf_topic,
            Input::TfStatic if o.pose_topic.is_none() => &o.tf_static_topic,
            Input::Pose => o.pose_topic.as_deref()?,
            Input::Labels if self.masks => &o.labels_topic,
            Input::Segments if self.masks => &o.segments_topic,
            _ => return None,
        })
    }

    /// Decodes one message. The error names what is wrong with it; the caller adds the topic.
    pub fn add(&mut self, input: Input, data: &[u8], received_unix_ns: i64) -> Result<(), String> {
        let at = |h: &live::Header| format!(" (stamp {} s)", crate::fmt_time(h.stamp_ns));
        match input {
            Input::Color => {
                let (h, c) = live::color_image(self.wire, data)?;
                self.colors.push_back((h.stamp_ns, h.frame_id, c));
            }
            Input::Depth => {
                let (h, d) = live::depth_image(self.wire, data)?;
                self.depths.push_back((h.stamp_ns, d, received_unix_ns));
            }
            Input::CameraInfo => {
                let (h, k, warning) = live::camera_info(self.wire, data)?;
                if self.distortion.is_none()
                    && let Some(w) = warning
                {
                    let topic = &self.options.info_topic;
                    self.distortion = Some(Some(format!("{topic}: {w}")));
                }
                self.infos.push_back((h.stamp_ns, k));
            }
            Input::Tf | Input::TfStatic => {
                for t in live::transforms(self.wire, data)? {
                    if self.tf.frames() >= MAX_FRAMES && !self.tf.has_parent(&t.child_frame_id) {
                        return Err(format!(
                            "more than {MAX_FRAMES} frames on {} and {}: {} not added",
                            self.options.tf_topic, self.options.tf_static_topic, t.child_frame_id
                        ));
                    }
                    self.tf
                        .add(&t, input == Input::TfStatic)
                        .map_err(|e| format!("{e}{}", at(&t.header)))?;
                }
            }
            Input::Pose => {
                let (h, pose) = live::pose_stamped(self.wire, data)?;
                self.poses.push(h.stamp_ns, pose);
            }
            Input::Labels => {
                let (h, l) = live::label_image(self.wire, data)?;
                self.labels.push_back((h.stamp_ns, l));
            }
            Input::Segments => {
                let (t, list) = live::segment_list(self.wire, data)?;
                self.lists.push_back((t, list));
            }
        }
        Ok(())
    }

    /// Frames that are complete, in depth-stamp order, and depth images given up.
    pub fn take_ready(&mut self) -> Vec<Result<Assembled, Unpaired>> {
        let mut out = Vec::new();
        while self.depths.len() > MAX_PENDING {
            let (t, _, _) = self.depths.pop_front().expect("non-empty");
            out.push(Err(Unpaired {
                stamp_ns: t,
                reason: format!("more than {MAX_PENDING} depth images waiting"),
            }));
        }
        while let Some((t, _, _)) = self.depths.front() {
            let t = *t;
            match self.try_frame(t) {
                Ok((mut frame, camera_frame, world_frame)) => {
                    let (_, depth, received) = self.depths.pop_front().expect("non-empty");
                    frame.depth = depth;
                    out.push(Ok(Assembled {
                        frame,
                        stamp_ns: t,
                        received_unix_ns: received,
                        camera_frame,
                        world_frame,
                    }));
                }
                Err(reason) => {
                    let newest = self.depths.back().map(|d| d.0).unwrap_or(t);
                    if newest - t > ns(MAX_WAIT_S) {
                        self.depths.pop_front();
                        out.push(Err(Unpaired {
                            stamp_ns: t,
                            reason,
                        }));
                    } else {
                        break;
                    }
                }
            }
        }
        self.forget_old();
        out
    }

    /// The frame for the depth image at `t` (its depth left empty) with the camera's and the
    /// world's frame names, or what is missing.
    fn try_frame(&mut self, t: i64) -> Result<(Frame, String, String), String> {
        let o = &self.options;
        let tolerance = ns(o.sync_tolerance_s);
        let when = crate::fmt_time(t);
        let Some(ci) = self
            .colors
            .iter()
            .enumerate()
            .filter(|(_, c)| (c.0 - t).abs() <= tolerance)
            .min_by_key(|(_, c)| (c.0 - t).abs())
            .map(|(i, _)| i)
        else {
            return Err(format!(
                "no {} image within {:.0} ms of the depth stamp {when} s",
                o.color_topic,
                o.sync_tolerance_s * 1e3
            ));
        };
        let color_stamp = self.colors[ci].0;
        let Some(&(_, intrinsics)) = self
            .infos
            .iter()
            .min_by_key(|(s, _)| (s - color_stamp).abs())
        else {
            return Err(format!("no camera_info on {} yet", o.info_topic));
        };
        let max_gap = ns(o.max_tf_gap_s);
        let camera = match &o.camera_frame {
            Some(f) => f.clone(),
            None => self.colors[ci].1.clone(),
        };
        let (pose, world) = match &o.pose_topic {
            Some(topic) => {
                let pose = self
                    .poses
                    .at(t, max_gap, tolerance)
                    .map_err(|e| format!("{topic} has no pose at {when} s: {e}"))?;
                (
                    pose,
                    o.world_frame.clone().unwrap_or_else(|| "world".into()),
                )
            }
            None => {
                if camera.is_empty() {
                    return Err(format!(
                        "{} images have no header.frame_id: name the camera frame",
                        o.color_topic
                    ));
                }
                if self.tf.is_empty() {
                    return Err(format!(
                        "no transform on {} or {} yet",
                        o.tf_topic, o.tf_static_topic
                    ));
                }
                let world = match &o.world_frame {
                    Some(w) => w.clone(),
                    None if !self.tf.moves(&camera)? => {
                        return Err(format!(
                            "no {} transform above {camera} yet (a camera on /tf_static only \
                             needs --world-frame)",
                            o.tf_topic
                        ));
                    }
                    None => self.tf.root(&camera)?,
                };
                (
                    self.tf.lookup(&world, &camera, t, max_gap, tolerance)?,
                    world,
                )
            }
        };
        let segments = if self.masks {
            let Some((lt, labels)) = within(&self.labels, color_stamp, tolerance) else {
                return Err(format!(
                    "no {} label image within {:.0} ms of the colour stamp {} s",
                    o.labels_topic,
                    o.sync_tolerance_s * 1e3,
                    crate::fmt_time(color_stamp)
                ));
            };
            let Some((_, list)) = within(&self.lists, *lt, tolerance) else {
                return Err(format!(
                    "no {} segment list for the label image at {} s",
                    o.segments_topic,
                    crate::fmt_time(*lt)
                ));
            };
            let missing: Vec<u16> = voxpan_core::segment_ids(labels)
                .into_iter()
                .filter(|id| !list.iter().any(|s| s.id == *id))
                .collect();
            if !missing.is_empty() {
                return Err(format!(
                    "{} at {} s does not list segment id(s) {missing:?} of the label image",
                    o.segments_topic,
                    crate::fmt_time(*lt)
                ));
            }
            Some(Segments {
                labels: labels.clone(),
                segments: list.clone(),
            })
        } else {
            None
        };
        let color = self.colors[ci].2.clone();
        let k = intrinsics;
        let depth_dims = self.depths.front().map(|d| d.1.dims()).unwrap_or_default();
        let mut sizes = vec![(&o.color_topic, color.dims()), (&o.depth_topic, depth_dims)];
        if let Some(s) = &segments {
            sizes.push((&o.labels_topic, s.labels.dims()));
        }
        for (topic, (w, h)) in sizes {
            if (w, h) != (k.width, k.height) {
                return Err(format!(
                    "{topic} image at {when} s is {w}x{h}, but {} says {}x{}",
                    o.info_topic, k.width, k.height
                ));
            }
        }
        let id = format!("{:06}", self.next_id);
        self.next_id += 1;
        let frame = Frame {
            id,
            timestamp: t as f64 / 1e9,
            color,
            depth: DepthImage::filled(0, 0, 0.0),
            pose,
            intrinsics: k,
            segments,
            ground_truth: None,
        };
        let camera = if camera.is_empty() {
            "camera".into()
        } else {
            camera
        };
        Ok((frame, camera, world))
    }

    /// Messages and transform samples held, over every stream.
    pub fn held(&self) -> usize {
        self.colors.len()
            + self.depths.len()
            + self.infos.len()
            + self.labels.len()
            + self.lists.len()
            + self.tf.samples()
            + self.poses.len()
    }

    /// Drops what no waiting or future depth image can pair with, then the oldest beyond
    /// [`MAX_HELD`] (memory stays bounded whatever the stamps).
    fn forget_old(&mut self) {
        self.forget_by_stamp();
        fn bound<T>(queue: &mut VecDeque<T>) {
            while queue.len() > MAX_HELD {
                queue.pop_front();
            }
        }
        bound(&mut self.colors);
        bound(&mut self.infos);
        bound(&mut self.labels);
        bound(&mut self.lists);
        self.tf.keep_newest(MAX_HELD);
        self.poses.keep_newest(MAX_HELD);
    }

    fn forget_by_stamp(&mut self) {
        let wait = ns(MAX_WAIT_S);
        let horizon = match (self.depths.front(), self.colors.back()) {
            (Some(d), _) => d.0 - ns(self.options.sync_tolerance_s) - wait,
            // Nothing waits: keep the newest second of each stream for depth still to come.
            (None, Some(c)) => c.0 - wait,
            (None, None) => return,
        };
        self.forget_before(horizon);
    }

    fn forget_before(&mut self, t: i64) {
        self.colors.retain(|c| c.0 >= t);
        self.labels.retain(|c| c.0 >= t);
        self.lists.retain(|c| c.0 >= t);
        // The newest camera_info always stays: it rarely changes, and some drivers latch it.
        while self.infos.len() > 1 && self.infos.front().is_some_and(|i| i.0 < t) {
            self.infos.pop_front();
        }
        self.tf.forget_before(t);
        self.poses.forget_before(t);
    }
}
