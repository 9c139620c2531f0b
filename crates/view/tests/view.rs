//! The live view read back as a viewer would: the MCAP recording with the `mcap` crate (an
//! independent reader) and the WebSocket server with a plain WebSocket client speaking
//! Foxglove's protocol; every message decoded with Foxglove's own schemas.

use std::collections::BTreeMap;
use std::net::TcpStream;
use std::time::{Duration, Instant};

use foxglove::Decode;
use foxglove::schemas::{FrameTransform, RawImage, SceneUpdate};
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{Frame, Segment, Segments};
use voxpan_map::{Coloring, MapConfig, PanopticMap};
use voxpan_sim::trajectory::look_along;
use voxpan_sim::{Object, Scene, Shape, Surface, SynthConfig, render};
use voxpan_view::{LiveOptions, LiveView, block_id, partial_path};

/// A box before a long wall, seen by a camera sliding sideways along the wall: each update
/// adds new wall and leaves the far end alone, so updates are partial.
fn frames(n: usize) -> Vec<(Frame, Segments)> {
    let mut scene = Scene::empty(Vector3::new(20.0, 20.0, 20.0));
    let object = |instance_id, is_thing, color, shape| Object {
        instance_id,
        class_id: 3,
        is_thing,
        color,
        surface: Surface::Plain,
        specular: false,
        shapes: vec![shape],
    };
    scene.add(object(
        1,
        true,
        [200, 60, 40],
        Shape::Cuboid {
            center: Point3::new(0.0, 2.2, 0.0),
            half: Vector3::new(0.4, 0.3, 0.4),
            yaw: 0.3,
        },
    ));
    scene.add(object(
        2,
        false,
        [120, 120, 200],
        Shape::Cuboid {
            center: Point3::new(0.0, 3.1, 0.0),
            half: Vector3::new(6.0, 0.1, 2.0),
            yaw: 0.0,
        },
    ));
    let k = SynthConfig::tiny().intrinsics();
    (0..n)
        .map(|i| {
            let eye = Point3::new(-2.0 + 0.5 * i as f64, 0.0, 0.3);
            let pose = look_along(eye, Vector3::y());
            let v = render(&scene, &pose, &k);
            // The object's pixels as one segment (ground-truth id 1 → segment 1).
            let labels = v.instances.map(|&id| u16::from(id == 1));
            let frame = Frame {
                id: format!("{i:06}"),
                timestamp: 10.0 + 0.1 * i as f64,
                color: v.color,
                depth: v.depth,
                pose,
                intrinsics: k,
                segments: None,
                ground_truth: None,
            };
            let segments = Segments {
                labels,
                segments: vec![Segment {
                    id: 1,
                    class_id: Some(3),
                    is_thing: Some(true),
                    score: Some(0.9),
                }],
            };
            (frame, segments)
        })
        .collect()
}

fn map_with(view: &mut LiveView, frames: &[(Frame, Segments)]) -> PanopticMap {
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    for (frame, segments) in frames {
        map.integrate(frame.view(), Some(segments)).unwrap();
        view.show(frame, Some(segments), &mut map).unwrap();
    }
    map
}

/// The scene a viewer holds after applying `updates` in order: entity id → triangle count.
fn apply(updates: &[SceneUpdate]) -> BTreeMap<String, usize> {
    let mut scene = BTreeMap::new();
    for update in updates {
        for deletion in &update.deletions {
            scene.remove(&deletion.id);
        }
        for entity in &update.entities {
            let triangles = entity.triangles.iter().map(|t| t.indices.len() / 3).sum();
            scene.insert(entity.id.clone(), triangles);
        }
    }
    scene
}

/// The viewer's scene equals the map's mesh (a short message when not).
fn assert_same_scene(viewer: BTreeMap<String, usize>, map: &PanopticMap) {
    let expected = expected_scene(map);
    let differing = expected
        .iter()
        .filter(|(id, n)| viewer.get(*id) != Some(n))
        .count()
        + viewer
            .keys()
            .filter(|id| !expected.contains_key(*id))
            .count();
    assert!(
        differing == 0,
        "the viewer holds {} blocks, the map {}; {differing} differ",
        viewer.len(),
        expected.len()
    );
}

/// What the map's own mesh says the viewer should hold.
fn expected_scene(map: &PanopticMap) -> BTreeMap<String, usize> {
    map.mesh_blocks()
        .iter()
        .map(|b| {
            let mesh = map.block_mesh(b, Coloring::Instance).unwrap();
            (block_id(b), mesh.triangles.len())
        })
        .collect()
}

#[test]
fn the_recording_holds_every_frame_and_the_final_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let input = frames(6);
    let mut view = LiveView::start(&LiveOptions {
        listen: None,
        record: Some(path.clone()),
        mesh_every: 2,
        ..LiveOptions::default()
    })
    .unwrap();
    let mut map = map_with(&mut view, &input);
    assert!(
        !path.exists(),
        "only the partial file exists before the end"
    );
    assert!(partial_path(&path).exists());
    view.finish(&mut map).unwrap();
    assert!(!partial_path(&path).exists());

    let bytes = std::fs::read(&path).unwrap();
    let mut by_topic: BTreeMap<String, Vec<(u64, Vec<u8>, String)>> = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let m = message.unwrap();
        let schema = m.channel.schema.as_ref().map(|s| s.name.clone());
        assert_eq!(m.channel.message_encoding, "protobuf");
        by_topic.entry(m.channel.topic.clone()).or_default().push((
            m.log_time,
            m.data.to_vec(),
            schema.unwrap_or_default(),
        ));
    }
    let topics: Vec<&str> = by_topic.keys().map(String::as_str).collect();
    assert_eq!(
        topics,
        [
            "/camera/calibration",
            "/camera/color",
            "/camera/depth",
            "/map/mesh",
            "/tf"
        ]
    );
    for (topic, schema) in [
        ("/camera/color", "foxglove.RawImage"),
        ("/camera/depth", "foxglove.RawImage"),
        ("/tf", "foxglove.FrameTransform"),
        ("/map/mesh", "foxglove.SceneUpdate"),
    ] {
        assert!(
            by_topic[topic].iter().all(|(_, _, s)| s == schema),
            "{topic}"
        );
    }
    // One image, calibration and pose per frame, stamped with the frame's time.
    for topic in [
        "/camera/color",
        "/camera/depth",
        "/camera/calibration",
        "/tf",
    ] {
        assert_eq!(by_topic[topic].len(), input.len(), "{topic}");
    }
    for ((stamp, data, _), (frame, segments)) in by_topic["/tf"].iter().zip(&input) {
        assert_eq!(*stamp, (frame.timestamp * 1e9).round() as u64);
        let tf = FrameTransform::decode(data.as_slice()).unwrap();
        let t = tf.translation.unwrap();
        let q = tf.rotation.unwrap();
        let expect = frame.pose.rotation.quaternion();
        assert!((t.x - frame.pose.translation.x).abs() < 1e-12);
        assert!((t.z - frame.pose.translation.z).abs() < 1e-12);
        assert!((q.w - expect.w).abs() < 1e-12 && (q.x - expect.i).abs() < 1e-12);
        assert_eq!(
            (tf.parent_frame_id.as_str(), tf.child_frame_id.as_str()),
            ("world", "camera")
        );
        let _ = segments;
    }
    // The colour image: the frame's pixels outside the masks, blended inside.
    let (frame, segments) = &input[3];
    let color = RawImage::decode(by_topic["/camera/color"][3].1.as_slice()).unwrap();
    assert_eq!(
        (color.width as usize, color.height as usize),
        (frame.color.width(), frame.color.height())
    );
    assert_eq!(
        (color.encoding.as_str(), color.step as usize),
        ("rgb8", 3 * frame.color.width())
    );
    let labels = segments.labels.pixels();
    let (mut inside, mut outside) = (0, 0);
    for (i, rgb) in frame.color.pixels().iter().enumerate() {
        let shown = &color.data[3 * i..3 * i + 3];
        if labels[i] == 0 {
            assert_eq!(shown, rgb, "pixel {i} outside the mask is unchanged");
            outside += 1;
        } else {
            let tint = voxpan_map::id_color(1);
            for c in 0..3 {
                assert_eq!(shown[c] as u16, (rgb[c] as u16 + tint[c] as u16) / 2);
            }
            inside += 1;
        }
    }
    assert!(inside > 100 && outside > 100, "{inside} {outside}");
    // Depth as 32-bit floats, metres.
    let depth = RawImage::decode(by_topic["/camera/depth"][3].1.as_slice()).unwrap();
    assert_eq!(depth.encoding, "32FC1");
    let z: Vec<f32> = depth
        .data
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(z.len(), frame.depth.pixels().len());
    for (a, b) in z.iter().zip(frame.depth.pixels()) {
        assert!(a == b || (*a == 0.0 && !voxpan_core::is_valid_depth(*b)));
    }
    // Mesh updates every second frame plus the final one; replayed in order they leave the
    // viewer with exactly the map's mesh, block by block.
    let updates: Vec<SceneUpdate> = by_topic["/map/mesh"]
        .iter()
        .map(|(_, data, _)| SceneUpdate::decode(data.as_slice()).unwrap())
        .collect();
    assert!(updates.len() >= 3, "{} mesh updates", updates.len());
    let expected = expected_scene(&map);
    assert!(!expected.is_empty());
    assert_same_scene(apply(&updates), &map);
    // Later updates carry only what changed, not the whole map again.
    let sizes: Vec<usize> = updates.iter().map(|u| u.entities.len()).collect();
    assert!(
        sizes[1..].iter().all(|&n| n < expected.len()),
        "{sizes:?} of {}",
        expected.len()
    );
}

#[test]
fn options_that_cannot_work_are_refused() {
    let nothing = LiveView::start(&LiveOptions {
        listen: None,
        record: None,
        ..LiveOptions::default()
    });
    assert!(nothing.is_err());
    let missing = std::path::Path::new("/nonexistent-folder-voxpan/run.mcap");
    let e = LiveView::start(&LiveOptions {
        listen: None,
        record: Some(missing.into()),
        ..LiveOptions::default()
    })
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("/nonexistent-folder-voxpan/run.mcap"), "{e}");
    let e = LiveView::start(&LiveOptions {
        listen: Some(("256.1.1.1".into(), 0)),
        record: None,
        ..LiveOptions::default()
    })
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("256.1.1.1"), "{e}");
}

type Socket = tungstenite::WebSocket<TcpStream>;

fn read_json(socket: &mut Socket, op: &str) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if let tungstenite::Message::Text(text) = socket.read().unwrap() {
            let value: serde_json::Value = serde_json::from_str(&text).unwrap();
            if value["op"] == op {
                return value;
            }
        }
    }
    panic!("no {op} message within 10 s");
}

/// A Foxglove WebSocket "message data" frame: opcode 1, u32 subscription id, u64 log time,
/// then the message.
fn parse_message(data: &[u8]) -> Option<(u32, u64, &[u8])> {
    if data.len() < 13 || data[0] != 1 {
        return None;
    }
    let subscription = u32::from_le_bytes(data[1..5].try_into().unwrap());
    let time = u64::from_le_bytes(data[5..13].try_into().unwrap());
    Some((subscription, time, &data[13..]))
}

/// Binary messages until one for `subscription` arrives: (log time, payload).
fn read_message(socket: &mut Socket, subscription: u32) -> (u64, Vec<u8>) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if let tungstenite::Message::Binary(data) = socket.read().unwrap()
            && let Some((id, time, payload)) = parse_message(&data)
            && id == subscription
        {
            return (time, payload.to_vec());
        }
    }
    panic!("no message for subscription {subscription} within 10 s");
}

#[test]
fn a_viewer_connecting_over_websocket_sees_the_topics_and_the_mesh() {
    let input = frames(4);
    let mut view = LiveView::start(&LiveOptions {
        listen: Some(("127.0.0.1".into(), 0)),
        record: None,
        mesh_every: 1,
        ..LiveOptions::default()
    })
    .unwrap();
    let port = view.port().unwrap();
    // The map already has surface, meshed, before the viewer connects.
    let mut map = PanopticMap::new(MapConfig::default()).unwrap();
    let (frame, segments) = &input[0];
    map.integrate(frame.view(), Some(segments)).unwrap();
    view.show(frame, Some(segments), &mut map).unwrap();
    assert!(!map.mesh_blocks().is_empty());
    let mut request = tungstenite::client::IntoClientRequest::into_client_request(format!(
        "ws://127.0.0.1:{port}"
    ))
    .unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let (mut socket, _) = tungstenite::client(request, stream).unwrap();

    let advertised = read_json(&mut socket, "advertise");
    let channels: BTreeMap<String, (u64, String)> = advertised["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            (
                c["topic"].as_str().unwrap().to_string(),
                (
                    c["id"].as_u64().unwrap(),
                    c["schemaName"].as_str().unwrap().to_string(),
                ),
            )
        })
        .collect();
    assert_eq!(channels["/map/mesh"].1, "foxglove.SceneUpdate");
    assert_eq!(channels["/camera/color"].1, "foxglove.RawImage");
    assert_eq!(channels.len(), 5, "{channels:?}");
    let subscribe = serde_json::json!({
        "op": "subscribe",
        "subscriptions": [
            {"id": 7, "channelId": channels["/map/mesh"].0},
            {"id": 8, "channelId": channels["/tf"].0},
        ]
    });
    socket
        .send(tungstenite::Message::Text(subscribe.to_string().into()))
        .unwrap();
    // Subscriptions take effect asynchronously: publish the first frame again until its pose
    // comes back; mesh updates that arrive meanwhile are kept, in order.
    let mut updates = Vec::new();
    let mut got_pose = None;
    let deadline = Instant::now() + Duration::from_secs(10);
    socket
        .get_ref()
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    while got_pose.is_none() && Instant::now() < deadline {
        view.show(frame, Some(segments), &mut map).unwrap();
        while let Ok(tungstenite::Message::Binary(data)) = socket.read() {
            match parse_message(&data) {
                Some((7, _, payload)) => updates.push(SceneUpdate::decode(payload).unwrap()),
                Some((8, _, payload)) => got_pose = Some(FrameTransform::decode(payload).unwrap()),
                _ => {}
            }
        }
    }
    let pose = got_pose.expect("the subscribed pose arrives");
    assert!((pose.translation.unwrap().x - frame.pose.translation.x).abs() < 1e-12);
    socket
        .get_ref()
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    // The map did not change, yet the new subscriber got the whole mesh: it joined late.
    assert_same_scene(apply(&updates), &map);
    // Each later frame's update reaches it, stamped with the frame's time; replayed, they
    // give the map's mesh.
    for (frame, segments) in &input[1..] {
        map.integrate(frame.view(), Some(segments)).unwrap();
        view.show(frame, Some(segments), &mut map).unwrap();
        let stamp = (frame.timestamp * 1e9).round() as u64;
        loop {
            let (time, payload) = read_message(&mut socket, 7);
            updates.push(SceneUpdate::decode(payload.as_slice()).unwrap());
            if time == stamp {
                break;
            }
        }
    }
    assert!(
        updates
            .iter()
            .flat_map(|u| &u.entities)
            .all(|e| e.frame_id == "world")
    );
    assert_same_scene(apply(&updates), &map);
    view.finish(&mut map).unwrap();
}
