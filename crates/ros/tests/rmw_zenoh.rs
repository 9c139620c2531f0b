//! voxpan-ros's ROS 2 wire layer against independent implementations, through
//! tools/ros/ros2_wire_reference.py in the venv tools/ros/setup.sh makes: type hashes from PyPI
//! rosbags, CDR bytes from rosbags' serializer, attachments from eclipse-zenoh's serializer,
//! publisher ids from PyPI xxhash.

mod common;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::{Value, json};
use voxpan_core::nalgebra::{Quaternion, Translation3, UnitQuaternion};
use voxpan_core::{Intrinsics, Pose};
use voxpan_ros::msgs::{geometry_msgs, sensor_msgs, std_msgs, visualization_msgs};
use voxpan_ros::rmw_zenoh::{
    Attachment, EntityKind, NodeName, Qos, endpoint_token, node_token, publisher_id, types,
};
use voxpan_ros::{cdr, encode};

fn venv_python() -> Option<PathBuf> {
    let py = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/ros-venv/bin/python");
    if py.is_file() {
        return Some(py);
    }
    if voxpan_test_support::missing_data_allowed() {
        eprintln!("SKIPPED: no target/ros-venv (tools/ros/setup.sh)");
        return None;
    }
    panic!("no target/ros-venv: run tools/ros/setup.sh or set VOXPAN_ALLOW_MISSING_DATA=1");
}

fn reference(py: &Path, request: &Value) -> Value {
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ros/ros2_wire_reference.py");
    let mut child = Command::new(py)
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(request.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn header_json(h: &std_msgs::Header) -> Value {
    json!({"sec": h.stamp.secs, "nanosec": h.stamp.nsecs, "frame_id": h.frame_id})
}

fn pose_json(p: &geometry_msgs::Pose) -> Value {
    let (t, q) = (&p.position, &p.orientation);
    json!({"t": [t.x, t.y, t.z], "q": [q.x, q.y, q.z, q.w]})
}

#[test]
fn ros2_wire_bytes_match_independent_implementations() {
    let Some(py) = venv_python() else {
        return;
    };
    // Odd sizes and a stamp with nanoseconds, so alignment and every field are exercised.
    let header = encode::header(1_700_000_000_123_456_789, "camera_color_optical_frame");
    let image = sensor_msgs::Image {
        header: header.clone(),
        height: 3,
        width: 1,
        encoding: "mono8".into(),
        is_bigendian: 0,
        step: 1,
        data: vec![1, 2, 3],
    };
    let k = Intrinsics {
        width: 640,
        height: 480,
        fx: 525.0,
        fy: 524.5,
        cx: 319.5,
        cy: 239.25,
    };
    let mut info = encode::camera_info(header.clone(), &k);
    // Fields voxpan leaves at zero, set here so that their order is checked too.
    (info.binning_x, info.binning_y) = (2, 3);
    info.roi = sensor_msgs::RegionOfInterest {
        x_offset: 4,
        y_offset: 5,
        height: 6,
        width: 7,
        do_rectify: true,
    };
    let pose = Pose::from_parts(
        Translation3::new(0.25, -1.5, 2.0),
        UnitQuaternion::from_quaternion(Quaternion::new(0.9, 0.1, 0.2, 0.3)),
    );
    let pose = encode::pose_stamped(encode::header(5, "world"), &pose);
    let text = std_msgs::String {
        data: "{\"segments\":[]}".into(),
    };
    let mesh = voxpan_core::Mesh {
        vertices: vec![[0.0, 0.0, 1.0], [0.5, 0.0, 1.0], [0.0, 0.25, 1.5]],
        colors: vec![[255, 0, 0], [0, 255, 0], [0, 0, 255]],
        triangles: vec![[0, 1, 2]],
        ..Default::default()
    };
    let mut markers = visualization_msgs::MarkerArray {
        markers: vec![
            encode::block_marker(encode::header(7, "world"), "voxpan_mesh", 3, Some(&mesh)),
            encode::block_marker(encode::header(7, "world"), "voxpan_mesh", 4, None),
        ],
    };
    let m = &mut markers.markers[1];
    m.lifetime.sec = 8;
    m.lifetime.nsec = 9;
    (m.frame_locked, m.mesh_use_embedded_materials) = (true, true);
    (m.text, m.mesh_resource) = ("text".into(), "package://mesh.dae".into());

    let costmap = common::small_costmap();
    let grid = encode::occupancy_grid(encode::header(11, "world"), &costmap);
    assert_eq!(grid.data, [100, 0, -1, 0, 100, 0]);
    let slice = encode::esdf_slice(encode::header(12, "world"), &costmap, 2.0);
    assert_eq!((slice.width, slice.row_step), (5, 80));

    let marker_json: Vec<Value> = markers
        .markers
        .iter()
        .map(|m| {
            json!({
                "header": header_json(&m.header), "ns": m.ns, "id": m.id, "type": m.r#type,
                "action": m.action, "pose": pose_json(&m.pose),
                "scale": [m.scale.x, m.scale.y, m.scale.z],
                "color": [m.color.r, m.color.g, m.color.b, m.color.a],
                "points": m.points.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>(),
                "colors": m.colors.iter().map(|c| [c.r, c.g, c.b, c.a]).collect::<Vec<_>>(),
                "lifetime": [m.lifetime.sec, m.lifetime.nsec], "frame_locked": m.frame_locked,
                "text": m.text, "mesh_resource": m.mesh_resource,
                "mesh_use_embedded_materials": m.mesh_use_embedded_materials,
            })
        })
        .collect();
    let messages = [
        (
            "sensor_msgs/msg/Image",
            json!({"header": header_json(&image.header), "height": image.height,
                   "width": image.width, "encoding": image.encoding,
                   "is_bigendian": image.is_bigendian, "step": image.step, "data": image.data}),
            cdr::image(&image),
        ),
        (
            "sensor_msgs/msg/CameraInfo",
            json!({"header": header_json(&info.header), "height": info.height,
                   "width": info.width, "distortion_model": info.distortion_model,
                   "d": info.D, "k": info.K, "r": info.R, "p": info.P,
                   "binning": [info.binning_x, info.binning_y],
                   "roi": [info.roi.x_offset, info.roi.y_offset, info.roi.height,
                           info.roi.width, info.roi.do_rectify]}),
            cdr::camera_info(&info),
        ),
        (
            "geometry_msgs/msg/PoseStamped",
            json!({"header": header_json(&pose.header), "pose": pose_json(&pose.pose)}),
            cdr::pose_stamped(&pose),
        ),
        (
            "std_msgs/msg/String",
            json!({"data": text.data}),
            cdr::string(&text),
        ),
        (
            "visualization_msgs/msg/MarkerArray",
            json!({"markers": marker_json}),
            cdr::marker_array(&markers),
        ),
        (
            "nav_msgs/msg/OccupancyGrid",
            json!({"header": header_json(&grid.header),
                   "load_time": [grid.info.map_load_time.secs, grid.info.map_load_time.nsecs],
                   "resolution": grid.info.resolution, "width": grid.info.width,
                   "height": grid.info.height, "origin": pose_json(&grid.info.origin),
                   "data": grid.data}),
            cdr::occupancy_grid(&grid),
        ),
        (
            "sensor_msgs/msg/PointCloud2",
            json!({"header": header_json(&slice.header), "height": slice.height,
                   "width": slice.width,
                   "fields": slice.fields.iter().map(|f| json!({"name": f.name,
                       "offset": f.offset, "datatype": f.datatype, "count": f.count}))
                       .collect::<Vec<_>>(),
                   "is_bigendian": slice.is_bigendian, "point_step": slice.point_step,
                   "row_step": slice.row_step, "data": slice.data,
                   "is_dense": slice.is_dense}),
            cdr::point_cloud2(&slice),
        ),
    ];

    let node = NodeName {
        domain: 0,
        session_id: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
        node_id: 2,
        enclave: "/".into(),
        namespace: "/robot".into(),
        name: "voxpan_map".into(),
    };
    let tokens = [
        node_token(&node),
        endpoint_token(
            &node,
            3,
            EntityKind::Publisher,
            "/voxpan/mesh",
            &types::MARKER_ARRAY,
            &Qos::DEFAULT,
        ),
    ];
    let attachment = Attachment {
        sequence: 41,
        timestamp_ns: 1_700_000_000_987_654_321,
        publisher_id: publisher_id(&tokens[1]),
    };

    let request = json!({
        "types": types::ALL.iter().map(|t| t.name).collect::<Vec<_>>(),
        "messages": messages.iter().map(|(t, v, _)| json!({"type": t, "value": v}))
            .collect::<Vec<_>>(),
        "attachment": {"sequence": attachment.sequence, "timestamp_ns": attachment.timestamp_ns,
                       "gid": hex(&attachment.publisher_id)},
        "tokens": tokens,
    });
    let theirs = reference(&py, &request);

    for t in types::ALL {
        assert_eq!(theirs["hashes"][t.name], t.hash, "{}", t.name);
    }
    for (i, (name, _, ours)) in messages.iter().enumerate() {
        assert_eq!(theirs["cdr"][i], hex(ours), "{name}");
    }
    assert_eq!(theirs["attachment"], hex(&attachment.to_bytes()));
    for (i, token) in tokens.iter().enumerate() {
        assert_eq!(theirs["gids"][i], hex(&publisher_id(token)), "{token}");
    }
}
