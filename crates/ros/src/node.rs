//! The nodes: `perceive` (camera topics in; filled depth, refined masks and the frame's
//! camera, pose and colour out, stamped like the depth image), `map` (those in; the map,
//! whose mesh goes out as RViz markers, changed blocks only) and both in one process.
//!
//! Threads: a tokio runtime receives and sends (roslibrust's tasks on ROS 1; on ROS 2 zenoh's
//! callbacks feed it); perception and integration each run
//! on their own thread behind a [`Mailbox`] that drops the oldest frame when they fall behind
//! (counted in [`NodeReport`]), so no queue grows without bound.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use roslibrust::ros1::ServiceServer;
use tokio::sync::mpsc;
use voxpan_bag::BagOptions;
use voxpan_bag::live::Wire;
use voxpan_core::{Frame, Segments};
use voxpan_map::{BlockIndex, Coloring, PanopticMap};
use voxpan_perception::{Perceived, Perception};

use crate::mailbox::Mailbox;
use crate::msgs::{
    geometry_msgs, nav_msgs, sensor_msgs, std_msgs, std_srvs, visualization_msgs, voxpan_msgs,
};
use crate::rmw_zenoh::types;
use crate::transport::{Counters, Middleware, Node, Outlet};
use crate::{encode, inbound};
use voxpan_bag::assemble::{Assembled, Assembler, Input, Unpaired};

/// Why a node could not run.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error("ROS master {uri}: {message}")]
    Master { uri: String, message: String },
    #[error("ROS 2 (zenoh): {message}")]
    Ros2 { message: String },
    #[error("topic {topic}: {message}")]
    Topic { topic: String, message: String },
    #[error("saving the map to {}: {source}", path.display())]
    Save {
        path: PathBuf,
        #[source]
        source: voxpan_map::MapError,
    },
}

/// Where a node connects and what it calls itself.
#[derive(Clone, Debug)]
pub struct Connection {
    /// ROS 1's master or ROS 2's zenoh endpoints.
    pub middleware: Middleware,
    pub node_name: String,
    /// Messages each subscription holds before the oldest are skipped (counted as lagged).
    pub subscriber_queue: usize,
}

/// The perception node's outputs (and the mapping node's inputs), under one prefix.
#[derive(Clone, Debug)]
pub struct Outputs {
    pub prefix: String,
}

impl Outputs {
    pub fn topic(&self, name: &str) -> String {
        format!("{}/{name}", self.prefix.trim_end_matches('/'))
    }
    pub fn depth(&self) -> String {
        self.topic("depth")
    }
    pub fn color(&self) -> String {
        self.topic("color")
    }
    pub fn camera_info(&self) -> String {
        self.topic("camera_info")
    }
    pub fn pose(&self) -> String {
        self.topic("pose")
    }
    pub fn labels(&self) -> String {
        self.topic("segments/image")
    }
    pub fn segments(&self) -> String {
        self.topic("segments/labels")
    }
}

impl Default for Outputs {
    fn default() -> Self {
        Self {
            prefix: "/voxpan".into(),
        }
    }
}

/// The perception node: camera topics as the bag reader names them ([`BagOptions`]), masks
/// from its label topics (`masks_from_topics`) or from the perception stage's segmenter.
#[derive(Clone, Debug)]
pub struct PerceiveOptions {
    pub connection: Connection,
    pub inputs: BagOptions,
    pub masks_from_topics: bool,
    pub outputs: Outputs,
    /// Frames waiting for perception before the oldest is dropped.
    pub queue: usize,
    /// The names of the segments' class ids (the network's label table, or `--classes`),
    /// sent with every segment list so that the mapping node's map names its classes.
    pub class_names: std::collections::BTreeMap<u32, String>,
}

/// The mapping node.
#[derive(Clone, Debug)]
pub struct MapOptions {
    pub connection: Connection,
    pub inputs: Outputs,
    /// visualization_msgs/MarkerArray of the changed blocks' meshes.
    pub mesh_topic: String,
    /// Re-mesh and publish every this many integrated frames (and at the end); 0: never.
    pub mesh_every: usize,
    pub coloring: Coloring,
    /// nav_msgs/OccupancyGrid of the costmap cut from the distance field.
    pub costmap_topic: String,
    /// sensor_msgs/PointCloud2 of the costmap's clearance (a `distance` per known cell),
    /// published with the costmap.
    pub esdf_slice_topic: String,
    /// Update the distance field and publish the costmap every this many integrated frames
    /// (and at the end); 0: never. The map should be built with `[esdf] enabled`, which
    /// allocates the free space the costmap's free cells come from.
    pub costmap_every: usize,
    /// Frames waiting for integration before the oldest is dropped.
    pub queue: usize,
    /// Where the map is saved when the node stops, and on each call of the save service
    /// (std_srvs/Trigger `PREFIX/save_map`).
    pub save: Option<PathBuf>,
}

impl MapOptions {
    /// The std_srvs/Trigger service that saves the map now (to `save`).
    pub fn save_service(&self) -> String {
        self.inputs.topic("save_map")
    }

    /// The voxpan_msgs/DistanceQuery service answering distances and gradients at points
    /// (ROS 1; offered when the map keeps a distance field).
    pub fn distance_service(&self) -> String {
        self.inputs.topic("distance")
    }
}

/// What a node did.
#[derive(Clone, Debug, Default)]
pub struct NodeReport {
    /// Frames that reached the node's worker (assembled or joined).
    pub frames_in: u64,
    /// Frames perceived (perception node) or integrated (mapping node).
    pub frames_done: u64,
    /// Frames dropped because the worker was busy (the mailbox was full).
    pub dropped_busy: u64,
    /// Messages skipped because the node read them too slowly (subscription queues full).
    pub dropped_lagged: u64,
    /// Depth images that found no partner in time, with why.
    pub unpaired: Vec<Unpaired>,
    /// Messages that could not be decoded, with the first few reasons.
    pub bad_messages: u64,
    pub bad_examples: Vec<String>,
    /// Frames the worker failed on.
    pub failed: Vec<String>,
    /// Milliseconds from the perception node receiving a depth image to the frame being
    /// integrated (mapping node; same host clock) or perceived and sent (perception node).
    pub latency_ms: Vec<f64>,
    pub seconds: f64,
}

impl NodeReport {
    /// Frames per second done over the node's life.
    pub fn fps(&self) -> f64 {
        if self.seconds > 0.0 {
            self.frames_done as f64 / self.seconds
        } else {
            0.0
        }
    }

    /// Share of frames lost to back-pressure (busy or lagged) among those offered.
    pub fn drop_rate(&self) -> f64 {
        let lost = self.dropped_busy + self.dropped_lagged;
        let offered = self.frames_in + self.dropped_lagged;
        if offered == 0 {
            0.0
        } else {
            lost as f64 / offered as f64
        }
    }

    pub fn summary(&self) -> String {
        let mut lat = self.latency_ms.clone();
        lat.sort_by(f64::total_cmp);
        let pct = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
        let latency = if lat.is_empty() {
            "no latency (no frame done)".to_owned()
        } else {
            format!("latency median {:.1} ms, p95 {:.1} ms", pct(0.5), pct(0.95))
        };
        format!(
            "{} frames in, {} done ({:.1} frames/s), dropped {} busy + {} lagged ({:.1} %), \
             {} unpaired, {} bad messages, {} failed; {latency}",
            self.frames_in,
            self.frames_done,
            self.fps(),
            self.dropped_busy,
            self.dropped_lagged,
            self.drop_rate() * 100.0,
            self.unpaired.len(),
            self.bad_messages,
            self.failed.len(),
        )
    }
}

/// Unix time in nanoseconds.
pub fn unix_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

/// How a node reports progress (one line per event worth a line).
pub type Log = Arc<dyn Fn(&str) + Send + Sync>;

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        // Receiving and sending only: the heavy work has its own threads.
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a tokio runtime can be built")
}

/// A frame perceived, on its way to integration.
struct ToMap {
    frame: Frame,
    segments: Option<Segments>,
    received_unix_ns: i64,
    /// The perception node's label table, when it sent one.
    class_names: Option<std::collections::BTreeMap<u32, String>>,
}

/// Perception on its own thread: takes assembled frames, hands each result to `output`. The
/// segmenter runs on this thread, refinement on rayon's pool beside the mapper's integration.
fn perception_worker(
    mut perception: Perception,
    inbox: Arc<Mailbox<Assembled>>,
    log: Log,
    mut output: impl FnMut(&Assembled, Perceived) + Send + 'static,
) -> std::thread::JoinHandle<(u64, Vec<String>, Vec<f64>)> {
    std::thread::Builder::new()
        .name("voxpan-perceive".into())
        .spawn(move || {
            let (mut done, mut failed, mut latency) = (0, Vec::new(), Vec::new());
            while let Some(mut a) = inbox.take() {
                let frame = std::mem::replace(&mut a.frame, empty_frame());
                let id = frame.id.clone();
                match perception.process_on_workers(frame) {
                    Ok(p) => {
                        output(&a, p);
                        done += 1;
                        latency.push((unix_ns() - a.received_unix_ns) as f64 / 1e6);
                    }
                    Err(e) => {
                        let line = format!(
                            "frame {id} (stamp {} s): {e}",
                            voxpan_bag::fmt_time(a.stamp_ns)
                        );
                        log(&line);
                        failed.push(line);
                    }
                }
            }
            (done, failed, latency)
        })
        .expect("a thread can be spawned")
}

fn empty_frame() -> Frame {
    Frame {
        id: String::new(),
        timestamp: 0.0,
        color: voxpan_core::Image::filled(0, 0, [0; 3]),
        depth: voxpan_core::Image::filled(0, 0, 0.0),
        pose: voxpan_core::Pose::identity(),
        intrinsics: voxpan_core::Intrinsics {
            width: 0,
            height: 0,
            fx: 1.0,
            fy: 1.0,
            cx: 0.0,
            cy: 0.0,
        },
        segments: None,
        ground_truth: None,
    }
}

/// The map while the mapping thread integrates: shared with the save service, which saves it
/// between two frames. `None` once the thread has handed it back.
type SharedMap = Arc<Mutex<Option<PanopticMap>>>;

/// What the mapping thread hands back.
struct MapDone {
    map: PanopticMap,
    done: u64,
    failed: Vec<String>,
    latency: Vec<f64>,
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
            while let Some(item) = inbox.take() {
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
                match map.integrate(f, item.segments.as_ref()) {
                    Ok(_) => {
                        done += 1;
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
                failed,
                latency,
            }
        })
        .expect("a thread can be spawned")
}

/// Sends block meshes as one MarkerArray; marker ids stay fixed per block so a re-sent block
/// replaces its old triangles in RViz.
struct MeshPublisher {
    publisher: Outlet<visualization_msgs::MarkerArray>,
    ids: HashMap<BlockIndex, i32>,
    frame_id: Arc<Mutex<String>>,
    runtime: tokio::runtime::Handle,
}

impl MeshPublisher {
    fn publish(&mut self, blocks: Vec<(BlockIndex, Option<voxpan_core::Mesh>)>) {
        let frame_id = self.frame_id.lock().expect("no panics while held").clone();
        let header = encode::header(unix_ns(), &frame_id);
        let mut markers = Vec::with_capacity(blocks.len());
        for (block, mesh) in blocks {
            let next = self.ids.len() as i32;
            let id = *self.ids.entry(block).or_insert(next);
            markers.push(encode::block_marker(
                header.clone(),
                "voxpan_mesh",
                id,
                mesh.as_ref(),
            ));
        }
        let msg = visualization_msgs::MarkerArray { markers };
        // A publish fails only when the node is shutting down; the map is saved regardless.
        let _ = self.runtime.block_on(self.publisher.publish(&msg));
    }
}

/// Sends the costmap as a nav_msgs/OccupancyGrid in the world frame, and its clearance as a
/// sensor_msgs/PointCloud2 (distances capped at `max_distance`).
struct CostmapPublisher {
    grid: Outlet<nav_msgs::OccupancyGrid>,
    slice: Outlet<sensor_msgs::PointCloud2>,
    max_distance: f32,
    frame_id: Arc<Mutex<String>>,
    runtime: tokio::runtime::Handle,
}

impl CostmapPublisher {
    fn publish(&mut self, costmap: voxpan_map::Costmap) {
        let frame_id = self.frame_id.lock().expect("no panics while held").clone();
        let header = encode::header(unix_ns(), &frame_id);
        let grid = encode::occupancy_grid(header.clone(), &costmap);
        let slice = encode::esdf_slice(header, &costmap, self.max_distance);
        // As the mesh: a publish fails only when the node is shutting down.
        let _ = self.runtime.block_on(self.grid.publish(&grid));
        let _ = self.runtime.block_on(self.slice.publish(&slice));
    }
}

/// Receives `(input, message, arrival)` until `stop`; `handle` sees each one.
async fn receive<K: Copy>(
    rx: &mut mpsc::Receiver<(K, Bytes, i64)>,
    stop: &AtomicBool,
    mut handle: impl FnMut(K, &[u8], i64),
) {
    loop {
        tokio::select! {
            m = rx.recv() => match m {
                Some((k, data, at)) => handle(k, &data, at),
                None => break,
            },
            _ = tokio::time::sleep(Duration::from_millis(50)) => {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
            }
        }
    }
}

/// Subscribes the camera inputs and assembles frames into `inbox`.
async fn camera_inputs(
    node: &Node,
    options: &PerceiveOptions,
    inbox: &Mailbox<Assembled>,
    stop: &AtomicBool,
    log: &Log,
    counters: &Arc<Counters>,
    report: &mut NodeReport,
) -> Result<(), NodeError> {
    let mut assembler = Assembler::new(
        options.inputs.clone(),
        options.masks_from_topics,
        node.wire(),
    );
    let (tx, mut rx) = mpsc::channel(64);
    for input in Input::ALL {
        if let Some(topic) = assembler.topic(input) {
            let topic = topic.to_owned();
            node.forward(
                &topic,
                &crate::rmw_zenoh::input_type(input),
                options.connection.subscriber_queue,
                input,
                tx.clone(),
                counters.clone(),
            )
            .await?;
        }
    }
    drop(tx);
    log(&format!(
        "perceive: listening on {} and {}",
        options.inputs.color_topic, options.inputs.depth_topic
    ));
    receive(&mut rx, stop, |input, data, at| {
        if let Err(e) = assembler.add(input, data, at) {
            let topic = assembler.topic(input).unwrap_or("?").to_owned();
            counters.bad(&topic, e);
        }
        if let Some(warning) = assembler.take_warning() {
            log(&format!("warning: {warning}"));
        }
        for ready in assembler.take_ready() {
            match ready {
                Ok(a) => {
                    report.frames_in += 1;
                    inbox.put(a);
                }
                Err(u) => {
                    log(&format!(
                        "depth image at {} s given up: {}",
                        voxpan_bag::fmt_time(u.stamp_ns),
                        u.reason
                    ));
                    report.unpaired.push(u);
                }
            }
        }
    })
    .await;
    Ok(())
}

fn finish_counters(report: &mut NodeReport, counters: &Counters) {
    report.dropped_lagged = counters.lagged.load(Ordering::Relaxed);
    report.bad_messages = counters.bad.load(Ordering::Relaxed);
    report.bad_examples = counters
        .bad_examples
        .lock()
        .expect("no panics while held")
        .clone();
}

/// Publishers of the perception node's outputs.
struct PerceivePublishers {
    class_names: std::collections::BTreeMap<u32, String>,
    depth: Outlet<sensor_msgs::Image>,
    color: Outlet<sensor_msgs::Image>,
    info: Outlet<sensor_msgs::CameraInfo>,
    pose: Outlet<geometry_msgs::PoseStamped>,
    labels: Outlet<sensor_msgs::Image>,
    segments: Outlet<std_msgs::String>,
}

impl PerceivePublishers {
    async fn new(
        node: &Node,
        out: &Outputs,
        class_names: std::collections::BTreeMap<u32, String>,
    ) -> Result<Self, NodeError> {
        // Deep enough for a few frames in flight to a peer that reads them a little late.
        let q = 8;
        Ok(Self {
            class_names,
            depth: node.advertise(&out.depth(), q).await?,
            color: node.advertise(&out.color(), q).await?,
            info: node.advertise(&out.camera_info(), q).await?,
            pose: node.advertise(&out.pose(), q).await?,
            labels: node.advertise(&out.labels(), q).await?,
            segments: node.advertise(&out.segments(), q).await?,
        })
    }

    /// The frame's messages, all stamped with its depth stamp; the segment list goes last:
    /// the mapping node's sign that the frame is complete.
    async fn publish(&self, a: &Assembled, p: &Perceived) -> Result<(), String> {
        let header = |frame_id: &str| encode::header(a.stamp_ns, frame_id);
        let camera = a.camera_frame.as_str();
        let f = &p.frame;
        self.depth
            .publish(&encode::depth_image(header(camera), &f.depth))
            .await?;
        self.color
            .publish(&encode::color_image(header(camera), &f.color))
            .await?;
        self.info
            .publish(&encode::camera_info(header(camera), &f.intrinsics))
            .await?;
        self.pose
            .publish(&encode::pose_stamped(header(&a.world_frame), &f.pose))
            .await?;
        if let Some(s) = &p.segments {
            self.labels
                .publish(&encode::label_image(header(camera), &s.labels))
                .await
                .map_err(|e| e.to_string())?;
        }
        let list = p.segments.as_ref().map(|s| s.segments.as_slice());
        self.segments
            .publish(&encode::segment_list(
                a.stamp_ns,
                camera,
                list,
                a.received_unix_ns,
                &self.class_names,
            ))
            .await?;
        Ok(())
    }
}

/// Runs the perception node until `stop` is set.
pub fn run_perceive(
    options: &PerceiveOptions,
    perception: Perception,
    stop: Arc<AtomicBool>,
    log: Log,
) -> Result<NodeReport, NodeError> {
    let rt = runtime();
    let handle = rt.handle().clone();
    rt.block_on(async {
        let start = Instant::now();
        let c = &options.connection;
        let node = Node::connect(&c.middleware, &c.node_name, log.clone(), stop.clone()).await?;
        let publishers = Arc::new(
            PerceivePublishers::new(&node, &options.outputs, options.class_names.clone()).await?,
        );
        let inbox = Arc::new(Mailbox::new(options.queue));
        let counters = Arc::new(Counters::logging(log.clone()));
        let worker = {
            let log2 = log.clone();
            perception_worker(perception, inbox.clone(), log.clone(), move |a, p| {
                if let Err(e) = handle.block_on(publishers.publish(a, &p)) {
                    log2(&format!("frame {}: not published: {e}", p.frame.id));
                }
            })
        };
        let mut report = NodeReport::default();
        let received =
            camera_inputs(&node, options, &inbox, &stop, &log, &counters, &mut report).await;
        node.shutting_down();
        // Counted now: what still arrives while the workers finish is not the run's.
        finish_counters(&mut report, &counters);
        inbox.close();
        let (done, failed, latency) = tokio::task::spawn_blocking(move || worker.join())
            .await
            .expect("the join task runs")
            .expect("the perception thread does not panic");
        received?;
        report.frames_done = done;
        report.failed = failed;
        report.latency_ms = latency;
        report.dropped_busy = inbox.dropped();
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    })
}

/// Partial frames of the mapping node, by stamp.
#[derive(Default)]
struct Partial {
    depth: Option<voxpan_core::DepthImage>,
    color: Option<voxpan_core::ColorImage>,
    intrinsics: Option<voxpan_core::Intrinsics>,
    pose: Option<(String, voxpan_core::Pose)>,
    labels: Option<voxpan_core::LabelImage>,
    /// `Some(None)`: the frame has no masks.
    list: Option<inbound::SegmentList>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum MapInput {
    Depth,
    Color,
    CameraInfo,
    Pose,
    Labels,
    Segments,
}

/// Frames the perception node's messages make, joined by stamp.
struct Joiner {
    partial: std::collections::BTreeMap<i64, Partial>,
    next_id: usize,
    wire: Wire,
}

/// Partial frames kept at most; the oldest is given up first.
const MAX_PARTIAL: usize = 64;

impl Joiner {
    fn new(wire: Wire) -> Self {
        Self {
            partial: Default::default(),
            next_id: 0,
            wire,
        }
    }

    fn add(&mut self, input: MapInput, data: &[u8]) -> Result<(), String> {
        match input {
            MapInput::Depth => {
                let (h, d) = voxpan_bag::live::depth_image(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().depth = Some(d);
            }
            MapInput::Color => {
                let (h, c) = voxpan_bag::live::color_image(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().color = Some(c);
            }
            MapInput::CameraInfo => {
                let (h, k, _) = voxpan_bag::live::camera_info(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().intrinsics = Some(k);
            }
            MapInput::Pose => {
                let (h, p) = voxpan_bag::live::pose_stamped(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().pose = Some((h.frame_id, p));
            }
            MapInput::Labels => {
                let (h, l) = voxpan_bag::live::label_image(self.wire, data)?;
                self.partial.entry(h.stamp_ns).or_default().labels = Some(l);
            }
            MapInput::Segments => {
                let list = inbound::segment_list(self.wire, data)?;
                let t = list.stamp_ns;
                self.partial.entry(t).or_default().list = Some(list);
            }
        }
        Ok(())
    }

    /// Complete frames in stamp order (with the world frame's name and the perception node's
    /// arrival time), and stamps given up.
    fn take_ready(&mut self) -> (Vec<(ToMap, String)>, Vec<Unpaired>) {
        let mut ready = Vec::new();
        let mut given_up = Vec::new();
        let complete: Vec<i64> = self
            .partial
            .iter()
            .filter(|(_, p)| {
                let masks_ok = match &p.list {
                    Some(l) => l.segments.is_none() || p.labels.is_some(),
                    None => false,
                };
                masks_ok
                    && p.depth.is_some()
                    && p.color.is_some()
                    && p.intrinsics.is_some()
                    && p.pose.is_some()
            })
            .map(|(t, _)| *t)
            .collect();
        for t in complete {
            // Older incomplete frames will not complete now that a newer one has.
            let older: Vec<i64> = self.partial.range(..t).map(|(s, _)| *s).collect();
            for s in older {
                self.partial.remove(&s);
                given_up.push(Unpaired {
                    stamp_ns: s,
                    reason: "some of its messages never arrived".into(),
                });
            }
            let p = self.partial.remove(&t).expect("listed");
            let list = p.list.expect("complete");
            let (world, pose) = p.pose.expect("complete");
            let segments = list.segments.map(|segments| Segments {
                labels: p.labels.expect("complete"),
                segments,
            });
            let frame = Frame {
                id: format!("{:06}", self.next_id),
                timestamp: t as f64 / 1e9,
                color: p.color.expect("complete"),
                depth: p.depth.expect("complete"),
                pose,
                intrinsics: p.intrinsics.expect("complete"),
                segments: None,
                ground_truth: None,
            };
            self.next_id += 1;
            ready.push((
                ToMap {
                    frame,
                    segments,
                    received_unix_ns: list.received_unix_ns,
                    class_names: list.class_names,
                },
                world,
            ));
        }
        while self.partial.len() > MAX_PARTIAL {
            let (s, _) = self.partial.pop_first().expect("non-empty");
            given_up.push(Unpaired {
                stamp_ns: s,
                reason: format!("more than {MAX_PARTIAL} frames incomplete"),
            });
        }
        (ready, given_up)
    }
}

/// Saves the map where asked, then reports.
fn save(map: &PanopticMap, path: Option<&PathBuf>, log: &Log) -> Result<(), NodeError> {
    if let Some(path) = path {
        map.save(path).map_err(|source| NodeError::Save {
            path: path.clone(),
            source,
        })?;
        log(&format!("map saved to {}", path.display()));
    }
    Ok(())
}

/// What a running mapping stage hands its feeder: the world frame's name for the mesh
/// headers, its inbox, its thread, and its services (unadvertised when dropped).
type Mapping = (
    Arc<Mutex<String>>,
    Arc<Mailbox<ToMap>>,
    std::thread::JoinHandle<MapDone>,
    Vec<ServiceServer>,
);

/// The save service's answer: the map saved to `--save` between two frames (atomically, as at
/// exit), or why not.
fn save_now(shared: &SharedMap, path: Option<&PathBuf>, log: &Log) -> (bool, String) {
    let Some(path) = path else {
        return (
            false,
            "no --save PATH was given to this node: nowhere to save".into(),
        );
    };
    // Serialised under the lock (in memory), written after it is released, so that a slow
    // disk stalls neither integration nor the mailbox.
    let (bytes, instances) = {
        let guard = shared.lock().unwrap_or_else(|p| p.into_inner());
        let Some(map) = guard.as_ref() else {
            return (
                false,
                "the node is stopping; the map is saved as it exits".into(),
            );
        };
        (map.to_bytes(), map.instance_count())
    };
    match voxpan_io::write_atomically(path, |out| out.write_all(&bytes)) {
        Ok(()) => {
            let line = format!(
                "map saved to {} ({instances} instances) on request",
                path.display()
            );
            log(&line);
            (true, line)
        }
        Err(e) => (false, format!("cannot save the map: {e}")),
    }
}

/// Advertises the mesh topic and starts the mapping thread (the map node and `both` alike).
async fn start_mapping(
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
                    inbox.put(item);
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
        report.failed = done.failed;
        report.latency_ms = done.latency;
        report.dropped_busy = inbox.dropped();
        report.seconds = start.elapsed().as_secs_f64();
        save(&done.map, options.save.as_ref(), &log)?;
        Ok((done.map, report))
    })
}

/// Both nodes in one process: camera topics in, perception, integration, mesh out; no ROS
/// between the two stages.
pub fn run_both(
    perceive: &PerceiveOptions,
    options: &MapOptions,
    perception: Perception,
    map: PanopticMap,
    stop: Arc<AtomicBool>,
    log: Log,
) -> Result<(PanopticMap, NodeReport), NodeError> {
    let rt = runtime();
    let handle = rt.handle().clone();
    rt.block_on(async {
        let start = Instant::now();
        let c = &perceive.connection;
        let node = Node::connect(&c.middleware, &c.node_name, log.clone(), stop.clone()).await?;
        let (frame_id, map_inbox, map_thread, _services) =
            start_mapping(&node, options, map, &log, &handle).await?;
        let inbox = Arc::new(Mailbox::new(perceive.queue));
        let perception_thread = {
            let map_inbox = map_inbox.clone();
            perception_worker(perception, inbox.clone(), log.clone(), move |a, p| {
                *frame_id.lock().expect("no panics while held") = a.world_frame.clone();
                map_inbox.put(ToMap {
                    frame: p.frame,
                    segments: p.segments,
                    received_unix_ns: a.received_unix_ns,
                    class_names: None,
                });
            })
        };
        let counters = Arc::new(Counters::logging(log.clone()));
        let mut report = NodeReport::default();
        let received =
            camera_inputs(&node, perceive, &inbox, &stop, &log, &counters, &mut report).await;
        node.shutting_down();
        finish_counters(&mut report, &counters);
        inbox.close();
        let (_, mut failed, _) = tokio::task::spawn_blocking(move || perception_thread.join())
            .await
            .expect("the join task runs")
            .expect("the perception thread does not panic");
        map_inbox.close();
        let done = tokio::task::spawn_blocking(move || map_thread.join())
            .await
            .expect("the join task runs")
            .expect("the mapping thread does not panic");
        received?;
        failed.extend(done.failed);
        report.frames_done = done.done;
        report.failed = failed;
        report.latency_ms = done.latency;
        report.dropped_busy = inbox.dropped() + map_inbox.dropped();
        report.seconds = start.elapsed().as_secs_f64();
        save(&done.map, options.save.as_ref(), &log)?;
        Ok((done.map, report))
    })
}
