//! `voxpan info BAG`, and the bag options `voxpan run` takes.

use std::path::{Path, PathBuf};

use anyhow::Result;
use voxpan_bag::{BagDataset, BagOptions, fmt_time, summarize};
use voxpan_dataset::FrameSource;

/// Which topics of a ROS bag make the frames (defaults: the RealSense ROS driver's).
#[derive(clap::Args, Clone, Debug)]
pub struct BagArgs {
    /// sensor_msgs/Image colour topic (rgb8, bgr8, rgba8, bgra8, mono8).
    #[arg(
        long,
        default_value = "/camera/color/image_raw",
        help_heading = "ROS bags"
    )]
    color_topic: String,
    /// sensor_msgs/Image depth topic (16UC1 millimetres or 32FC1 metres), registered to colour.
    #[arg(
        long,
        default_value = "/camera/aligned_depth_to_color/image_raw",
        help_heading = "ROS bags"
    )]
    depth_topic: String,
    /// sensor_msgs/CameraInfo topic of the colour camera (the intrinsics).
    #[arg(
        long,
        default_value = "/camera/color/camera_info",
        help_heading = "ROS bags"
    )]
    info_topic: String,
    /// geometry_msgs/PoseStamped or TransformStamped topic with the camera's pose in the
    /// world; without it, /tf + /tf_static.
    #[arg(long, help_heading = "ROS bags")]
    pose_topic: Option<String>,
    /// World frame of the tf chain [default: the root of the camera frame's tree].
    #[arg(long, help_heading = "ROS bags")]
    world_frame: Option<String>,
    /// Camera (optical) frame [default: the colour images' header.frame_id].
    #[arg(long, help_heading = "ROS bags")]
    camera_frame: Option<String>,
    /// sensor_msgs/Image label-image topic (masks; 0 = void) [default:
    /// /camera/segments/image, used when the bag has it].
    #[arg(long, help_heading = "ROS bags")]
    labels_topic: Option<String>,
    /// std_msgs/String topic with each label image's segment list (JSON).
    #[arg(
        long,
        default_value = "/camera/segments/labels",
        help_heading = "ROS bags"
    )]
    segments_topic: String,
    /// Colour and label images pair with a depth image within this many milliseconds.
    #[arg(
        long,
        default_value_t = 20.0,
        help_heading = "ROS bags",
        allow_negative_numbers = true,
        value_parser = parse_tolerance_ms
    )]
    sync_tolerance_ms: f64,
    /// The network's label table (detectron_labels.csv format) naming the segments' classes.
    #[arg(long, help_heading = "ROS bags")]
    classes: Option<PathBuf>,
}

/// A pairing tolerance: a finite number of milliseconds, at least 0 (NaN would pair nothing,
/// silently).
fn parse_tolerance_ms(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(ms) if ms.is_finite() && ms >= 0.0 => Ok(ms),
        _ => Err(format!(
            "expected a number of milliseconds, at least 0, not {text:?}"
        )),
    }
}

impl BagArgs {
    pub fn options(&self) -> BagOptions {
        let defaults = BagOptions::default();
        BagOptions {
            color_topic: self.color_topic.clone(),
            depth_topic: self.depth_topic.clone(),
            info_topic: self.info_topic.clone(),
            pose_topic: self.pose_topic.clone(),
            world_frame: self.world_frame.clone(),
            camera_frame: self.camera_frame.clone(),
            require_labels: self.labels_topic.is_some(),
            labels_topic: self
                .labels_topic
                .clone()
                .unwrap_or(defaults.labels_topic.clone()),
            segments_topic: self.segments_topic.clone(),
            sync_tolerance_s: self.sync_tolerance_ms / 1e3,
            classes: self.classes.clone(),
            ..defaults
        }
    }
}

#[derive(clap::Args)]
pub struct InfoArgs {
    /// ROS 1 .bag, ROS 2 .mcap or .db3, a ROS 2 bag folder, or a saved map (.voxpan).
    bag: PathBuf,
    /// Also open the bag as voxpan would map it (with the topic options) and say how many
    /// frames it makes and which are skipped.
    #[arg(long)]
    frames: bool,
    #[command(flatten)]
    topics: BagArgs,
}

pub fn info(args: InfoArgs) -> Result<()> {
    if args.bag.is_file()
        && let Some(version) = voxpan_map::map_file_version(&args.bag)?
    {
        return super::map_info::describe(&args.bag, version);
    }
    let s = summarize(&args.bag)?;
    println!("path:     {}", s.path.display());
    println!("format:   {}", s.format);
    println!(
        "duration: {:.3} s ({} .. {} s)",
        s.duration_s(),
        fmt_time(s.start_ns as i64),
        fmt_time(s.end_ns as i64)
    );
    println!("messages: {}", s.messages);
    let width = s
        .topics
        .iter()
        .map(|t| t.topic.len())
        .max()
        .unwrap_or(5)
        .max(5);
    let type_width = s
        .topics
        .iter()
        .map(|t| t.msg_type.len())
        .max()
        .unwrap_or(4)
        .max(4);
    println!(
        "{:width$}  {:type_width$}  {:>7}  {:>9}",
        "topic", "type", "count", "rate"
    );
    for t in &s.topics {
        let rate = t.rate_hz().map_or("-".into(), |r| format!("{r:.2} Hz"));
        println!(
            "{:width$}  {:type_width$}  {:>7}  {:>9}",
            t.topic, t.msg_type, t.count, rate
        );
    }
    if args.frames {
        print_frames(&args.bag, args.topics.options())?;
    }
    Ok(())
}

fn print_frames(bag: &Path, options: BagOptions) -> Result<()> {
    let d = BagDataset::open(bag, options)?;
    println!("frames:   {} (skipped {})", d.len(), d.skipped().len());
    let skipped = d.skipped().iter().map(|(f, r)| (f.as_str(), r.as_str()));
    for group in voxpan_dataset::group_skipped(skipped) {
        println!("  {group}");
    }
    Ok(())
}
