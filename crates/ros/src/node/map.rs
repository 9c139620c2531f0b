//! The mapping thread (integration, mesh and costmap schedules) and the mapping node.

use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use roslibrust::ros1::ServiceServer;
use tokio::sync::mpsc;
use voxpan_fill::HoleFiller;
use voxpan_map::{BlockIndex, Coloring, PanopticMap};
use voxpan_perception::{MaskRefiner, PerceptionConfig, StageTimes};

use super::join::{Joiner, MapInput};
use super::publish::{CostmapPublisher, MeshPublisher};
use super::save::{save, save_now};
use super::{
    Log, MapOptions, NodeError, NodeReport, ToMap, finish_counters, receive, runtime, unix_ns,
};
use crate::mailbox::Mailbox;
use crate::msgs::{std_srvs, voxpan_msgs};
use crate::rmw_zenoh::types;
use crate::transport::{Counters, Node};

/// The map while the mapping thread integrates: shared with the save service, which saves it
/// between two frames. `None` once the thread has handed it back.
pub(super) type SharedMap = Arc<Mutex<Option<PanopticMap>>>;

/// What the mapping thread hands back.
pub(super) struct MapDone {
    pub(super) map: PanopticMap,
    pub(super) done: u64,
    /// Frames integrated with masks of their own (not carried between keyframes).
    pub(super) segmented: u64,
    pub(super) failed: Vec<String>,
    pub(super) latency: Vec<f64>,
}

/// Integration on its own thread; every `mesh_every` frames and at the end the changed
/// blocks go to `publish_mesh`, every `costmap_every` frames and at the end the costmap to
/// `publish_costmap`.
#[allow(clippy::too_many_arguments)] // the map, its inbox, two schedules, two publishers
fn map_worker(
    shared: SharedMap,
    inbox: Arc<Mailbox<ToMap>>,
    mesh_every: usize,
    coloring: Coloring,
    costmap_every: usize,
    log: Log,
    mut publish_mesh: impl FnMut(Vec<(BlockIndex, Option<voxpan_core::Mesh>)>) + Send + 'static,
    mut publish_costmap: impl FnMut(voxpan_map::Costmap) + Send + 'static,
) -> std::thread::JoinHandle<MapDone> {
    std::thread::Builder::new()
        .name("voxpan-map".into())
        .spawn(move || {
            let (mut done, mut failed, mut latency) = (0u64, Vec::new(), Vec::new());
            let changed_meshes = |map: &mut PanopticMap| {
                let changed = map.update_mesh();
                changed
                    .into_iter()
                    .map(|b| {
                        let mesh = map
                            .block_mesh(&b, coloring)
                            .filter(|m| !m.triangles.is_empty());
                        (b, mesh)
                    })
                    .collect::<Vec<_>>()
            };
            let costmap = |map: &mut PanopticMap| {
                map.update_esdf();
                map.costmap()
            };
            let lock = || shared.lock().unwrap_or_else(|p| p.into_inner());
            let mut carrier: Option<Carrier> = None;
            let mut segmented = 0;
            while let Some(mut item) = inbox.take() {
                // Held while one frame is integrated (and its mesh update made), so that the
                // save service saves between frames; released before publishing.
                let mut guard = lock();
                let map = guard.as_mut().expect("only this thread takes the map");
                // Before the first frame that carries them: class names choose the tracker's
                // families of confusable classes, as `voxpan run` sets them from the start.
                if let Some(names) = &item.class_names
                    && names != map.class_names()
                {
                    map.set_class_names(names.clone());
                }
                let carried = match item.carry.take() {
                    Some(carry) => {
                        let config = carry.config;
                        let carrier = match &mut carrier {
                            Some(c) if c.config == config => c,
                            other => other.insert(Carrier::new(config)),
                        };
                        match carrier.masks(map, &mut item.frame, carry.measured) {
                            Ok(segments) => Some(segments),
                            Err(e) => {
                                let line = format!("frame {}: {e}", item.frame.id);
                                log(&line);
                                failed.push(line);
                                continue;
                            }
                        }
                    }
                    None => None,
                };
                let f = &item.frame;
                // As `voxpan run`: a frame without one usable depth is skipped, not integrated.
                let (lo, hi) = (map.config().tsdf.min_range, map.config().tsdf.max_range);
                let usable =
                    f.depth.pixels().iter().any(|&z| {
                        voxpan_core::is_valid_depth(z) && (lo..=hi).contains(&(z as f64))
                    });
                if !usable {
                    let line = format!("frame {}: no depth between {lo} and {hi} m", f.id);
                    log(&line);
                    failed.push(line);
                    continue;
                }
                let integrated = match &carried {
                    Some(segments) => map.integrate_carried(f.view(), segments),
                    None => map.integrate(f.view(), item.segments.as_ref()),
                };
                match integrated {
                    Ok(_) => {
                        done += 1;
                        segmented += u64::from(carried.is_none());
                        latency.push((unix_ns() - item.received_unix_ns) as f64 / 1e6);
                        log(&format!(
                            "integrated frame {} ({} frames, {} instances)",
                            f.id,
                            done,
                            map.instance_count()
                        ));
                        let due = |every: usize| every > 0 && done % every as u64 == 0;
                        let blocks = due(mesh_every).then(|| changed_meshes(map));
                        let grid = due(costmap_every).then(|| costmap(map)).flatten();
                        drop(guard);
                        if let Some(blocks) = blocks.filter(|b| !b.is_empty()) {
                            publish_mesh(blocks);
                        }
                        if let Some(grid) = grid {
                            publish_costmap(grid);
                        }
                    }
                    Err(e) => {
                        let line = format!("frame {}: {e}", f.id);
                        log(&line);
                        failed.push(line);
                    }
                }
            }
            let mut map = lock().take().expect("only this thread takes the map");
            // As `voxpan run` after its last frame; the blocks it relabels mesh again below.
            map.consolidate();
            if mesh_every > 0 {
                let blocks = changed_meshes(&mut map);
                if !blocks.is_empty() {
                    publish_mesh(blocks);
                }
            }
            if costmap_every > 0
                && let Some(grid) = costmap(&mut map)
            {
                publish_costmap(grid);
            }
            MapDone {
                map,
                done,
                segmented,
                failed,
                latency,
            }
        })
        .expect("a thread can be spawned")
}

/// Makes the masks of frames between keyframes as `voxpan run` does: fills the depth's holes
/// first when the perception node sent it unfilled, takes the map's instances at the filled
/// surface, and refines them on the measured depth.
struct Carrier {
    config: PerceptionConfig,
    refiner: MaskRefiner,
    filler: HoleFiller,
}

impl Carrier {
    fn new(config: PerceptionConfig) -> Self {
        Self {
            refiner: MaskRefiner::new(config.refine),
            filler: HoleFiller::new(config.fill.params()),
            config,
        }
    }

    /// The frame's masks; `measured`: its depth as measured when the frame's own is filled
    /// already, else the frame's depth is the measured one and is filled here first. As in
    /// `voxpan run`: looked up at the filled depth, refined on the measured one.
    fn masks(
        &mut self,
        map: &PanopticMap,
        frame: &mut voxpan_core::Frame,
        measured: Option<voxpan_core::DepthImage>,
    ) -> Result<voxpan_core::Segments, String> {
        let measured = measured.unwrap_or_else(|| {
            let measured = frame.depth.clone();
            if self.config.fill.enabled {
                self.filler.fill(&mut frame.depth);
            }
            measured
        });
        let mut segments = map.carried_segments(&frame.depth, &frame.intrinsics, &frame.pose);
        self.refiner
            .refine(&measured, &mut segments, &mut StageTimes::default())
            .map_err(|e| e.to_string())?;
        Ok(segments)
    }
}

/// What a running mapping stage hands its feeder: the world frame's name for the mesh
/// headers, its inbox, its thread, and its services (unadvertised when dropped).
pub(super) type Mapping = (
    Arc<Mutex<String>>,
    Arc<Mailbox<ToMap>>,
    std::thread::JoinHandle<MapDone>,
    Vec<ServiceServer>,
);

/// Advertises the mesh topic and starts the mapping thread (the map node and `both` alike).
pub(super) async fn start_mapping(
    node: &Node,
    options: &MapOptions,
    map: PanopticMap,
    log: &Log,
    runtime: &tokio::runtime::Handle,
) -> Result<Mapping, NodeError> {
    let frame_id = Arc::new(Mutex::new(String::from("world")));
    let mut mesh = MeshPublisher {
        publisher: node.advertise(&options.mesh_topic, 4).await?,
        ids: HashMap::new(),
        frame_id: frame_id.clone(),
        runtime: runtime.clone(),
    };
    // Advertised only when they will be sent.
    let mut costmap = match options.costmap_every {
        0 => None,
        _ => Some(CostmapPublisher {
            grid: node.advertise_latched(&options.costmap_topic, 2).await?,
            slice: node.advertise_latched(&options.esdf_slice_topic, 2).await?,
            max_distance: map.config().esdf.max_distance as f32,
            frame_id: frame_id.clone(),
            runtime: runtime.clone(),
        }),
    };
    let keeps_distances = map.config().esdf.enabled;
    let inbox = Arc::new(Mailbox::new(options.queue));
    let shared: SharedMap = Arc::new(Mutex::new(Some(map)));
    let mut services = Vec::new();
    {
        let (shared, path, log) = (shared.clone(), options.save.clone(), log.clone());
        let name = options.save_service();
        let service = node
            .service::<std_srvs::Trigger>(&name, "save", {
                let log = log.clone();
                move |_| {
                    let (success, message) = save_now(&shared, path.as_ref(), &log);
                    std_srvs::TriggerResponse { success, message }
                }
            })
            .await?;
        match service {
            Some(service) => services.push(service),
            None => {
                let saved = match &options.save {
                    Some(path) => {
                        format!("the map is saved to {} when the node stops", path.display())
                    }
                    None => "give --save PATH to keep the map".into(),
                };
                log(&format!("no {name} service on ROS 2: {saved}"));
            }
        }
    }
    if keeps_distances {
        let shared = shared.clone();
        let service = node
            .service::<voxpan_msgs::DistanceQuery>(
                &options.distance_service(),
                "distance",
                move |request| {
                    let mut guard = shared.lock().unwrap_or_else(|p| p.into_inner());
                    crate::query::distance_response(guard.as_mut(), &request.points)
                },
            )
            .await?;
        services.extend(service);
    }
    let worker = map_worker(
        shared,
        inbox.clone(),
        options.mesh_every,
        options.coloring,
        options.costmap_every,
        log.clone(),
        move |blocks| mesh.publish(blocks),
        move |grid| {
            if let Some(costmap) = &mut costmap {
                costmap.publish(grid);
            }
        },
    );
    Ok((frame_id, inbox, worker, services))
}

/// Runs the mapping node until `stop` is set; integrates what is queued, saves the map.
pub fn run_map(
    options: &MapOptions,
    map: PanopticMap,
    stop: Arc<AtomicBool>,
    log: Log,
) -> Result<(PanopticMap, NodeReport), NodeError> {
    let rt = runtime();
    let handle = rt.handle().clone();
    rt.block_on(async {
        let start = Instant::now();
        let c = &options.connection;
        let node = Node::connect(&c.middleware, &c.node_name, log.clone(), stop.clone()).await?;
        let (frame_id, inbox, worker, _services) =
            start_mapping(&node, options, map, &log, &handle).await?;
        let counters = Arc::new(Counters::logging(log.clone()));
        let (tx, mut rx) = mpsc::channel(64);
        let inputs = &options.inputs;
        let topics = [
            (MapInput::Depth, inputs.depth(), types::IMAGE),
            (MapInput::Color, inputs.color(), types::IMAGE),
            (
                MapInput::CameraInfo,
                inputs.camera_info(),
                types::CAMERA_INFO,
            ),
            (MapInput::Pose, inputs.pose(), types::POSE_STAMPED),
            (MapInput::Labels, inputs.labels(), types::IMAGE),
            (MapInput::Segments, inputs.segments(), types::STRING),
        ];
        let mut subscribed = Ok(());
        for (input, topic, ty) in &topics {
            subscribed = node
                .forward(
                    topic,
                    ty,
                    options.connection.subscriber_queue,
                    *input,
                    tx.clone(),
                    counters.clone(),
                )
                .await;
            if subscribed.is_err() {
                break;
            }
        }
        drop(tx);
        let mut report = NodeReport::default();
        if subscribed.is_ok() {
            log(&format!("map: listening on {}/*", inputs.prefix));
            let mut joiner = Joiner::new(node.wire());
            receive(&mut rx, &stop, |input, data, _| {
                if let Err(e) = joiner.add(input, data) {
                    let topic = topics.iter().find(|t| t.0 == input).map(|t| t.1.as_str());
                    counters.bad(topic.unwrap_or("?"), e);
                }
                let (ready, given_up) = joiner.take_ready();
                for (item, world) in ready {
                    report.frames_in += 1;
                    *frame_id.lock().expect("no panics while held") = world;
                    inbox.put_dropping_first(item, ToMap::is_carried);
                }
                for u in given_up {
                    log(&format!(
                        "frame at {} s given up: {}",
                        voxpan_bag::fmt_time(u.stamp_ns),
                        u.reason
                    ));
                    report.unpaired.push(u);
                }
            })
            .await;
        }
        node.shutting_down();
        finish_counters(&mut report, &counters);
        inbox.close();
        let done = tokio::task::spawn_blocking(move || worker.join())
            .await
            .expect("the join task runs")
            .expect("the mapping thread does not panic");
        subscribed?;
        report.frames_done = done.done;
        report.keyframes = Some(done.segmented);
        report.failed = done.failed;
        report.latency_ms = done.latency;
        report.dropped_busy = inbox.dropped();
        report.seconds = start.elapsed().as_secs_f64();
        save(&done.map, options.save.as_ref(), &log)?;
        Ok((done.map, report))
    })
}
