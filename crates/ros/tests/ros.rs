//! voxpan-ros against independent implementations: the message types' MD5 sums and the bytes
//! they serialise to, checked with Debian's ROS 1 Python messages (genpy); the perception
//! node's inputs assembled from a synthetic sequence like the bag reader assembles them.

mod common;

use std::process::Command;

use roslibrust::RosMessageType;
use voxpan_ros::cdr::Ros2Message;
use voxpan_ros::encode;
use voxpan_ros::msgs::{
    geometry_msgs, nav_msgs, sensor_msgs, std_msgs, visualization_msgs, voxpan_msgs,
};

/// Runs `code` with Debian's /usr/bin/python3 (where rospy's message packages live); `None`
/// (skipped) only with VOXPAN_ALLOW_MISSING_DATA=1.
fn debian_python(test: &str, code: &str) -> Option<String> {
    let out = Command::new("/usr/bin/python3").args(["-c", code]).output();
    match out {
        Ok(o) if o.status.success() => Some(String::from_utf8(o.stdout).unwrap()),
        other => {
            let why = match other {
                Ok(o) => String::from_utf8_lossy(&o.stderr).into_owned(),
                Err(e) => e.to_string(),
            };
            if voxpan_test_support::missing_data_allowed() {
                eprintln!("SKIPPED {test}: Debian's ROS 1 messages not importable: {why}");
                return None;
            }
            panic!(
                "{test}: Debian's ROS 1 Python messages are needed (tools/ros/setup.sh, as \
                 root) or VOXPAN_ALLOW_MISSING_DATA=1: {why}"
            );
        }
    }
}

#[test]
fn md5_sums_are_ros_own() {
    let ours = [
        ("sensor_msgs/Image", sensor_msgs::Image::DESCRIPTION.md5sum),
        (
            "sensor_msgs/CameraInfo",
            sensor_msgs::CameraInfo::DESCRIPTION.md5sum,
        ),
        (
            "geometry_msgs/PoseStamped",
            geometry_msgs::PoseStamped::DESCRIPTION.md5sum,
        ),
        ("std_msgs/String", std_msgs::String::DESCRIPTION.md5sum),
        (
            "visualization_msgs/Marker",
            visualization_msgs::Marker::DESCRIPTION.md5sum,
        ),
        (
            "visualization_msgs/MarkerArray",
            visualization_msgs::MarkerArray::DESCRIPTION.md5sum,
        ),
        (
            "nav_msgs/OccupancyGrid",
            nav_msgs::OccupancyGrid::DESCRIPTION.md5sum,
        ),
        (
            "sensor_msgs/PointCloud2",
            sensor_msgs::PointCloud2::DESCRIPTION.md5sum,
        ),
    ];
    let code = r#"
import importlib
for t in ['sensor_msgs/Image', 'sensor_msgs/CameraInfo', 'geometry_msgs/PoseStamped',
          'std_msgs/String', 'visualization_msgs/Marker', 'visualization_msgs/MarkerArray',
          'nav_msgs/OccupancyGrid', 'sensor_msgs/PointCloud2']:
    pkg, name = t.split('/')
    print(t, getattr(importlib.import_module(pkg + '.msg'), name)._md5sum)
"#;
    let Some(theirs) = debian_python("md5_sums_are_ros_own", code) else {
        return;
    };
    for (t, md5) in ours {
        let line = format!("{t} {md5}");
        assert!(theirs.lines().any(|l| l == line), "{line} not in\n{theirs}");
    }
}

/// voxpan's own service type: its MD5 as genmsg (ROS 1's message tooling) computes it from
/// the same .srv file, and the Python classes genpy generates from it (what a rospy client
/// calls the map node with) carry that sum.
#[test]
fn the_distance_service_md5_is_genmsgs() {
    use roslibrust::RosServiceType;
    let srv = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/msg/voxpan_msgs/srv/DistanceQuery.srv"
    );
    let code = format!(
        r#"
import genmsg, genmsg.msg_loader, genmsg.gentools, genpy.generator
ctx = genmsg.MsgContext.create_default()
spec = genmsg.msg_loader.load_srv_from_file(ctx, "{srv}", "voxpan_msgs/DistanceQuery")
paths = {{"geometry_msgs": ["/usr/share/geometry_msgs/msg"]}}
genmsg.msg_loader.load_depends(ctx, spec, paths)
code = "\n".join(genpy.generator.srv_generator(ctx, spec, paths))
ns = {{}}
exec(code, ns)
print(genmsg.gentools.compute_md5(ctx, spec), ns["DistanceQuery"]._md5sum)
"#
    );
    let Some(theirs) = debian_python("the_distance_service_md5_is_genmsgs", &code) else {
        return;
    };
    let ours = voxpan_msgs::DistanceQuery::MD5SUM;
    assert_eq!(theirs.trim(), format!("{ours} {ours}"));
}

/// The distance slice, as roslibrust serialises it, read back by ROS 1's own point cloud
/// reader (sensor_msgs.point_cloud2 under genpy): the same points and distances.
#[test]
fn the_esdf_slice_reads_back_with_ros_point_cloud2() {
    // Up along -y: the plane's coordinates are x and z, the band's height -y.
    let costmap = common::small_costmap();
    let slice = encode::esdf_slice(encode::header(5, "world"), &costmap, 2.0);
    let hex: String = body(&slice).iter().map(|b| format!("{b:02x}")).collect();
    let code = format!(
        r#"
import sensor_msgs.msg, sensor_msgs.point_cloud2 as pc2
m = sensor_msgs.msg.PointCloud2()
m.deserialize(bytes.fromhex("{hex}"))
print(m.header.frame_id, [f.name for f in m.fields])
for p in pc2.read_points(m, field_names=("x", "y", "z", "distance")):
    print(" ".join("%.4f" % v for v in p))
"#
    );
    let Some(theirs) = debian_python("the_esdf_slice_reads_back_with_ros_point_cloud2", &code)
    else {
        return;
    };
    let expected = "world ['x', 'y', 'z', 'distance']\n\
                    -1.2250 -0.1000 0.5250 0.0000\n\
                    -1.1750 -0.1000 0.5250 0.1000\n\
                    -1.2250 -0.1000 0.5750 0.5000\n\
                    -1.1750 -0.1000 0.5750 0.0300\n\
                    -1.1250 -0.1000 0.5750 2.0000\n";
    assert_eq!(theirs, expected);
}

/// A message's ROS 1 serialisation, as roslibrust sends it (without the length prefix).
fn body<T: RosMessageType>(m: &T) -> Vec<u8> {
    roslibrust_serde_rosmsg::to_vec_skip_length(m).unwrap()
}

fn ns(s: f64) -> i64 {
    (s * 1e9).round() as i64
}

fn tf_message(stamp: i64, parent: &str, child: &str, x: f64) -> Vec<u8> {
    // TFMessage = TransformStamped[]; written by hand (voxpan publishes none).
    let mut b = Vec::new();
    b.extend(1u32.to_le_bytes());
    let h = body(&encode::header(stamp, parent));
    b.extend(&h);
    b.extend((child.len() as u32).to_le_bytes());
    b.extend(child.as_bytes());
    for v in [x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
        b.extend(v.to_le_bytes());
    }
    b
}

/// A message as it travels: ROS 1's serialisation (TCPROS body) or ROS 2's CDR sample.
fn on_wire<T: RosMessageType + Ros2Message>(wire: voxpan_bag::live::Wire, m: &T) -> Vec<u8> {
    match wire {
        voxpan_bag::live::Wire::Ros1 => body(m),
        voxpan_bag::live::Wire::Cdr => m.to_cdr(),
    }
}

#[test]
fn published_messages_decode_to_what_was_sent() {
    use voxpan_bag::live::{self, Wire};
    use voxpan_core::{Image, Intrinsics, Pose, Segment};
    // The same values through both middlewares' encoders and the bag reader's decoders.
    for wire in [Wire::Ros1, Wire::Cdr] {
        let t = 1_700_000_000_123_456_789;
        let depth = Image::from_vec(3, 2, vec![0.0, 1.5, f32::NAN, 2.25, 0.001, 7.0]).unwrap();
        let (h, d) = live::depth_image(
            wire,
            &on_wire(wire, &encode::depth_image(encode::header(t, "cam"), &depth)),
        )
        .unwrap();
        assert_eq!((h.stamp_ns, h.frame_id.as_str()), (t, "cam"));
        assert_eq!(d.pixels(), &[0.0, 1.5, 0.0, 2.25, 0.001, 7.0]);
        let color = Image::from_vec(2, 1, vec![[1, 2, 3], [250, 251, 252]]).unwrap();
        let (_, c) = live::color_image(
            wire,
            &on_wire(wire, &encode::color_image(encode::header(t, "cam"), &color)),
        )
        .unwrap();
        assert_eq!(c, color);
        let labels = Image::from_vec(2, 2, vec![0u16, 7, 65535, 300]).unwrap();
        let (_, l) = live::label_image(
            wire,
            &on_wire(wire, &encode::label_image(encode::header(t, "c"), &labels)),
        )
        .unwrap();
        assert_eq!(l, labels);
        let k = Intrinsics {
            width: 640,
            height: 480,
            fx: 525.5,
            fy: 524.25,
            cx: 319.75,
            cy: 239.5,
        };
        let (_, k2, distorted) = live::camera_info(
            wire,
            &on_wire(wire, &encode::camera_info(encode::header(t, "c"), &k)),
        )
        .unwrap();
        assert_eq!(k2, k);
        assert_eq!(distorted, None, "voxpan's camera_info says D = 0");
        let pose = Pose::from_parts(
            voxpan_core::nalgebra::Translation3::new(1.0, -2.0, 0.5),
            voxpan_core::nalgebra::UnitQuaternion::from_euler_angles(0.1, -0.4, 2.0),
        );
        let (h, p) = live::pose_stamped(
            wire,
            &on_wire(
                wire,
                &encode::pose_stamped(encode::header(t, "world"), &pose),
            ),
        )
        .unwrap();
        assert_eq!(h.frame_id, "world");
        assert!((p.to_homogeneous() - pose.to_homogeneous()).abs().max() < 1e-12);
        let segments = vec![
            Segment {
                id: 3,
                class_id: Some(62),
                is_thing: Some(true),
                score: Some(0.93),
            },
            Segment::bare(9),
        ];
        // The label table travels whole, names with quotes and non-ASCII letters included.
        let names: std::collections::BTreeMap<u32, String> =
            [(62, "tv".to_owned()), (75, "vase \"Ming\" — 明".to_owned())].into();
        let list = voxpan_ros::inbound::segment_list(
            wire,
            &on_wire(
                wire,
                &encode::segment_list(t, "cam", Some(&segments), 42, &names, None),
            ),
        )
        .unwrap();
        assert_eq!((list.stamp_ns, list.received_unix_ns), (t, 42));
        assert_eq!(list.segments.as_deref(), Some(segments.as_slice()));
        assert_eq!(list.class_names.as_ref(), Some(&names));
        // The bag reader reads the same list.
        let (t2, s2) = live::segment_list(
            wire,
            &on_wire(
                wire,
                &encode::segment_list(t, "c", Some(&segments), 0, &names, None),
            ),
        )
        .unwrap();
        assert_eq!((t2, s2), (t, segments));
        let none = voxpan_ros::inbound::segment_list(
            wire,
            &on_wire(
                wire,
                &encode::segment_list(t, "c", None, 0, &Default::default(), None),
            ),
        )
        .unwrap();
        assert_eq!((none.segments, none.class_names), (None, None));
        assert_eq!(none.carry, None);

        // Between keyframes: no masks, and the perception node's refinement and filling
        // settings (not the defaults) for the mapping node to apply.
        let mut settings = voxpan_perception::PerceptionConfig::default();
        settings.refine.rule = voxpan_refine::Rule::Paper;
        settings.refine.far_limit = 7.5;
        settings.fill.enabled = false;
        let carried = voxpan_ros::inbound::segment_list(
            wire,
            &on_wire(
                wire,
                &encode::segment_list(t, "c", None, 0, &names, Some(&settings)),
            ),
        )
        .unwrap();
        assert_eq!(carried.segments, None);
        assert_eq!(carried.carry, Some(settings));
        // Settings perception cannot run with, and masks on a carried frame, are refused
        // (the message counts as bad), never applied.
        let with_carry = |carry: &str, segments: &str| {
            let text = format!(
                "{{\"header\":{{\"stamp\":{{\"sec\":1,\"nanosec\":0}}}},\
                 \"segments\":{segments},\"carry\":{carry}}}"
            );
            voxpan_ros::inbound::segment_list(
                wire,
                &on_wire(wire, &std_msgs::String { data: text }),
            )
        };
        let refine = serde_json::to_string(&settings.refine).unwrap();
        let error = with_carry(&format!("{{\"refine\":{refine}}}"), "[]").unwrap_err();
        assert!(error.contains("expected \"segments\": null"), "{error}");
        let far = refine.replace("7.5", "-1.0");
        assert_ne!(far, refine);
        let error = with_carry(&format!("{{\"refine\":{far}}}"), "null").unwrap_err();
        assert!(
            error.contains("carry: ") && error.contains("far_limit"),
            "{error}"
        );
        let error = with_carry("{\"speed\":3}", "null").unwrap_err();
        assert!(
            error.contains("carry: ") && error.contains("speed"),
            "{error}"
        );
        assert!(with_carry(&format!("{{\"refine\":{refine}}}"), "null").is_ok());
    }
}

/// The assembler tests' camera: 2x1 pixels.
fn two_pixel_camera() -> voxpan_core::Intrinsics {
    voxpan_core::Intrinsics {
        width: 2,
        height: 1,
        fx: 10.0,
        fy: 10.0,
        cx: 1.0,
        cy: 0.5,
    }
}

/// A ROS 1 depth image of that camera at stamp `t` (ns), 1 m and 2 m.
fn two_pixel_depth(t: i64) -> Vec<u8> {
    body(&encode::depth_image(
        encode::header(t, "cam"),
        &voxpan_core::Image::from_vec(2, 1, vec![1.0, 2.0]).unwrap(),
    ))
}

/// A ROS 1 colour image of that camera at stamp `t`, every channel `value`.
fn two_pixel_color(t: i64, value: u8) -> Vec<u8> {
    body(&encode::color_image(
        encode::header(t, "cam"),
        &voxpan_core::Image::from_vec(2, 1, vec![[value; 3]; 2]).unwrap(),
    ))
}

#[test]
fn frames_are_assembled_as_the_bag_reader_pairs_them() {
    use voxpan_bag::BagOptions;
    use voxpan_bag::assemble::{Assembler, Input};
    use voxpan_bag::live::Wire;
    let k = two_pixel_camera();
    let mut a = Assembler::new(BagOptions::default(), false, Wire::Ros1);
    let t0 = ns(100.0);
    let depth = two_pixel_depth;
    let color = |t: i64| two_pixel_color(t, (t % 250) as u8);
    a.add(
        Input::CameraInfo,
        &body(&encode::camera_info(encode::header(t0, "cam"), &k)),
        0,
    )
    .unwrap();
    a.add(Input::TfStatic, &tf_message(t0, "base", "cam", 0.5), 0)
        .unwrap();
    // Depth first, colour 3 ms later: waits for the transform.
    a.add(Input::Depth, &depth(t0), 7).unwrap();
    a.add(Input::Color, &color(t0 + ns(0.003)), 0).unwrap();
    assert!(a.take_ready().is_empty(), "no pose yet");
    a.add(Input::Tf, &tf_message(t0, "world", "base", 1.0), 0)
        .unwrap();
    let ready = a.take_ready();
    assert_eq!(ready.len(), 1);
    let f = ready.into_iter().next().unwrap().unwrap();
    assert_eq!((f.stamp_ns, f.received_unix_ns), (t0, 7));
    assert_eq!(
        (f.camera_frame.as_str(), f.world_frame.as_str()),
        ("cam", "world")
    );
    assert_eq!(f.frame.pose.translation.x, 1.5);
    assert_eq!(f.frame.depth.pixels(), &[1.0, 2.0]);
    assert_eq!(f.frame.intrinsics, k);
    // A second frame between two transforms is interpolated.
    a.add(
        Input::Tf,
        &tf_message(t0 + ns(0.2), "world", "base", 2.0),
        0,
    )
    .unwrap();
    a.add(Input::Depth, &depth(t0 + ns(0.1)), 0).unwrap();
    a.add(Input::Color, &color(t0 + ns(0.1)), 0).unwrap();
    let f = a.take_ready().pop().unwrap().unwrap();
    assert!((f.frame.pose.translation.x - 2.0).abs() < 1e-12);
    // A depth image whose colour never comes is given up once depth a second newer arrives,
    // naming the colour topic; the frames after it still come.
    a.add(Input::Depth, &depth(t0 + ns(0.15)), 0).unwrap();
    assert!(a.take_ready().is_empty());
    for i in 0..3 {
        let t = t0 + ns(0.2 + 0.5 * i as f64);
        a.add(Input::Tf, &tf_message(t, "world", "base", 3.0), 0)
            .unwrap();
        a.add(Input::Depth, &depth(t), 0).unwrap();
        a.add(Input::Color, &color(t), 0).unwrap();
    }
    let out = a.take_ready();
    let given_up = out[0].as_ref().unwrap_err();
    assert_eq!(given_up.stamp_ns, t0 + ns(0.15));
    assert!(
        given_up.reason.contains("/camera/color/image_raw"),
        "{}",
        given_up.reason
    );
    assert_eq!(out.iter().filter(|r| r.is_ok()).count(), 3);
    // Garbage is an error, not a panic.
    assert!(a.add(Input::Depth, &[1, 2, 3], 0).is_err());
    assert!(a.add(Input::Color, &depth(t0), 0).is_err());
}

/// A peer can send stamps that never age (all equal, or in the future) on every stream, and
/// new frame names on /tf without end: what the assembler holds stays bounded, and a real
/// frame still pairs afterwards.
#[test]
fn a_flood_on_any_stream_cannot_grow_the_assembler() {
    use voxpan_bag::BagOptions;
    use voxpan_bag::assemble::{Assembler, Input, MAX_FRAMES, MAX_HELD, MAX_PENDING};
    use voxpan_bag::live::Wire;
    let k = two_pixel_camera();
    let t0 = ns(100.0);
    let depth = two_pixel_depth;
    let color = |t: i64| two_pixel_color(t, 9);
    let info = |t: i64| body(&encode::camera_info(encode::header(t, "cam"), &k));
    type Message<'a> = Box<dyn Fn(usize) -> (Input, Vec<u8>) + 'a>;
    let floods: [(&str, Message); 6] = [
        ("colour, one stamp", Box::new(|_| (Input::Color, color(t0)))),
        (
            "colour, stamps going back",
            Box::new(|i| (Input::Color, color(t0 - ns(i as f64)))),
        ),
        (
            "camera_info, one stamp",
            Box::new(|_| (Input::CameraInfo, info(t0))),
        ),
        (
            "depth, future stamps",
            Box::new(|i| (Input::Depth, depth(t0 + ns(1e-4 * i as f64)))),
        ),
        (
            "/tf, one edge, future stamps",
            Box::new(|i| {
                (
                    Input::Tf,
                    tf_message(t0 + ns(i as f64), "world", "cam", 1.0),
                )
            }),
        ),
        (
            "/tf, a new frame each time",
            Box::new(|i| {
                (
                    Input::Tf,
                    tf_message(t0, &format!("f{i}"), &format!("g{i}"), 1.0),
                )
            }),
        ),
    ];
    for (name, message) in floods {
        let mut a = Assembler::new(BagOptions::default(), false, Wire::Ros1);
        let mut refused = 0;
        for i in 0..3 * MAX_FRAMES {
            let (input, data) = message(i);
            refused += usize::from(a.add(input, &data, 0).is_err());
            let _ = a.take_ready();
        }
        let bound = MAX_HELD.max(MAX_PENDING).max(MAX_FRAMES);
        assert!(a.held() <= bound, "{name}: {} held", a.held());
        if name.contains("new frame") {
            assert_eq!(refused, 2 * MAX_FRAMES, "{name}");
        } else {
            assert_eq!(refused, 0, "{name}");
        }
    }
    // After a flood of colour images, a real frame still pairs.
    let mut a = Assembler::new(BagOptions::default(), false, Wire::Ros1);
    for _ in 0..3 * MAX_HELD {
        a.add(Input::Color, &color(t0 - ns(5.0)), 0).unwrap();
        let _ = a.take_ready();
    }
    a.add(Input::CameraInfo, &info(t0), 0).unwrap();
    a.add(Input::Tf, &tf_message(t0, "world", "cam", 1.0), 0)
        .unwrap();
    a.add(Input::Color, &color(t0), 0).unwrap();
    a.add(Input::Depth, &depth(t0), 0).unwrap();
    let ready = a.take_ready();
    assert_eq!(ready.len(), 1);
    assert!(ready[0].is_ok(), "{:?}", ready[0].as_ref().err());
}

/// A node stopped before any frame says so in its summary, not "NaN ms"; with frames it gives
/// the latency's median and 95th percentile.
#[test]
fn the_summary_of_a_node_without_frames_has_no_nan() {
    let idle = voxpan_ros::node::NodeReport::default().summary();
    assert!(
        idle.contains("no latency (no frame done)") && !idle.contains("NaN"),
        "{idle}"
    );
    let busy = voxpan_ros::node::NodeReport {
        frames_in: 3,
        frames_done: 3,
        seconds: 1.0,
        latency_ms: vec![30.0, 10.0, 20.0],
        ..Default::default()
    }
    .summary();
    assert!(
        busy.contains("latency median 20.0 ms, p95 30.0 ms"),
        "{busy}"
    );
}
