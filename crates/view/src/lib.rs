//! A live view of a voxpan run for [Foxglove](https://foxglove.dev): a WebSocket server that
//! Foxglove (the app or the browser) connects to, and/or an MCAP recording it opens later.
//!
//! Topics (Foxglove's own schemas, protobuf-encoded, in the frames `world` and `camera`):
//! - `/camera/color` (`foxglove.RawImage`, `rgb8`): the colour image with the refined masks
//!   blended over it, one colour per segment;
//! - `/camera/depth` (`foxglove.RawImage`, `32FC1`, metres; 0 = no depth): the depth that was
//!   integrated (hole-filled);
//! - `/camera/calibration` (`foxglove.CameraCalibration`): so the 3-D panel can place the images;
//! - `/tf` (`foxglove.FrameTransform`): `world` → `camera`, the frame's `T_world_camera`;
//! - `/map/mesh` (`foxglove.SceneUpdate`): the map's mesh, one scene entity per voxel block
//!   (`block x y z`), re-sent only for blocks that changed since the last update and deleted
//!   when a block's surface disappears, so the mesh grows incrementally as in voxblox's RViz
//!   plugin.
//!
//! ```no_run
//! use voxpan_view::{LiveOptions, LiveView};
//! # fn frames() -> Vec<(voxpan_core::Frame, Option<voxpan_core::Segments>)> { vec![] }
//! let mut map = voxpan_map::PanopticMap::new(voxpan_map::MapConfig::default()).unwrap();
//! let mut view = LiveView::start(&LiveOptions {
//!     listen: Some(("127.0.0.1".into(), 8765)),
//!     record: Some("run.mcap".into()),
//!     ..LiveOptions::default()
//! })
//! .unwrap();
//! for (frame, segments) in frames() {
//!     map.integrate(frame.view(), segments.as_ref()).unwrap();
//!     view.show(&frame, segments.as_ref(), &mut map).unwrap();
//! }
//! view.finish(&mut map).unwrap();
//! ```

use std::collections::HashSet;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use foxglove::schemas::{
    CameraCalibration, Color, FrameTransform, Point3, Quaternion, RawImage, SceneEntity,
    SceneEntityDeletion, SceneUpdate, Timestamp, TriangleListPrimitive, Vector3,
    scene_entity_deletion,
};
use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{Channel, Context, McapWriterHandle, WebSocketServerHandle};
use voxpan_core::{Frame, Mesh, Segments};
use voxpan_map::{BlockIndex, Coloring, PanopticMap, id_color};

pub const WORLD_FRAME: &str = "world";
pub const CAMERA_FRAME: &str = "camera";

/// What to serve and record.
#[derive(Clone, Debug)]
pub struct LiveOptions {
    /// Host and port of the WebSocket server (Foxglove's default port is 8765; port 0 picks a
    /// free one); `None`: no server.
    pub listen: Option<(String, u16)>,
    /// MCAP file to record into; `None`: no recording.
    pub record: Option<PathBuf>,
    /// How the mesh is coloured.
    pub coloring: Coloring,
    /// Send mesh updates every this many frames (and once at the end): re-meshing the changed
    /// blocks costs about as much as integrating a frame, and a viewer needs a few updates per
    /// second, not one per frame.
    pub mesh_every: usize,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            listen: Some(("127.0.0.1".into(), 8765)),
            record: None,
            coloring: Coloring::Instance,
            mesh_every: 10,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("live view: neither a server address nor a recording file was given")]
    NothingToDo,
    #[error("live view: cannot start the Foxglove WebSocket server on {host}:{port}: {source}")]
    Server {
        host: String,
        port: u16,
        source: foxglove::FoxgloveError,
    },
    #[error("live view: cannot record to {path}: {source}")]
    Record {
        path: PathBuf,
        source: foxglove::FoxgloveError,
    },
    #[error("live view: cannot move the recording {from} to {to}: {source}")]
    Rename {
        from: PathBuf,
        to: PathBuf,
        source: std::io::Error,
    },
    #[error("live view: mesh option: {0}")]
    Options(String),
}

/// What one [`LiveView::show`] sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Shown {
    /// Mesh blocks sent (changed) and deleted (their surface vanished) in this update.
    pub blocks_sent: usize,
    pub blocks_deleted: usize,
}

/// The live view: channels in a context of its own (so two views, or tests, never mix),
/// the sinks on it, and which mesh blocks the viewer holds.
pub struct LiveView {
    _context: Arc<Context>,
    server: Option<WebSocketServerHandle>,
    recording: Option<(PathBuf, McapWriterHandle<BufWriter<File>>)>,
    color: Channel<RawImage>,
    depth: Channel<RawImage>,
    calibration: Channel<CameraCalibration>,
    tf: Channel<FrameTransform>,
    mesh: Channel<SceneUpdate>,
    coloring: Coloring,
    mesh_every: usize,
    frames: usize,
    last_stamp: Timestamp,
    /// Blocks sent and not deleted since.
    shown_blocks: HashSet<BlockIndex>,
    /// Set when a viewer subscribes to the mesh: the server keeps no history, so the next
    /// update carries every block, not only the changed ones.
    resend_mesh: Arc<AtomicBool>,
}

/// Hears the server's subscriptions, to give a viewer that joins late the whole mesh.
struct MeshSubscriptions(Arc<AtomicBool>);

impl ServerListener for MeshSubscriptions {
    fn on_subscribe(&self, _client: Client, channel: ChannelView) {
        if channel.topic() == MESH_TOPIC {
            self.0.store(true, Ordering::Relaxed);
        }
    }
}

const MESH_TOPIC: &str = "/map/mesh";

impl LiveView {
    /// Starts the server and/or opens the recording. The channels are made first, so that a
    /// viewer connecting at once sees every topic advertised.
    pub fn start(options: &LiveOptions) -> Result<Self, ViewError> {
        if options.listen.is_none() && options.record.is_none() {
            return Err(ViewError::NothingToDo);
        }
        if options.mesh_every == 0 {
            return Err(ViewError::Options(
                "mesh updates every 0 frames: use 1 or more".into(),
            ));
        }
        let context = Context::new();
        let color = context.channel_builder("/camera/color").build();
        let depth = context.channel_builder("/camera/depth").build();
        let calibration = context.channel_builder("/camera/calibration").build();
        let tf = context.channel_builder("/tf").build();
        let mesh = context.channel_builder(MESH_TOPIC).build();
        let resend_mesh = Arc::new(AtomicBool::new(false));
        // Recorded under a temporary name and renamed when closed: a run that fails or is
        // killed leaves no half-written file under the name asked for.
        let recording = match &options.record {
            Some(path) => {
                let partial = partial_path(path);
                let handle = context
                    .mcap_writer()
                    .create_new_buffered_file(&partial)
                    .map_err(|source| ViewError::Record {
                        path: path.clone(),
                        source,
                    })?;
                Some((path.clone(), handle))
            }
            None => None,
        };
        let server = match &options.listen {
            Some((host, port)) => Some(
                context
                    .websocket_server()
                    .name("voxpan")
                    .listener(Arc::new(MeshSubscriptions(resend_mesh.clone())))
                    .bind(host.clone(), *port)
                    .start_blocking()
                    .map_err(|source| ViewError::Server {
                        host: host.clone(),
                        port: *port,
                        source,
                    })?,
            ),
            None => None,
        };
        Ok(Self {
            _context: context,
            server,
            recording,
            color,
            depth,
            calibration,
            tf,
            mesh,
            coloring: options.coloring,
            mesh_every: options.mesh_every,
            frames: 0,
            last_stamp: Timestamp::new(0, 0),
            shown_blocks: HashSet::new(),
            resend_mesh,
        })
    }

    /// The server's port (useful with port 0), if serving.
    pub fn port(&self) -> Option<u16> {
        self.server.as_ref().map(|s| s.port())
    }

    /// Publishes a mapped frame: images, calibration, pose, and every `mesh_every` frames the
    /// mesh blocks that changed. Messages nobody listens to are not built.
    pub fn show(
        &mut self,
        frame: &Frame,
        segments: Option<&Segments>,
        map: &mut PanopticMap,
    ) -> Result<Shown, ViewError> {
        let stamp = timestamp(frame.timestamp);
        self.last_stamp = stamp;
        let nanos = stamp_nanos(stamp);
        if self.color.has_sinks() {
            self.color
                .log_with_time(&color_with_masks(frame, segments, stamp), nanos);
        }
        if self.depth.has_sinks() {
            self.depth.log_with_time(&depth_image(frame, stamp), nanos);
        }
        if self.calibration.has_sinks() {
            self.calibration
                .log_with_time(&calibration(frame, stamp), nanos);
        }
        if self.tf.has_sinks() {
            self.tf.log_with_time(&camera_pose(frame, stamp), nanos);
        }
        self.frames += 1;
        if self.frames.is_multiple_of(self.mesh_every) {
            return Ok(self.send_mesh(map));
        }
        Ok(Shown::default())
    }

    /// Sends the last mesh update and closes the recording (an MCAP file is only complete
    /// once closed) and the server.
    pub fn finish(mut self, map: &mut PanopticMap) -> Result<Shown, ViewError> {
        let shown = self.send_mesh(map);
        if let Some((path, handle)) = self.recording.take() {
            let partial = partial_path(&path);
            handle.close().map_err(|source| ViewError::Record {
                path: path.clone(),
                source,
            })?;
            std::fs::rename(&partial, &path).map_err(|e| ViewError::Rename {
                from: partial,
                to: path,
                source: e,
            })?;
        }
        if let Some(server) = self.server.take() {
            // Waiting for the shutdown would need the server's async runtime; dropping the
            // returned handle lets it finish in the background.
            drop(server.stop());
        }
        Ok(shown)
    }

    /// Re-meshes what changed (the map's own incremental mesher, so the final mesh costs
    /// less afterwards) and sends those blocks.
    fn send_mesh(&mut self, map: &mut PanopticMap) -> Shown {
        let changed = map.update_mesh();
        if !self.mesh.has_sinks() {
            return Shown::default();
        }
        let send = if self.resend_mesh.swap(false, Ordering::Relaxed) {
            let mut all = map.mesh_blocks();
            // Blocks whose surface vanished since still need their deletion.
            all.extend(changed.iter().filter(|b| self.shown_blocks.contains(*b)));
            all.sort_unstable();
            all.dedup();
            all
        } else {
            changed
        };
        let mut update = SceneUpdate::default();
        let mut shown = Shown::default();
        for index in send {
            let id = block_id(&index);
            match map.block_mesh(&index, self.coloring) {
                Some(mesh) if !mesh.triangles.is_empty() => {
                    update
                        .entities
                        .push(block_entity(id, &mesh, self.last_stamp));
                    self.shown_blocks.insert(index);
                    shown.blocks_sent += 1;
                }
                _ => {
                    if self.shown_blocks.remove(&index) {
                        update.deletions.push(SceneEntityDeletion {
                            timestamp: Some(self.last_stamp),
                            r#type: scene_entity_deletion::Type::MatchingId as i32,
                            id,
                        });
                        shown.blocks_deleted += 1;
                    }
                }
            }
        }
        if !update.entities.is_empty() || !update.deletions.is_empty() {
            self.mesh
                .log_with_time(&update, stamp_nanos(self.last_stamp));
        }
        shown
    }
}

/// Where a recording is written until it is complete: `FILE.partial` beside it.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".partial");
    PathBuf::from(name)
}

/// The scene entity id of a block: stable, so that a re-sent block replaces the old one.
pub fn block_id(index: &BlockIndex) -> String {
    format!("block {} {} {}", index[0], index[1], index[2])
}

fn timestamp(seconds: f64) -> Timestamp {
    let seconds = if seconds.is_finite() {
        seconds.max(0.0)
    } else {
        0.0
    };
    let whole = seconds.floor().min(u32::MAX as f64);
    let nanos = ((seconds - whole) * 1e9).round().min(999_999_999.0);
    Timestamp::new(whole as u32, nanos as u32)
}

fn stamp_nanos(stamp: Timestamp) -> u64 {
    stamp.sec() as u64 * 1_000_000_000 + stamp.nsec() as u64
}

/// The colour image with each listed segment's pixels half-blended with its colour (the
/// map's instance palette, by segment id).
pub fn color_with_masks(frame: &Frame, segments: Option<&Segments>, stamp: Timestamp) -> RawImage {
    let (w, h) = (frame.color.width(), frame.color.height());
    let mut data = Vec::with_capacity(w * h * 3);
    let listed: HashSet<u16> = segments
        .map(|s| s.segments.iter().map(|seg| seg.id).collect())
        .unwrap_or_default();
    let labels = segments.map(|s| s.labels.pixels());
    for (i, rgb) in frame.color.pixels().iter().enumerate() {
        let id = labels.map_or(0, |l| l[i]);
        if id != 0 && listed.contains(&id) {
            let tint = id_color(id as u32);
            data.extend((0..3).map(|c| ((rgb[c] as u16 + tint[c] as u16) / 2) as u8));
        } else {
            data.extend_from_slice(rgb);
        }
    }
    RawImage {
        timestamp: Some(stamp),
        frame_id: CAMERA_FRAME.into(),
        width: w as u32,
        height: h as u32,
        encoding: "rgb8".into(),
        step: (w * 3) as u32,
        data: data.into(),
    }
}

fn depth_image(frame: &Frame, stamp: Timestamp) -> RawImage {
    let (w, h) = (frame.depth.width(), frame.depth.height());
    let data: Vec<u8> = frame
        .depth
        .pixels()
        .iter()
        .flat_map(|&z| {
            let z = if voxpan_core::is_valid_depth(z) {
                z
            } else {
                0.0
            };
            z.to_le_bytes()
        })
        .collect();
    RawImage {
        timestamp: Some(stamp),
        frame_id: CAMERA_FRAME.into(),
        width: w as u32,
        height: h as u32,
        encoding: "32FC1".into(),
        step: (w * 4) as u32,
        data: data.into(),
    }
}

fn calibration(frame: &Frame, stamp: Timestamp) -> CameraCalibration {
    let k = &frame.intrinsics;
    CameraCalibration {
        timestamp: Some(stamp),
        frame_id: CAMERA_FRAME.into(),
        width: k.width as u32,
        height: k.height as u32,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: vec![k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![
            k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
    }
}

fn camera_pose(frame: &Frame, stamp: Timestamp) -> FrameTransform {
    let t = frame.pose.translation.vector;
    let q = frame.pose.rotation.quaternion();
    FrameTransform {
        timestamp: Some(stamp),
        parent_frame_id: WORLD_FRAME.into(),
        child_frame_id: CAMERA_FRAME.into(),
        translation: Some(Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        }),
        rotation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

fn block_entity(id: String, mesh: &Mesh, stamp: Timestamp) -> SceneEntity {
    let points = mesh
        .vertices
        .iter()
        .map(|v| Point3 {
            x: v[0] as f64,
            y: v[1] as f64,
            z: v[2] as f64,
        })
        .collect();
    let colors = mesh
        .colors
        .iter()
        .map(|c| Color {
            r: c[0] as f64 / 255.0,
            g: c[1] as f64 / 255.0,
            b: c[2] as f64 / 255.0,
            a: 1.0,
        })
        .collect();
    SceneEntity {
        timestamp: Some(stamp),
        frame_id: WORLD_FRAME.into(),
        id,
        frame_locked: true,
        triangles: vec![TriangleListPrimitive {
            pose: None,
            points,
            color: Some(Color {
                r: 0.7,
                g: 0.7,
                b: 0.7,
                a: 1.0,
            }),
            colors,
            indices: mesh.triangles.iter().flatten().copied().collect(),
        }],
        ..SceneEntity::default()
    }
}
