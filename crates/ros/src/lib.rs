//! voxpan on ROS, in pure Rust: ROS 1 (roslibrust's TCPROS + XML-RPC) and, with the feature
//! `ros2`, ROS 2 over rmw_zenoh's wire format (the `zenoh` crate). No ROS installation is
//! needed to build; Debian's ROS 1 tools and zenoh peers that follow rmw_zenoh talk to these
//! nodes ([`transport`] picks the middleware).
//!
//! - [`node::run_perceive`]: subscribes a camera's colour, depth, camera_info and /tf (or a
//!   pose topic), and a label image with its segment list when masks come from a topic;
//!   pairs them as the bag reader does ([`voxpan_bag::assemble`]); fills, segments and refines; publishes
//!   under `/voxpan`: `depth` (32FC1, filled), `color` (rgb8), `camera_info`, `pose`
//!   (PoseStamped, `T_world_camera`), `segments/image` (16UC1 refined labels) and
//!   `segments/labels` (std_msgs/String JSON), all stamped with the depth image's stamp.
//! - [`node::run_map`]: subscribes those, joins them by stamp, integrates, publishes the mesh
//!   of changed blocks as a visualization_msgs/MarkerArray (one TRIANGLE_LIST per block) and
//!   saves the map when stopped and on each call of the std_srvs/Trigger service
//!   `/voxpan/save_map`; with the distance field, publishes the costmap
//!   (nav_msgs/OccupancyGrid) and its clearance (sensor_msgs/PointCloud2) and answers
//!   distance queries (voxpan_msgs/DistanceQuery `/voxpan/distance`, [`query`]).
//! - [`node::run_both`]: the two in one process.
//!
//! Frames that arrive faster than a node works are dropped oldest first and counted
//! ([`node::NodeReport`]); nothing queues without bound.
//!
//! ROS 2: [`rmw_zenoh`] (key expressions, liveliness tokens, QoS text, attachments, publisher
//! ids) and [`cdr`] (ROS 2 layouts of the published messages) are the wire layer, checked
//! against independent implementations; `ros2` (feature `ros2`) is the zenoh session that
//! carries them. ROS 2 has no services here (rmw_zenoh's services are not implemented):
//! the map is saved when the node stops.

pub mod cdr;
pub mod encode;
pub mod inbound;
pub mod mailbox;
pub mod msgs;
pub mod node;
pub mod query;
pub mod rmw_zenoh;
mod ros1;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod transport;

pub use transport::{Middleware, Ros2Options};

pub use node::{
    Connection, MapOptions, NodeError, NodeReport, Outputs, PerceiveOptions, run_both, run_map,
    run_perceive,
};
