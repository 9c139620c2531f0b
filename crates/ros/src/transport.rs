//! The nodes' middleware, ROS 1 or ROS 2, behind one small interface: connect, subscribe a
//! topic as raw message bodies, advertise a typed publisher, and (ROS 1) offer the save
//! service. The nodes' logic above it is the same for both; only the bodies' serialisation
//! differs ([`Wire`]), and the decoders take it as a parameter.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use bytes::Bytes;
use roslibrust::RosMessageType;
use roslibrust::ros1::{Publisher, ServiceServer, SubscriberAny};
use tokio::sync::mpsc;
use voxpan_bag::live::Wire;

use crate::cdr::Ros2Message;
use crate::node::{Log, NodeError, unix_ns};
use crate::rmw_zenoh::RosType;
use crate::ros1::Ros1Node;

/// Which ROS, and where its peers are.
#[derive(Clone, Debug)]
pub enum Middleware {
    /// ROS 1: the master's `http://HOST:PORT` (ROS_MASTER_URI).
    Ros1 { master_uri: String },
    /// ROS 2 over rmw_zenoh's wire format (needs the crate feature `ros2`).
    Ros2(Ros2Options),
}

/// Where a ROS 2 node connects: rmw_zenoh's session settings.
#[derive(Clone, Debug)]
pub struct Ros2Options {
    /// Zenoh endpoints to connect to (the router), e.g. `tcp/127.0.0.1:7447`.
    pub connect: Vec<String>,
    /// Endpoints this node listens on for peers (`tcp/127.0.0.1:0`: any port on loopback).
    pub listen: Vec<String>,
    /// ROS_DOMAIN_ID.
    pub domain: u32,
}

impl Default for Ros2Options {
    /// rmw_zenoh's default session configuration.
    fn default() -> Self {
        Self {
            connect: vec!["tcp/localhost:7447".into()],
            listen: vec!["tcp/localhost:0".into()],
            domain: 0,
        }
    }
}

impl Ros2Options {
    /// The endpoints parse as zenoh endpoints (`tcp/HOST:PORT`); the error names the option.
    /// Checked before a node loads its network or map.
    pub fn check(&self) -> Result<(), String> {
        #[cfg(feature = "ros2")]
        for (option, list) in [
            ("--zenoh-connect", &self.connect),
            ("--zenoh-listen", &self.listen),
        ] {
            for endpoint in list {
                endpoint
                    .parse::<zenoh::config::EndPoint>()
                    .map_err(|e| format!("{option} {endpoint}: not a zenoh endpoint: {e}"))?;
            }
        }
        Ok(())
    }
}

/// What the receiving tasks count.
#[derive(Default)]
pub(crate) struct Counters {
    pub lagged: Arc<AtomicU64>,
    pub bad: AtomicU64,
    pub bad_examples: Mutex<Vec<String>>,
    /// Bad messages so far on each topic (the subscribed ones: a bounded set).
    bad_per_topic: Mutex<std::collections::HashMap<String, u64>>,
    /// Where each bad message is said as it arrives (the first few of each topic, then one
    /// in a hundred), so that a flood on one topic does not hide another's.
    log: Option<crate::node::Log>,
}

/// Bad messages of a topic said one by one before the log thins out to one in
/// [`BAD_LOG_EVERY`].
const BAD_LOG_FIRST: u64 = 5;
const BAD_LOG_EVERY: u64 = 100;

impl Counters {
    /// Counters that say each bad message's reason in `log` as it arrives.
    pub fn logging(log: crate::node::Log) -> Self {
        Self {
            log: Some(log),
            ..Self::default()
        }
    }

    pub fn bad(&self, topic: &str, message: String) {
        let n = self.bad.fetch_add(1, Ordering::Relaxed) + 1;
        let on_topic = {
            let mut counts = self.bad_per_topic.lock().expect("no panics while held");
            let count = counts.entry(topic.to_owned()).or_default();
            *count += 1;
            *count
        };
        let line = format!("{topic}: {message}");
        if let Some(log) = &self.log
            && (on_topic <= BAD_LOG_FIRST || on_topic.is_multiple_of(BAD_LOG_EVERY))
        {
            log(&format!("bad message on {line} ({n} bad so far)"));
        }
        let mut ex = self.bad_examples.lock().expect("no panics while held");
        if ex.len() < 5 {
            ex.push(line);
        }
    }
}

/// A connected node.
pub(crate) enum Node {
    Ros1(Ros1Node),
    #[cfg(feature = "ros2")]
    Ros2(crate::ros2::Ros2Node),
}

/// A typed publisher on either middleware.
pub(crate) enum Outlet<T> {
    Ros1(Publisher<T>),
    #[cfg(feature = "ros2")]
    Ros2(crate::ros2::Ros2Publisher),
}

impl<T: RosMessageType + Ros2Message> Outlet<T> {
    pub async fn publish(&self, message: &T) -> Result<(), String> {
        match self {
            Outlet::Ros1(p) => p.publish(message).await.map_err(|e| e.to_string()),
            #[cfg(feature = "ros2")]
            Outlet::Ros2(p) => p.put(message.to_cdr()).await,
        }
    }
}

impl Node {
    /// Connects; `log` hears of the middleware's own events (a ROS 1 master lost and back);
    /// `stop` is set when the middleware tells the node to shut down (ROS 1's `rosnode
    /// kill`), as Ctrl-C sets it.
    pub async fn connect(
        middleware: &Middleware,
        node_name: &str,
        log: Log,
        stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    ) -> Result<Node, NodeError> {
        match middleware {
            Middleware::Ros1 { master_uri } => Ros1Node::connect(master_uri, node_name, log, stop)
                .await
                .map(Node::Ros1)
                .map_err(|message| NodeError::Master {
                    uri: master_uri.clone(),
                    message,
                }),
            #[cfg(feature = "ros2")]
            Middleware::Ros2(options) => crate::ros2::Ros2Node::open(options, node_name)
                .await
                .map(Node::Ros2)
                .map_err(|message| NodeError::Ros2 { message }),
            #[cfg(not(feature = "ros2"))]
            Middleware::Ros2(_) => Err(NodeError::Ros2 {
                message: "this build has no ROS 2 transport: build voxpan with --features ros2"
                    .into(),
            }),
        }
    }

    /// Called when the node begins to shut down: a ROS 1 node stops registering again with
    /// a restarted master, so that what it gives up on the way out stays given up.
    pub fn shutting_down(&self) {
        match self {
            Node::Ros1(node) => node.stop_watch(),
            #[cfg(feature = "ros2")]
            Node::Ros2(_) => {}
        }
    }

    /// How message bodies are serialised on this middleware.
    pub fn wire(&self) -> Wire {
        match self {
            Node::Ros1(_) => Wire::Ros1,
            #[cfg(feature = "ros2")]
            Node::Ros2(_) => Wire::Cdr,
        }
    }

    /// Advertises `topic` as `T`; ROS 1 queues `queue` messages per subscriber, ROS 2's
    /// samples wait for the network instead (see [`crate::ros2::Ros2Node::publisher`]).
    pub async fn advertise<T: RosMessageType + Ros2Message>(
        &self,
        topic: &str,
        queue: usize,
    ) -> Result<Outlet<T>, NodeError> {
        self.advertise_as::<T>(topic, queue, false).await
    }

    /// As [`Node::advertise`], latched on ROS 1: a subscriber that connects later (RViz
    /// opened after mapping, move_base's static layer) gets the last message at once. ROS 2
    /// publishers here are volatile either way.
    pub async fn advertise_latched<T: RosMessageType + Ros2Message>(
        &self,
        topic: &str,
        queue: usize,
    ) -> Result<Outlet<T>, NodeError> {
        self.advertise_as::<T>(topic, queue, true).await
    }

    async fn advertise_as<T: RosMessageType + Ros2Message>(
        &self,
        topic: &str,
        queue: usize,
        latched: bool,
    ) -> Result<Outlet<T>, NodeError> {
        let failed = |message: String| NodeError::Topic {
            topic: topic.to_owned(),
            message: format!("cannot advertise: {message}"),
        };
        match self {
            Node::Ros1(node) => node
                .advertise::<T>(topic, queue, latched)
                .await
                .map(Outlet::Ros1)
                .map_err(failed),
            #[cfg(feature = "ros2")]
            Node::Ros2(node) => node
                .publisher(topic, &T::TYPE)
                .await
                .map(Outlet::Ros2)
                .map_err(failed),
        }
    }

    /// Subscribes `topic` (ROS 2: as type `ty`) and forwards each message body with its
    /// arrival time, tagged `kind`, to `tx`. Each subscription buffers `queue` messages; what
    /// overflows is skipped and counted as lagged.
    pub async fn forward<K: Copy + Send + 'static>(
        &self,
        topic: &str,
        ty: &RosType,
        queue: usize,
        kind: K,
        tx: mpsc::Sender<(K, Bytes, i64)>,
        counters: Arc<Counters>,
    ) -> Result<(), NodeError> {
        let failed = |message: String| NodeError::Topic {
            topic: topic.to_owned(),
            message: format!("cannot subscribe: {message}"),
        };
        match self {
            Node::Ros1(node) => {
                let _ = ty; // TCPROS negotiates the type with the publisher.
                let sub = node.subscribe_any(topic, queue).await.map_err(failed)?;
                tokio::spawn(forward_ros1(sub, topic.to_owned(), kind, tx, counters));
            }
            #[cfg(feature = "ros2")]
            Node::Ros2(node) => {
                let (sub_tx, mut sub_rx) = mpsc::channel(queue.max(1));
                let bad = {
                    let (counters, topic) = (counters.clone(), topic.to_owned());
                    move |message: String| counters.bad(&topic, message)
                };
                let subscription = node
                    .subscribe(topic, ty, sub_tx, counters.lagged.clone(), bad)
                    .await
                    .map_err(failed)?;
                tokio::spawn(async move {
                    // Alive while the node's receiver is.
                    let _subscription = subscription;
                    while let Some((data, at)) = sub_rx.recv().await {
                        if tx.send((kind, data, at)).await.is_err() {
                            break;
                        }
                    }
                });
            }
        }
        Ok(())
    }

    /// The service `name` of type `T` answered by `handler` (ROS 1; `what` says what it is
    /// for in the error). `None` on ROS 2, where rmw_zenoh's services are not implemented
    /// here.
    pub async fn service<T: roslibrust::RosServiceType>(
        &self,
        name: &str,
        what: &str,
        handler: impl Fn(T::Request) -> T::Response + Send + Sync + 'static,
    ) -> Result<Option<ServiceServer>, NodeError> {
        match self {
            Node::Ros1(node) => node
                .service::<T>(name, handler)
                .await
                .map(Some)
                .map_err(|e| NodeError::Topic {
                    topic: name.to_owned(),
                    message: format!("cannot advertise the {what} service: {e}"),
                }),
            #[cfg(feature = "ros2")]
            Node::Ros2(_) => {
                let _ = (name, what, handler);
                Ok(None)
            }
        }
    }
}

/// TCPROS frames each message with its length; the decoders read the body.
async fn forward_ros1<K: Copy>(
    mut sub: SubscriberAny,
    topic: String,
    kind: K,
    tx: mpsc::Sender<(K, Bytes, i64)>,
    counters: Arc<Counters>,
) {
    while let Some(item) = sub.next().await {
        match item {
            Ok(data) if data.len() >= 4 => {
                if tx.send((kind, data.slice(4..), unix_ns())).await.is_err() {
                    break;
                }
            }
            Ok(_) => {}
            Err(e) => {
                // roslibrust does not export its error type; `Lagged(n)` is in its Debug.
                let text = format!("{e:?}");
                match text
                    .strip_prefix("Lagged(")
                    .and_then(|s| s.strip_suffix(')'))
                    .and_then(|n| n.parse::<u64>().ok())
                {
                    Some(n) => {
                        counters.lagged.fetch_add(n, Ordering::Relaxed);
                    }
                    None => counters.bad(&topic, e.to_string()),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    #[test]
    fn a_flood_of_bad_messages_on_one_topic_does_not_hide_another_topics() {
        let lines = Arc::new(Mutex::new(Vec::new()));
        let sink = lines.clone();
        let counters = super::Counters::logging(Arc::new(move |l: &str| {
            sink.lock().unwrap().push(l.to_owned())
        }));
        for _ in 0..250 {
            counters.bad("/a", "garbage".into());
        }
        counters.bad("/b", "garbage".into());
        let lines = lines.lock().unwrap();
        // The first five of /a, then its 100th and 200th; /b's first all the same.
        assert_eq!(
            lines
                .iter()
                .filter(|l| l.starts_with("bad message on /a: "))
                .count(),
            7
        );
        assert_eq!(
            lines.last().unwrap(),
            "bad message on /b: garbage (251 bad so far)"
        );
        assert_eq!(counters.bad.load(std::sync::atomic::Ordering::Relaxed), 251);
    }
}
