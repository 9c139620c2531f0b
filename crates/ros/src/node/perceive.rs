//! The perception node: camera topics in, frames assembled, perceived on their own thread,
//! and sent on as the mapping node's inputs.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use tokio::sync::mpsc;
use voxpan_bag::assemble::{Assembled, Assembler, Input};
use voxpan_core::Frame;
use voxpan_perception::{Perceived, Perception};

use super::publish::PerceivePublishers;
use super::{
    Log, NodeError, NodeReport, PerceiveOptions, finish_counters, receive, runtime, unix_ns,
};
use crate::mailbox::Mailbox;
use crate::transport::{Counters, Node};

/// What the perception thread did: frames done, keyframes among them, failures, latencies.
pub(super) struct PerceptionDone {
    pub(super) done: u64,
    pub(super) keyframes: u64,
    pub(super) failed: Vec<String>,
    pub(super) latency: Vec<f64>,
}

/// Perception on its own thread: takes assembled frames, hands each result to `output`. The
/// segmenter runs on this thread, refinement on rayon's pool beside the mapper's integration.
pub(super) fn perception_worker(
    mut perception: Perception,
    inbox: Arc<Mailbox<Assembled>>,
    log: Log,
    mut output: impl FnMut(&Assembled, Perceived) + Send + 'static,
) -> std::thread::JoinHandle<PerceptionDone> {
    std::thread::Builder::new()
        .name("voxpan-perceive".into())
        .spawn(move || {
            let (mut done, mut keyframes) = (0, 0);
            let (mut failed, mut latency) = (Vec::new(), Vec::new());
            while let Some(mut a) = inbox.take() {
                let frame = std::mem::replace(&mut a.frame, empty_frame());
                let id = frame.id.clone();
                match perception.process_on_workers(frame) {
                    Ok(p) => {
                        keyframes += u64::from(p.keyframe);
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
            PerceptionDone {
                done,
                keyframes,
                failed,
                latency,
            }
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

/// Subscribes the camera inputs and assembles frames into `inbox`.
pub(super) async fn camera_inputs(
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
            PerceivePublishers::new(
                &node,
                &options.outputs,
                options.class_names.clone(),
                *perception.config(),
            )
            .await?,
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
        let done = tokio::task::spawn_blocking(move || worker.join())
            .await
            .expect("the join task runs")
            .expect("the perception thread does not panic");
        received?;
        report.frames_done = done.done;
        report.keyframes = Some(done.keyframes);
        report.failed = done.failed;
        report.latency_ms = done.latency;
        report.dropped_busy = inbox.dropped();
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    })
}
