//! The live ROS 2 transport: a zenoh session that follows rmw_zenoh's rules ([`crate::rmw_zenoh`]),
//! so ROS 2 nodes running rmw_zenoh_cpp and voxpan's nodes see each other's topics. Like a
//! ROS 2 node on rmw_zenoh's default configuration, the session is a zenoh peer that connects
//! to the router (`ros2 run rmw_zenoh_cpp rmw_zenohd`, `tcp/localhost:7447`) and keeps
//! retrying it: a node started before its router, or whose router restarts, connects when it
//! can.

use std::sync::Arc;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

use bytes::Bytes;
use tokio::sync::mpsc;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;

use crate::rmw_zenoh::{
    Attachment, EntityKind, NodeName, Qos, RosType, data_key, endpoint_token, node_token,
    publisher_id,
};
use crate::transport::Ros2Options;

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// One ROS 2 node on its own zenoh session.
pub struct Ros2Node {
    session: zenoh::Session,
    name: NodeName,
    /// Entity ids after the node's own; unique within the session, as rmw_zenoh needs.
    next_entity: AtomicU64,
    _token: LivelinessToken,
    /// Says when the router stops or starts answering; stopped with the node.
    router_watch: tokio::task::AbortHandle,
}

impl Drop for Ros2Node {
    fn drop(&mut self) {
        self.router_watch.abort();
    }
}

/// How often the node looks whether a router answers.
const ROUTER_CHECK: std::time::Duration = std::time::Duration::from_secs(2);

/// Says on standard error when no router answers at `connect` (then this node sees only peers
/// it already knows: none, at start), and when one answers again; silent while all is well.
async fn watch_router(session: zenoh::Session, connect: Vec<String>) {
    let endpoints = connect.join(", ");
    let mut reached = true;
    loop {
        tokio::time::sleep(ROUTER_CHECK).await;
        if session.is_closed() {
            return;
        }
        let now = session.info().routers_zid().await.next().is_some();
        if now != reached {
            if now {
                eprintln!("ROS 2: the zenoh router at {endpoints} answers");
            } else {
                eprintln!(
                    "ROS 2: no zenoh router answers at {endpoints}; still trying. Until one \
                     does, this node reaches no other ROS 2 node: start one (`ros2 run \
                     rmw_zenoh_cpp rmw_zenohd`) or name it (--zenoh-connect)"
                );
            }
            reached = now;
        }
    }
}

/// A publisher: its zenoh publisher, its liveliness token, the id and sequence its samples'
/// attachments carry.
pub struct Ros2Publisher {
    publisher: Publisher<'static>,
    id: [u8; 16],
    sequence: AtomicI64,
    _token: LivelinessToken,
}

impl Ros2Publisher {
    /// Puts one CDR sample with its attachment.
    pub async fn put(&self, cdr: Vec<u8>) -> Result<(), String> {
        let attachment = Attachment {
            sequence: self.sequence.fetch_add(1, Ordering::Relaxed) + 1,
            timestamp_ns: crate::node::unix_ns(),
            publisher_id: self.id,
        };
        self.publisher
            .put(cdr)
            .attachment(attachment.to_bytes().to_vec())
            .await
            .map_err(text)
    }
}

/// What a subscription keeps alive: undeclared when dropped.
pub struct Ros2Subscription {
    _subscriber: Subscriber<()>,
    _token: LivelinessToken,
}

impl Ros2Node {
    /// Opens the session and declares the node. `full_name` is `/name` or `/namespace/name`.
    pub async fn open(options: &Ros2Options, full_name: &str) -> Result<Ros2Node, String> {
        let mut config = zenoh::Config::default();
        let json = |list: &[String]| serde_json::to_string(list).expect("strings serialise");
        // rmw_zenoh's DEFAULT_RMW_ZENOH_SESSION_CONFIG: a peer that finds others through the
        // router's gossip, not multicast.
        for (key, value) in [
            ("mode", "\"peer\"".to_owned()),
            ("connect/endpoints", json(&options.connect)),
            ("listen/endpoints", json(&options.listen)),
            ("scouting/multicast/enabled", "false".to_owned()),
            ("scouting/gossip/enabled", "true".to_owned()),
        ] {
            config
                .insert_json5(key, &value)
                .map_err(|e| format!("zenoh configuration {key} = {value}: {e}"))?;
        }
        let session = zenoh::open(config).await.map_err(|e| {
            format!(
                "cannot open a zenoh session (connect {:?}, listen {:?}): {e}",
                options.connect, options.listen
            )
        })?;
        let (namespace, name) = match full_name.trim_end_matches('/').rsplit_once('/') {
            Some(("", name)) => ("/".to_owned(), name.to_owned()),
            Some((ns, name)) => (ns.to_owned(), name.to_owned()),
            None => ("/".to_owned(), full_name.to_owned()),
        };
        let name = NodeName {
            domain: options.domain,
            session_id: session.zid().to_string(),
            node_id: 0,
            enclave: "/".into(),
            namespace,
            name,
        };
        let token = session
            .liveliness()
            .declare_token(node_token(&name))
            .await
            .map_err(|e| format!("cannot declare the node's liveliness token: {e}"))?;
        let router_watch =
            tokio::spawn(watch_router(session.clone(), options.connect.clone())).abort_handle();
        Ok(Ros2Node {
            session,
            name,
            next_entity: AtomicU64::new(1),
            _token: token,
            router_watch,
        })
    }

    fn token(&self, kind: EntityKind, topic: &str, ty: &RosType, qos: &Qos) -> String {
        let id = self.next_entity.fetch_add(1, Ordering::Relaxed);
        endpoint_token(&self.name, id, kind, topic, ty, qos)
    }

    /// Advertises `topic`: reliable, volatile, keep-all, and a sample waits for room in the
    /// network's queues rather than being dropped (rmw_zenoh's BLOCK, which it uses for
    /// reliable keep-all). What the nodes drop when they fall behind is then decided by their
    /// mailboxes, and counted; and a mesh update of many megabytes still reaches a viewer on a
    /// busy link (dropped under congestion, it would almost never arrive whole).
    pub async fn publisher(&self, topic: &str, ty: &RosType) -> Result<Ros2Publisher, String> {
        // Depth 0 under keep-all, as rclcpp's; the token then leaves it out (`::2,:,:,:,,`).
        let qos = Qos {
            keep_all: true,
            depth: 0,
            ..Qos::DEFAULT
        };
        let token_key = self.token(EntityKind::Publisher, topic, ty, &qos);
        let publisher = self
            .session
            .declare_publisher(data_key(self.name.domain, topic, ty))
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(text)?;
        let token = self
            .session
            .liveliness()
            .declare_token(token_key.clone())
            .await
            .map_err(text)?;
        Ok(Ros2Publisher {
            publisher,
            id: publisher_id(&token_key),
            sequence: AtomicI64::new(0),
            _token: token,
        })
    }

    /// Subscribes `topic` and sends each sample's CDR bytes with its arrival time to `tx`;
    /// when `tx` is full the sample is dropped and counted in `lagged`. A sample without
    /// rmw_zenoh's attachment is counted in `bad` (rmw_zenoh drops those too).
    pub async fn subscribe(
        &self,
        topic: &str,
        ty: &RosType,
        tx: mpsc::Sender<(Bytes, i64)>,
        lagged: Arc<AtomicU64>,
        bad: impl Fn(String) + Send + Sync + 'static,
    ) -> Result<Ros2Subscription, String> {
        let qos = Qos {
            depth: tx.max_capacity(),
            ..Qos::DEFAULT
        };
        let token_key = self.token(EntityKind::Subscription, topic, ty, &qos);
        let subscriber = self
            .session
            .declare_subscriber(data_key(self.name.domain, topic, ty))
            .callback(move |sample| {
                let arrival = crate::node::unix_ns();
                if let Err(e) = sample
                    .attachment()
                    .ok_or_else(|| "sample without rmw_zenoh's attachment".to_owned())
                    .and_then(|a| Attachment::parse(&a.to_bytes()))
                {
                    bad(e);
                    return;
                }
                let data = Bytes::from(sample.payload().to_bytes().into_owned());
                if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send((data, arrival)) {
                    lagged.fetch_add(1, Ordering::Relaxed);
                }
            })
            .await
            .map_err(text)?;
        // Declared after the subscriber: a publisher that waits for subscribers (many ROS 2
        // drivers do) starts only once samples can be received.
        let token = self
            .session
            .liveliness()
            .declare_token(token_key)
            .await
            .map_err(text)?;
        Ok(Ros2Subscription {
            _subscriber: subscriber,
            _token: token,
        })
    }
}
