//! [`PanopticMap`]: the one object a robot program holds (nvblox's `Mapper`, Open3D's
//! `VoxelBlockGrid`).

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use rustc_hash::FxHashSet;

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{
    DepthImage, FrameCheckError, Intrinsics, LabelImage, Mesh, Pose, RgbdView, Segments,
};

use crate::associate::{
    AssociationStats, InstanceTracker, Surface, claiming_pixels, class_families, observe,
};
use crate::esdf::{Costmap, ESDF_BLOCK_BYTES, Esdf, EsdfStats};
use crate::integrate::{Claims, FrameInstances, IntegrationStats, TsdfIntegrator};
use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, UpdateBits, VoxelIndex};
use crate::mesh::{Coloring, MeshLayer, id_color};
use crate::render::{RaySpan, RenderedView, instances_at_depth, raycast};
use crate::serialize::{self, MapFileError};
use crate::{ConfigError, MapConfig};

/// Consumer slots of the map's own mesher and distance field; publishers get the others.
const MESHER: u8 = 0;
const ESDF: u8 = 1;

/// How a frame's segment ids become map instances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Labelling {
    /// Matched with the map's instances by the tracker (a network's per-frame ids).
    Tracked,
    /// Segment ids are instance ids (ground truth, an upstream tracker).
    Identified,
    /// Segment ids are instance ids the map rendered itself (frames between keyframes).
    Carried,
}

/// Why the map refused something.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    #[error("invalid map configuration: {0}")]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Frame(#[from] FrameCheckError),
    #[error("the segments' label image is {found:?}, the frame {expected:?}")]
    SegmentsSize {
        found: (usize, usize),
        expected: (usize, usize),
    },
    #[error(transparent)]
    File(#[from] MapFileError),
    #[error(
        "every change-consumer slot is taken (at most {} besides the mesher and the distance field)",
        u8::BITS - 2
    )]
    NoConsumerSlot,
    #[error(
        "the map would grow to {} ({blocks} blocks of {} voxels), past its memory limit of {}; \
         use a coarser tsdf.voxel_size or a shorter tsdf.max_range, or raise the limit (--max-memory)",
        human_bytes(*needed), crate::layer::VOXELS_PER_BLOCK, human_bytes(*limit)
    )]
    MemoryLimit {
        blocks: usize,
        needed: u64,
        limit: u64,
    },
}

/// Bytes of one voxel in memory: distance, weight, colour and instance evidence.
pub const VOXEL_BYTES: usize = std::mem::size_of::<crate::layer::TsdfVoxel>()
    + std::mem::size_of::<crate::layer::LabelVoxel>();

/// Voxels in one block (8³).
pub const BLOCK_VOXELS: usize = crate::layer::VOXELS_PER_BLOCK;

/// Bytes one allocated block holds: its voxels and labels, plus the hash-map entry, two
/// boxes' allocator headers, the per-instance surface counts (a vector of 4-byte pairs, a
/// few per block) and the list of instances its labels hold (a vector of 2-byte ids): an
/// estimate, 168 bytes, under 3 % of a block.
pub const BLOCK_BYTES: u64 = (BLOCK_VOXELS * VOXEL_BYTES + 168) as u64;

/// A set of instance ids, one bit each: looked up per voxel and per mesh vertex.
#[derive(Clone, Debug)]
struct InstanceSet(Box<[u64]>);

impl InstanceSet {
    fn new(ids: impl IntoIterator<Item = u16>) -> Self {
        let mut bits = vec![0u64; (u16::MAX as usize + 1) / 64].into_boxed_slice();
        for id in ids {
            bits[id as usize / 64] |= 1 << (id % 64);
        }
        Self(bits)
    }

    #[inline]
    fn contains(&self, id: u16) -> bool {
        self.0[id as usize / 64] >> (id % 64) & 1 == 1
    }
}

/// `1.5 GB`, `320 MB`: sizes in messages.
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.0} MB", b / 1e6)
    } else {
        format!("{:.0} kB", b / 1e3)
    }
}

/// What integrating one frame did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameReport {
    pub integration: IntegrationStats,
    /// `None` when the frame came without segments.
    pub association: Option<AssociationStats>,
    /// Milliseconds spent matching segments to instances.
    pub track_ms: f64,
    /// Milliseconds spent fusing depth, colour and instances, block planning included.
    /// Planning runs beside matching, so the two times may add up to more than the frame's.
    pub integrate_ms: f64,
    /// Blocks dropped after the frame as beyond `tsdf.keep_radius`.
    pub dropped_blocks: usize,
    /// Milliseconds spent consolidating the map after the frame, when
    /// `tracking.consolidate_every` called for it.
    pub consolidate_ms: Option<f64>,
}

/// An axis-aligned box, metres.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Bounds {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Bounds {
    fn grow(b: &mut Option<Bounds>, p: &Point3<f64>, half: f64) {
        let (lo, hi) = (
            [p.x - half, p.y - half, p.z - half],
            [p.x + half, p.y + half, p.z + half],
        );
        match b {
            None => *b = Some(Bounds { min: lo, max: hi }),
            Some(b) => {
                for a in 0..3 {
                    b.min[a] = b.min[a].min(lo[a]);
                    b.max[a] = b.max[a].max(hi[a]);
                }
            }
        }
    }

    /// The box around both (either may be absent).
    fn union(a: Option<Bounds>, b: Option<Bounds>) -> Option<Bounds> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Bounds {
                min: std::array::from_fn(|k| a.min[k].min(b.min[k])),
                max: std::array::from_fn(|k| a.max[k].max(b.max[k])),
            }),
            (a, b) => a.or(b),
        }
    }

    /// Edge lengths.
    pub fn size(&self) -> [f64; 3] {
        std::array::from_fn(|a| self.max[a] - self.min[a])
    }
}

/// One map instance as the map knows it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InstanceSummary {
    pub id: u16,
    /// The most voted class id of the segments assigned to it, if any said.
    pub class_id: Option<u32>,
    /// That class's name, when the map knows its segmenter's label table.
    pub class_name: Option<String>,
    /// Whether most of its segments said "thing".
    pub is_thing: bool,
    /// Labelled surface voxels that carry it.
    pub voxels: usize,
    /// Box around those voxels.
    pub bounds: Option<Bounds>,
    /// Frames in which a segment was assigned to it.
    pub frames_seen: u32,
}

/// An observed voxel: where it is, what it measured and which instance leads it.
/// [`PanopticMap::surface_voxels`] yields those near the surface (|distance| below one voxel),
/// [`PanopticMap::voxel`] any observed voxel, however far from the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObservedVoxel {
    /// Global voxel coordinates (unique per voxel in the map).
    pub index: VoxelIndex,
    /// The voxel's centre, metres.
    pub position: Point3<f64>,
    pub distance: f32,
    pub weight: f32,
    pub color: [u8; 3],
    /// Map instance (0 = none).
    pub instance: u16,
}

/// Per instance: surface voxels, and the box around them.
type Extents = BTreeMap<u16, (usize, Option<Bounds>)>;

/// Counts a surface voxel centred at `p` (half a voxel `half`) towards instance `id`.
fn add_to_extent(extents: &mut Extents, id: u16, p: &Point3<f64>, half: f64) {
    let e = extents.entry(id).or_default();
    e.0 += 1;
    Bounds::grow(&mut e.1, p, half);
}

/// A registered consumer of map changes (see [`PanopticMap::subscribe`]).
#[derive(Debug, PartialEq, Eq)]
pub struct ChangeConsumer(u8);

/// A panoptic TSDF map: depth, colour and instances fused on hashed voxel blocks, with
/// association, incremental meshing, ray casting and a map file.
///
/// ```
/// use voxpan_core::{Frame, Image, Intrinsics, Pose};
/// use voxpan_map::{Coloring, MapConfig, PanopticMap};
///
/// let k = Intrinsics { width: 80, height: 60, fx: 40.0, fy: 40.0, cx: 40.0, cy: 30.0 };
/// // A wall 1.5 m in front of the camera.
/// let frame = Frame {
///     id: "0".into(),
///     timestamp: 0.0,
///     color: Image::filled(80, 60, [200, 180, 160]),
///     depth: Image::filled(80, 60, 1.5),
///     pose: Pose::identity(),
///     intrinsics: k,
///     segments: None,
///     ground_truth: None,
/// };
/// let mut map = PanopticMap::new(MapConfig::default())?;
/// map.integrate(frame.view(), None)?;
/// let mesh = map.mesh(Coloring::Rgb);
/// assert!(mesh.triangles.len() > 1000);
/// // Seen again from where it was taken, the wall is 1.5 m away.
/// let view = map.render(&k, &Pose::identity());
/// assert!((view.depth.get(40, 30) - 1.5).abs() < 0.01);
/// # Ok::<(), voxpan_map::MapError>(())
/// ```
#[derive(Clone, Debug)]
pub struct PanopticMap {
    config: MapConfig,
    layer: Layer,
    integrator: TsdfIntegrator,
    tracker: InstanceTracker,
    meshes: MeshLayer,
    /// Change-consumer slots in use (bits [`MESHER`] and [`ESDF`] always).
    consumers: u8,
    /// The distance field, once [`update_esdf`](Self::update_esdf) built it.
    esdf: Option<Esdf>,
    /// Per instance, the surface voxels it led in blocks dropped by
    /// [`remove_blocks_beyond`](Self::remove_blocks_beyond), and their box.
    dropped: Extents,
    /// The blocks [`remove_blocks_beyond`](Self::remove_blocks_beyond) dropped since the last
    /// [`save_dropped_blocks`](Self::save_dropped_blocks), when they are kept for writing
    /// out (`None`: dropped blocks are discarded).
    dropped_blocks: Option<Layer>,
    /// Names of the class ids segments carry, when the segmenter's label table is known.
    class_names: BTreeMap<u32, String>,
    /// Most bytes of blocks integration may hold (`None`: unbounded).
    memory_limit: Option<u64>,
    /// The instances outputs show: confirmed, leading `tracking.min_voxels` surface voxels
    /// (kept up to date by everything that changes either), and not judged out.
    shown: InstanceSet,
    /// Instances scattered or overruled when the map was last consolidated (see
    /// [`Self::judge_instances`]), sorted.
    judged_out: Vec<u16>,
    /// Frames with segments since the map was last consolidated.
    unconsolidated_frames: u32,
}

impl PanopticMap {
    /// An empty map; the configuration is checked first.
    pub fn new(config: MapConfig) -> Result<Self, MapError> {
        config.validate()?;
        Ok(Self {
            config,
            layer: empty_layer(&config),
            integrator: TsdfIntegrator::new(config.tsdf, config.esdf.enabled),
            tracker: InstanceTracker::new(config.tracking),
            meshes: MeshLayer::default(),
            consumers: 1 << MESHER | 1 << ESDF,
            esdf: None,
            dropped: BTreeMap::new(),
            dropped_blocks: None,
            class_names: BTreeMap::new(),
            memory_limit: None,
            shown: InstanceSet::new([]),
            judged_out: Vec::new(),
            unconsolidated_frames: 0,
        })
    }

    pub fn config(&self) -> &MapConfig {
        &self.config
    }

    pub fn voxel_size(&self) -> f64 {
        self.layer.voxel_size()
    }

    /// Allocated blocks (`8³` voxels each).
    pub fn block_count(&self) -> usize {
        self.layer.len()
    }

    /// The allocated blocks' indices (block coordinates: a voxel's global index divided by
    /// 8, rounded down), sorted.
    pub fn block_indices(&self) -> Vec<BlockIndex> {
        self.layer.sorted_indices()
    }

    /// Bytes the map's blocks hold ([`BLOCK_BYTES`] each, and the distance field's; meshes
    /// not counted).
    pub fn memory_bytes(&self) -> u64 {
        let kept = self.dropped_blocks.as_ref().map_or(0, Layer::len);
        (self.layer.len() + kept) as u64 * BLOCK_BYTES
            + self
                .esdf
                .as_ref()
                .map_or(0, |e| e.len() as u64 * ESDF_BLOCK_BYTES)
    }

    /// Bytes a new block takes: with the distance field on, each TSDF block gets one of the
    /// field's too.
    fn block_bytes(&self) -> u64 {
        BLOCK_BYTES + u64::from(self.config.esdf.enabled) * ESDF_BLOCK_BYTES
    }

    /// Bounds the memory blocks may take: a frame that would allocate past `bytes` is refused
    /// with [`MapError::MemoryLimit`] before anything changes (`None`: no bound).
    pub fn set_memory_limit(&mut self, bytes: Option<u64>) {
        self.memory_limit = bytes;
    }

    pub fn memory_limit(&self) -> Option<u64> {
        self.memory_limit
    }

    /// The most bytes one frame of camera `k` can add to the map under this configuration
    /// (every sampled pixel's band in blocks never seen): what a memory budget must allow for
    /// a single frame.
    pub fn frame_memory_bound(&self, k: &Intrinsics) -> u64 {
        self.integrator.frame_block_bound(k, self.voxel_size()) as u64 * self.block_bytes()
    }

    /// Voxels in allocated blocks, observed or not.
    pub fn allocated_voxels(&self) -> usize {
        self.layer.allocated_voxels()
    }

    /// Fuses one camera frame: depth, colour, camera and pose (a dataset's
    /// [`Frame::view`](voxpan_core::Frame::view)). With `segments` (the frame's refined
    /// segmentation), each segment is first matched to a map instance (or founds one) and its
    /// pixels' instances are fused too. Errors leave the map unchanged.
    pub fn integrate(
        &mut self,
        frame: RgbdView<'_>,
        segments: Option<&Segments>,
    ) -> Result<FrameReport, MapError> {
        self.integrate_with(frame, segments, Labelling::Tracked)
    }

    fn integrate_with(
        &mut self,
        frame: RgbdView<'_>,
        segments: Option<&Segments>,
        labelling: Labelling,
    ) -> Result<FrameReport, MapError> {
        frame.check()?;
        let expected = (frame.intrinsics.width, frame.intrinsics.height);
        if let Some(s) = segments
            && s.labels.dims() != expected
        {
            return Err(MapError::SegmentsSize {
                found: s.labels.dims(),
                expected,
            });
        }
        let mut report = FrameReport::default();
        // Planning the blocks and associating the segments only read the map: they run side
        // by side (this thread is the pipeline's critical path) unless the frame could reach
        // the memory limit, which must refuse it before the tracker changes.
        let within_limit = self.memory_limit.is_none_or(|limit| {
            self.memory_bytes() + self.frame_memory_bound(frame.intrinsics) <= limit
        });
        let (layer, limit) = (&self.layer, self.memory_limit);
        let block_bytes = self.block_bytes();
        let plan = || {
            let t = Instant::now();
            let touched = self
                .integrator
                .plan(layer, frame.depth, frame.pose, frame.intrinsics);
            (touched, t.elapsed().as_secs_f64() * 1e3)
        };
        let (tracker, tsdf, downscale) = (
            &mut self.tracker,
            &self.config.tsdf,
            self.config.tracking.downscale,
        );
        let mut track = || {
            let t = Instant::now();
            let assignment = segments.map(|s| {
                match labelling {
                    Labelling::Identified => return tracker.identified(&s.labels, &s.segments),
                    Labelling::Carried => return tracker.carried(&s.labels, &s.segments),
                    Labelling::Tracked => {}
                }
                let mut surface =
                    Surface::new(layer, frame.depth, frame.pose, frame.intrinsics, tsdf);
                let observed = observe(&mut surface, downscale);
                tracker.assign(&s.labels, &s.segments, &observed, &mut surface)
            });
            (assignment, t.elapsed().as_secs_f64() * 1e3)
        };
        let ((touched, plan_ms), (assignment, track_ms)) = if within_limit {
            let (planned, tracked) = rayon::join(plan, track);
            debug_assert!(
                check_memory(&self.layer, limit, &planned.0, block_bytes).is_ok(),
                "the frame's block bound bounds what it plans"
            );
            (planned, tracked)
        } else {
            let planned = plan();
            check_memory(layer, limit, &planned.0, block_bytes)?;
            (planned, track())
        };
        let t = Instant::now();
        if let Some(a) = &assignment {
            self.apply_merges(&a.merges);
        }
        report.track_ms = track_ms + t.elapsed().as_secs_f64() * 1e3;
        report.association = assignment.as_ref().map(|a| a.stats);
        let t = Instant::now();
        let claims = match (&assignment, labelling) {
            (Some(a), Labelling::Tracked) => self.flush_claims(&a.instances, &frame),
            _ => None,
        };
        report.integration = self.integrator.integrate(
            &mut self.layer,
            &touched,
            frame.depth,
            Some(frame.color),
            assignment.as_ref().map(|a| match labelling {
                Labelling::Carried => FrameInstances::carried(&a.instances),
                _ => FrameInstances {
                    claims: claims
                        .as_ref()
                        .map(|(pixels, stuff)| Claims { pixels, stuff }),
                    ..FrameInstances::observed(&a.instances)
                },
            }),
            frame.pose,
            frame.intrinsics,
        );
        let keep_radius = self.config.tsdf.keep_radius;
        if keep_radius > 0.0 {
            // Not the frame's own blocks: depth is cut at max_range along the optical axis,
            // so the frustum's corners reach farther than any radius of that size.
            let camera = Point3::from(frame.pose.translation.vector);
            report.dropped_blocks = self.drop_blocks_beyond(&camera, keep_radius, &touched);
        }
        self.update_shown();
        report.integrate_ms = plan_ms + t.elapsed().as_secs_f64() * 1e3;
        // Identified ids are the segmenter's own decision: nothing for the tracker to join.
        if segments.is_some() && labelling != Labelling::Identified {
            self.unconsolidated_frames += 1;
            let every = self.config.tracking.consolidate_every;
            if every > 0 && self.unconsolidated_frames >= every {
                let t = Instant::now();
                self.consolidate();
                report.consolidate_ms = Some(t.elapsed().as_secs_f64() * 1e3);
            }
        }
        Ok(report)
    }

    /// Where the frame's shown flush things take their voxels from stuff (see
    /// `associate::claims`): per pixel of `instances`, and per instance id whether it is
    /// stuff. `None` when no shown flush thing is in the frame.
    fn flush_claims(
        &self,
        instances: &LabelImage,
        frame: &RgbdView<'_>,
    ) -> Option<(Vec<bool>, Vec<bool>)> {
        let ids = u16::MAX as usize + 1;
        let (mut claiming, mut stuff) = (vec![false; ids], vec![false; ids]);
        let mut any = false;
        for (&id, info) in &self.tracker.instances {
            match info.kind() {
                Some(false) => stuff[id as usize] = true,
                Some(true) if self.shown.contains(id) && self.tracker.is_flush(id) => {
                    claiming[id as usize] = true;
                    any = true;
                }
                _ => {}
            }
        }
        if !any {
            return None;
        }
        let pixels = claiming_pixels(
            instances,
            frame.depth,
            frame.intrinsics.fx,
            self.voxel_size(),
            &claiming,
        )?;
        Some((pixels, stuff))
    }

    /// Relabels the map for the tracker's merges `(from, into)`, in order: the voxels, the
    /// dropped blocks kept for writing out, and the dropped blocks' instance summaries.
    fn apply_merges(&mut self, merges: &[(u16, u16)]) {
        self.layer.relabel(merges);
        if let Some(kept) = &mut self.dropped_blocks {
            kept.relabel(merges);
        }
        for &(from, into) in merges {
            if let Some((voxels, bounds)) = self.dropped.remove(&from) {
                let e = self.dropped.entry(into).or_default();
                *e = (e.0 + voxels, Bounds::union(e.1, bounds));
            }
        }
    }

    /// Joins the instances the whole map shows to be one object, which frame-by-frame
    /// association could not (see the tracker's `consolidate`): confirmed instances, of any
    /// class, whose surfaces meet along a seam and that frames did not tell apart more often
    /// than they covered them together. Then hides the scattered and overruled instances (see
    /// [`Self::judge_instances`]) and fills the label holes: unlabelled surface that
    /// only one shown instance borders and that is smaller than it takes that instance
    /// (surface fused between keyframes, or that no mask covered; see `Layer::fill_label_holes`).
    /// `voxpan run`, `voxpan eval` and the map node call it once, after the last frame;
    /// with `tracking.consolidate_every` the map also calls it itself every that many frames.
    /// Returns the merges made.
    pub fn consolidate(&mut self) -> usize {
        self.unconsolidated_frames = 0;
        let touching = self.layer.touching_instances();
        let merges = self
            .tracker
            .consolidate(&touching, self.layer.surface_counts());
        self.apply_merges(&merges);
        // Judged before the holes are filled, so that a hidden instance fills none; filling
        // only grows the instances shown, and adds no runner-up, so none is judged out by it.
        self.judge_instances();
        let shown = &self.shown;
        self.layer.fill_label_holes(|id| shown.contains(id));
        self.update_shown();
        merges.len()
    }

    /// Hides, until it is called again, the instances the whole map says are not objects:
    /// - **scattered**: none of its pieces of surface holds `tracking.min_voxels` voxels (its
    ///   surface voxels linked through steps within the TSDF truncation distance, within which
    ///   integration fuses measurements into one surface). An object is one piece; an instance
    ///   out-voted almost everywhere its masks reached keeps a few voxels scattered over that
    ///   region, which counted together pass `min_voxels`.
    /// - **overruled**: most of its own label counts lie in voxels where it is the runner-up
    ///   to a thing (see `Layer::label_votes`), not in voxels it leads: the frames that saw
    ///   that surface mostly said it was the other thing, as when a network's mask of a small
    ///   false object merges into the table under it in other views. Losses under stuff do
    ///   not count, since masks spill over the wall behind a thing.
    ///
    /// [`consolidate`](Self::consolidate) calls it; a map fed identified segments (which it
    /// never consolidates) may call it after its last frame. Instances with surface in
    /// dropped blocks are not judged (that surface is gone). Returns how many instances are
    /// judged out, counting those also hidden for another reason (unconfirmed, too small).
    pub fn judge_instances(&mut self) -> usize {
        let min_voxels = self.config.tracking.min_voxels;
        let instances = &self.tracker.instances;
        let votes = self
            .layer
            .label_votes(|id| instances.get(&id).is_some_and(|i| i.is_thing()));
        let overruled = votes
            .into_iter()
            .filter(|(_, v)| v.won > 0 && v.won <= v.lost_to_things)
            .map(|(id, _)| id);
        let mut judged_out: Vec<u16> = self
            .layer
            .scattered_instances(min_voxels)
            .into_iter()
            .chain(overruled)
            .filter(|id| !self.dropped.contains_key(id))
            .collect();
        judged_out.sort_unstable();
        judged_out.dedup();
        self.judged_out = judged_out;
        self.update_shown();
        self.judged_out.len()
    }

    /// Drops every block whose centre lies farther than `radius` metres from `centre`, with
    /// its mesh and distance field (voxblox's `max_block_distance_from_body`); returns how
    /// many. Instances keep their summaries: the surface voxels they led in dropped blocks
    /// still count towards [`instances`](Self::instances) and `tracking.min_voxels` (an area
    /// seen again counts again). Maps built with `tsdf.keep_radius` do this after every frame, but
    /// for the blocks the frame itself touched. With
    /// [`keep_dropped_blocks`](Self::keep_dropped_blocks) the blocks are kept to be written out.
    pub fn remove_blocks_beyond(&mut self, centre: &Point3<f64>, radius: f64) -> usize {
        self.drop_blocks_beyond(centre, radius, &FxHashSet::default())
    }

    /// [`remove_blocks_beyond`](Self::remove_blocks_beyond) but for the blocks in `keep`.
    fn drop_blocks_beyond(
        &mut self,
        centre: &Point3<f64>,
        radius: f64,
        keep: &FxHashSet<BlockIndex>,
    ) -> usize {
        let mut far: Vec<BlockIndex> = self
            .layer
            .iter()
            .map(|(i, _)| *i)
            .filter(|i| (self.layer.block_center(i) - centre).norm() > radius && !keep.contains(i))
            .collect();
        if far.is_empty() {
            return 0;
        }
        far.sort_unstable();
        let (voxel, half) = (self.voxel_size(), self.voxel_size() / 2.0);
        for index in &far {
            let block = self.layer.remove(index).expect("listed");
            for i in 0..block.voxels.len() {
                let id = block.labels[i].instance();
                if id != 0 && self.layer.is_surface(&block.voxels.get(i)) {
                    let p = Block::voxel_center(*index, i, voxel);
                    add_to_extent(&mut self.dropped, id, &p, half);
                }
            }
            if let Some(kept) = &mut self.dropped_blocks {
                // A block dropped again after it was seen anew replaces the older copy.
                kept.insert(*index, block);
            }
        }
        self.meshes.remove(&self.layer, &far);
        if let Some(esdf) = &mut self.esdf {
            esdf.update(&self.layer, &far);
        }
        self.update_shown();
        far.len()
    }

    /// Keeps the blocks [`remove_blocks_beyond`](Self::remove_blocks_beyond) drops (and
    /// `tsdf.keep_radius` after each frame) until [`save_dropped_blocks`] writes them out,
    /// instead of discarding them; `false` discards them again, with any kept.
    ///
    /// [`save_dropped_blocks`]: Self::save_dropped_blocks
    pub fn keep_dropped_blocks(&mut self, keep: bool) {
        self.dropped_blocks = keep.then(|| {
            self.dropped_blocks
                .take()
                .unwrap_or_else(|| empty_layer(&self.config))
        });
    }

    /// Blocks dropped and kept, not yet written out.
    pub fn dropped_block_count(&self) -> usize {
        self.dropped_blocks.as_ref().map_or(0, Layer::len)
    }

    /// Writes the dropped blocks kept so far to `path` as a map file of their own (this map's
    /// configuration, instances and class names, with only those blocks: `load`, `voxpan
    /// mesh` and `voxpan info` read it), atomically, then lets them go; returns how many.
    /// Nothing is written, and they stay kept, if none are kept or the write fails.
    pub fn save_dropped_blocks(&mut self, path: &Path) -> Result<usize, MapError> {
        let Some(kept) = self.dropped_blocks.as_mut().filter(|k| k.len() > 0) else {
            return Ok(0);
        };
        serialize::save(
            path,
            &self.config,
            kept,
            &self.tracker.instances,
            &self.class_names,
        )?;
        Ok(std::mem::replace(kept, empty_layer(&self.config)).len())
    }

    /// Recomputes which instances are shown from the tracker's confirmations and the layer's
    /// surface counts (kept per instance as blocks change: a pass over instances, not voxels).
    fn update_shown(&mut self) {
        let min_voxels = self.config.tracking.min_voxels;
        let counts = self.layer.surface_counts();
        let shown = self
            .tracker
            .instances
            .iter()
            .filter(|(_, info)| info.confirmed && info.earned())
            .map(|(&id, _)| id)
            .filter(|id| self.judged_out.binary_search(id).is_err())
            .filter(|id| {
                let dropped = self.dropped.get(id).map_or(0, |d| d.0);
                min_voxels == 0 || counts.get(id).copied().unwrap_or(0) + dropped >= min_voxels
            });
        self.shown = InstanceSet::new(shown);
    }

    /// Fuses one frame whose segment ids already identify objects across frames (ground
    /// truth, or an upstream tracker): each segment id is used as the map instance id, with no
    /// association. An instance is shown once seen in `tracking.min_observations` frames, as a
    /// tracked one is. A map should be built either this way or with
    /// [`integrate`](Self::integrate), not both (their ids would mix).
    pub fn integrate_identified(
        &mut self,
        frame: RgbdView<'_>,
        segments: &Segments,
    ) -> Result<FrameReport, MapError> {
        self.integrate_with(frame, Some(segments), Labelling::Identified)
    }

    /// Fuses one frame between keyframes, labelled with the map's own instances:
    /// `segments` are [`carried_segments`](Self::carried_segments) at the frame's pose,
    /// refined on its depth. Geometry and colour fuse as usual, but the masks label only
    /// voxels that hold no instance yet, and no instance is founded, confirmed, voted for or
    /// told apart: only a segmenter's masks are evidence. Counted where the map already has a
    /// label, the map's own labels outvoted the keyframes four to one at every 5 and kept what
    /// the map had wrong (docs/network.md).
    pub fn integrate_carried(
        &mut self,
        frame: RgbdView<'_>,
        segments: &Segments,
    ) -> Result<FrameReport, MapError> {
        self.integrate_with(frame, Some(segments), Labelling::Carried)
    }

    /// The map's shown instances at the surface a camera measures, as a frame's segments:
    /// each pixel of `depth` (a frame's depth, with intrinsics `k`, at `pose`) takes the
    /// instance of the voxel its depth lands in; segment id = map instance id, with the
    /// instance's class and kind. Frames between keyframes take these for masks instead of
    /// running a network. Give the depth the frame is integrated with (holes filled): a pixel
    /// the sensor missed then takes the surface it is fused into, as a network's mask covers
    /// it (looked up at the measured depth, the synthetic rooms' holes left a tenth of each
    /// frame unlabelled). Pixels whose surface the map has not labelled (new, moved, or
    /// never segmented) stay 0, as do instances not yet shown: carrying fragments a keyframe
    /// has not confirmed lowered the tracker's voxel PQ everywhere it was measured
    /// (docs/network.md).
    ///
    /// A ray cast ([`render`](Self::render)) would find the same surface, but it cost as much
    /// as the network (flat, 2 cm: 167 ms a frame against 166 for YOLOv5s-seg at 640 px);
    /// the frame's own depth says where the surface is, so one voxel look-up per pixel does.
    pub fn carried_segments(&self, depth: &DepthImage, k: &Intrinsics, pose: &Pose) -> Segments {
        let span = RaySpan {
            near: self.config.tsdf.min_range,
            far: self.config.tsdf.max_range,
        };
        let mut labels = instances_at_depth(&self.layer, depth, k, pose, span);
        let mut seen = vec![false; u16::MAX as usize + 1];
        for id in labels.pixels_mut() {
            *id = self.shown(*id);
            seen[*id as usize] = true;
        }
        let segments = (1..=u16::MAX)
            .filter(|&id| seen[id as usize])
            .map(|id| {
                let info = self.tracker.instances.get(&id);
                voxpan_core::Segment {
                    id,
                    class_id: info.and_then(|i| i.class()),
                    is_thing: info.and_then(|i| i.kind()),
                    score: None,
                }
            })
            .collect();
        Segments { labels, segments }
    }

    /// Re-extracts the mesh where integration changed the map since the last call. Returns
    /// the blocks whose mesh changed (sorted).
    pub fn update_mesh(&mut self) -> Vec<BlockIndex> {
        let changed = self.take_changes_of(MESHER);
        self.meshes.update(&self.layer, &changed)
    }

    /// The whole map's mesh, brought up to date first: welded (each vertex once) with
    /// area-weighted normals, coloured as asked.
    pub fn mesh(&mut self, coloring: Coloring) -> Mesh {
        self.update_mesh();
        let mesh = self.meshes.combined();
        self.colored(mesh, coloring)
    }

    /// The blocks [`Self::block_mesh`] has a mesh for (as of the last [`Self::update_mesh`]),
    /// sorted: what a viewer that joins late needs to draw the whole map.
    pub fn mesh_blocks(&self) -> Vec<BlockIndex> {
        self.meshes.indices()
    }

    /// One block's current mesh (as of the last [`update_mesh`](Self::update_mesh)), indexed
    /// within the block; `None` where the block has no surface.
    pub fn block_mesh(&self, index: &BlockIndex, coloring: Coloring) -> Option<Mesh> {
        let mesh = self.meshes.get(index)?.to_mesh();
        Some(self.colored(mesh, coloring))
    }

    /// Recolours `mesh` (a mesh of this map, with instances) in place, by instance or class;
    /// `Coloring::Rgb` leaves it as it is (the camera colours cannot be recovered).
    pub fn recolor(&self, mesh: &mut Mesh, coloring: Coloring) {
        let color = |id: u16| match coloring {
            Coloring::Rgb => None,
            Coloring::Instance => Some(id_color(self.shown(id) as u32)),
            Coloring::Class => Some(id_color(self.class_of(id).map_or(0, |c| c + 1))),
        };
        if coloring == Coloring::Rgb {
            return;
        }
        mesh.colors.resize(mesh.vertices.len(), [0; 3]);
        for (c, &id) in mesh.colors.iter_mut().zip(&mesh.instances) {
            if let Some(new) = color(id) {
                *c = new;
            }
        }
    }

    fn colored(&self, mut mesh: Mesh, coloring: Coloring) -> Mesh {
        for id in &mut mesh.instances {
            *id = self.shown(*id);
        }
        match coloring {
            Coloring::Rgb => mesh,
            Coloring::Instance => mesh.colored_by(|id| id_color(id as u32)),
            Coloring::Class => {
                mesh.colored_by(|id| id_color(self.class_of(id).map_or(0, |c| c + 1)))
            }
        }
    }

    /// The class of shown map instance `id`, when its segments said.
    pub fn class_of(&self, id: u16) -> Option<u32> {
        if !self.shown.contains(id) {
            return None;
        }
        self.tracker.instances.get(&id).and_then(|i| i.class())
    }

    /// `id` if it is a shown instance, else 0: instances not yet re-observed, or smaller than
    /// `tracking.min_voxels`, stay hidden.
    #[inline]
    fn shown(&self, id: u16) -> u16 {
        if id != 0 && self.shown.contains(id) {
            id
        } else {
            0
        }
    }

    /// Names the class ids the segments carry (the segmenter's label table); kept in the map
    /// file, and used for instance names and reports.
    pub fn set_class_names(&mut self, names: BTreeMap<u32, String>) {
        self.tracker.set_families(class_families(&names));
        self.class_names = names;
    }

    /// The names of the class ids segments carry (empty when the segmenter's label table is
    /// not known).
    pub fn class_names(&self) -> &BTreeMap<u32, String> {
        &self.class_names
    }

    /// The name of class `class`, if known.
    pub fn class_name(&self, class: u32) -> Option<&str> {
        self.class_names.get(&class).map(String::as_str)
    }

    /// Number of map instances (shown ones: re-observed, see `tracking.min_observations`, and
    /// not smaller than `tracking.min_voxels`).
    pub fn instance_count(&self) -> usize {
        self.tracker
            .instances
            .keys()
            .filter(|&&id| self.shown.contains(id))
            .count()
    }

    /// The shown instances (confirmed, leading `tracking.min_voxels` surface voxels) with
    /// their class, kind, size and extent, by id.
    pub fn instances(&self) -> Vec<InstanceSummary> {
        let mut extent = Extents::new();
        let half = self.voxel_size() / 2.0;
        for v in self.surface_voxels().filter(|v| v.instance != 0) {
            add_to_extent(&mut extent, v.instance, &v.position, half);
        }
        self.tracker
            .instances
            .iter()
            .filter(|(id, _)| self.shown.contains(**id))
            .map(|(&id, info)| {
                let (held, in_view) = extent.get(&id).copied().unwrap_or_default();
                let (dropped, out_of_view) = self.dropped.get(&id).copied().unwrap_or_default();
                let (voxels, bounds) = (held + dropped, Bounds::union(in_view, out_of_view));
                InstanceSummary {
                    id,
                    class_id: info.class(),
                    class_name: info
                        .class()
                        .and_then(|c| self.class_name(c))
                        .map(str::to_owned),
                    is_thing: info.is_thing(),
                    voxels,
                    bounds,
                    frames_seen: info.frames_seen,
                }
            })
            .collect()
    }

    /// Every observed voxel within one voxel of the surface, in a fixed order.
    pub fn surface_voxels(&self) -> impl Iterator<Item = ObservedVoxel> + '_ {
        let voxel_size = self.voxel_size();
        self.layer
            .sorted_indices()
            .into_iter()
            .flat_map(move |index| {
                let block = self.layer.get(&index).expect("listed");
                (0..block.voxels.len()).filter_map(move |i| {
                    let v = block.voxels.get(i);
                    self.layer.is_surface(&v).then(|| ObservedVoxel {
                        index: Block::voxel_index(index, i),
                        position: Block::voxel_center(index, i, voxel_size),
                        distance: self.layer.distance(&v),
                        weight: v.weight(),
                        color: v.color(),
                        instance: self.shown(block.labels[i].instance()),
                    })
                })
            })
    }

    /// The observed voxel containing `p`, if any.
    pub fn voxel(&self, p: &Point3<f64>) -> Option<ObservedVoxel> {
        let index = self.layer.voxel_index(p);
        let (block, i) = self.layer.locate(index)?;
        let v = block.voxels.get(i);
        let side = BLOCK_SIDE as i32;
        v.observed().then(|| ObservedVoxel {
            index,
            position: Block::voxel_center(index.map(|c| c.div_euclid(side)), i, self.voxel_size()),
            distance: self.layer.distance(&v),
            weight: v.weight(),
            color: v.color(),
            instance: self.shown(block.labels[i].instance()),
        })
    }

    /// The map seen from a camera with intrinsics `k` at `pose` (`T_world_camera`): a ray
    /// cast of the TSDF's zero crossing, out to the far side of the mapped space.
    pub fn render(&self, k: &Intrinsics, pose: &Pose) -> RenderedView {
        let origin = Point3::from(pose.translation.vector);
        let far = self.farthest_block_distance(&origin);
        let mut view = raycast(
            &self.layer,
            k,
            pose,
            RaySpan {
                near: self.config.tsdf.min_range,
                far,
            },
        );
        for id in view.instances.pixels_mut() {
            *id = self.shown(*id);
        }
        view
    }

    /// Distance from `p` to the farthest corner of the allocated blocks' bounding box.
    fn farthest_block_distance(&self, p: &Point3<f64>) -> f64 {
        let (mut lo, mut hi) = ([i32::MAX; 3], [i32::MIN; 3]);
        for (index, _) in self.layer.iter() {
            for a in 0..3 {
                lo[a] = lo[a].min(index[a]);
                hi[a] = hi[a].max(index[a] + 1);
            }
        }
        if lo[0] > hi[0] {
            return 0.0;
        }
        let s = self.layer.block_size();
        let mut far: f64 = 0.0;
        for c in 0..8 {
            let corner = Point3::new(
                if c & 1 == 0 { lo[0] } else { hi[0] } as f64 * s,
                if c & 2 == 0 { lo[1] } else { hi[1] } as f64 * s,
                if c & 4 == 0 { lo[2] } else { hi[2] } as f64 * s,
            );
            far = far.max((corner - p).norm());
        }
        far
    }

    /// Brings the Euclidean signed distance field up to date: built from every block on the
    /// first call, then updated from the blocks integration changed since the last (nvblox's
    /// `updateEsdf`). Distances and the costmap read the field as of the last call.
    ///
    /// Free space is known only where integration allocated it, which it does while
    /// `esdf.enabled` is set: on a map built without it, only the truncation band around the
    /// surface has distances.
    ///
    /// ```
    /// use voxpan_core::{Frame, Image, Intrinsics, Pose};
    /// use voxpan_core::nalgebra::Point3;
    /// use voxpan_map::{MapConfig, PanopticMap};
    ///
    /// let k = Intrinsics { width: 80, height: 60, fx: 40.0, fy: 40.0, cx: 40.0, cy: 30.0 };
    /// // A wall 1.5 m in front of the camera (which looks along +z).
    /// let frame = Frame {
    ///     id: "0".into(),
    ///     timestamp: 0.0,
    ///     color: Image::filled(80, 60, [200, 180, 160]),
    ///     depth: Image::filled(80, 60, 1.5),
    ///     pose: Pose::identity(),
    ///     intrinsics: k,
    ///     segments: None,
    ///     ground_truth: None,
    /// };
    /// let mut config = MapConfig::default();
    /// config.esdf.enabled = true;
    /// let mut map = PanopticMap::new(config)?;
    /// map.integrate(frame.view(), None)?;
    /// map.update_esdf();
    /// // Half a metre in front of the wall, and the way out is back towards the camera.
    /// let (d, gradient) = map.distance_and_gradient(&Point3::new(0.0, 0.0, 1.0)).unwrap();
    /// assert!((d - 0.5).abs() < 0.03, "{d}");
    /// assert!(gradient.z < -0.9);
    /// // Behind the wall nothing was seen.
    /// assert_eq!(map.distance(&Point3::new(0.0, 0.0, 2.5)), None);
    /// # Ok::<(), voxpan_map::MapError>(())
    /// ```
    pub fn update_esdf(&mut self) -> EsdfStats {
        let changed = match &self.esdf {
            Some(_) => self.take_changes_of(ESDF),
            None => {
                self.take_changes_of(ESDF);
                self.layer.sorted_indices()
            }
        };
        let (voxel, max_distance) = (self.voxel_size(), self.config.esdf.max_distance);
        self.esdf
            .get_or_insert_with(|| Esdf::new(voxel, max_distance))
            .update(&self.layer, &changed)
    }

    /// Whether [`update_esdf`](Self::update_esdf) has built the distance field.
    pub fn has_esdf(&self) -> bool {
        self.esdf.is_some()
    }

    /// Signed distance (metres) from `p` to the nearest surface, as of the last
    /// [`update_esdf`](Self::update_esdf): negative inside objects, capped at
    /// `esdf.max_distance`; `None` where the map has not observed `p` (or no field was built).
    pub fn distance(&self, p: &Point3<f64>) -> Option<f32> {
        self.esdf.as_ref()?.distance(p)
    }

    /// [`distance`](Self::distance) interpolated trilinearly between voxel centres, with its
    /// gradient (pointing away from the nearest surface); `None` unless the eight voxels
    /// around `p` are observed.
    pub fn distance_and_gradient(&self, p: &Point3<f64>) -> Option<(f32, Vector3<f32>)> {
        self.esdf.as_ref()?.distance_and_gradient(p)
    }

    /// Every voxel of the distance field with a distance (observed), and its signed distance:
    /// sites read 0.
    pub fn esdf_voxels(&self) -> Vec<(VoxelIndex, f32)> {
        self.esdf
            .as_ref()
            .map_or_else(Vec::new, |e| e.voxels().collect())
    }

    /// [`distance`](Self::distance) at many points, in parallel.
    pub fn distances(&self, points: &[Point3<f64>]) -> Vec<Option<f32>> {
        use rayon::prelude::*;
        points.par_iter().map(|p| self.distance(p)).collect()
    }

    /// [`distance_and_gradient`](Self::distance_and_gradient) at many points, in parallel.
    pub fn distances_and_gradients(
        &self,
        points: &[Point3<f64>],
    ) -> Vec<Option<(f32, Vector3<f32>)>> {
        use rayon::prelude::*;
        points
            .par_iter()
            .map(|p| self.distance_and_gradient(p))
            .collect()
    }

    /// The 2-D costmap of the distance field between `esdf.slice_min_z` and
    /// `esdf.slice_max_z` along `esdf.up_axis`, obstacles inflated by `esdf.robot_radius`
    /// (as of the last [`update_esdf`](Self::update_esdf)); `None` when nothing observed lies
    /// in that band.
    pub fn costmap(&self) -> Option<Costmap> {
        let c = &self.config.esdf;
        self.esdf.as_ref()?.costmap(
            [c.slice_min_z, c.slice_max_z],
            c.up_axis,
            c.robot_radius as f32,
        )
    }

    /// Changes the `[esdf]` settings a costmap is cut with and how far distances reach (a
    /// changed `max_distance` rebuilds the field on the next update). Whether integration
    /// allocates free space stays as the map was made.
    pub fn set_esdf_config(&mut self, esdf: crate::EsdfConfig) -> Result<(), MapError> {
        esdf.validate(self.voxel_size())?;
        if esdf.max_distance != self.config.esdf.max_distance {
            self.esdf = None;
        }
        self.config.esdf = crate::EsdfConfig {
            enabled: self.config.esdf.enabled,
            ..esdf
        };
        Ok(())
    }

    /// Registers a consumer of map changes (a publisher of changed blocks, a GPU copy): from
    /// now on [`take_changes`](Self::take_changes) gives it the blocks integration touched since
    /// it last asked, independently of every other consumer. It starts with every block.
    pub fn subscribe(&mut self) -> Result<ChangeConsumer, MapError> {
        let slot = (0..u8::BITS as u8)
            .find(|s| self.consumers >> s & 1 == 0)
            .ok_or(MapError::NoConsumerSlot)?;
        self.consumers |= 1 << slot;
        for (_, block) in self.layer.iter_mut() {
            block.updates.0 |= 1 << slot;
        }
        Ok(ChangeConsumer(slot))
    }

    /// Releases a consumer's slot.
    pub fn unsubscribe(&mut self, consumer: ChangeConsumer) {
        self.consumers &= !(1 << consumer.0);
    }

    /// The blocks changed since `consumer` last asked (sorted), and marks them seen by it.
    pub fn take_changes(&mut self, consumer: &ChangeConsumer) -> Vec<BlockIndex> {
        self.take_changes_of(consumer.0)
    }

    fn take_changes_of(&mut self, slot: u8) -> Vec<BlockIndex> {
        let mut changed: Vec<BlockIndex> = self
            .layer
            .iter_mut()
            .filter(|(_, b)| b.updates.has(slot))
            .map(|(i, b)| {
                b.updates.clear(slot);
                *i
            })
            .collect();
        changed.sort_unstable();
        changed
    }

    /// Writes the map (voxels, instances, configuration) to `path`, atomically.
    pub fn save(&self, path: &Path) -> Result<(), MapError> {
        Ok(serialize::save(
            path,
            &self.config,
            &self.layer,
            &self.tracker.instances,
            &self.class_names,
        )?)
    }

    /// An upper bound of the map file's size (for checking free space before saving).
    pub fn file_size_estimate(&self) -> u64 {
        serialize::size_bound(&self.layer)
    }

    /// The map file's bytes (what [`save`](Self::save) writes).
    pub fn to_bytes(&self) -> Vec<u8> {
        serialize::to_bytes(
            &self.config,
            &self.layer,
            &self.tracker.instances,
            &self.class_names,
        )
    }

    /// Reads a map written by [`save`](Self::save) (or by an older voxpan); mapping can go on
    /// from it.
    pub fn load(path: &Path) -> Result<Self, MapError> {
        Self::from_stored(serialize::load(path)?)
    }

    /// Parses a map file's bytes; `name` is used in error messages.
    pub fn from_bytes(bytes: &[u8], name: &Path) -> Result<Self, MapError> {
        Self::from_stored(serialize::from_bytes(bytes, name)?)
    }

    fn from_stored(stored: serialize::StoredMap) -> Result<Self, MapError> {
        let mut map = Self::new(stored.config)?;
        map.layer = stored.layer;
        for (_, block) in map.layer.iter_mut() {
            block.updates = UpdateBits::ALL;
        }
        map.tracker = InstanceTracker::with_instances(stored.config.tracking, stored.instances);
        map.set_class_names(stored.class_names);
        map.layer.count_surfaces();
        map.judge_instances();
        Ok(map)
    }
}

impl PartialEq for PanopticMap {
    /// Same configuration, voxels and instances (meshes and consumers are derived state).
    fn eq(&self, other: &Self) -> bool {
        self.config == other.config
            && self.class_names == other.class_names
            && self.tracker.instances == other.tracker.instances
            && self.layer.len() == other.layer.len()
            && self.layer.iter().all(|(i, b)| {
                other
                    .layer
                    .get(i)
                    .is_some_and(|o| o.voxels == b.voxels && o.labels == b.labels)
            })
    }
}

/// A layer of no blocks with the voxels `config` asks for.
fn empty_layer(config: &MapConfig) -> Layer {
    Layer::new(config.tsdf.voxel_size, config.tsdf.truncation())
}

/// Refuses a frame whose planned blocks would take the map past `limit` bytes.
fn check_memory(
    layer: &Layer,
    limit: Option<u64>,
    touched: &FxHashSet<BlockIndex>,
    block_bytes: u64,
) -> Result<(), MapError> {
    let Some(limit) = limit else {
        return Ok(());
    };
    let new = touched.iter().filter(|i| !layer.contains(i)).count();
    let blocks = layer.len() + new;
    let needed = blocks as u64 * block_bytes;
    if needed > limit {
        return Err(MapError::MemoryLimit {
            blocks,
            needed,
            limit,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use voxpan_core::nalgebra::{Translation3, UnitQuaternion};
    use voxpan_core::{Frame, Image, Segment};

    use super::*;

    /// Surface voxels by leading instance, counted voxel by voxel.
    fn scanned(layer: &Layer) -> rustc_hash::FxHashMap<u16, usize> {
        let mut counts = rustc_hash::FxHashMap::default();
        for (_, block) in layer.iter() {
            for (v, l) in block.voxels.iter().zip(block.labels.iter()) {
                if l.instance() != 0 && layer.is_surface(&v) {
                    *counts.entry(l.instance()).or_insert(0) += 1;
                }
            }
        }
        counts
    }

    #[test]
    fn block_surface_counts_follow_integration_and_merges() {
        let k = Intrinsics {
            width: 80,
            height: 60,
            fx: 40.0,
            fy: 40.0,
            cx: 40.0,
            cy: 30.0,
        };
        // A wall 1.5 m away, its left half segment 1 and its right half segment 2, seen
        // from a camera sliding sideways (so later frames move the surface band's voxels).
        let mut labels = Image::filled(80, 60, 1u16);
        for y in 0..60 {
            for x in 40..80 {
                *labels.get_mut(x, y) = 2;
            }
        }
        let segment = |id| Segment {
            id,
            class_id: Some(1),
            is_thing: Some(false),
            score: None,
        };
        let segments = Segments {
            labels,
            segments: vec![segment(1), segment(2)],
        };
        let mut map = PanopticMap::new(MapConfig::default()).unwrap();
        for i in 0..4 {
            let frame = Frame {
                id: i.to_string(),
                timestamp: 0.0,
                color: Image::filled(80, 60, [200, 180, 160]),
                depth: Image::filled(80, 60, 1.5 + 0.013 * i as f32),
                pose: Pose::from_parts(
                    Translation3::new(0.07 * i as f64, 0.0, 0.0),
                    UnitQuaternion::identity(),
                ),
                intrinsics: k,
                segments: None,
                ground_truth: None,
            };
            map.integrate_identified(frame.view(), &segments).unwrap();
            assert_eq!(map.layer.surface_counts(), &scanned(&map.layer));
        }
        assert_eq!(map.layer.surface_counts().len(), 2);
        map.layer.relabel(&[(2, 1)]);
        assert_eq!(map.layer.surface_counts(), &scanned(&map.layer));
        assert_eq!(map.layer.surface_counts().len(), 1);
    }
}
