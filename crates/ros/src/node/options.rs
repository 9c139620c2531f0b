//! What each node is told: its connection, topics, queues and schedules.

use std::path::PathBuf;

use voxpan_bag::BagOptions;
use voxpan_map::Coloring;

use super::Connection;

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
