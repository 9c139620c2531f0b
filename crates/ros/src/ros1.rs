//! ROS 1 through roslibrust, plus what a node on a robot needs that roslibrust (like rospy
//! and roscpp) lacks: registering again with a master that restarted.
//!
//! A ROS 1 master keeps its registry in memory only. When `roscore` dies, peers already
//! connected keep talking (TCPROS runs peer to peer), but once a new master is up nothing new
//! can find a node until it registers again: a bag played or a node restarted afterwards
//! would never reach it. The watch below asks the master once a [`WATCH_PERIOD`] whether it
//! still knows this node's publications, subscriptions and services, and registers what it
//! forgot. A subscription registered again also learns the publishers that registered in the
//! meantime: the master answers with them, and the node's own slave API is told of them
//! (`publisherUpdate`, as a master would have sent had it known the subscriber). As with any
//! ROS 1 master's update, the list replaces the subscription's: a second publisher of the
//! same topic that has not registered again is cut until it does (within a period for a
//! voxpan node; roscpp and rospy nodes never do). The watch stops when the node begins to shut
//! down. At exit roslibrust unregisters from the master, waiting up to 2 s per registration
//! when its host is unreachable.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use roslibrust::ros1::{
    MasterClient, NodeHandle, Publisher, ServiceServer, SubscriberAny, SystemState,
};
use roslibrust::{RosMessageType, RosServiceType};

use crate::node::Log;

/// How often the master is asked whether it still knows this node. One small XML-RPC call:
/// negligible load at 1 Hz, and a restarted master is whole again within a second (rosmaster
/// itself takes longer to start).
const WATCH_PERIOD: Duration = Duration::from_secs(1);

/// What this node told the master, to tell a new master again.
#[derive(Clone, Default)]
struct Registry {
    /// (topic, type)
    publications: Vec<(String, String)>,
    /// (topic, type); `*` for raw subscriptions, as roslibrust registers them.
    subscriptions: Vec<(String, String)>,
    /// (service, its rosrpc:// URI)
    services: Vec<(String, String)>,
}

/// How long one pass of the watch may take: a master host gone from the network leaves a
/// half-open connection that would otherwise stall the watch until TCP gives up (minutes).
const WATCH_PASS_LIMIT: Duration = Duration::from_secs(5);

/// A roslibrust node and the watch that keeps it registered.
pub(crate) struct Ros1Node {
    handle: NodeHandle,
    /// The node's global name (roslibrust's caller id).
    caller_id: String,
    master: Arc<MasterClient>,
    registry: Arc<Mutex<Registry>>,
    watch: tokio::task::AbortHandle,
}

impl Drop for Ros1Node {
    fn drop(&mut self) {
        self.watch.abort();
    }
}

/// A global name as a master resolves `name` for a node called `caller_id` (`/ns/node`):
/// relative names in the node's namespace, private (`~`) names under the node. roslibrust
/// passes topic names to the master as given, so the node resolves them first: the master's
/// registry and the node's own subscriptions then use the same names.
fn resolve(name: &str, caller_id: &str) -> String {
    if name.starts_with('/') {
        return name.to_owned();
    }
    if let Some(private) = name.strip_prefix('~') {
        return format!("{caller_id}/{}", private.trim_start_matches('/'));
    }
    let namespace = caller_id.rsplit_once('/').map_or("", |(ns, _)| ns);
    format!("{namespace}/{name}")
}

impl Ros1Node {
    pub async fn connect(
        master_uri: &str,
        node_name: &str,
        log: Log,
        stop: Arc<std::sync::atomic::AtomicBool>,
    ) -> Result<Self, String> {
        let handle = NodeHandle::new(master_uri, node_name)
            .await
            .map_err(|e| format!("cannot register node {node_name}: {e}"))?;
        let client_uri = handle
            .get_client_uri()
            .await
            .map_err(|e| format!("node {node_name} has no XML-RPC address: {e}"))?;
        // roslibrust's rule for node names: all global.
        let caller_id = if node_name.starts_with('/') {
            node_name.to_owned()
        } else {
            format!("/{node_name}")
        };
        let master = MasterClient::new(master_uri, &client_uri, &caller_id)
            .await
            .map(Arc::new)
            .map_err(|e| format!("cannot reach the master: {e}"))?;
        let registry = Arc::new(Mutex::new(Registry::default()));
        let watch = tokio::spawn(watch(
            handle.clone(),
            master.clone(),
            caller_id.clone(),
            client_uri,
            registry.clone(),
            log,
            stop,
        ))
        .abort_handle();
        Ok(Self {
            handle,
            caller_id,
            master,
            registry,
            watch,
        })
    }

    fn registry(&self) -> std::sync::MutexGuard<'_, Registry> {
        self.registry.lock().expect("no panics while held")
    }

    /// Stops registering again: called when the node starts shutting down, so that what it
    /// gives up on the way out (publishers dropped with their threads) stays given up.
    pub fn stop_watch(&self) {
        self.watch.abort();
    }

    /// A publisher of `topic`; a latched one sends its last message to each new subscriber
    /// (as map_server's `/map`).
    pub async fn advertise<T: RosMessageType>(
        &self,
        topic: &str,
        queue: usize,
        latched: bool,
    ) -> Result<Publisher<T>, String> {
        let topic = resolve(topic, &self.caller_id);
        let publisher = self
            .handle
            .advertise::<T>(&topic, queue, latched)
            .await
            .map_err(|e| e.to_string())?;
        let ty = T::DESCRIPTION.ros_type_name.to_owned();
        self.registry().publications.push((topic, ty));
        Ok(publisher)
    }

    pub async fn subscribe_any(&self, topic: &str, queue: usize) -> Result<SubscriberAny, String> {
        let topic = resolve(topic, &self.caller_id);
        let subscriber = self
            .handle
            .subscribe_any(&topic, queue)
            .await
            .map_err(|e| e.to_string())?;
        let ty = roslibrust::ShapeShifter::DESCRIPTION
            .ros_type_name
            .to_owned();
        self.registry().subscriptions.push((topic, ty));
        Ok(subscriber)
    }

    /// The service `name` of type `T`, answered by `handler`.
    pub async fn service<T: RosServiceType>(
        &self,
        name: &str,
        handler: impl Fn(T::Request) -> T::Response + Send + Sync + 'static,
    ) -> Result<ServiceServer, String> {
        let name = resolve(name, &self.caller_id);
        let server = self
            .handle
            .advertise_service::<T, _>(&name, move |request| Ok(handler(request)))
            .await
            .map_err(|e| e.to_string())?;
        // roslibrust keeps the service's address to itself; the master has it now.
        let uri = self
            .master
            .lookup_service(&name)
            .await
            .map_err(|e| format!("the master lost the service just advertised: {e}"))?;
        self.registry().services.push((name, uri));
        Ok(server)
    }
}

/// Keeps the node registered with whichever master answers at its URI, while the node runs.
async fn watch(
    handle: NodeHandle,
    master: Arc<MasterClient>,
    caller_id: String,
    client_uri: String,
    registry: Arc<Mutex<Registry>>,
    log: Log,
    stop: Arc<std::sync::atomic::AtomicBool>,
) {
    let uri = master.get_master_uri().to_owned();
    let mut lost = false;
    let mut interval = tokio::time::interval(WATCH_PERIOD);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    interval.tick().await;
    loop {
        interval.tick().await;
        if !handle.is_ok() {
            // roslibrust's node has shut down: told to through the slave API (`rosnode
            // kill`, a master replacing a node of the same name); the node stops as on
            // Ctrl-C (the watch is aborted before a node drops its handle itself).
            log("told to shut down (ROS 1 slave API shutdown, as rosnode kill sends): stopping");
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
            return;
        }
        // What the node registered before the master is asked: an entry added in between is
        // then checked on the next pass, not taken for one the master forgot.
        let wanted = registry.lock().expect("no panics while held").clone();
        let pass = async {
            let state = master.get_system_state().await.map_err(|e| e.to_string())?;
            register_again(&master, &state, &wanted, &caller_id, &client_uri).await
        };
        let registered = match tokio::time::timeout(WATCH_PASS_LIMIT, pass).await {
            Ok(registered) => registered,
            Err(_) => Err(format!("no answer within {WATCH_PASS_LIMIT:?}")),
        };
        let registered = match registered {
            Ok(n) => n,
            Err(e) => {
                if !lost {
                    log(&format!(
                        "ROS master {uri} lost ({e}); connected peers keep talking, and this \
                         node registers again when a master answers there"
                    ));
                    lost = true;
                }
                continue;
            }
        };
        if registered > 0 {
            log(&format!(
                "ROS master {uri}: registered {registered} topics and services again"
            ));
        }
        if lost {
            log(&format!("ROS master {uri} answers again"));
            lost = false;
        }
    }
}

/// Registers what `state` lacks of `wanted`; returns how many entries that was.
async fn register_again(
    master: &MasterClient,
    state: &SystemState,
    wanted: &Registry,
    caller_id: &str,
    client_uri: &str,
) -> Result<usize, String> {
    let mut count = 0;
    for (topic, ty) in &wanted.publications {
        if !state.is_publishing(topic, caller_id) {
            // The master tells the topic's subscribers of this publisher itself.
            master
                .register_publisher(topic, ty)
                .await
                .map_err(|e| format!("publisher of {topic}: {e}"))?;
            count += 1;
        }
    }
    for (topic, ty) in &wanted.subscriptions {
        if !state.is_subscribed(topic, caller_id) {
            let publishers = master
                .register_subscriber(topic, ty)
                .await
                .map_err(|e| format!("subscription to {topic}: {e}"))?;
            // An update replaces the node's publisher list: an empty one would only cut the
            // connections to publishers still alive that have yet to register again (they
            // will, and the master then sends the update itself).
            if !publishers.is_empty() {
                publisher_update(client_uri, topic, publishers)
                    .await
                    .map_err(|e| format!("subscription to {topic}: telling the node: {e}"))?;
            }
            count += 1;
        }
    }
    for (service, service_uri) in &wanted.services {
        if !state.is_service_provider(service, caller_id) {
            master
                .register_service(service, service_uri)
                .await
                .map_err(|e| format!("service {service}: {e}"))?;
            count += 1;
        }
    }
    Ok(count)
}

/// The slave API's `publisherUpdate`, sent to this node's own XML-RPC server: its
/// subscription then connects to every publisher listed (and drops those no longer listed).
async fn publisher_update(
    client_uri: &str,
    topic: &str,
    publishers: Vec<String>,
) -> Result<(), String> {
    use serde_xmlrpc::Value;
    let body = serde_xmlrpc::request_to_string(
        "publisherUpdate",
        vec![
            Value::String("/master".into()),
            Value::String(topic.into()),
            Value::Array(publishers.into_iter().map(Value::String).collect()),
        ],
    )
    .map_err(|e| e.to_string())?;
    let response = reqwest::Client::builder()
        .timeout(WATCH_PASS_LIMIT)
        .build()
        .map_err(|e| e.to_string())?
        .post(client_uri)
        .body(body)
        .send()
        .await
        .map_err(|e| e.to_string())?;
    if !response.status().is_success() {
        return Err(format!("HTTP {}", response.status()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::resolve;

    #[test]
    fn names_resolve_as_a_master_resolves_them() {
        assert_eq!(resolve("/camera/depth", "/ns/node"), "/camera/depth");
        assert_eq!(resolve("camera/depth", "/node"), "/camera/depth");
        assert_eq!(
            resolve("camera/depth", "/robot1/node"),
            "/robot1/camera/depth"
        );
        assert_eq!(
            resolve("~save_map", "/robot1/node"),
            "/robot1/node/save_map"
        );
    }
}
