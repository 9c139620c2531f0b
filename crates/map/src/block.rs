use voxpan_core::nalgebra::{Point3, Vector3};

use crate::{LabelVoxel, TsdfVoxel};

/// Voxels along a block edge.
pub const BLOCK_SIDE: usize = 8;
pub const VOXELS_PER_BLOCK: usize = BLOCK_SIDE * BLOCK_SIDE * BLOCK_SIDE;

/// Integer coordinates of a block: block `b` covers `[b, b + 1) × block size` on each axis.
pub type BlockIndex = [i32; 3];

/// `8³` voxels, x fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    pub voxels: Box<[TsdfVoxel; VOXELS_PER_BLOCK]>,
    pub labels: Box<[LabelVoxel; VOXELS_PER_BLOCK]>,
    /// Bit `i` set when voxel `i` is a labelled surface voxel (observed, |distance| < one
    /// voxel, an instance): what instance rendering reads, without scanning the block.
    pub surface: [u64; VOXELS_PER_BLOCK / 64],
    /// Set when integration touched the block since the flag was last cleared (for incremental
    /// meshing).
    pub updated: bool,
}

impl Default for Block {
    fn default() -> Self {
        Self {
            voxels: Box::new([TsdfVoxel::default(); VOXELS_PER_BLOCK]),
            labels: Box::new([LabelVoxel::default(); VOXELS_PER_BLOCK]),
            surface: [0; VOXELS_PER_BLOCK / 64],
            updated: false,
        }
    }
}

impl Block {
    /// Recomputes [`Block::surface`] for voxels of edge `voxel_size`.
    pub fn refresh_surface(&mut self, voxel_size: f64) {
        let limit = voxel_size as f32;
        self.surface = [0; VOXELS_PER_BLOCK / 64];
        for (i, (v, l)) in self.voxels.iter().zip(self.labels.iter()).enumerate() {
            if v.observed() && v.distance.abs() < limit && l.instance() != 0 {
                self.surface[i / 64] |= 1 << (i % 64);
            }
        }
    }

    /// Indices of the labelled surface voxels.
    pub fn surface_voxels(&self) -> impl Iterator<Item = usize> + '_ {
        self.surface.iter().enumerate().flat_map(|(w, &bits)| {
            (0..64)
                .filter(move |b| bits >> b & 1 == 1)
                .map(move |b| w * 64 + b)
        })
    }

    /// Index of voxel `(x, y, z)` within the block.
    #[inline]
    pub fn linear(x: usize, y: usize, z: usize) -> usize {
        x + BLOCK_SIDE * (y + BLOCK_SIDE * z)
    }

    /// Voxel coordinates within the block of linear index `i`.
    #[inline]
    pub fn coords(i: usize) -> (usize, usize, usize) {
        (
            i % BLOCK_SIDE,
            (i / BLOCK_SIDE) % BLOCK_SIDE,
            i / (BLOCK_SIDE * BLOCK_SIDE),
        )
    }

    /// World position of the centre of voxel `i` of block `index`.
    #[inline]
    pub fn voxel_center(index: BlockIndex, i: usize, voxel_size: f64) -> Point3<f64> {
        let (x, y, z) = Self::coords(i);
        let origin = Vector3::new(index[0] as f64, index[1] as f64, index[2] as f64)
            * (BLOCK_SIDE as f64 * voxel_size);
        Point3::from(
            origin + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * voxel_size,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_and_coords_are_inverse() {
        for i in 0..VOXELS_PER_BLOCK {
            let (x, y, z) = Block::coords(i);
            assert_eq!(Block::linear(x, y, z), i);
        }
    }

    #[test]
    fn voxel_centres() {
        let c = Block::voxel_center([-1, 0, 2], 0, 0.1);
        assert!((c - Point3::new(-0.75, 0.05, 1.65)).norm() < 1e-12);
    }
}
