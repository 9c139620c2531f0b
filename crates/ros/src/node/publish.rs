//! The nodes' publishers: the perception node's outputs, the mesh markers, the costmap.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use voxpan_bag::assemble::Assembled;
use voxpan_map::BlockIndex;
use voxpan_perception::Perceived;

use super::{NodeError, Outputs, unix_ns};
use crate::encode;
use crate::msgs::{geometry_msgs, nav_msgs, sensor_msgs, std_msgs, visualization_msgs};
use crate::transport::{Node, Outlet};

/// Sends block meshes as one MarkerArray; marker ids stay fixed per block so a re-sent block
/// replaces its old triangles in RViz.
pub(super) struct MeshPublisher {
    pub(super) publisher: Outlet<visualization_msgs::MarkerArray>,
    pub(super) ids: HashMap<BlockIndex, i32>,
    pub(super) frame_id: Arc<Mutex<String>>,
    pub(super) runtime: tokio::runtime::Handle,
}

impl MeshPublisher {
    pub(super) fn publish(&mut self, blocks: Vec<(BlockIndex, Option<voxpan_core::Mesh>)>) {
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
pub(super) struct CostmapPublisher {
    pub(super) grid: Outlet<nav_msgs::OccupancyGrid>,
    pub(super) slice: Outlet<sensor_msgs::PointCloud2>,
    pub(super) max_distance: f32,
    pub(super) frame_id: Arc<Mutex<String>>,
    pub(super) runtime: tokio::runtime::Handle,
}

impl CostmapPublisher {
    pub(super) fn publish(&mut self, costmap: voxpan_map::Costmap) {
        let frame_id = self.frame_id.lock().expect("no panics while held").clone();
        let header = encode::header(unix_ns(), &frame_id);
        let grid = encode::occupancy_grid(header.clone(), &costmap);
        let slice = encode::esdf_slice(header, &costmap, self.max_distance);
        // As the mesh: a publish fails only when the node is shutting down.
        let _ = self.runtime.block_on(self.grid.publish(&grid));
        let _ = self.runtime.block_on(self.slice.publish(&slice));
    }
}

/// Publishers of the perception node's outputs.
pub(super) struct PerceivePublishers {
    class_names: std::collections::BTreeMap<u32, String>,
    /// The `[refine]` and `[fill]` the mapping node applies between keyframes.
    perception: voxpan_perception::PerceptionConfig,
    depth: Outlet<sensor_msgs::Image>,
    color: Outlet<sensor_msgs::Image>,
    info: Outlet<sensor_msgs::CameraInfo>,
    pose: Outlet<geometry_msgs::PoseStamped>,
    labels: Outlet<sensor_msgs::Image>,
    segments: Outlet<std_msgs::String>,
}

impl PerceivePublishers {
    pub(super) async fn new(
        node: &Node,
        out: &Outputs,
        class_names: std::collections::BTreeMap<u32, String>,
        perception: voxpan_perception::PerceptionConfig,
    ) -> Result<Self, NodeError> {
        // Deep enough for a few frames in flight to a peer that reads them a little late.
        let q = 8;
        Ok(Self {
            class_names,
            perception,
            depth: node.advertise(&out.depth(), q).await?,
            color: node.advertise(&out.color(), q).await?,
            info: node.advertise(&out.camera_info(), q).await?,
            pose: node.advertise(&out.pose(), q).await?,
            labels: node.advertise(&out.labels(), q).await?,
            segments: node.advertise(&out.segments(), q).await?,
        })
    }

    /// The frame's messages, all stamped with its depth stamp; the segment list goes last:
    /// the mapping node's sign that the frame is complete. A frame between keyframes goes
    /// with its depth as measured and no masks, its segment list saying `carry`: the mapping
    /// node makes its masks from the map and fills the depth.
    pub(super) async fn publish(&self, a: &Assembled, p: &Perceived) -> Result<(), String> {
        let header = |frame_id: &str| encode::header(a.stamp_ns, frame_id);
        let camera = a.camera_frame.as_str();
        let f = &p.frame;
        let depth = p.measured_depth.as_ref().unwrap_or(&f.depth);
        self.depth
            .publish(&encode::depth_image(header(camera), depth))
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
                p.measured_depth.as_ref().map(|_| &self.perception),
            ))
            .await?;
        Ok(())
    }
}
