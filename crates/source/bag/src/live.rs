//! The same decoders for messages that arrive one at a time (live ROS 1 subscriptions): each
//! function takes one ROS 1-serialised message body, so a live node and a bag agree on every
//! pixel, intrinsic and pose.

use std::path::Path;

use voxpan_core::{ColorImage, DepthImage, Intrinsics, LabelImage, Pose, Segment};

use crate::msgs::{self, Wire};
use crate::{Decoded, Kind, decode_pixels};

pub use crate::msgs::{Header, TransformMsg};
pub use crate::tf::{TfTree, Track, pose_of};

pub type Result<T> = std::result::Result<T, String>;

fn image(data: &[u8], kind: Kind) -> Result<(Header, Decoded)> {
    let m = msgs::image(Wire::Ros1, data)?;
    let decoded = decode_pixels(&m, kind)?;
    Ok((m.header, decoded))
}

/// A sensor_msgs/Image in rgb8, bgr8, rgba8, bgra8 or mono8.
pub fn color_image(data: &[u8]) -> Result<(Header, ColorImage)> {
    match image(data, Kind::Color)? {
        (h, Decoded::Color(c)) => Ok((h, c)),
        _ => unreachable!("asked for colour"),
    }
}

/// A sensor_msgs/Image in 16UC1 millimetres or 32FC1 metres (no data: 0).
pub fn depth_image(data: &[u8]) -> Result<(Header, DepthImage)> {
    match image(data, Kind::Depth)? {
        (h, Decoded::Depth(d)) => Ok((h, d)),
        _ => unreachable!("asked for depth"),
    }
}

/// A sensor_msgs/Image label image (16UC1/mono16 or 8UC1/mono8, 0 = void).
pub fn label_image(data: &[u8]) -> Result<(Header, LabelImage)> {
    match image(data, Kind::Labels)? {
        (h, Decoded::Labels(l)) => Ok((h, l)),
        _ => unreachable!("asked for labels"),
    }
}

/// A sensor_msgs/CameraInfo's pinhole intrinsics (checked usable).
pub fn camera_info(data: &[u8]) -> Result<(Header, Intrinsics)> {
    let info = msgs::camera_info(Wire::Ros1, data)?;
    let k = crate::intrinsics_of(&info);
    k.check().map_err(|e| format!("unusable intrinsics: {e}"))?;
    Ok((info.header, k))
}

/// A tf2_msgs/TFMessage's transforms.
pub fn transforms(data: &[u8]) -> Result<Vec<TransformMsg>> {
    msgs::tf_message(Wire::Ros1, data)
}

/// A geometry_msgs/PoseStamped as `T_{header.frame_id}_camera`.
pub fn pose_stamped(data: &[u8]) -> Result<(Header, Pose)> {
    let t = msgs::pose_stamped(Wire::Ros1, data)?;
    Ok((t.header.clone(), pose_of(&t)?))
}

/// A std_msgs/String segment list (`{"header": {"stamp": ..}, "segments": [...]}`): its stamp
/// in nanoseconds and the segments.
pub fn segment_list(data: &[u8]) -> Result<(i64, Vec<Segment>)> {
    let text = msgs::string(Wire::Ros1, data)?;
    crate::parse_segment_list(&text, Path::new("segment list"))
}

/// A std_msgs/String's text.
pub fn string(data: &[u8]) -> Result<String> {
    msgs::string(Wire::Ros1, data)
}
