//! Projective TSDF integration (voxblox's "projective" integrator): allocate the blocks around
//! the observed surface, then update every voxel of those blocks from the pixel it projects to.

use rustc_hash::FxHashSet;
use std::ops::RangeInclusive;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{ColorImage, DepthImage, Intrinsics, LabelImage, Pose, is_valid_depth};

use wide::{f32x4, f32x8};

#[cfg(target_arch = "x86_64")]
use crate::lanes::Avx2;
use crate::lanes::{Lanes, VectorUnit};

use super::prefetch::prefetch_rect;

use crate::TsdfConfig;
use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, TsdfVoxel, UpdateBits, on_surface_lanes};

/// What one integration did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct IntegrationStats {
    pub new_blocks: usize,
    pub updated_blocks: usize,
    pub updated_voxels: usize,
}

/// Fuses frames into a [`Layer`].
#[derive(Clone, Debug, Default)]
pub(crate) struct TsdfIntegrator {
    pub config: TsdfConfig,
    /// Also allocate the blocks between the camera and the band (the free space a distance
    /// field needs to know), not only those around the surface.
    pub free_space: bool,
}

impl TsdfIntegrator {
    pub fn new(config: TsdfConfig, free_space: bool) -> Self {
        Self { config, free_space }
    }

    /// The blocks a frame will update (its observed surface's truncation band): the first
    /// half of integration, so callers can check what it would allocate before any change.
    pub fn plan(
        &self,
        layer: &Layer,
        depth: &DepthImage,
        pose: &Pose,
        k: &Intrinsics,
    ) -> FxHashSet<BlockIndex> {
        let truncation = self.config.truncation_voxels * layer.voxel_size();
        self.blocks_near_surface(layer, depth, pose, k, truncation)
    }

    /// Integrates one depth frame (planar depth, metres) seen from `pose` (`T_world_camera`),
    /// with its colour and map-instance image (0 = no instance) when given, into the
    /// `touched` blocks from [`Self::plan`]. Labels are recorded only inside the truncation
    /// band.
    #[allow(clippy::too_many_arguments)]
    pub fn integrate(
        &self,
        layer: &mut Layer,
        touched: &FxHashSet<BlockIndex>,
        depth: &DepthImage,
        color: Option<&ColorImage>,
        instances: Option<FrameInstances<'_>>,
        pose: &Pose,
        k: &Intrinsics,
    ) -> IntegrationStats {
        // In index order, neighbouring blocks are updated one after the other and read
        // neighbouring pixels, which then stay in cache (the set's order is a hash's).
        let mut order: Vec<BlockIndex> = touched.iter().copied().collect();
        order.sort_unstable();
        let frame = FrameView::new(layer, self.config, depth, color, instances, pose, k);
        let (updated_voxels, new_blocks) =
            layer.update_blocks(&order, |index, block| update_block(index, block, &frame));
        IntegrationStats {
            new_blocks,
            updated_blocks: order.len(),
            updated_voxels,
        }
    }

    /// The most blocks one frame of camera `k` can touch: [`Self::integrate`] allocates
    /// blocks only at its sampled pixels' band points (and free-space points).
    pub fn frame_block_bound(&self, k: &Intrinsics, voxel: f64) -> usize {
        let (stride, steps) = self.sampling(k, voxel);
        let samples = k.width.div_ceil(stride) * k.height.div_ceil(stride);
        if !self.free_space {
            return samples * (steps + 1);
        }
        let by_samples = samples * (steps + 1 + self.free_steps(voxel, self.config.max_range) + 1);
        by_samples.min(self.frustum_block_bound(k, voxel))
    }

    /// The most blocks the view frustum can touch: every touched block holds a point of the
    /// frustum (depth up to the range plus the band), so it lies within a block diagonal `δ`
    /// of it, and blocks are disjoint. Within `δ` of the frustum, the cross-section at depth
    /// `u - δ` is at most `(a u + 2δ) × (b u + 2δ)` (`a`, `b`: the image's width and height
    /// over the focal lengths), for `u` up to `L` = depth + 2δ; its volume over a block's.
    fn frustum_block_bound(&self, k: &Intrinsics, voxel: f64) -> usize {
        let block = voxel * BLOCK_SIDE as f64;
        let delta = 3f64.sqrt() * block;
        let (a, b) = (k.width as f64 / k.fx, k.height as f64 / k.fy);
        let depth = self.config.max_range + self.config.truncation_voxels * voxel;
        let l = depth + 2.0 * delta;
        let volume =
            a * b * l.powi(3) / 3.0 + delta * (a + b) * l.powi(2) + 4.0 * delta * delta * l;
        (volume / block.powi(3)).ceil() as usize
    }

    /// Pixel stride and band steps of the block search.
    fn sampling(&self, k: &Intrinsics, voxel: f64) -> (usize, usize) {
        let block = voxel * BLOCK_SIDE as f64;
        let truncation = self.config.truncation_voxels * voxel;
        let stride =
            ((k.fx.min(k.fy) * block / (2.0 * self.config.max_range)).floor() as usize).max(1);
        // Along the ray through the band, at most half a block apart.
        let steps = ((2.0 * truncation / (0.5 * block)).ceil() as usize).max(1);
        (stride, steps)
    }

    /// Steps of at most half a block from the near range to `depth` along a ray.
    fn free_steps(&self, voxel: f64, depth: f64) -> usize {
        let block = voxel * BLOCK_SIDE as f64;
        ((depth - self.config.min_range).max(0.0) / (0.5 * block)).ceil() as usize
    }

    /// Blocks within the truncation band of the observed surface. Pixels are sampled with a
    /// stride of half a block's footprint at maximum range, so no block is skipped.
    fn blocks_near_surface(
        &self,
        layer: &Layer,
        depth: &DepthImage,
        pose: &Pose,
        k: &Intrinsics,
        truncation: f64,
    ) -> FxHashSet<BlockIndex> {
        let (stride, steps) = self.sampling(k, layer.voxel_size());
        let rotation = pose.rotation.to_rotation_matrix().into_inner();
        let translation = pose.translation.vector;
        let mut set = FxHashSet::default();
        // Per band step, the block the previous sample's point fell in: neighbouring samples
        // mostly share it, and skipping the repeat saves most of the set's hashing.
        let mut previous: Vec<Option<BlockIndex>> = vec![None; steps + 1];
        // What each sampled column's and band step's terms are, computed once per frame
        // rather than per sample (the same operations: `k.ray`'s and the band's).
        let columns: Vec<(usize, f64)> = (0..depth.width())
            .step_by(stride)
            .map(|u| (u, (u as f64 - k.cx) / k.fx))
            .collect();
        let band_offsets: Vec<f64> = (0..=steps)
            .map(|s| 2.0 * truncation * s as f64 / steps as f64)
            .collect();
        for v in (0..depth.height()).step_by(stride) {
            let ray_y = (v as f64 - k.cy) / k.fy;
            for &(u, ray_x) in &columns {
                let z = *depth.get(u, v) as f64;
                if !is_valid_depth(z as f32)
                    || z < self.config.min_range
                    || z > self.config.max_range
                {
                    continue;
                }
                // The ray in world axes once per pixel; each band point is a step along it.
                let ray = rotation * Vector3::new(ray_x, ray_y, 1.0);
                if self.free_space {
                    // From the near range to the band, the blocks the ray crosses (a step
                    // of half a block may clip a corner, which the next ray's covers).
                    let end = z - truncation;
                    let steps = self.free_steps(layer.voxel_size(), end);
                    let mut last = None;
                    for s in 0..=steps {
                        let d = self.config.min_range
                            + (end - self.config.min_range) * s as f64 / steps.max(1) as f64;
                        let block = layer.block_index(&Point3::from(ray * d + translation));
                        if last != Some(block) {
                            set.insert(block);
                            last = Some(block);
                        }
                    }
                }
                for (previous, offset) in previous.iter_mut().zip(&band_offsets) {
                    let d = z - truncation + offset;
                    let p = Point3::from(ray * d + translation);
                    let block = layer.block_index(&p);
                    if *previous != Some(block) {
                        set.insert(block);
                        *previous = Some(block);
                    }
                }
            }
        }
        set
    }
}

/// A frame's instance image (0 = no instance) and how its labels count in the voxels they land
/// on.
#[derive(Clone, Copy, Debug)]
pub struct FrameInstances<'a> {
    pub image: &'a LabelImage,
    /// Labels carried from the map itself (a frame between keyframes): they label only voxels
    /// holding no candidate yet. Elsewhere they would count the map's own label once more: at
    /// every 5, four echoes for each keyframe's observation, which kept whatever the map had
    /// wrong against the keyframes that saw it right (docs/network.md).
    pub fills_only: bool,
    /// Pixels whose thing takes the lead of the voxels stuff leads (see
    /// `associate::claims`).
    pub claims: Option<Claims<'a>>,
}

/// Where a thing's observation takes its voxel from the stuff leading it.
#[derive(Clone, Copy, Debug)]
pub struct Claims<'a> {
    /// Per pixel of the instance image: its observation takes the lead from stuff.
    pub pixels: &'a [bool],
    /// Per instance id: a stuff instance.
    pub stuff: &'a [bool],
}

impl<'a> FrameInstances<'a> {
    /// A segmenter's masks, matched to map instances: every label counts.
    pub fn observed(image: &'a LabelImage) -> Self {
        Self {
            image,
            fills_only: false,
            claims: None,
        }
    }

    /// The map's own instances carried into a frame: they only fill unlabelled voxels.
    pub fn carried(image: &'a LabelImage) -> Self {
        Self {
            image,
            fills_only: true,
            claims: None,
        }
    }
}

/// What every block's update reads of one frame.
struct FrameView<'a> {
    /// What the rows run on.
    vectors: VectorUnit,
    voxel: f64,
    /// The layer's band in metres (its f32 value: voxels store fractions of it).
    truncation: f64,
    config: TsdfConfig,
    depth: &'a DepthImage,
    color: Option<&'a ColorImage>,
    instances: Option<FrameInstances<'a>>,
    world_to_camera: Pose,
    k: &'a Intrinsics,
}

impl<'a> FrameView<'a> {
    /// One frame as `layer`'s blocks see it, on the widest vector unit this CPU has.
    fn new(
        layer: &Layer,
        config: TsdfConfig,
        depth: &'a DepthImage,
        color: Option<&'a ColorImage>,
        instances: Option<FrameInstances<'a>>,
        pose: &Pose,
        k: &'a Intrinsics,
    ) -> Self {
        Self {
            vectors: VectorUnit::detect(),
            voxel: layer.voxel_size(),
            // The layer's band (the configuration's, in f32): voxels store fractions of it.
            truncation: layer.truncation() as f64,
            config,
            depth,
            color,
            instances,
            world_to_camera: pose.inverse(),
            k,
        }
    }
}

/// A block's voxel grid in the camera frame, in f32: its first voxel's centre, the rotated
/// voxel axes that step from it (a block is a regular grid), and the frame's constants every
/// voxel's projection and blend use.
struct BlockInCamera {
    /// The centre of voxel (0, 0, 0).
    first: Vector3<f32>,
    /// One voxel along the block's x, y and z.
    axes: [Vector3<f32>; 3],
    /// `[fx, fy, cx, cy]` in pixels.
    pinhole: [f32; 4],
    /// Depths integrated: `[min_range, max_range]`.
    range: [f32; 2],
    /// The band's half-width in metres, and one over it.
    band: [f32; 2],
    /// The voxel's edge in metres.
    voxel: f32,
    /// Projections at or beyond these (image width and height less half a pixel) have no
    /// nearest pixel.
    image_end: [f32; 2],
}

impl BlockInCamera {
    fn new(index: BlockIndex, frame: &FrameView) -> Self {
        let FrameView {
            voxel,
            truncation,
            config,
            depth,
            world_to_camera,
            k,
            ..
        } = frame;
        let voxel = *voxel;
        let rotation = world_to_camera.rotation.to_rotation_matrix();
        let axis = |a: usize| {
            let mut v = Vector3::zeros();
            v[a] = voxel;
            (rotation * v).cast::<f32>()
        };
        let (w, h) = depth.dims();
        Self {
            first: (world_to_camera * Block::voxel_center(index, 0, voxel))
                .coords
                .cast::<f32>(),
            axes: [axis(0), axis(1), axis(2)],
            pinhole: [k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32],
            range: [config.min_range as f32, config.max_range as f32],
            band: [*truncation as f32, 1.0 / *truncation as f32],
            voxel: voxel as f32,
            image_end: [w as f32 - 0.5, h as f32 - 0.5],
        }
    }
}

/// Blends a voxel's colour with the one `seen` by `weight` over the total, `previous` the
/// voxel's weight before and `inv_total` one over their sum.
#[inline]
fn blend_color(fused: &mut [u8; 3], seen: &[u8; 3], previous: f32, weight: f32, inv_total: f32) {
    // The three channels side by side, each with the same operations as alone.
    let channels = |c: &[u8; 3]| f32x4::new([c[0] as f32, c[1] as f32, c[2] as f32, 0.0]);
    let blended = (channels(fused) * f32x4::splat(previous)
        + channels(seen) * f32x4::splat(weight))
        * f32x4::splat(inv_total);
    // A weighted mean of two bytes, so within [0, 255] up to rounding: adding 0.5 and
    // truncating rounds, and the unchecked vector conversion is exact in that range (a
    // channel's checked `as` conversion cost a compare and a branch each).
    let rounded = (blended + f32x4::splat(0.5)).trunc_int().to_array();
    *fused = [rounded[0] as u8, rounded[1] as u8, rounded[2] as u8];
}

/// The lanes whose bits are set in `mask`, lowest first.
#[inline(always)]
fn set_lanes(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let x = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            x
        })
    })
}

/// Counts an observation of the instance `instances` shows at `pixel` (if any) in voxel `i`;
/// returns that instance (0 for none), which the caller lists in the block's instances (see
/// [`Block::note_instance`]) once per run of equal ids, not once per voxel.
#[inline]
fn observe_instance(
    block: &mut Block,
    i: usize,
    instances: Option<FrameInstances>,
    pixel: usize,
) -> u16 {
    let Some(frame) = instances else {
        return 0;
    };
    let id = frame.image.pixels()[pixel];
    let label = &mut block.labels[i];
    if id == 0 || (frame.fills_only && label.instance() != 0) {
        return 0;
    }
    match frame.claims {
        Some(claims) if claims.pixels[pixel] && claims.stuff[label.instance() as usize] => {
            label.observe_over(id)
        }
        _ => label.observe(id),
    }
    id
}

/// The pixels a block's voxels read, as inclusive column and row ranges: the bounding box of
/// its corner voxels' nearest pixels (a projection keeps the block's voxels inside its
/// corners' hull), clipped to the image. None when a corner lies behind the camera's near
/// range, or when the box exceeds [`MAX_FOOTPRINT`] pixels a side.
fn footprint(
    first: Vector3<f32>,
    axes: [Vector3<f32>; 3],
    [fx, fy, cx, cy]: [f32; 4],
    min_range: f32,
    depth: &DepthImage,
) -> Option<(RangeInclusive<usize>, RangeInclusive<usize>)> {
    let last = (BLOCK_SIDE - 1) as f32;
    let (mut low, mut high) = ([f32::MAX; 2], [f32::MIN; 2]);
    for corner in 0..8 {
        let p = first
            + axes[0] * (last * (corner & 1) as f32)
            + axes[1] * (last * (corner >> 1 & 1) as f32)
            + axes[2] * (last * (corner >> 2) as f32);
        if p.z < min_range {
            return None;
        }
        let pixel = [fx * p.x / p.z + cx + 0.5, fy * p.y / p.z + cy + 0.5];
        for a in 0..2 {
            low[a] = low[a].min(pixel[a]);
            high[a] = high[a].max(pixel[a]);
        }
    }
    let (w, h) = depth.dims();
    let clip = |a: usize, size: usize| {
        // Saturating conversions: off-image boxes clip to an edge and are then empty.
        let (first, last) = (low[a].max(0.0) as usize, (high[a] as usize).min(size - 1));
        (high[a] >= 0.0 && first <= last && last - first < MAX_FOOTPRINT).then_some(first..=last)
    };
    Some((clip(0, w)?, clip(1, h)?))
}

/// Blocks whose footprint exceeds this many pixels a side (closer than about 0.8 m at 2 cm
/// voxels and a 525-pixel focal length) are read without hints. A block's 512 voxels read at
/// most 1,536 cache lines of the three images; a square footprint of side `s` spans about
/// `s² × 9 / 64` lines (4 + 3 + 2 bytes a pixel), so past 104 pixels most hinted lines would
/// be fetched for nothing. On flat the cap changes nothing measurable: 64, 160, 320 pixels
/// and none all read 4.6-4.9 ms in `integrate_frame` (1 thread).
const MAX_FOOTPRINT: usize = 104;

/// Updates the voxels of one block; returns how many changed.
fn update_block(index: BlockIndex, block: &mut Block, frame: &FrameView) -> usize {
    match frame.vectors {
        // SAFETY: `VectorUnit::Avx2` is only chosen where the CPU has AVX2.
        #[cfg(target_arch = "x86_64")]
        VectorUnit::Avx2 => unsafe { update_block_avx2(index, block, frame) },
        VectorUnit::Portable => update_block_with::<f32x8>(index, block, frame),
    }
}

/// [`update_block_with`] compiled for AVX2: its rows are single 256-bit registers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn update_block_avx2(index: BlockIndex, block: &mut Block, frame: &FrameView) -> usize {
    update_block_with::<Avx2>(index, block, frame)
}

/// Updates the voxels of one block with rows of lanes `L`; returns how many changed.
///
/// Voxel centres are stepped through the camera frame by adding the rotated voxel axes (a
/// block is a regular grid), in f32: the per-voxel work is a projection and a blend.
#[inline(always)]
fn update_block_with<L: Lanes>(index: BlockIndex, block: &mut Block, frame: &FrameView) -> usize {
    let BlockInCamera {
        first,
        axes: [ax, ay, az],
        pinhole: [fx, fy, cx, cy],
        range: [min_range, max_range],
        band: [truncation, inv_truncation],
        voxel,
        image_end: [wf, hf],
    } = BlockInCamera::new(index, frame);
    let (config, depth) = (&frame.config, frame.depth);
    let (color, instances) = (frame.color, frame.instances);
    let w = depth.width();
    let depths = depth.pixels();
    // The block's pixels are asked for at once, so their cache misses overlap.
    if let Some((columns, rows)) =
        footprint(first, [ax, ay, az], [fx, fy, cx, cy], min_range, depth)
    {
        prefetch_rect(depth, columns.clone(), rows.clone());
        if let Some(color) = color {
            prefetch_rect(color, columns.clone(), rows.clone());
        }
        if let Some(instances) = instances {
            prefetch_rect(instances.image, columns, rows);
        }
    }
    // A row of the block's voxels along x is one 8-lane vector: its projections, tests and
    // blends are computed together (the lanes' arithmetic is the scalar update's, operation
    // for operation, so the map is bit for bit what a voxel-by-voxel loop gives); only the
    // image reads and the writes of the voxels kept are per voxel.
    let splat = L::splat;
    let lane = L::new([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    let (step_x, step_y, step_z) = (lane * splat(ax.x), lane * splat(ax.y), lane * splat(ax.z));
    let behind_span = splat(truncation - voxel);
    let mut updated = 0;
    // The instance last listed in the block's instances: neighbouring voxels see one.
    let mut noted = 0;
    for z in 0..BLOCK_SIDE {
        for y in 0..BLOCK_SIDE {
            let row = first + ay * y as f32 + az * z as f32;
            let (px, py, pz) = (
                splat(row.x) + step_x,
                splat(row.y) + step_y,
                splat(row.z) + step_z,
            );
            let inv_z = splat(1.0) / pz;
            let u = splat(fx) * px * inv_z + splat(cx);
            let v = splat(fy) * py * inv_z + splat(cy);
            // Nearest pixel, inside the image (and in front of the camera).
            let inside = pz.simd_ge(splat(min_range))
                & u.simd_ge(splat(-0.5))
                & v.simd_ge(splat(-0.5))
                & u.simd_lt(splat(wf))
                & v.simd_lt(splat(hf));
            let inside_lanes = inside.to_bitmask();
            if inside_lanes == 0 {
                continue;
            }
            // In range: i32 conversions are the cheapest saturating ones.
            let (ui, vi) = ((u + splat(0.5)).trunc_int(), (v + splat(0.5)).trunc_int());
            let mut pixels = [0; BLOCK_SIDE];
            let mut measured = [0.0f32; BLOCK_SIDE];
            for x in 0..BLOCK_SIDE {
                if inside_lanes >> x & 1 != 0 {
                    pixels[x] = vi[x] as usize * w + ui[x] as usize;
                    measured[x] = depths[pixels[x]];
                }
            }
            let measured = L::new(measured);
            let within = measured.is_finite()
                & measured.simd_gt(splat(0.0))
                & measured.simd_ge(splat(min_range))
                & measured.simd_le(splat(max_range));
            // Projective distance along the optical axis: positive in front of the surface.
            let sdf = measured - pz;
            let kept = (inside & within & sdf.simd_ge(splat(-truncation))).to_bitmask();
            if kept == 0 {
                continue;
            }
            // Measurements get noisier with range (structured light: σ ∝ z²), and behind
            // the surface they are guesses: voxblox's linear drop-off from one voxel to the
            // truncation distance.
            let weight = splat(1.0) / (measured * measured);
            let weight = sdf
                .simd_lt(splat(-voxel))
                .select(weight * ((splat(truncation) + sdf) / behind_span), weight);
            let sdf = sdf.min(splat(truncation));
            let first_voxel = Block::linear(0, y, z);
            let previous: L = TsdfVoxel::weight_lanes(block.voxels.weight_bits_row(first_voxel));
            let stored: L = TsdfVoxel::decode_lanes(block.voxels.steps_row(first_voxel));
            let total = previous + weight;
            // One division per voxel: the blends below share it.
            let inv_total = splat(1.0) / total;
            let tsdf = (stored * previous + sdf * splat(inv_truncation) * weight) * inv_total;
            let (steps, weight_bits) =
                TsdfVoxel::encode_lanes(tsdf, total.min(splat(config.max_weight)));
            // The block's surface counts follow the voxels that enter, leave or change
            // instance on the surface (a recount would visit all 512).
            let was_surface = on_surface_lanes(stored, previous, truncation, voxel);
            let is_surface = on_surface_lanes::<L>(
                TsdfVoxel::decode_lanes(steps),
                TsdfVoxel::weight_lanes(weight_bits),
                truncation,
                voxel,
            );
            let (sdf, weight, previous) = (sdf.to_array(), weight.to_array(), previous.to_array());
            let inv_total = inv_total.to_array();
            block
                .voxels
                .store_row(first_voxel, kept, steps, weight_bits);
            // Few voxels are on the surface: their instances are read before and after the
            // row's updates, in lanes of their own, and the update loop stays branch-light.
            let mut was = [0u16; BLOCK_SIDE];
            for x in set_lanes(was_surface & kept) {
                was[x] = block.labels[first_voxel + x].instance();
            }
            for x in set_lanes(kept) {
                let (i, pixel) = (first_voxel + x, pixels[x]);
                if let Some(color) = color
                    && sdf[x] < truncation
                {
                    let seen = &color.pixels()[pixel];
                    let fused = block.voxels.color_mut(i);
                    blend_color(fused, seen, previous[x], weight[x], inv_total[x]);
                }
                if sdf[x].abs() < truncation {
                    let id = observe_instance(block, i, instances, pixel);
                    if id != noted {
                        block.note_instance(id);
                        noted = id;
                    }
                }
            }
            // In lane order, as the moves were made before (a block's counts list keeps it).
            for x in set_lanes((was_surface | is_surface) & kept) {
                let is = if is_surface >> x & 1 != 0 {
                    block.labels[first_voxel + x].instance()
                } else {
                    0
                };
                if was[x] != is {
                    block.move_surface_voxel(was[x], is);
                }
                let was_unlabelled = was_surface >> x & 1 != 0 && was[x] == 0;
                let is_unlabelled = is_surface >> x & 1 != 0 && is == 0;
                if is_unlabelled && !was_unlabelled {
                    block.unlabelled_surface += 1;
                } else if was_unlabelled && !is_unlabelled {
                    block.unlabelled_surface = block.unlabelled_surface.saturating_sub(1);
                }
            }
            updated += kept.count_ones() as usize;
        }
    }
    if updated > 0 {
        block.updates = UpdateBits::ALL;
    }
    updated
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;
    use voxpan_core::is_depth_within;
    use voxpan_core::nalgebra::{Translation3, UnitQuaternion};

    use crate::layer::{LabelVoxel, MAX_WEIGHT, MIN_WEIGHT};

    /// The update as it was written before its rows became vectors, one voxel at a time and
    /// recounting the block's surface after: the reference the vector rows must match bit for
    /// bit.
    fn update_voxel_by_voxel(index: BlockIndex, block: &mut Block, frame: &FrameView) -> usize {
        let g = BlockInCamera::new(index, frame);
        let (first, [ax, ay, az], [fx, fy, cx, cy]) = (g.first, g.axes, g.pinhole);
        let ([min_range, max_range], [wf, hf]) = (g.range, g.image_end);
        let ([truncation, inv_truncation], voxel) = (g.band, g.voxel);
        let (config, depth) = (&frame.config, frame.depth);
        let (color, instances) = (frame.color, frame.instances);
        let w = depth.width();
        let depths = depth.pixels();
        let mut updated = 0;
        for z in 0..BLOCK_SIDE {
            for y in 0..BLOCK_SIDE {
                let row = first + ay * y as f32 + az * z as f32;
                // First the row's projections, then its depth reads (cache misses, mostly), which
                // overlap without the updates' early exits between them; then the updates.
                let mut pixels = [0; BLOCK_SIDE];
                let mut measured = [0.0f32; BLOCK_SIDE];
                let mut u = [0.0f32; BLOCK_SIDE];
                let mut v = [0.0f32; BLOCK_SIDE];
                let mut inside = [false; BLOCK_SIDE];
                for x in 0..BLOCK_SIDE {
                    let p = row + ax * x as f32;
                    let inv_z = 1.0 / p.z;
                    (u[x], v[x]) = (fx * p.x * inv_z + cx, fy * p.y * inv_z + cy);
                    // Nearest pixel, inside the image (and in front of the camera).
                    inside[x] =
                        p.z >= min_range && u[x] >= -0.5 && v[x] >= -0.5 && u[x] < wf && v[x] < hf;
                }
                for x in 0..BLOCK_SIDE {
                    if inside[x] {
                        // In range: i32 conversions are the cheapest saturating ones.
                        pixels[x] = (v[x] + 0.5) as i32 as usize * w + (u[x] + 0.5) as i32 as usize;
                        measured[x] = depths[pixels[x]];
                    }
                }
                for x in 0..BLOCK_SIDE {
                    let (pixel, measured) = (pixels[x], measured[x]);
                    if !inside[x] || !is_depth_within(measured, min_range, max_range) {
                        continue;
                    }
                    let p = row + ax * x as f32;
                    // Projective distance along the optical axis: positive in front of the surface.
                    let sdf = measured - p.z;
                    if sdf < -truncation {
                        continue;
                    }
                    // Measurements get noisier with range (structured light: σ ∝ z²), and behind
                    // the surface they are guesses: voxblox's linear drop-off from one voxel to the
                    // truncation distance.
                    let mut weight = 1.0 / (measured * measured);
                    if sdf < -voxel {
                        weight *= (truncation + sdf) / (truncation - voxel);
                    }
                    let sdf = sdf.min(truncation);
                    let i = Block::linear(x, y, z);
                    let vox = block.voxels.get(i);
                    let previous = vox.weight();
                    let total = previous + weight;
                    // One division per voxel: the blends below share it.
                    let inv_total = 1.0 / total;
                    let tsdf = (vox.tsdf() * previous + sdf * inv_truncation * weight) * inv_total;
                    let mut fused = vox.color();
                    if let Some(color) = color
                        && sdf < truncation
                    {
                        let seen = &color.pixels()[pixel];
                        blend_color(&mut fused, seen, previous, weight, inv_total);
                    }
                    let voxel = TsdfVoxel::new(tsdf, total.min(config.max_weight), fused);
                    block.voxels.set(i, voxel);
                    // The recount below lists the block's instances.
                    if sdf.abs() < truncation {
                        observe_instance(block, i, instances, pixel);
                    }
                    updated += 1;
                }
            }
        }
        if updated > 0 {
            block.updates = UpdateBits::ALL;
            block.count_surface(truncation, voxel);
        }
        updated
    }

    /// A small deterministic generator (xorshift): scenes need thousands of values.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }

        /// Uniform in [0, 1).
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// What a voxel stores, bit for bit (`PartialEq` on the weight would equate +0 and -0).
    fn stored(block: &Block) -> Vec<(i16, u32, [u8; 3], LabelVoxel)> {
        block
            .voxels
            .iter()
            .zip(block.labels.iter())
            .map(|(v, l)| (v.tsdf_steps(), v.weight().to_bits(), v.color(), *l))
            .collect()
    }

    /// A camera at a random pose near the origin looking along +z at a random surface with
    /// holes, non-finite and out-of-range depths, over blocks that already hold random
    /// evidence (unobserved voxels, tiny and saturated weights): every block updated by the
    /// vector rows and by the reference holds the same bits, and both count the same voxels.
    fn check_scene(seed: u64, voxel: f64, truncation_voxels: f64, with_images: bool) {
        let mut rng = Rng(seed | 1);
        let k = Intrinsics {
            width: 37,
            height: 29,
            fx: 30.0,
            fy: 31.5,
            cx: 18.2,
            cy: 13.7,
        };
        let config = TsdfConfig {
            voxel_size: voxel,
            truncation_voxels,
            max_range: 1.5,
            min_range: 0.1,
            max_weight: 50.0,
            keep_radius: 0.0,
        };
        let depth = DepthImage::from_fn(k.width, k.height, |_, _| match rng.next() % 16 {
            0 => f32::NAN,
            1 => 0.0,
            2 => -0.4,
            3 => f32::INFINITY,
            4 => 0.05,
            5 => 1.7,
            _ => 0.2 + 1.2 * rng.unit(),
        });
        let color = ColorImage::from_fn(k.width, k.height, |_, _| {
            let c = rng.next();
            [c as u8, (c >> 8) as u8, (c >> 16) as u8]
        });
        // Ids 1-4 are also in the blocks' labels before the frame; 5 enters with the frame.
        let instances = LabelImage::from_fn(k.width, k.height, |_, _| (rng.next() % 6) as u16);
        // Half the scenes carry their labels (they fill only unlabelled voxels); two thirds
        // let a third of the pixels take voxels from the stuff instances 1 and 2.
        let claimed: Vec<bool> = (0..k.width * k.height)
            .map(|_| rng.next().is_multiple_of(3))
            .collect();
        let mut stuff = vec![false; u16::MAX as usize + 1];
        stuff[1] = true;
        stuff[2] = true;
        let instances = FrameInstances {
            image: &instances,
            fills_only: seed.is_multiple_of(2),
            claims: (seed % 3 != 2).then_some(Claims {
                pixels: &claimed,
                stuff: &stuff,
            }),
        };
        let axis = Vector3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5).cast();
        let camera_to_world = Pose::from_parts(
            Translation3::new(0.1 * rng.unit() as f64, -0.05, 0.02),
            UnitQuaternion::from_scaled_axis(axis * 0.3),
        );
        let world_to_camera = camera_to_world.inverse();
        let truncation = (truncation_voxels * voxel) as f32 as f64;
        let reach = (1.6 / (voxel * BLOCK_SIDE as f64)).ceil() as i32;
        let mut compared = 0;
        for bx in -reach..=reach {
            for by in -reach..=reach {
                for bz in -1..=reach {
                    let index = [bx, by, bz];
                    let mut block = Block::default();
                    for i in 0..block.voxels.len() {
                        let weight = match rng.next() % 5 {
                            0 => 0.0,
                            1 => MIN_WEIGHT,
                            2 => 60.0,
                            _ => 5.0 * rng.unit(),
                        };
                        let c = rng.next();
                        let voxel = TsdfVoxel::new(
                            2.0 * rng.unit() - 1.0,
                            weight,
                            [c as u8, (c >> 8) as u8, (c >> 16) as u8],
                        );
                        block.voxels.set(i, voxel);
                        for _ in 0..rng.next() % 3 {
                            block.labels[i].observe((rng.next() % 4 + 1) as u16);
                        }
                    }
                    // As every block in a layer: its surface counted.
                    block.count_surface(truncation as f32, voxel as f32);
                    let mut expected = block.clone();
                    let (color, instances) = if with_images {
                        (Some(&color), Some(instances))
                    } else {
                        (None, None)
                    };
                    let frame = |vectors| FrameView {
                        vectors,
                        voxel,
                        truncation,
                        config,
                        depth: &depth,
                        color,
                        instances,
                        world_to_camera,
                        k: &k,
                    };
                    let expected_updated =
                        update_voxel_by_voxel(index, &mut expected, &frame(VectorUnit::Portable));
                    expected.surface.sort_unstable();
                    for vectors in vector_units() {
                        let mut block = block.clone();
                        let updated = update_block(index, &mut block, &frame(vectors));
                        assert_eq!(updated, expected_updated, "block {index:?} ({vectors:?})");
                        assert!(
                            stored(&block) == stored(&expected),
                            "block {index:?} ({vectors:?})"
                        );
                        // Kept count by count, the surface lists the same instances in an
                        // order of its own.
                        block.surface.sort_unstable();
                        assert_eq!(
                            block.surface, expected.surface,
                            "block {index:?} ({vectors:?})"
                        );
                        assert_eq!(
                            block.unlabelled_surface, expected.unlabelled_surface,
                            "block {index:?} ({vectors:?}): unlabelled surface voxels"
                        );
                        // Every instance the labels hold is listed (the rows list them as
                        // they go, the reference recounts them), so a merge finds the block.
                        assert!(
                            expected
                                .instances
                                .iter()
                                .all(|id| block.instances.contains(id)),
                            "block {index:?} ({vectors:?}): {:?} lists {:?}",
                            expected.instances,
                            block.instances
                        );
                    }
                    compared += expected_updated;
                }
            }
        }
        assert!(compared > 1000, "the scene updated only {compared} voxels");
    }

    /// The vector units this CPU runs: the portable lanes, and AVX2 where it has it (the
    /// test then compares both against the reference).
    fn vector_units() -> Vec<VectorUnit> {
        let mut units = vec![VectorUnit::Portable];
        if VectorUnit::detect() != VectorUnit::Portable {
            units.push(VectorUnit::detect());
        } else {
            eprintln!("this CPU has only the portable lanes: AVX2 rows not compared");
        }
        units
    }

    /// A 64 x 48 camera, 50 px focal length.
    fn small_camera() -> Intrinsics {
        Intrinsics {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
        }
    }

    /// Integration updates the touched blocks in place, in parallel, allocating the new ones
    /// on the workers: the layer must be what updating them one by one gives, surface totals
    /// included, in a map that already holds blocks inside and outside the frame's band.
    #[test]
    fn in_place_parallel_integration_matches_block_by_block_updates() {
        let mut rng = Rng(0x1a7e);
        let k = small_camera();
        let config = TsdfConfig::default();
        let integrator = TsdfIntegrator::new(config, false);
        let voxel = 0.02;
        let mut layer = Layer::new(voxel, config.truncation_voxels * voxel);
        let pose = Pose::identity();
        let depth = DepthImage::from_fn(k.width, k.height, |u, _| 1.0 + 0.004 * u as f32);
        let color = ColorImage::from_fn(k.width, k.height, |u, v| [u as u8, v as u8, 7]);
        let instances = LabelImage::from_fn(k.width, k.height, |u, _| 1 + (u / 16) as u16);
        // Earlier observations: every other block of the frame's band, and blocks elsewhere.
        let touched = integrator.plan(&layer, &depth, &pose, &k);
        let mut order: Vec<BlockIndex> = touched.iter().copied().collect();
        order.sort_unstable();
        let elsewhere = [[40, 40, 40], [-9, 3, 1]];
        for index in order.iter().step_by(2).chain(&elsewhere) {
            let (block, _) = layer.get_or_allocate(*index);
            for i in 0..block.voxels.len() {
                let c = rng.next();
                let voxel = TsdfVoxel::new(2.0 * rng.unit() - 1.0, 3.0 * rng.unit(), [c as u8; 3]);
                block.voxels.set(i, voxel);
                block.labels[i].observe((rng.next() % 3 + 1) as u16);
            }
        }
        layer.count_surfaces();
        let mut expected = layer.clone();
        let frame = FrameView::new(
            &expected,
            config,
            &depth,
            Some(&color),
            Some(FrameInstances::observed(&instances)),
            &pose,
            &k,
        );
        let (mut expected_voxels, mut expected_new) = (0, 0);
        for &index in &order {
            let (block, new) = expected.get_or_allocate(index);
            expected_voxels += update_block(index, block, &frame);
            expected_new += new as usize;
        }
        expected.count_surfaces();
        let stats = integrator.integrate(
            &mut layer,
            &touched,
            &depth,
            Some(&color),
            Some(FrameInstances::observed(&instances)),
            &pose,
            &k,
        );
        assert!(
            expected_new > 0 && expected_new < order.len(),
            "{expected_new} new blocks"
        );
        assert_eq!(stats.new_blocks, expected_new);
        assert_eq!(stats.updated_voxels, expected_voxels);
        assert_eq!(layer.surface_counts(), expected.surface_counts());
        assert_eq!(layer.len(), expected.len());
        for (index, block) in expected.iter() {
            let got = layer.get(index).expect("the same blocks");
            assert!(stored(got) == stored(block), "block {index:?}");
        }
    }

    #[test]
    fn vector_rows_match_the_voxel_by_voxel_update() {
        check_scene(0x5eed, 0.02, 2.0, true);
        check_scene(0x5eee, 0.02, 2.0, true);
        check_scene(7, 0.02, 3.0, false);
    }

    /// Labels carried from the map fill voxels without a candidate and leave every labelled
    /// voxel as it was, where a segmenter's labels count in both.
    #[test]
    fn carried_labels_fill_only_unlabelled_voxels() {
        let k = small_camera();
        let config = TsdfConfig::default();
        let integrator = TsdfIntegrator::new(config, false);
        let pose = Pose::identity();
        let wall = DepthImage::from_fn(k.width, k.height, |_, _| 1.2);
        // The first frame measures the left half of the wall only.
        let left = DepthImage::from_fn(k.width, k.height, |u, _| if u < 32 { 1.2 } else { 0.0 });
        let ones = LabelImage::from_fn(k.width, k.height, |_, _| 1);
        let twos = LabelImage::from_fn(k.width, k.height, |_, _| 2);
        let integrate = |layer: &mut Layer, depth: &DepthImage, instances| {
            let touched = integrator.plan(layer, depth, &pose, &k);
            integrator.integrate(layer, &touched, depth, None, Some(instances), &pose, &k);
        };
        let mut first = Layer::new(0.02, config.truncation_voxels * 0.02);
        integrate(&mut first, &left, FrameInstances::observed(&ones));
        let labels = |layer: &Layer| -> BTreeMap<(BlockIndex, usize), LabelVoxel> {
            layer
                .iter()
                .flat_map(|(&index, block)| {
                    block
                        .labels
                        .iter()
                        .enumerate()
                        .map(move |(i, l)| ((index, i), *l))
                })
                .filter(|(_, l)| l.instance() != 0)
                .collect()
        };
        let before = labels(&first);
        assert!(!before.is_empty());
        for (instances, carried) in [
            (FrameInstances::carried(&twos), true),
            (FrameInstances::observed(&twos), false),
        ] {
            let mut layer = first.clone();
            integrate(&mut layer, &wall, instances);
            let after = labels(&layer);
            let kept = before.iter().all(|(at, l)| after.get(at) == Some(l));
            let filled = after
                .iter()
                .filter(|(at, l)| !before.contains_key(at) && l.ids()[0] == 2)
                .count();
            assert_eq!(kept, carried, "carried {carried}");
            assert!(
                filled > 0,
                "carried {carried}: no unlabelled voxel took the label"
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn vector_rows_match_on_random_scenes(
            seed in any::<u64>(),
            voxel in 0.01f64..0.05,
            truncation_voxels in 1.0f64..4.0,
        ) {
            check_scene(seed, voxel, truncation_voxels, true);
        }
    }

    /// Every pixel a block's voxels read lies in its footprint (give or take a pixel, where
    /// the corners' rounding and the stepped voxel centres' differ), for random poses.
    #[test]
    fn footprints_cover_what_blocks_read() {
        let k = Intrinsics {
            width: 160,
            height: 120,
            fx: 120.0,
            fy: 118.0,
            cx: 80.3,
            cy: 59.6,
        };
        let depth = DepthImage::filled(k.width, k.height, 1.0);
        let mut rng = Rng(0xf00d);
        let mut checked = 0;
        for _ in 0..200 {
            let axis = Vector3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
            let world_to_camera = Pose::from_parts(
                Translation3::new(rng.unit() as f64 - 0.5, rng.unit() as f64 - 0.5, 0.0),
                UnitQuaternion::from_scaled_axis(axis.cast::<f64>() * 0.6),
            );
            let index = [
                (rng.next() % 9) as i32 - 4,
                (rng.next() % 9) as i32 - 4,
                (rng.next() % 12) as i32 + 1,
            ];
            let frame = FrameView {
                vectors: VectorUnit::Portable,
                voxel: 0.02,
                truncation: 0.04,
                config: TsdfConfig::default(),
                depth: &depth,
                color: None,
                instances: None,
                world_to_camera,
                k: &k,
            };
            let g = BlockInCamera::new(index, &frame);
            let [fx, fy, cx, cy] = g.pinhole;
            let Some((columns, rows)) = footprint(g.first, g.axes, g.pinhole, g.range[0], &depth)
            else {
                continue;
            };
            for (x, y, z) in (0..BLOCK_SIDE * BLOCK_SIDE * BLOCK_SIDE).map(Block::coords) {
                let p =
                    g.first + g.axes[1] * y as f32 + g.axes[2] * z as f32 + g.axes[0] * x as f32;
                let inv_z = 1.0 / p.z;
                let (u, v) = (fx * p.x * inv_z + cx + 0.5, fy * p.y * inv_z + cy + 0.5);
                if u < 0.0 || v < 0.0 || u >= k.width as f32 || v >= k.height as f32 {
                    continue;
                }
                let (u, v) = (u as usize, v as usize);
                assert!(
                    u + 1 >= *columns.start() && u <= columns.end() + 1,
                    "column {u} outside {columns:?} (block {index:?})"
                );
                assert!(
                    v + 1 >= *rows.start() && v <= rows.end() + 1,
                    "row {v} outside {rows:?} (block {index:?})"
                );
                checked += 1;
            }
        }
        assert!(checked > 10_000, "only {checked} voxels checked");
    }

    /// Lanes encode as [`TsdfVoxel::new`] does, at the values where rounding, saturation and
    /// NaN handling decide.
    #[test]
    fn lane_encoding_matches_new() {
        let step = 1.0 / 32767.0;
        let tsdf = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            1.0 + 1e-6,
            -1.0 - 1e-6,
            3.0,
            -3.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.5 * step,
            -0.5 * step,
            1.5 * step,
            -1.5 * step,
            0.3,
            -0.7,
        ];
        let weight = [
            0.0,
            MIN_WEIGHT,
            1.0,
            1.0 + 1.0 / 256.0,
            1.0 + 3.0 / 256.0,
            255.5,
            10_000.0,
            MAX_WEIGHT,
            3.3e-7,
            0.001,
            7.77,
            123.456,
            2.0,
            1e30,
            0.5,
            1.5,
            99.9,
        ];
        for start in 0..tsdf.len() {
            let lanes: [f32; 8] = std::array::from_fn(|i| tsdf[(start + i) % tsdf.len()]);
            let weights: [f32; 8] = std::array::from_fn(|i| weight[(start + i) % weight.len()]);
            let (steps, bits) = TsdfVoxel::encode_lanes(f32x8::new(lanes), f32x8::new(weights));
            for i in 0..8 {
                let expected = TsdfVoxel::new(lanes[i], weights[i], [0; 3]);
                assert_eq!(steps[i], expected.tsdf_steps(), "tsdf {}", lanes[i]);
                assert_eq!(
                    f32::from_bits((bits[i] as u32) << 16).to_bits(),
                    expected.weight().to_bits(),
                    "weight {}",
                    weights[i]
                );
            }
        }
    }
}
