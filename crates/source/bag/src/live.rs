//! The same decoders for messages that arrive one at a time (live subscriptions): each
//! function takes one message body, ROS 1-serialised (TCPROS) or CDR (ROS 2, with its
//! encapsulation header), so a live node and a bag agree on every pixel, intrinsic and pose.

use std::path::Path;

use voxpan_core::{ColorImage, DepthImage, Intrinsics, LabelImage, Pose, Segment};

use crate::msgs;
use crate::{Decoded, Kind, decode_pixels};

pub use crate::attachment::{ATTACHMENT_LEN, Attachment};
pub use crate::msgs::{Header, TransformMsg, Wire};
pub use crate::tf::{TfTree, Track, pose_of};

pub type Result<T> = std::result::Result<T, String>;

fn image(wire: Wire, data: &[u8], kind: Kind) -> Result<(Header, Decoded)> {
    let m = msgs::image(wire, data)?;
    let decoded = decode_pixels(&m, kind)?;
    Ok((m.header, decoded))
}

/// A sensor_msgs/Image in rgb8, bgr8, rgba8, bgra8 or mono8.
pub fn color_image(wire: Wire, data: &[u8]) -> Result<(Header, ColorImage)> {
    match image(wire, data, Kind::Color)? {
        (h, Decoded::Color(c)) => Ok((h, c)),
        _ => unreachable!("asked for colour"),
    }
}

/// A sensor_msgs/Image in 16UC1 millimetres or 32FC1 metres (no data: 0).
pub fn depth_image(wire: Wire, data: &[u8]) -> Result<(Header, DepthImage)> {
    match image(wire, data, Kind::Depth)? {
        (h, Decoded::Depth(d)) => Ok((h, d)),
        _ => unreachable!("asked for depth"),
    }
}

/// A sensor_msgs/Image label image (16UC1/mono16 or 8UC1/mono8, 0 = void).
pub fn label_image(wire: Wire, data: &[u8]) -> Result<(Header, LabelImage)> {
    match image(wire, data, Kind::Labels)? {
        (h, Decoded::Labels(l)) => Ok((h, l)),
        _ => unreachable!("asked for labels"),
    }
}

/// A sensor_msgs/CameraInfo's pinhole intrinsics (checked usable), and why the images are
/// not pinhole images when its distortion is not zero.
pub fn camera_info(wire: Wire, data: &[u8]) -> Result<(Header, Intrinsics, Option<String>)> {
    let info = msgs::camera_info(wire, data)?;
    let k = crate::intrinsics_of(&info);
    k.check().map_err(|e| format!("unusable intrinsics: {e}"))?;
    let warning = info.distortion_warning();
    Ok((info.header, k, warning))
}

/// A tf2_msgs/TFMessage's transforms.
pub fn transforms(wire: Wire, data: &[u8]) -> Result<Vec<TransformMsg>> {
    msgs::tf_message(wire, data)
}

/// A geometry_msgs/PoseStamped as `T_{header.frame_id}_camera`.
pub fn pose_stamped(wire: Wire, data: &[u8]) -> Result<(Header, Pose)> {
    let t = msgs::pose_stamped(wire, data)?;
    Ok((t.header.clone(), pose_of(&t)?))
}

/// A std_msgs/String segment list (`{"header": {"stamp": ..}, "segments": [...]}`): its stamp
/// in nanoseconds and the segments.
pub fn segment_list(wire: Wire, data: &[u8]) -> Result<(i64, Vec<Segment>)> {
    let text = msgs::string(wire, data)?;
    crate::parse_segment_list(&text, Path::new("segment list"))
}

/// A std_msgs/String's text.
pub fn string(wire: Wire, data: &[u8]) -> Result<String> {
    msgs::string(wire, data)
}
