//! The nodes: `perceive` (camera topics in; filled depth, refined masks and the frame's
//! camera, pose and colour out, stamped like the depth image), `map` (those in; the map,
//! whose mesh goes out as RViz markers, changed blocks only) and both in one process.
//!
//! Threads: a tokio runtime receives and sends (roslibrust's tasks on ROS 1; on ROS 2 zenoh's
//! callbacks feed it); perception and integration each run
//! on their own thread behind a [`Mailbox`] that drops the oldest frame when they fall behind
//! (counted in [`NodeReport`]), so no queue grows without bound.

//!
//! Rooms: [`options`] (what each node is told), [`report`] (what it did), [`perceive`] (the
//! perception node and its thread), [`map`] (the mapping thread and node), [`join`] (frames
//! joined by stamp from the perception node's messages), [`publish`] (the nodes' publishers),
//! [`save`] (the map saved on request and at exit); here what they share and [`run_both`].

mod join;
mod map;
mod options;
mod perceive;
mod publish;
mod report;
mod save;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use tokio::sync::mpsc;
use voxpan_core::{DepthImage, Frame, Segments};
use voxpan_map::PanopticMap;
use voxpan_perception::{Perception, PerceptionConfig};

use self::map::start_mapping;
use self::perceive::{camera_inputs, perception_worker};
use self::save::save;
use crate::mailbox::Mailbox;
use crate::transport::{Counters, Middleware, Node};

pub use map::run_map;
pub use options::{MapOptions, Outputs, PerceiveOptions};
pub use perceive::run_perceive;
pub use report::NodeReport;

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
    /// A frame between keyframes, whose masks the map renders.
    carry: Option<Carry>,
    received_unix_ns: i64,
    /// The perception node's label table, when it sent one.
    class_names: Option<std::collections::BTreeMap<u32, String>>,
}

impl ToMap {
    /// A frame between keyframes: dropped first when the mapping thread falls behind.
    fn is_carried(&self) -> bool {
        self.carry.is_some()
    }
}

/// A frame between keyframes: no masks of its own. The mapping thread renders the map's at
/// its pose, refines them on its measured depth and fills the depth's holes as perception
/// does, so that the map is the one `voxpan run` makes with the same keyframes.
struct Carry {
    /// The perception node's `[refine]` and `[fill]`.
    config: PerceptionConfig,
    /// The depth as measured, when the frame's own depth is already filled (both stages in
    /// one process); `None`: the frame's depth is the measured one, filled once the masks are
    /// refined (the perception node sends it so, rather than both).
    measured: Option<DepthImage>,
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

fn finish_counters(report: &mut NodeReport, counters: &Counters) {
    report.dropped_lagged = counters.lagged.load(Ordering::Relaxed);
    report.bad_messages = counters.bad.load(Ordering::Relaxed);
    report.bad_examples = counters
        .bad_examples
        .lock()
        .expect("no panics while held")
        .clone();
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
            let config = *perception.config();
            perception_worker(perception, inbox.clone(), log.clone(), move |a, p| {
                *frame_id.lock().expect("no panics while held") = a.world_frame.clone();
                let item = ToMap {
                    frame: p.frame,
                    segments: p.segments,
                    carry: p.measured_depth.map(|measured| Carry {
                        config,
                        measured: Some(measured),
                    }),
                    received_unix_ns: a.received_unix_ns,
                    class_names: None,
                };
                map_inbox.put_dropping_first(item, ToMap::is_carried);
            })
        };
        let counters = Arc::new(Counters::logging(log.clone()));
        let mut report = NodeReport::default();
        let received =
            camera_inputs(&node, perceive, &inbox, &stop, &log, &counters, &mut report).await;
        node.shutting_down();
        finish_counters(&mut report, &counters);
        inbox.close();
        let perceived = tokio::task::spawn_blocking(move || perception_thread.join())
            .await
            .expect("the join task runs")
            .expect("the perception thread does not panic");
        let mut failed = perceived.failed;
        map_inbox.close();
        let done = tokio::task::spawn_blocking(move || map_thread.join())
            .await
            .expect("the join task runs")
            .expect("the mapping thread does not panic");
        received?;
        failed.extend(done.failed);
        report.frames_done = done.done;
        report.keyframes = Some(done.segmented);
        report.failed = failed;
        report.latency_ms = done.latency;
        report.dropped_busy = inbox.dropped() + map_inbox.dropped();
        report.seconds = start.elapsed().as_secs_f64();
        save(&done.map, options.save.as_ref(), &log)?;
        Ok((done.map, report))
    })
}
