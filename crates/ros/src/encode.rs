//! voxpan's data as standard ROS 1 messages, so stock tools (rostopic, rosbag record, RViz,
//! Foxglove) read every topic, and `voxpan run` reads a recording of them back.

use roslibrust::codegen::integral_types::Time;
use voxpan_core::{ColorImage, DepthImage, Intrinsics, LabelImage, Mesh, Pose, Segment};

use crate::msgs::{geometry_msgs, nav_msgs, sensor_msgs, std_msgs, visualization_msgs};

/// A header stamped `stamp_ns` (nanoseconds since the epoch) in `frame_id`.
pub fn header(stamp_ns: i64, frame_id: &str) -> std_msgs::Header {
    std_msgs::Header {
        seq: 0,
        stamp: Time {
            // ROS 1 time is unsigned 32-bit seconds on the wire; the bits are kept as they are.
            secs: (stamp_ns.div_euclid(1_000_000_000)) as u32 as i32,
            nsecs: stamp_ns.rem_euclid(1_000_000_000) as i32,
        },
        frame_id: frame_id.to_owned(),
    }
}

/// Nanoseconds since the epoch of a ROS 1 stamp.
pub fn stamp_ns(t: &Time) -> i64 {
    t.secs as u32 as i64 * 1_000_000_000 + t.nsecs as i64
}

fn image(
    header: std_msgs::Header,
    (width, height): (usize, usize),
    encoding: &str,
    bytes_per_pixel: usize,
    data: Vec<u8>,
) -> sensor_msgs::Image {
    sensor_msgs::Image {
        header,
        height: height as u32,
        width: width as u32,
        encoding: encoding.to_owned(),
        is_bigendian: 0,
        step: (width * bytes_per_pixel) as u32,
        data,
    }
}

/// Depth in metres as 32FC1; pixels without a measurement (0) become NaN, as REP 117 says.
pub fn depth_image(header: std_msgs::Header, depth: &DepthImage) -> sensor_msgs::Image {
    let mut data = Vec::with_capacity(depth.pixels().len() * 4);
    for &z in depth.pixels() {
        let z = if z > 0.0 && z.is_finite() {
            z
        } else {
            f32::NAN
        };
        data.extend_from_slice(&z.to_le_bytes());
    }
    image(header, depth.dims(), "32FC1", 4, data)
}

/// Colour as rgb8.
pub fn color_image(header: std_msgs::Header, color: &ColorImage) -> sensor_msgs::Image {
    let data = color.pixels().iter().flatten().copied().collect();
    image(header, color.dims(), "rgb8", 3, data)
}

/// A label image as 16UC1 (0 = void).
pub fn label_image(header: std_msgs::Header, labels: &LabelImage) -> sensor_msgs::Image {
    let mut data = Vec::with_capacity(labels.pixels().len() * 2);
    for &l in labels.pixels() {
        data.extend_from_slice(&l.to_le_bytes());
    }
    image(header, labels.dims(), "16UC1", 2, data)
}

/// A pinhole camera without distortion (voxpan's images are rectified).
pub fn camera_info(header: std_msgs::Header, k: &Intrinsics) -> sensor_msgs::CameraInfo {
    sensor_msgs::CameraInfo {
        header,
        height: k.height as u32,
        width: k.width as u32,
        distortion_model: "plumb_bob".into(),
        D: vec![0.0; 5],
        K: [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
        R: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P: [
            k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
        ..Default::default()
    }
}

/// `T_world_camera` as a PoseStamped in the world frame.
pub fn pose_stamped(header: std_msgs::Header, pose: &Pose) -> geometry_msgs::PoseStamped {
    geometry_msgs::PoseStamped {
        header,
        pose: ros_pose(pose),
    }
}

fn ros_pose(pose: &Pose) -> geometry_msgs::Pose {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion().coords;
    geometry_msgs::Pose {
        position: geometry_msgs::Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: geometry_msgs::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        },
    }
}

/// The costmap as a `nav_msgs/OccupancyGrid` (100 occupied, 0 free, -1 unknown, row-major
/// from the origin cell), for Nav2 and move_base.
pub fn occupancy_grid(
    header: std_msgs::Header,
    costmap: &voxpan_map::Costmap,
) -> nav_msgs::OccupancyGrid {
    nav_msgs::OccupancyGrid {
        info: nav_msgs::MapMetaData {
            map_load_time: header.stamp.clone(),
            resolution: costmap.resolution as f32,
            width: costmap.width as u32,
            height: costmap.height as u32,
            origin: ros_pose(&costmap.origin_pose()),
        },
        header,
        data: costmap.occupancy(),
    }
}

/// The costmap's clearance as a `sensor_msgs/PointCloud2` (nvblox's distance slice): a
/// point per known cell at its centre, fields `x`, `y`, `z` and `distance` (metres to the
/// nearest obstacle in the plane, at most `cap`), all float32, little endian.
pub fn esdf_slice(
    header: std_msgs::Header,
    costmap: &voxpan_map::Costmap,
    cap: f32,
) -> sensor_msgs::PointCloud2 {
    const POINT_BYTES: u32 = 16;
    let field = |name: &str, offset: u32| sensor_msgs::PointField {
        name: name.to_owned(),
        offset,
        datatype: sensor_msgs::PointField::FLOAT32,
        count: 1,
    };
    let points = costmap.clearance_points(cap);
    let mut data = Vec::with_capacity(points.len() * POINT_BYTES as usize);
    for ([x, y, z], distance) in &points {
        for v in [*x as f32, *y as f32, *z as f32, *distance] {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    sensor_msgs::PointCloud2 {
        header,
        height: 1,
        width: points.len() as u32,
        fields: vec![
            field("x", 0),
            field("y", 4),
            field("z", 8),
            field("distance", 12),
        ],
        is_bigendian: false,
        point_step: POINT_BYTES,
        row_step: POINT_BYTES * points.len() as u32,
        data,
        is_dense: true,
    }
}

/// A frame's segment list in the bag reader's format: `{"header": {"stamp": {"sec",
/// "nanosec"}, "frame_id"}, "segments": [labels.json entries]}`; `null` segments say the
/// frame has no masks. `received_unix_ns` (when the perception node got the frame) lets the
/// mapping node measure latency; `class_names` (the segmenter's whole label table, id ->
/// name, left out when empty) lets it name the map's classes as `voxpan run` does. `carry`
/// marks a frame between keyframes (no masks, its depth as measured): the mapping node
/// renders the map's masks at its pose, refines them with these `[refine]` settings and fills
/// the depth's holes with these `[fill]` ones, as `voxpan run` does.
pub fn segment_list(
    stamp_ns: i64,
    frame_id: &str,
    segments: Option<&[Segment]>,
    received_unix_ns: i64,
    class_names: &std::collections::BTreeMap<u32, String>,
    carry: Option<&voxpan_perception::PerceptionConfig>,
) -> std_msgs::String {
    let segments = match segments {
        Some(s) => voxpan_io::segments_json(s),
        None => "null".to_owned(),
    };
    let header = serde_json::json!({
        "stamp": {
            "sec": stamp_ns.div_euclid(1_000_000_000),
            "nanosec": stamp_ns.rem_euclid(1_000_000_000),
        },
        "frame_id": frame_id,
    });
    let names = if class_names.is_empty() {
        String::new()
    } else {
        let names: serde_json::Map<String, serde_json::Value> = class_names
            .iter()
            .map(|(id, name)| (id.to_string(), name.clone().into()))
            .collect();
        format!(",\"class_names\":{}", serde_json::Value::Object(names))
    };
    // What the mapping node refines and fills the map's masks with between keyframes:
    // the perception node's own settings, so that only it is configured.
    let carry = carry.map_or(String::new(), |c| {
        let settings = serde_json::json!({"refine": c.refine, "fill": c.fill});
        format!(",\"carry\":{settings}")
    });
    std_msgs::String {
        data: format!(
            "{{\"header\":{header},\"segments\":{segments},\"received_unix_ns\":{received_unix_ns}{names}{carry}}}"
        ),
    }
}

/// One block's mesh as an RViz TRIANGLE_LIST marker (three points per triangle, a colour per
/// point), in the world frame; `mesh` `None` deletes the marker `id`.
pub fn block_marker(
    header: std_msgs::Header,
    namespace: &str,
    id: i32,
    mesh: Option<&Mesh>,
) -> visualization_msgs::Marker {
    let mut marker = visualization_msgs::Marker {
        header,
        ns: namespace.to_owned(),
        id,
        r#type: visualization_msgs::Marker::TRIANGLE_LIST as i32,
        action: visualization_msgs::Marker::ADD as i32,
        pose: ros_pose(&Pose::identity()),
        scale: geometry_msgs::Vector3 {
            x: 1.0,
            y: 1.0,
            z: 1.0,
        },
        color: std_msgs::ColorRGBA {
            r: 1.0,
            g: 1.0,
            b: 1.0,
            a: 1.0,
        },
        ..Default::default()
    };
    let Some(mesh) = mesh else {
        marker.action = visualization_msgs::Marker::DELETE as i32;
        return marker;
    };
    let n = mesh.triangles.len() * 3;
    marker.points.reserve(n);
    marker.colors.reserve(n);
    for t in &mesh.triangles {
        for &v in t {
            let [x, y, z] = mesh.vertices[v as usize];
            marker.points.push(geometry_msgs::Point {
                x: x as f64,
                y: y as f64,
                z: z as f64,
            });
            let [r, g, b] = mesh.colors.get(v as usize).copied().unwrap_or([200; 3]);
            marker.colors.push(std_msgs::ColorRGBA {
                r: r as f32 / 255.0,
                g: g as f32 / 255.0,
                b: b as f32 / 255.0,
                a: 1.0,
            });
        }
    }
    marker
}
