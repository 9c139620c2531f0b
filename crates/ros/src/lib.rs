//! voxpan on ROS 1, in pure Rust (roslibrust's TCPROS + XML-RPC): no ROS installation is
//! needed to build, and Debian's ROS 1 tools talk to these nodes.
//!
//! - [`node::run_perceive`]: subscribes a camera's colour, depth, camera_info and /tf (or a
//!   pose topic), and a label image with its segment list when masks come from a topic;
//!   pairs them as the bag reader does ([`assemble`]); fills, segments and refines; publishes
//!   under `/voxpan`: `depth` (32FC1, filled), `color` (rgb8), `camera_info`, `pose`
//!   (PoseStamped, `T_world_camera`), `segments/image` (16UC1 refined labels) and
//!   `segments/labels` (std_msgs/String JSON), all stamped with the depth image's stamp.
//! - [`node::run_map`]: subscribes those, joins them by stamp, integrates, publishes the mesh
//!   of changed blocks as a visualization_msgs/MarkerArray (one TRIANGLE_LIST per block) and
//!   saves the map when stopped and on each call of the std_srvs/Trigger service
//!   `/voxpan/save_map`.
//! - [`node::run_both`]: the two in one process.
//!
//! Frames that arrive faster than a node works are dropped oldest first and counted
//! ([`node::NodeReport`]); nothing queues without bound.
//!
//! ROS 2: [`rmw_zenoh`] (key expressions, liveliness tokens, QoS text, attachments, publisher
//! ids) and [`cdr`] (ROS 2 layouts of the published messages) are the wire layer of an
//! rmw_zenoh transport, checked against independent implementations; the zenoh session that
//! would carry them is not built yet.

pub mod assemble;
pub mod cdr;
pub mod encode;
pub mod inbound;
pub mod mailbox;
pub mod msgs;
pub mod node;
pub mod rmw_zenoh;

pub use node::{
    Connection, MapOptions, NodeError, NodeReport, Outputs, PerceiveOptions, run_both, run_map,
    run_perceive,
};
