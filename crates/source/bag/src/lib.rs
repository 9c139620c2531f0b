//! ROS bags as voxpan frame sources: ROS 1 `.bag` (plain, bz2 and lz4 chunks, read with the
//! `rosbag` crate) and ROS 2 bags, MCAP or SQLite `.db3` (a file or a bag folder holding one,
//! read with the `mcap` and `rusqlite` crates, CDR payloads with `cdr-encoding`).
//!
//! [`BagDataset::open`] reads the bag once: the camera_info, /tf, /tf_static (or a pose
//! topic) and segment lists are decoded, every image is indexed by its header stamp. Each depth
//! image is a frame; its colour image (and label image) is the one nearest in stamp within
//! [`BagOptions::sync_tolerance_s`] (20 ms by default, under a 30 Hz camera's period); its
//! pose is `T_world_camera` at the depth stamp, from the chain of /tf and /tf_static edges
//! (interpolated between samples at most [`BagOptions::max_tf_gap_s`] apart) or a
//! PoseStamped/TransformStamped topic; its intrinsics come from the camera_info nearest the
//! colour image, never from a default. Images are decoded when a frame is loaded
//! ([`FrameSource::load`], from any thread).
//!
//! Depth: `16UC1` millimetres (0 = no data) or `32FC1` metres (NaN = no data). Colour:
//! `rgb8`, `bgr8`, `rgba8`, `bgra8`, `mono8`. Labels: `16UC1`/`mono16` or `8UC1`/`mono8`, 0 =
//! void, with the frame's segment list from a std_msgs/String topic holding
//! `{"header": {"stamp": {"sec", "nanosec"}}, "segments": [labels.json entries]}` when the bag
//! has one. Errors name the bag, the topic and the stamp; frames without a colour image or a
//! pose are skipped with the reason ([`FrameSource::skipped`]).

pub mod assemble;
mod attachment;
mod container;
pub mod live;
mod msgs;
mod plan;
mod tf;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use voxpan_core::{
    ClassTable, ColorImage, DepthImage, Frame, Image, Intrinsics, LabelImage, Pose, Segment,
    Segments, segment_ids,
};
use voxpan_dataset::{DatasetError, FrameSource};

pub use container::looks_like_bag;
use container::{Connection, Container, Locator};
use msgs::Wire;

/// A bag that cannot be read as asked; the message names the topic and stamp where it can.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct BagError {
    pub path: PathBuf,
    pub message: String,
}

impl BagError {
    fn new(path: &Path, message: impl Into<String>) -> Self {
        Self {
            path: path.to_owned(),
            message: message.into(),
        }
    }
}

impl From<BagError> for DatasetError {
    fn from(e: BagError) -> Self {
        DatasetError::Invalid {
            path: e.path,
            message: e.message,
        }
    }
}

/// A stamp in nanoseconds as seconds with all nine decimals (what `rosbag info` and
/// `ros2 bag` users compare against).
pub fn fmt_time(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let a = ns.unsigned_abs();
    format!("{sign}{}.{:09}", a / 1_000_000_000, a % 1_000_000_000)
}

/// Which topics and frames make the RGB-D frames. The defaults are the RealSense ROS
/// driver's topics (a D435i's colour and aligned depth) and voxpan's label topics.
#[derive(Clone, Debug)]
pub struct BagOptions {
    pub color_topic: String,
    pub depth_topic: String,
    pub info_topic: String,
    /// A geometry_msgs/PoseStamped or TransformStamped topic with `T_world_camera`; `None`:
    /// /tf + /tf_static.
    pub pose_topic: Option<String>,
    pub tf_topic: String,
    pub tf_static_topic: String,
    /// The world frame; `None`: the root of the camera frame's tree.
    pub world_frame: Option<String>,
    /// The camera frame; `None`: the colour image's `header.frame_id`.
    pub camera_frame: Option<String>,
    /// sensor_msgs/Image label images (0 = void).
    pub labels_topic: String,
    /// std_msgs/String JSON segment lists for the label images.
    pub segments_topic: String,
    /// Whether a missing labels topic is an error (it was asked for) or means no masks.
    pub require_labels: bool,
    /// Colour (and label) images pair with a depth image within this many seconds.
    pub sync_tolerance_s: f64,
    /// Poses are interpolated only between samples at most this far apart (seconds).
    pub max_tf_gap_s: f64,
    /// The network's label table (a `detectron_labels.csv`), naming the segment lists'
    /// `category_id`s: bags carry no class names.
    pub classes: Option<PathBuf>,
}

impl Default for BagOptions {
    fn default() -> Self {
        Self {
            color_topic: "/camera/color/image_raw".into(),
            depth_topic: "/camera/aligned_depth_to_color/image_raw".into(),
            info_topic: "/camera/color/camera_info".into(),
            pose_topic: None,
            tf_topic: "/tf".into(),
            tf_static_topic: "/tf_static".into(),
            world_frame: None,
            camera_frame: None,
            labels_topic: "/camera/segments/image".into(),
            segments_topic: "/camera/segments/labels".into(),
            require_labels: false,
            sync_tolerance_s: 0.02,
            max_tf_gap_s: 0.25,
            classes: None,
        }
    }
}

/// One topic of a bag, for `voxpan info`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TopicSummary {
    pub topic: String,
    pub msg_type: String,
    pub count: u64,
    /// Record times of the first and last message, nanoseconds.
    pub first_ns: u64,
    pub last_ns: u64,
}

impl TopicSummary {
    /// Messages per second over the topic's own span (`None` with fewer than two).
    pub fn rate_hz(&self) -> Option<f64> {
        (self.count > 1 && self.last_ns > self.first_ns)
            .then(|| (self.count - 1) as f64 / ((self.last_ns - self.first_ns) as f64 / 1e9))
    }
}

/// What a bag holds.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BagSummary {
    pub path: PathBuf,
    /// "ROS 1" or "MCAP".
    pub format: &'static str,
    pub messages: u64,
    pub start_ns: u64,
    pub end_ns: u64,
    pub topics: Vec<TopicSummary>,
}

impl BagSummary {
    pub fn duration_s(&self) -> f64 {
        self.end_ns.saturating_sub(self.start_ns) as f64 / 1e9
    }
}

/// Lists a bag's topics with their types, counts and record times.
pub fn summarize(path: &Path) -> Result<BagSummary, BagError> {
    let file = container::resolve(path)?;
    let (bag, connections) = Container::open(&file)?;
    let mut topics: BTreeMap<&str, TopicSummary> = BTreeMap::new();
    for c in &connections {
        topics.entry(&c.topic).or_insert_with(|| TopicSummary {
            topic: c.topic.clone(),
            msg_type: c.msg_type.clone(),
            count: 0,
            first_ns: u64::MAX,
            last_ns: 0,
        });
    }
    bag.scan(&mut |m| {
        let t = topics
            .get_mut(connections[m.connection].topic.as_str())
            .expect("every connection listed");
        t.count += 1;
        t.first_ns = t.first_ns.min(m.log_time);
        t.last_ns = t.last_ns.max(m.log_time);
        Ok(())
    })?;
    let topics: Vec<TopicSummary> = topics.into_values().collect();
    let seen = topics.iter().filter(|t| t.count > 0);
    Ok(BagSummary {
        path: file.clone(),
        format: bag.format(),
        messages: topics.iter().map(|t| t.count).sum(),
        start_ns: seen.clone().map(|t| t.first_ns).min().unwrap_or(0),
        end_ns: seen.map(|t| t.last_ns).max().unwrap_or(0),
        topics,
    })
}

/// An image message found in the bag: its header stamp and where to read it again.
#[derive(Clone, Copy)]
struct Indexed {
    stamp: i64,
    at: Locator,
    wire: Wire,
}

struct Planned {
    id: String,
    stamp: i64,
    color: Indexed,
    depth: Indexed,
    labels: Option<(Indexed, Option<Vec<Segment>>)>,
    pose: Pose,
    intrinsics: Intrinsics,
}

/// An opened bag: the frames it makes, decoded on demand.
pub struct BagDataset {
    path: PathBuf,
    bag: Container,
    options: BagOptions,
    frames: Vec<Planned>,
    skipped: Vec<(String, String)>,
    classes: Option<ClassTable>,
    warnings: Vec<String>,
}

fn nearest<T>(list: &[(i64, T)], t: i64) -> Option<&(i64, T)> {
    let i = list.partition_point(|(s, _)| *s < t);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|j| list.get(j))
        .min_by_key(|(s, _)| (s - t).unsigned_abs())
}

fn within<T>(list: &[(i64, T)], t: i64, tolerance: i64) -> Option<&(i64, T)> {
    nearest(list, t).filter(|(s, _)| (s - t).abs() <= tolerance)
}

/// The topics of `connections` of a type, for hints in errors.
fn topics_of(connections: &[Connection], msg_type: &str) -> String {
    let mut names: Vec<&str> = connections
        .iter()
        .filter(|c| c.msg_type == msg_type)
        .map(|c| c.topic.as_str())
        .collect();
    names.sort_unstable();
    names.dedup();
    if names.is_empty() {
        "none".into()
    } else {
        names.join(", ")
    }
}

impl BagDataset {
    pub fn open(path: &Path, options: BagOptions) -> Result<Self, BagError> {
        let tolerance = options.sync_tolerance_s;
        if !(tolerance.is_finite() && tolerance >= 0.0) {
            return Err(BagError::new(
                path,
                format!(
                    "the sync tolerance must be a finite number of seconds, at least 0, not {tolerance}"
                ),
            ));
        }
        let classes = match &options.classes {
            Some(csv) => Some(
                voxpan_io::read_class_csv(csv).map_err(|e| BagError::new(csv, e.to_string()))?,
            ),
            None => None,
        };
        let file = container::resolve(path)?;
        let (bag, connections) = Container::open(&file)?;
        let inputs = plan::check_topics(&file, &connections, &options)?;
        let scanned = plan::scan(&bag, &file, &connections, &options, &inputs)?;
        let (camera, world) = plan::frames_of_reference(&file, &scanned, &options)?;
        let (frames, skipped) =
            plan::plan_frames(&file, &scanned, &options, &inputs, (&camera, &world))?;
        if frames.is_empty() {
            let why = skipped.first().map(|(id, r)| format!(" (frame {id}: {r})"));
            return Err(BagError::new(
                &file,
                format!("no usable frame{}", why.unwrap_or_default()),
            ));
        }
        let warnings = plan::distortion_warning(&scanned, &options);
        Ok(Self {
            path: file,
            bag,
            options,
            frames,
            skipped,
            classes,
            warnings,
        })
    }

    fn load_frame(&self, f: &Planned) -> Result<Frame, String> {
        let o = &self.options;
        // The frame's images in one read: each chunk is decompressed once.
        let mut wanted = vec![(&f.color, o.color_topic.as_str(), Kind::Color)];
        wanted.push((&f.depth, o.depth_topic.as_str(), Kind::Depth));
        if let Some((l, _)) = &f.labels {
            wanted.push((l, o.labels_topic.as_str(), Kind::Labels));
        }
        let ats: Vec<Locator> = wanted.iter().map(|w| w.0.at).collect();
        let mut decoded: Vec<Option<Result<Decoded, String>>> = ats.iter().map(|_| None).collect();
        self.bag
            .read_many(&ats, &mut |i, data| {
                let (image, _, what) = wanted[i];
                decoded[i] =
                    Some(msgs::image(image.wire, data).and_then(|m| decode_pixels(&m, what)));
            })
            .map_err(|e| e.message)?;
        let mut decoded = decoded.into_iter();
        let mut read = |i: &Indexed, topic: &str, _what: Kind| -> Result<Decoded, String> {
            decoded
                .next()
                .flatten()
                .expect("read_many fills every entry")
                .map_err(|e| format!("{topic} image at {} s: {e}", fmt_time(i.stamp)))
        };
        let Decoded::Color(color) = read(&f.color, &o.color_topic, Kind::Color)? else {
            unreachable!("asked for colour")
        };
        let Decoded::Depth(depth) = read(&f.depth, &o.depth_topic, Kind::Depth)? else {
            unreachable!("asked for depth")
        };
        let k = f.intrinsics;
        let mut sizes = vec![
            (&o.color_topic, f.color.stamp, color.dims()),
            (&o.depth_topic, f.depth.stamp, depth.dims()),
        ];
        let segments = match &f.labels {
            Some((l, list)) => {
                let Decoded::Labels(labels) = read(l, &o.labels_topic, Kind::Labels)? else {
                    unreachable!("asked for labels")
                };
                sizes.push((&o.labels_topic, l.stamp, labels.dims()));
                let ids = segment_ids(&labels);
                let segments = match list {
                    Some(list) => {
                        let missing: Vec<u16> = ids
                            .into_iter()
                            .filter(|id| !list.iter().any(|s| s.id == *id))
                            .collect();
                        if !missing.is_empty() {
                            return Err(format!(
                                "{} at {} s does not list segment id(s) {missing:?} of the \
                                 label image",
                                o.segments_topic,
                                fmt_time(l.stamp)
                            ));
                        }
                        list.clone()
                    }
                    None => ids.into_iter().map(Segment::bare).collect(),
                };
                Some(Segments { labels, segments })
            }
            None => None,
        };
        for (topic, stamp, (w, h)) in sizes {
            if (w, h) != (k.width, k.height) {
                return Err(format!(
                    "{topic} image at {} s is {w}x{h}, but {} says {}x{}",
                    fmt_time(stamp),
                    o.info_topic,
                    k.width,
                    k.height
                ));
            }
        }
        Ok(Frame {
            id: f.id.clone(),
            timestamp: f.stamp as f64 / 1e9,
            color,
            depth,
            pose: f.pose,
            intrinsics: k,
            segments,
            ground_truth: None,
        })
    }

    /// The bag file (inside a ROS 2 bag folder: the .mcap).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header stamp (nanoseconds) of frame `index`'s depth image.
    pub fn stamp_ns(&self, index: usize) -> i64 {
        self.frames[index].stamp
    }
}

impl FrameSource for BagDataset {
    fn kind(&self) -> &'static str {
        "bag"
    }

    fn len(&self) -> usize {
        self.frames.len()
    }

    fn frame_id(&self, index: usize) -> &str {
        &self.frames[index].id
    }

    fn load(&self, index: usize) -> Result<Frame, DatasetError> {
        let f = &self.frames[index];
        self.load_frame(f).map_err(|message| DatasetError::Frame {
            frame: f.id.clone(),
            source: Box::new(DatasetError::Invalid {
                path: self.path.clone(),
                message,
            }),
        })
    }

    fn skipped(&self) -> &[(String, String)] {
        &self.skipped
    }

    fn warnings(&self) -> &[String] {
        &self.warnings
    }

    fn network_classes(&self) -> Option<&ClassTable> {
        self.classes.as_ref()
    }
}

/// A camera_info's pinhole intrinsics (distortion is not modelled: rectified images).
fn intrinsics_of(info: &msgs::CameraInfoMsg) -> Intrinsics {
    Intrinsics {
        width: info.width as usize,
        height: info.height as usize,
        fx: info.k[0],
        fy: info.k[4],
        cx: info.k[2],
        cy: info.k[5],
    }
}

/// A JSON header's stamp in nanoseconds; `None` where it does not fit (seconds from anyone
/// on the network can be any integer).
pub fn json_stamp_ns(sec: i64, nsec: i64) -> Option<i64> {
    sec.checked_mul(1_000_000_000)?.checked_add(nsec)
}

/// `{"header": {"stamp": {"sec", "nanosec"|"nsec"}}, "segments": [...]}` -> (stamp, list).
fn parse_segment_list(text: &str, path: &Path) -> Result<(i64, Vec<Segment>), String> {
    let doc: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("segment list is not JSON: {e}"))?;
    let stamp = &doc["header"]["stamp"];
    let sec = stamp["sec"].as_i64();
    let nsec = stamp["nanosec"].as_i64().or(stamp["nsec"].as_i64());
    let (Some(sec), Some(nsec)) = (sec, nsec) else {
        return Err("segment list has no header.stamp {sec, nanosec}".into());
    };
    let list = doc
        .get("segments")
        .ok_or("segment list has no \"segments\"")?;
    let segments = voxpan_io::parse_segments_json(&list.to_string(), path)
        .map_err(|e| format!("segment list: {e}"))?;
    let stamp = json_stamp_ns(sec, nsec)
        .ok_or_else(|| format!("segment list stamp {sec} s {nsec} ns is out of range"))?;
    Ok((stamp, segments))
}

#[derive(Clone, Copy)]
enum Kind {
    Color,
    Depth,
    Labels,
}

enum Decoded {
    Color(ColorImage),
    Depth(DepthImage),
    Labels(LabelImage),
}

/// Pixels of an Image message as voxpan's images. Rows may be padded (`step`); 16- and 32-bit
/// samples honour `is_bigendian`.
fn decode_pixels(m: &msgs::ImageMsg<'_>, kind: Kind) -> Result<Decoded, String> {
    let (w, h) = (m.width as usize, m.height as usize);
    let enc = m.encoding.as_str();
    let bytes_per_pixel = match (kind, enc) {
        (Kind::Color, "rgb8" | "bgr8") => 3,
        (Kind::Color, "rgba8" | "bgra8") => 4,
        (Kind::Color, "mono8") => 1,
        (Kind::Depth, "16UC1" | "mono16") => 2,
        (Kind::Depth, "32FC1") => 4,
        (Kind::Labels, "16UC1" | "mono16") => 2,
        (Kind::Labels, "8UC1" | "mono8") => 1,
        _ => {
            let expected = match kind {
                Kind::Color => "rgb8, bgr8, rgba8, bgra8 or mono8",
                Kind::Depth => "16UC1 (millimetres) or 32FC1 (metres)",
                Kind::Labels => "16UC1, mono16, 8UC1 or mono8",
            };
            return Err(format!("unknown encoding {enc:?} (expected {expected})"));
        }
    };
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("image size {w}x{h} (1..=16384 per side)"));
    }
    let row = w * bytes_per_pixel;
    let step = m.step as usize;
    if step < row || m.data.len() != step * h {
        return Err(format!(
            "{} bytes of data for {h} rows of step {step} ({w} px of {bytes_per_pixel} bytes)",
            m.data.len()
        ));
    }
    let rows = m.data.chunks_exact(step).map(|r| &r[..row]);
    let be = m.is_bigendian;
    let u16_of = |b: &[u8]| {
        if be {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        }
    };
    let image = match (kind, enc) {
        (Kind::Color, _) => {
            let mut px = Vec::with_capacity(w * h);
            for r in rows {
                match enc {
                    "rgb8" => px.extend(r.chunks_exact(3).map(|p| [p[0], p[1], p[2]])),
                    "bgr8" => px.extend(r.chunks_exact(3).map(|p| [p[2], p[1], p[0]])),
                    "rgba8" => px.extend(r.chunks_exact(4).map(|p| [p[0], p[1], p[2]])),
                    "bgra8" => px.extend(r.chunks_exact(4).map(|p| [p[2], p[1], p[0]])),
                    _ => px.extend(r.iter().map(|&g| [g, g, g])),
                }
            }
            Decoded::Color(Image::from_vec(w, h, px).expect("w*h pixels"))
        }
        (Kind::Depth, "32FC1") => {
            let mut px = Vec::with_capacity(w * h);
            for r in rows {
                px.extend(r.chunks_exact(4).map(|b| {
                    let b = [b[0], b[1], b[2], b[3]];
                    let v = if be {
                        f32::from_be_bytes(b)
                    } else {
                        f32::from_le_bytes(b)
                    };
                    // NaN (and anything not a distance) is "no data": 0 in voxpan.
                    if v.is_finite() && v > 0.0 { v } else { 0.0 }
                }));
            }
            Decoded::Depth(Image::from_vec(w, h, px).expect("w*h pixels"))
        }
        (Kind::Depth, _) => {
            let mut px = Vec::with_capacity(w * h);
            for r in rows {
                px.extend(r.chunks_exact(2).map(|b| u16_of(b) as f32 / 1000.0));
            }
            Decoded::Depth(Image::from_vec(w, h, px).expect("w*h pixels"))
        }
        (Kind::Labels, _) => {
            let mut px = Vec::with_capacity(w * h);
            for r in rows {
                if bytes_per_pixel == 2 {
                    px.extend(r.chunks_exact(2).map(u16_of));
                } else {
                    px.extend(r.iter().map(|&v| v as u16));
                }
            }
            Decoded::Labels(Image::from_vec(w, h, px).expect("w*h pixels"))
        }
    };
    Ok(image)
}
