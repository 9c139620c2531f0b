use voxpan_core::nalgebra::{Point3, Vector3};

use super::{LabelVoxel, TsdfVoxel};
use crate::lanes::Lanes;

/// Voxels along a block edge. 8 (nvblox's size): small blocks allocate tightly around the
/// surface; 16³ was measured as slower to integrate and no faster to mesh.
/// Voxels along each edge of a block.
pub const BLOCK_SIDE: usize = 8;
pub(crate) const VOXELS_PER_BLOCK: usize = BLOCK_SIDE * BLOCK_SIDE * BLOCK_SIDE;

/// Integer coordinates of a block: block `b` covers `[b, b + 1) × block size` on each axis.
pub type BlockIndex = [i32; 3];

/// Integer coordinates of a voxel in the whole map: voxel `v` covers
/// `[v, v + 1) × voxel size` on each axis (its centre is at `(v + ½) × voxel size`).
pub type VoxelIndex = [i32; 3];

/// One bit per consumer of map changes (the mesher, publishers, ...): set by integration on
/// every block it touches, cleared by each consumer when it has seen the block (voxblox's
/// update bits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct UpdateBits(pub u8);

impl UpdateBits {
    pub const ALL: UpdateBits = UpdateBits(u8::MAX);

    pub fn has(self, consumer: u8) -> bool {
        self.0 >> consumer & 1 == 1
    }

    pub fn clear(&mut self, consumer: u8) {
        self.0 &= !(1 << consumer);
    }
}

/// A block's TSDF voxels as three arrays (distances, weights, colours) instead of one array of
/// 7-byte voxels: the distances or weights of a row of eight voxels are then 16 contiguous
/// bytes, which the integrator reads and writes whole. Voxels go in and out as [`TsdfVoxel`]
/// values; the size per voxel is the same.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Voxels {
    tsdf: [i16; VOXELS_PER_BLOCK],
    weight: [u16; VOXELS_PER_BLOCK],
    color: [[u8; 3]; VOXELS_PER_BLOCK],
}

impl Default for Voxels {
    fn default() -> Self {
        let unobserved = TsdfVoxel::default();
        Self {
            tsdf: [unobserved.tsdf_steps(); VOXELS_PER_BLOCK],
            weight: [unobserved.weight_bits(); VOXELS_PER_BLOCK],
            color: [unobserved.color(); VOXELS_PER_BLOCK],
        }
    }
}

impl Voxels {
    pub const fn len(&self) -> usize {
        VOXELS_PER_BLOCK
    }

    #[inline]
    pub fn get(&self, i: usize) -> TsdfVoxel {
        TsdfVoxel::from_parts(self.tsdf[i], self.weight[i], self.color[i])
    }

    #[inline]
    pub fn set(&mut self, i: usize, voxel: TsdfVoxel) {
        self.tsdf[i] = voxel.tsdf_steps();
        self.weight[i] = voxel.weight_bits();
        self.color[i] = voxel.color();
    }

    /// The voxels in index order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = TsdfVoxel> + '_ {
        (0..VOXELS_PER_BLOCK).map(|i| self.get(i))
    }

    /// Eight stored distances (in steps) from voxel `first` on.
    #[inline(always)]
    pub fn steps_row(&self, first: usize) -> [i16; BLOCK_SIDE] {
        self.tsdf[first..first + BLOCK_SIDE]
            .try_into()
            .expect("a row")
    }

    /// Every voxel's stored distance in steps and weight bits, in voxel order.
    pub fn steps_and_weights(&self) -> (&[i16; VOXELS_PER_BLOCK], &[u16; VOXELS_PER_BLOCK]) {
        (&self.tsdf, &self.weight)
    }

    /// Eight stored weights (bfloat16 bits) from voxel `first` on.
    #[inline(always)]
    pub fn weight_bits_row(&self, first: usize) -> [u16; BLOCK_SIDE] {
        self.weight[first..first + BLOCK_SIDE]
            .try_into()
            .expect("a row")
    }

    /// Stores the distances (in steps) and weights (bfloat16 bits) of the row from voxel
    /// `first` on where `lanes` has a bit set, the others' kept: one select and one store each.
    #[inline(always)]
    pub fn store_row(
        &mut self,
        first: usize,
        lanes: u32,
        steps: [i16; BLOCK_SIDE],
        weight_bits: [u16; BLOCK_SIDE],
    ) {
        let (old_steps, old_weights) = (self.steps_row(first), self.weight_bits_row(first));
        let kept = |x: usize| lanes >> x & 1 != 0;
        let steps: [i16; BLOCK_SIDE] =
            std::array::from_fn(|x| if kept(x) { steps[x] } else { old_steps[x] });
        let weights: [u16; BLOCK_SIDE] = std::array::from_fn(|x| {
            if kept(x) {
                weight_bits[x]
            } else {
                old_weights[x]
            }
        });
        self.tsdf[first..first + BLOCK_SIDE].copy_from_slice(&steps);
        self.weight[first..first + BLOCK_SIDE].copy_from_slice(&weights);
    }

    #[inline(always)]
    pub fn color_mut(&mut self, i: usize) -> &mut [u8; 3] {
        &mut self.color[i]
    }
}

/// `8³` voxels, x fastest.
#[derive(Clone, Debug)]
pub(crate) struct Block {
    pub voxels: Box<Voxels>,
    pub labels: Box<[LabelVoxel; VOXELS_PER_BLOCK]>,
    /// Which consumers have not seen the block's latest change.
    pub updates: UpdateBits,
    /// How many of the block's surface voxels each instance leads (derived from `voxels` and
    /// `labels` by [`Block::count_surface`] whenever they change): summing blocks sizes every
    /// instance without a pass over the voxels. 512 voxels a block: `u16` counts.
    pub surface: Vec<(u16, u16)>,
    /// The instances its labels may hold, leading or runner-up, each once: kept a superset
    /// as labels change (see [`Block::note_instance`]), made exact by
    /// [`Block::count_surface`]. A merge then relabels only the blocks that list the merged
    /// instance, not the whole map.
    pub instances: Vec<u16>,
    /// How many of its surface voxels no instance leads (kept with `surface`): hole filling
    /// reads the voxels of only the blocks that have some.
    pub unlabelled_surface: u16,
}

/// Blocks are equal when their voxels, labels, update bits and surface counts are:
/// `instances` may list instances the labels no longer hold.
impl PartialEq for Block {
    fn eq(&self, other: &Self) -> bool {
        self.voxels == other.voxels
            && self.labels == other.labels
            && self.updates == other.updates
            && self.surface == other.surface
            && self.unlabelled_surface == other.unlabelled_surface
    }
}

impl Default for Block {
    fn default() -> Self {
        Self {
            voxels: Box::default(),
            labels: Box::new([LabelVoxel::default(); VOXELS_PER_BLOCK]),
            updates: UpdateBits::default(),
            surface: Vec::new(),
            instances: Vec::new(),
            unlabelled_surface: 0,
        }
    }
}

/// Adds instance `id` (not 0) to a block's `instances` unless listed (the recount borrows
/// the block's labels while it lists, so it takes the field, not the block).
#[inline]
fn list_instance(instances: &mut Vec<u16>, id: u16) {
    if id != 0 && !instances.contains(&id) {
        instances.push(id);
    }
}

/// Adds `n` surface voxels led by instance `id` to a block's `surface` counts (the recount
/// borrows the block's labels while it counts, so it takes the field, not the block).
#[inline]
pub(crate) fn count_surface_voxels(surface: &mut Vec<(u16, u16)>, id: u16, n: u16) {
    // A block holds a few instances at most: a linear search beats hashing.
    match surface.iter_mut().find(|(i, _)| *i == id) {
        Some((_, m)) => *m += n,
        None => surface.push((id, n)),
    }
}

/// Whether `voxel` (which stores its distance as a fraction of `truncation` metres) is
/// observed and within `limit` metres of the surface: what the map calls a surface voxel.
#[inline]
pub(crate) fn on_surface(voxel: &TsdfVoxel, truncation: f32, limit: f32) -> bool {
    voxel.observed() && (voxel.tsdf() * truncation).abs() < limit
}

/// Which of eight voxels are surface voxels (see [`on_surface`]), one bit each: from their
/// distances over the truncation distance and their weights, as the voxels decode them.
#[inline(always)]
pub(crate) fn on_surface_lanes<L: Lanes>(tsdf: L, weight: L, truncation: f32, limit: f32) -> u32 {
    // Observed: any weight bit set (as `TsdfVoxel::observed`).
    let observed = weight.nonzero_bitmask();
    let near = (tsdf * L::splat(truncation))
        .abs()
        .simd_lt(L::splat(limit))
        .to_bitmask();
    observed & near
}

/// The block holding global voxel `v`, and `v`'s index inside it.
pub(crate) fn split(v: VoxelIndex) -> (BlockIndex, usize) {
    let side = BLOCK_SIDE as i32;
    let block = v.map(|c| c.div_euclid(side));
    let local = v.map(|c| c.rem_euclid(side) as usize);
    (block, Block::linear(local[0], local[1], local[2]))
}

impl Block {
    /// Recounts [`Block::surface`]: surface voxels (see [`on_surface`]) by leading instance.
    pub fn count_surface(&mut self, truncation: f32, limit: f32) {
        self.surface.clear();
        self.instances.clear();
        self.unlabelled_surface = 0;
        for (voxel, label) in self.voxels.iter().zip(self.labels.iter()) {
            for (id, n) in label.ids().into_iter().zip(label.counts()) {
                if n > 0 {
                    list_instance(&mut self.instances, id);
                }
            }
            if !on_surface(&voxel, truncation, limit) {
                continue;
            }
            let id = label.instance();
            if id == 0 {
                self.unlabelled_surface += 1;
                continue;
            }
            count_surface_voxels(&mut self.surface, id, 1);
        }
    }

    /// Lists instance `id` among those the block's labels may hold (see
    /// [`Block::instances`]); call it whenever a label may have taken `id`.
    #[inline]
    pub fn note_instance(&mut self, id: u16) {
        list_instance(&mut self.instances, id);
    }

    /// Moves one surface voxel's count from instance `from` to instance `into` (0 = none):
    /// keeps [`Block::surface`] as a recount would give it while voxels change one by one.
    pub fn move_surface_voxel(&mut self, from: u16, into: u16) {
        if from != 0 {
            let counted = self.surface.iter().position(|(i, _)| *i == from);
            debug_assert!(
                counted.is_some(),
                "instance {from} has no surface count here"
            );
            if let Some(k) = counted {
                self.surface[k].1 -= 1;
                if self.surface[k].1 == 0 {
                    self.surface.swap_remove(k);
                }
            }
        }
        if into != 0 {
            count_surface_voxels(&mut self.surface, into, 1);
        }
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

    /// Global index of voxel `i` of block `index`.
    #[inline]
    pub fn voxel_index(index: BlockIndex, i: usize) -> VoxelIndex {
        let (x, y, z) = Self::coords(i);
        let side = BLOCK_SIDE as i32;
        [
            index[0] * side + x as i32,
            index[1] * side + y as i32,
            index[2] * side + z as i32,
        ]
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

    #[test]
    fn global_voxel_indices_split_into_block_and_local() {
        for v in [[0, 0, 0], [-1, 7, 8], [-9, -8, 17]] {
            let (block, local) = split(v);
            assert_eq!(Block::voxel_index(block, local), v);
        }
        assert_eq!(split([-1, 0, 0]).0, [-1, 0, 0]);
    }
}
