use rustc_hash::FxHashMap;
use voxpan_core::nalgebra::Point3;

use crate::{Block, BlockIndex, TsdfVoxel, BLOCK_SIDE};

/// A sparse voxel grid: blocks allocated only where something was observed.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    voxel_size: f64,
    pub blocks: FxHashMap<BlockIndex, Block>,
}

impl Layer {
    pub fn new(voxel_size: f64) -> Self {
        Self {
            voxel_size,
            blocks: FxHashMap::default(),
        }
    }

    pub fn voxel_size(&self) -> f64 {
        self.voxel_size
    }

    /// Edge length of a block in metres.
    pub fn block_size(&self) -> f64 {
        self.voxel_size * BLOCK_SIDE as f64
    }

    /// The block containing `p`.
    pub fn block_index(&self, p: &Point3<f64>) -> BlockIndex {
        let s = self.block_size();
        [
            (p.x / s).floor() as i32,
            (p.y / s).floor() as i32,
            (p.z / s).floor() as i32,
        ]
    }

    /// The block containing `p` and the index of `p`'s voxel in it, if the block exists.
    fn locate(&self, p: &Point3<f64>) -> Option<(&Block, usize)> {
        let index = self.block_index(p);
        let block = self.blocks.get(&index)?;
        let s = self.block_size();
        let local =
            |v: f64, b: i32| (((v - b as f64 * s) / self.voxel_size) as usize).min(BLOCK_SIDE - 1);
        let i = Block::linear(
            local(p.x, index[0]),
            local(p.y, index[1]),
            local(p.z, index[2]),
        );
        Some((block, i))
    }

    /// The voxel containing `p`, if its block exists.
    pub fn voxel_at(&self, p: &Point3<f64>) -> Option<&TsdfVoxel> {
        self.locate(p).map(|(block, i)| &block.voxels[i])
    }

    /// Instance labels of the labelled voxels whose centres lie within `radius` of `p`.
    pub fn voxels_near(&self, p: &Point3<f64>, radius: f64) -> Vec<u16> {
        let mut out = Vec::new();
        let steps = (radius / self.voxel_size).ceil() as i64;
        for dz in -steps..=steps {
            for dy in -steps..=steps {
                for dx in -steps..=steps {
                    let q =
                        p + voxpan_core::nalgebra::Vector3::new(dx as f64, dy as f64, dz as f64)
                            * self.voxel_size;
                    if (q - p).norm() > radius {
                        continue;
                    }
                    if let Some((block, i)) = self.locate(&q) {
                        let id = block.labels[i].instance();
                        if id != 0 {
                            out.push(id);
                        }
                    }
                }
            }
        }
        out
    }

    /// Voxels allocated (observed or not).
    pub fn allocated_voxels(&self) -> usize {
        self.blocks.len() * crate::VOXELS_PER_BLOCK
    }
}
