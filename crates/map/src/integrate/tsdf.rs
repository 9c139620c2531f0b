//! Projective TSDF integration (voxblox's "projective" integrator): allocate the blocks around
//! the observed surface, then update every voxel of those blocks from the pixel it projects to.

use rayon::prelude::*;
use rustc_hash::FxHashSet;
use voxpan_core::nalgebra::Point3;
use voxpan_core::{
    ColorImage, DepthImage, Intrinsics, LabelImage, Pose, is_depth_within, is_valid_depth,
};

use crate::TsdfConfig;
use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, TsdfVoxel, UpdateBits};

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
}

impl TsdfIntegrator {
    pub fn new(config: TsdfConfig) -> Self {
        Self { config }
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
        instances: Option<&LabelImage>,
        pose: &Pose,
        k: &Intrinsics,
    ) -> IntegrationStats {
        let voxel = layer.voxel_size();
        // The layer's band (the configuration's, in f32): voxels store fractions of it.
        let truncation = layer.truncation() as f64;
        let mut stats = IntegrationStats::default();
        // The touched blocks leave the map while they are updated in parallel and go back
        // after: the cost follows the frame, not the map's size (filtering every block of a
        // large map each frame would not).
        let mut blocks: Vec<(BlockIndex, Block)> = touched
            .iter()
            .map(|&index| {
                let block = layer.take(&index).unwrap_or_else(|| {
                    stats.new_blocks += 1;
                    Block::default()
                });
                (index, block)
            })
            .collect();
        // In index order, neighbouring blocks are updated one after the other and read
        // neighbouring pixels, which then stay in cache (the set's order is a hash's).
        blocks.sort_unstable_by_key(|(index, _)| *index);
        let world_to_camera = pose.inverse();
        let config = self.config;
        stats.updated_blocks = blocks.len();
        stats.updated_voxels = blocks
            .par_iter_mut()
            .map(|(index, block)| {
                update_block(
                    *index,
                    block,
                    voxel,
                    truncation,
                    &config,
                    depth,
                    color,
                    instances,
                    &world_to_camera,
                    k,
                )
            })
            .sum();
        for (index, block) in blocks {
            layer.insert(index, block);
        }
        stats
    }

    /// The most blocks one frame of camera `k` can touch: [`Self::integrate`] allocates
    /// blocks only at its sampled pixels' band points.
    pub fn frame_block_bound(&self, k: &Intrinsics, voxel: f64) -> usize {
        let (stride, steps) = self.sampling(k, voxel);
        k.width.div_ceil(stride) * k.height.div_ceil(stride) * (steps + 1)
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
        for v in (0..depth.height()).step_by(stride) {
            for u in (0..depth.width()).step_by(stride) {
                let z = *depth.get(u, v) as f64;
                if !is_valid_depth(z as f32)
                    || z < self.config.min_range
                    || z > self.config.max_range
                {
                    continue;
                }
                // The ray in world axes once per pixel; each band point is a step along it.
                let ray = rotation * k.ray(u as f64, v as f64);
                for (s, previous) in previous.iter_mut().enumerate() {
                    let d = z - truncation + 2.0 * truncation * s as f64 / steps as f64;
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

/// Updates the voxels of one block; returns how many changed.
///
/// Voxel centres are stepped through the camera frame by adding the rotated voxel axes (a
/// block is a regular grid), in f32: the per-voxel work is a projection and a blend.
#[allow(clippy::too_many_arguments)]
fn update_block(
    index: BlockIndex,
    block: &mut Block,
    voxel: f64,
    truncation: f64,
    config: &TsdfConfig,
    depth: &DepthImage,
    color: Option<&ColorImage>,
    instances: Option<&LabelImage>,
    world_to_camera: &Pose,
    k: &Intrinsics,
) -> usize {
    let (w, h) = depth.dims();
    let rotation = world_to_camera.rotation.to_rotation_matrix();
    let axis = |a: usize| {
        let mut v = voxpan_core::nalgebra::Vector3::zeros();
        v[a] = voxel;
        (rotation * v).cast::<f32>()
    };
    let (ax, ay, az) = (axis(0), axis(1), axis(2));
    let first = (world_to_camera * Block::voxel_center(index, 0, voxel))
        .coords
        .cast::<f32>();
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    let (min_range, max_range) = (config.min_range as f32, config.max_range as f32);
    let (truncation, voxel) = (truncation as f32, voxel as f32);
    let inv_truncation = 1.0 / truncation;
    let (wf, hf) = (w as f32 - 0.5, h as f32 - 0.5);
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
                let vox = block.voxels[i];
                let previous = vox.weight();
                let total = previous + weight;
                // One division per voxel: the blends below share it.
                let inv_total = 1.0 / total;
                let tsdf = (vox.tsdf() * previous + sdf * inv_truncation * weight) * inv_total;
                let mut fused = vox.color();
                if let Some(color) = color {
                    if sdf < truncation {
                        let c = &color.pixels()[pixel];
                        for (fused, &seen) in fused.iter_mut().zip(c) {
                            let blended =
                                (*fused as f32 * previous + seen as f32 * weight) * inv_total;
                            // A weighted mean of two bytes, so within [0, 255] up to rounding:
                            // adding 0.5 and truncating rounds (libm's roundf is a call per
                            // channel on baseline x86-64), and the i32 conversion, one
                            // instruction, cannot leave 0..=255 (`as u8` would clamp first).
                            *fused = (blended + 0.5) as i32 as u8;
                        }
                    }
                }
                block.voxels[i] = TsdfVoxel::new(tsdf, total.min(config.max_weight), fused);
                if let Some(instances) = instances {
                    let id = instances.pixels()[pixel];
                    if id != 0 && sdf.abs() < truncation {
                        block.labels[i].observe(id);
                    }
                }
                updated += 1;
            }
        }
    }
    if updated > 0 {
        block.updates = UpdateBits::ALL;
        // The block is still in cache: recounting it here is the cheapest time.
        block.count_surface(truncation, voxel);
    }
    updated
}
