//! Projective TSDF integration (voxblox's "projective" integrator): allocate the blocks around
//! the observed surface, then update every voxel of those blocks from the pixel it projects to.

use rayon::prelude::*;
use rustc_hash::FxHashSet;
use voxpan_core::nalgebra::Point3;
use voxpan_core::{is_valid_depth, ColorImage, DepthImage, Intrinsics, Pose};

use crate::{Block, BlockIndex, Layer, TsdfVoxel, VOXELS_PER_BLOCK};

/// Integration parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TsdfConfig {
    /// Truncation distance in voxels (default 3): the band around the surface that is updated.
    pub truncation_voxels: f64,
    /// Depth beyond this (metres) is ignored (default 5, as panoptic_mapping on flat).
    pub max_range: f64,
    /// Depth below this is ignored (default 0.1).
    pub min_range: f64,
    /// Fusion weights saturate here, so the map keeps adapting (default 10 000, voxblox's).
    pub max_weight: f32,
}

impl Default for TsdfConfig {
    fn default() -> Self {
        Self {
            truncation_voxels: 3.0,
            max_range: 5.0,
            min_range: 0.1,
            max_weight: 1e4,
        }
    }
}

/// What one integration did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IntegrationStats {
    pub new_blocks: usize,
    pub updated_blocks: usize,
    pub updated_voxels: usize,
}

/// Fuses frames into a [`Layer`].
#[derive(Clone, Debug, Default)]
pub struct TsdfIntegrator {
    pub config: TsdfConfig,
}

impl TsdfIntegrator {
    pub fn new(config: TsdfConfig) -> Self {
        Self { config }
    }

    /// Integrates one depth frame (planar depth, metres) seen from `pose` (`T_world_camera`),
    /// with its colour when given.
    pub fn integrate(
        &self,
        layer: &mut Layer,
        depth: &DepthImage,
        color: Option<&ColorImage>,
        pose: &Pose,
        k: &Intrinsics,
    ) -> IntegrationStats {
        let voxel = layer.voxel_size();
        let truncation = self.config.truncation_voxels * voxel;
        let touched = self.blocks_near_surface(layer, depth, pose, k, truncation);
        let mut stats = IntegrationStats::default();
        for index in &touched {
            if !layer.blocks.contains_key(index) {
                layer.blocks.insert(*index, Block::default());
                stats.new_blocks += 1;
            }
        }
        let world_to_camera = pose.inverse();
        let config = self.config;
        let mut blocks: Vec<(&BlockIndex, &mut Block)> = layer
            .blocks
            .iter_mut()
            .filter(|(i, _)| touched.contains(*i))
            .collect();
        stats.updated_blocks = blocks.len();
        stats.updated_voxels = blocks
            .par_iter_mut()
            .map(|(index, block)| {
                update_block(
                    **index,
                    block,
                    voxel,
                    truncation,
                    &config,
                    depth,
                    color,
                    &world_to_camera,
                    k,
                )
            })
            .sum();
        stats
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
        let block = layer.block_size();
        let stride =
            ((k.fx.min(k.fy) * block / (2.0 * self.config.max_range)).floor() as usize).max(1);
        let mut set = FxHashSet::default();
        for v in (0..depth.height()).step_by(stride) {
            for u in (0..depth.width()).step_by(stride) {
                let z = *depth.get(u, v) as f64;
                if !is_valid_depth(z as f32)
                    || z < self.config.min_range
                    || z > self.config.max_range
                {
                    continue;
                }
                let ray = k.ray(u as f64, v as f64);
                // Along the ray through the band, at most half a block apart.
                let steps = ((2.0 * truncation / (0.5 * block)).ceil() as usize).max(1);
                for s in 0..=steps {
                    let d = z - truncation + 2.0 * truncation * s as f64 / steps as f64;
                    let p = pose * Point3::from(ray * d);
                    set.insert(layer.block_index(&p));
                }
            }
        }
        set
    }
}

/// Updates the voxels of one block; returns how many changed.
#[allow(clippy::too_many_arguments)]
fn update_block(
    index: BlockIndex,
    block: &mut Block,
    voxel: f64,
    truncation: f64,
    config: &TsdfConfig,
    depth: &DepthImage,
    color: Option<&ColorImage>,
    world_to_camera: &Pose,
    k: &Intrinsics,
) -> usize {
    let (w, h) = depth.dims();
    let mut updated = 0;
    for i in 0..VOXELS_PER_BLOCK {
        let p = world_to_camera * Block::voxel_center(index, i, voxel);
        if p.z < config.min_range {
            continue;
        }
        let Some((u, v)) = k.project(&p) else {
            continue;
        };
        let (u, v) = (u.round(), v.round());
        if u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
            continue;
        }
        let (u, v) = (u as usize, v as usize);
        let measured = *depth.get(u, v) as f64;
        if !is_valid_depth(measured as f32)
            || measured > config.max_range
            || measured < config.min_range
        {
            continue;
        }
        // Projective distance along the optical axis: positive in front of the surface.
        let sdf = measured - p.z;
        if sdf < -truncation {
            continue;
        }
        // Measurements get noisier with range (structured light: σ ∝ z²), and behind the
        // surface they are guesses: voxblox's linear drop-off from one voxel to the truncation.
        let mut weight = 1.0 / (measured * measured);
        if sdf < -voxel {
            weight *= (truncation + sdf) / (truncation - voxel);
        }
        let weight = weight as f32;
        let sdf = sdf.min(truncation) as f32;
        let vox: &mut TsdfVoxel = &mut block.voxels[i];
        let total = vox.weight + weight;
        vox.distance = (vox.distance * vox.weight + sdf * weight) / total;
        if let Some(color) = color {
            if (sdf as f64) < truncation {
                let c = color.get(u, v);
                let previous = vox.weight;
                for (fused, &seen) in vox.color.iter_mut().zip(c) {
                    let blended = (*fused as f32 * previous + seen as f32 * weight) / total;
                    *fused = blended.round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        vox.weight = total.min(config.max_weight);
        updated += 1;
    }
    if updated > 0 {
        block.updated = true;
    }
    updated
}
