//! The sparse voxel grid: `8³`-voxel blocks in a hash map keyed by integer block index
//! (voxblox's layer of blocks), each block remembering which consumers have not yet seen its
//! latest changes.

mod block;
mod holes;
mod pieces;
mod votes;
mod voxel;

use block::count_surface_voxels;
pub use block::{BLOCK_SIDE, BlockIndex, VoxelIndex};
pub(crate) use block::{Block, UpdateBits, VOXELS_PER_BLOCK, on_surface, on_surface_lanes, split};
pub(crate) use voxel::{LabelVoxel, MAX_WEIGHT, MIN_WEIGHT, TSDF_STEPS, TsdfVoxel};

use rayon::prelude::*;
use rustc_hash::FxHashMap;
use voxpan_core::nalgebra::Point3;

/// Blocks allocated only where something was observed.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Layer {
    voxel_size: f64,
    /// The truncation distance in metres: voxels store distances as a fraction of it.
    truncation: f32,
    blocks: FxHashMap<BlockIndex, Block>,
    /// Surface voxels led by each instance: the blocks' [`Block::surface`] counts summed,
    /// kept up to date as blocks are taken out and put back (integration's way of changing
    /// them), so that sizing every instance costs nothing per frame.
    surface_totals: FxHashMap<u16, usize>,
}

impl Layer {
    pub fn new(voxel_size: f64, truncation: f64) -> Self {
        Self {
            voxel_size,
            truncation: truncation as f32,
            blocks: FxHashMap::default(),
            surface_totals: FxHashMap::default(),
        }
    }

    pub fn voxel_size(&self) -> f64 {
        self.voxel_size
    }

    /// The truncation distance in metres: voxels store distances as fractions of it.
    pub fn truncation(&self) -> f32 {
        self.truncation
    }

    /// A voxel's signed distance in metres.
    pub fn distance(&self, v: &TsdfVoxel) -> f32 {
        v.tsdf() * self.truncation
    }

    /// A voxel holding `distance` metres with a positive `weight`, as a map file stores them:
    /// a weight beyond what a voxel holds is clamped into its range, so that the voxel stays
    /// observed and saves back as it loaded.
    pub fn voxel(&self, distance: f32, weight: f32, color: [u8; 3]) -> TsdfVoxel {
        TsdfVoxel::new(
            distance / self.truncation,
            weight.clamp(MIN_WEIGHT, MAX_WEIGHT),
            color,
        )
    }

    /// Edge length of a block in metres.
    pub fn block_size(&self) -> f64 {
        self.voxel_size * BLOCK_SIDE as f64
    }

    pub fn len(&self) -> usize {
        self.blocks.len()
    }

    pub fn get(&self, index: &BlockIndex) -> Option<&Block> {
        self.blocks.get(index)
    }

    pub fn contains(&self, index: &BlockIndex) -> bool {
        self.blocks.contains_key(index)
    }

    /// The block at `index`, allocated if missing; the flag says whether it was new.
    #[cfg(test)]
    pub fn get_or_allocate(&mut self, index: BlockIndex) -> (&mut Block, bool) {
        let mut new = false;
        let block = self.blocks.entry(index).or_insert_with(|| {
            new = true;
            Block::default()
        });
        (block, new)
    }

    /// Runs `update` on the blocks at `indices` (strictly increasing, so distinct) in parallel
    /// and in place, allocating the missing ones, and keeps the surface totals; returns the sum
    /// of what `update` returned and how many blocks were new. Neighbouring indices go to the
    /// same worker, one after the other (they read neighbouring pixels, which stay in cache).
    pub fn update_blocks(
        &mut self,
        indices: &[BlockIndex],
        update: impl Fn(BlockIndex, &mut Block) -> usize + Sync,
    ) -> (usize, usize) {
        assert!(
            indices.windows(2).all(|w| w[0] < w[1]),
            "block indices must be strictly increasing"
        );
        // Distinct keys name distinct entries: the map hands out one `&mut` per key, and it
        // is not changed while they live. (Taking the blocks out and putting them back cost
        // two hash operations per block on the mapping thread; filtering every block of the
        // map by the frame's set would cost what the map holds, not what the frame touches.)
        let blocks: Vec<Option<BlockPtr>> = indices
            .iter()
            .map(|index| {
                self.blocks
                    .get_mut(index)
                    .map(|b| BlockPtr(b as *mut Block))
            })
            .collect();
        let results: Vec<BlockUpdated> = indices
            .par_iter()
            .zip(blocks)
            .map(|(&index, slot)| match slot {
                // SAFETY: the pointers come from `get_mut` on distinct keys of `self.blocks`
                // (checked above), which is not touched until they are dropped below.
                Some(ptr) => {
                    let block = unsafe { &mut *ptr.0 };
                    let before = block.surface.clone();
                    let updated = update(index, block);
                    let surface = surface_changes(&before, &block.surface);
                    BlockUpdated {
                        updated,
                        new: None,
                        surface,
                    }
                }
                None => {
                    let mut block = Block::default();
                    let updated = update(index, &mut block);
                    // A new block's counts are tallied when it is inserted.
                    BlockUpdated {
                        updated,
                        new: Some(block),
                        surface: Vec::new(),
                    }
                }
            })
            .collect();
        let (mut updated, mut new) = (0, 0);
        for (&index, result) in indices.iter().zip(results) {
            updated += result.updated;
            retally(&mut self.surface_totals, &result.surface);
            if let Some(block) = result.new {
                new += 1;
                self.insert(index, block);
            }
        }
        (updated, new)
    }

    pub fn insert(&mut self, index: BlockIndex, block: Block) -> Option<Block> {
        tally(&mut self.surface_totals, &block.surface);
        let old = self.blocks.insert(index, block);
        if let Some(old) = &old {
            untally(&mut self.surface_totals, &old.surface);
        }
        old
    }

    /// Takes block `index` out, its surface counts with it.
    pub fn remove(&mut self, index: &BlockIndex) -> Option<Block> {
        let old = self.blocks.remove(index);
        if let Some(old) = &old {
            untally(&mut self.surface_totals, &old.surface);
        }
        old
    }

    /// The centre of block `index`.
    pub fn block_center(&self, index: &BlockIndex) -> Point3<f64> {
        let s = self.block_size();
        Point3::new(
            (index[0] as f64 + 0.5) * s,
            (index[1] as f64 + 0.5) * s,
            (index[2] as f64 + 0.5) * s,
        )
    }

    pub fn iter(&self) -> impl Iterator<Item = (&BlockIndex, &Block)> {
        self.blocks.iter()
    }

    pub fn iter_mut(&mut self) -> impl Iterator<Item = (&BlockIndex, &mut Block)> {
        self.blocks.iter_mut()
    }

    /// Block indices in a fixed order (so equal maps serialise and mesh identically).
    pub fn sorted_indices(&self) -> Vec<BlockIndex> {
        let mut indices: Vec<BlockIndex> = self.blocks.keys().copied().collect();
        indices.sort_unstable();
        indices
    }

    /// The block containing `p`.
    pub fn block_index(&self, p: &Point3<f64>) -> BlockIndex {
        let s = self.block_size();
        [floor_i32(p.x / s), floor_i32(p.y / s), floor_i32(p.z / s)]
    }

    /// The global voxel containing `p`.
    pub fn voxel_index(&self, p: &Point3<f64>) -> VoxelIndex {
        let s = self.voxel_size;
        [floor_i32(p.x / s), floor_i32(p.y / s), floor_i32(p.z / s)]
    }

    /// The block holding global voxel `v` and the voxel's index inside it, if allocated.
    pub fn locate(&self, v: VoxelIndex) -> Option<(&Block, usize)> {
        let (block, local) = block::split(v);
        self.blocks.get(&block).map(|b| (b, local))
    }

    /// Relabels each instance `from` as its `into` in every voxel, for `(from, into)` in
    /// `merges` in order (a later merge may move an earlier one's `into`; two slots holding
    /// the same instance then pool their counts); marks the blocks that changed for every
    /// consumer. One pass over the map whatever the number of merges.
    pub fn relabel(&mut self, merges: &[(u16, u16)]) {
        if merges.is_empty() {
            return;
        }
        // Each merged-away id straight to where it ends up, as a table indexed by id (0: kept):
        // a look-up per label a voxel holds, over the whole map.
        let mut ends: FxHashMap<u16, u16> = FxHashMap::default();
        for &(from, into) in merges {
            for target in ends.values_mut() {
                if *target == from {
                    *target = into;
                }
            }
            ends.insert(from, into);
        }
        let mut to = vec![0u16; usize::from(u16::MAX) + 1];
        for (&from, &into) in &ends {
            to[usize::from(from)] = into;
        }
        // Counts follow the ids below only when no id ends where another was merged away (the
        // tracker never merges into a merged-away id).
        debug_assert!(
            ends.values().all(|&into| to[usize::from(into)] == 0),
            "merges into a merged-away id: {merges:?}"
        );
        // Blocks relabel in parallel; each changed one reports how its surface counts changed,
        // which the totals then follow (as integration's updates do).
        let changes: Vec<Vec<(u16, i32)>> = self
            .blocks
            .par_iter_mut()
            .filter_map(|(_, block)| {
                // A block none of whose labels may hold a merged-away instance is untouched.
                if block.instances.iter().all(|&id| to[usize::from(id)] == 0) {
                    return None;
                }
                let mut changed = false;
                for l in block.labels.iter_mut() {
                    for id in l.ids() {
                        let into = to[usize::from(id)];
                        if id != 0 && into != 0 {
                            changed |= l.relabel(id, into);
                        }
                    }
                }
                changed.then(|| {
                    block.updates = UpdateBits::ALL;
                    // A voxel led by `id` is led by where `id` ends up (a label's two slots
                    // either keep their counts or pool into one), and the surface does not
                    // move: the counts follow the ids without a recount.
                    let end_of = |id: u16| match to[usize::from(id)] {
                        0 => id,
                        into => into,
                    };
                    let before = std::mem::take(&mut block.surface);
                    for &(id, n) in &before {
                        count_surface_voxels(&mut block.surface, end_of(id), n);
                    }
                    for id in std::mem::take(&mut block.instances) {
                        block.note_instance(end_of(id));
                    }
                    surface_changes(&before, &block.surface)
                })
            })
            .collect();
        for change in changes {
            retally(&mut self.surface_totals, &change);
        }
    }

    /// Pairs of instances whose surface voxels touch (face neighbours led by different
    /// instances), smaller id first, with how many such voxel faces they share.
    pub fn touching_instances(&self) -> FxHashMap<(u16, u16), u32> {
        self.blocks
            .par_iter()
            .fold(FxHashMap::default, |mut pairs, (&index, block)| {
                // A pair is counted from the block of its lower voxel, which must hold labelled
                // surface.
                let Some(&(only, _)) = block.surface.first() else {
                    return pairs;
                };
                // The blocks above along x, y and z, for the voxels on those faces.
                let above: [Option<&Block>; 3] = std::array::from_fn(|axis| {
                    let mut next = index;
                    next[axis] += 1;
                    self.blocks.get(&next)
                });
                // Most blocks lie inside one instance's surface: when the surface counts say
                // that this block and the blocks above lead no other instance, no pair starts
                // here, and no voxel needs reading.
                let alone = |b: &Block| b.surface.iter().all(|&(id, _)| id == only);
                if block.surface.len() == 1 && above.iter().all(|b| b.is_none_or(alone)) {
                    return pairs;
                }
                // Each voxel's leader is read once, not once more per neighbour.
                let leaders: [u16; VOXELS_PER_BLOCK] =
                    std::array::from_fn(|i| self.surface_leader(block, i));
                for (i, &id) in leaders.iter().enumerate() {
                    if id == 0 {
                        continue;
                    }
                    let (x, y, z) = Block::coords(i);
                    let at = [x, y, z];
                    for axis in 0..3 {
                        let mut next = at;
                        next[axis] += 1;
                        let other = if next[axis] < BLOCK_SIDE {
                            leaders[Block::linear(next[0], next[1], next[2])]
                        } else {
                            next[axis] = 0;
                            above[axis].map_or(0, |b| {
                                self.surface_leader(b, Block::linear(next[0], next[1], next[2]))
                            })
                        };
                        if other != 0 && other != id {
                            *pairs.entry((id.min(other), id.max(other))).or_insert(0) += 1;
                        }
                    }
                }
                pairs
            })
            .reduce(FxHashMap::default, |mut a, b| {
                for (pair, n) in b {
                    *a.entry(pair).or_insert(0) += n;
                }
                a
            })
    }

    /// How far from the surface (metres) a voxel counts as a surface voxel: within one voxel,
    /// the band a zero crossing's two sides fall in.
    pub fn surface_limit(&self) -> f32 {
        self.voxel_size as f32
    }

    /// The instance leading voxel `i` of `block` where it is a surface voxel (see
    /// [`Self::is_surface`]), else 0.
    pub(crate) fn surface_leader(&self, block: &Block, i: usize) -> u16 {
        let id = block.labels[i].instance();
        if id != 0 && self.is_surface(&block.voxels.get(i)) {
            id
        } else {
            0
        }
    }

    /// Whether `v` is a surface voxel (see [`Self::surface_limit`]).
    pub fn is_surface(&self, v: &TsdfVoxel) -> bool {
        on_surface(v, self.truncation, self.surface_limit())
    }

    /// Recounts every block's surface voxels by instance (after blocks were changed in place:
    /// loaded, or built by hand).
    pub fn count_surfaces(&mut self) {
        let (truncation, limit) = (self.truncation, self.surface_limit());
        self.surface_totals.clear();
        for block in self.blocks.values_mut() {
            block.count_surface(truncation, limit);
            tally(&mut self.surface_totals, &block.surface);
        }
    }

    /// Surface voxels led by each instance (instances leading none are absent).
    pub fn surface_counts(&self) -> &FxHashMap<u16, usize> {
        &self.surface_totals
    }

    /// Blocks allocated (observed or not).
    pub fn allocated_voxels(&self) -> usize {
        self.blocks.len() * VOXELS_PER_BLOCK
    }
}

/// What [`Layer::update_blocks`] learns from one block's update.
struct BlockUpdated {
    /// What the update returned.
    updated: usize,
    /// The block, when it was allocated for the update (not yet in the map).
    new: Option<Block>,
    /// How its surface counts changed, per instance.
    surface: Vec<(u16, i32)>,
}

/// A block's own pointer, sent to the worker that updates it (see [`Layer::update_blocks`]).
struct BlockPtr(*mut Block);

// SAFETY: each pointer is used by one worker only, to a block no one else reaches meanwhile.
unsafe impl Send for BlockPtr {}

/// How a block's surface counts changed from `before` to `after`, per instance.
fn surface_changes(before: &[(u16, u16)], after: &[(u16, u16)]) -> Vec<(u16, i32)> {
    let count = |list: &[(u16, u16)], id: u16| {
        list.iter()
            .find(|(i, _)| *i == id)
            .map_or(0, |&(_, n)| n as i32)
    };
    let mut changes: Vec<(u16, i32)> = after
        .iter()
        .map(|&(id, n)| (id, n as i32 - count(before, id)))
        .filter(|&(_, change)| change != 0)
        .collect();
    changes.extend(
        before
            .iter()
            .filter(|&&(id, _)| count(after, id) == 0)
            .map(|&(id, n)| (id, -(n as i32))),
    );
    changes
}

/// The 26 indices around `index` (of a block or of a voxel): its face, edge and corner
/// neighbours.
pub(crate) fn all_neighbours(index: [i32; 3]) -> impl Iterator<Item = [i32; 3]> {
    NEIGHBOUR_STEPS
        .map(|[x, y, z]| [index[0] + x, index[1] + y, index[2] + z])
        .into_iter()
}

/// `index` and the 26 indices around it.
pub(crate) fn with_neighbours(index: [i32; 3]) -> impl Iterator<Item = [i32; 3]> {
    std::iter::once(index).chain(all_neighbours(index))
}

/// The steps along x, y and z to the 26 neighbours of a voxel or a block, x fastest.
pub(crate) const NEIGHBOUR_STEPS: [[i32; 3]; 26] = {
    let mut steps = [[0i32; 3]; 26];
    let (mut k, mut n) = (0, 0);
    while k < 27 {
        if k != 13 {
            steps[n] = [k % 3 - 1, k / 3 % 3 - 1, k / 9 - 1];
            n += 1;
        }
        k += 1;
    }
    steps
};

/// Adds a block's surface counts to `totals`.
fn tally(totals: &mut FxHashMap<u16, usize>, block: &[(u16, u16)]) {
    for &(id, n) in block {
        *totals.entry(id).or_insert(0) += n as usize;
    }
}

/// Takes a block's surface counts (added before) back out of `totals`.
fn untally(totals: &mut FxHashMap<u16, usize>, block: &[(u16, u16)]) {
    for &(id, n) in block {
        if let Some(total) = totals.get_mut(&id) {
            *total -= n as usize;
            if *total == 0 {
                totals.remove(&id);
            }
        }
    }
}

/// Applies a block's surface count changes (see [`surface_changes`]) to `totals`.
fn retally(totals: &mut FxHashMap<u16, usize>, changes: &[(u16, i32)]) {
    for &(id, change) in changes {
        let total = totals.entry(id).or_insert(0);
        *total = total.wrapping_add_signed(change as isize);
        if *total == 0 {
            totals.remove(&id);
        }
    }
}

/// `floor(x) as i32` (saturating alike), without the libm call `f64::floor` is on baseline
/// x86-64: block and voxel look-ups do it per sample.
#[inline]
pub(crate) fn floor_i32(x: f64) -> i32 {
    let i = x as i32;
    // Truncation rounded up for negative non-integers: one less then, without a branch (its
    // direction follows the coordinates' signs, which a predictor does not guess well).
    i.saturating_sub(((i as f64) > x) as i32)
}

/// The voxel containing `p`, given `1 / voxel size` (a product per axis, not the division
/// [`Layer::voxel_index`] does: per-sample look-ups use this one).
#[inline]
pub(crate) fn voxel_of(p: &Point3<f64>, inv_voxel: f64) -> VoxelIndex {
    [
        floor_i32(p.x * inv_voxel),
        floor_i32(p.y * inv_voxel),
        floor_i32(p.z * inv_voxel),
    ]
}

/// The block of global voxel `v` (blocks are 8 voxels: an arithmetic shift floors negative
/// coordinates too).
#[inline]
pub(crate) fn block_of(v: VoxelIndex) -> BlockIndex {
    const SHIFT: u32 = BLOCK_SIDE.trailing_zeros();
    v.map(|c| c >> SHIFT)
}

#[cfg(test)]
mod tests {
    use super::{Block, LabelVoxel, Layer, VoxelIndex, floor_i32, surface_changes};
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    /// A layer of 2 cm voxels over 2 x 2 x 2 blocks with `voxels` set: each a surface voxel
    /// (on the zero crossing) or one far from the surface, led by its instance (0: none) with
    /// the runner-up `second` where given.
    fn layer_of(voxels: &[(VoxelIndex, bool, u16, u16)]) -> Layer {
        let mut layer = Layer::new(0.02, 0.08);
        for &(v, surface, id, second) in voxels {
            let voxel = layer.voxel(if surface { 0.0 } else { 0.08 }, 1.0, [0; 3]);
            let (index, i) = super::split(v);
            let (block, _) = layer.get_or_allocate(index);
            block.voxels.set(i, voxel);
            block.labels[i] = LabelVoxel::from_parts([id, second], [2, u16::from(second != 0)]);
        }
        layer.count_surfaces();
        layer
    }

    fn voxels() -> impl Strategy<Value = Vec<(VoxelIndex, bool, u16, u16)>> {
        proptest::collection::btree_map(
            (0i32..16, 0i32..16, 0i32..16),
            (any::<bool>(), 0u16..5, 0u16..5),
            0..800,
        )
        .prop_map(|m| {
            m.into_iter()
                .map(|((x, y, z), (s, id, second))| {
                    ([x, y, z], s, id, if second == id { 0 } else { second })
                })
                .collect()
        })
    }

    proptest! {
        /// The faces between surface voxels led by different instances, counted per pair,
        /// equal a brute-force count over every voxel and its six neighbours (each face twice).
        #[test]
        fn touching_instances_count_every_shared_face(voxels in voxels()) {
            let layer = layer_of(&voxels);
            let leader: BTreeMap<VoxelIndex, u16> = voxels
                .iter()
                .filter(|&&(_, surface, id, _)| surface && id != 0)
                .map(|&(v, _, id, _)| (v, id))
                .collect();
            let mut expected: BTreeMap<(u16, u16), u32> = BTreeMap::new();
            for (v, &a) in &leader {
                for axis in 0..3 {
                    for step in [-1, 1] {
                        let mut n = *v;
                        n[axis] += step;
                        if let Some(&b) = leader.get(&n).filter(|&&b| b != a) {
                            *expected.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                        }
                    }
                }
            }
            expected.values_mut().for_each(|n| *n /= 2);
            let found: BTreeMap<(u16, u16), u32> = layer.touching_instances().into_iter().collect();
            prop_assert_eq!(found, expected);
        }

        /// The same where most blocks hold one instance's surface, as most of a map's blocks
        /// do (the blocks whose surface counts rule out a pair are skipped unread).
        #[test]
        fn touching_instances_count_faces_between_blocks_of_one_instance_each(
            voxels in voxels(),
            stray in 0usize..4,
        ) {
            let voxels: Vec<(VoxelIndex, bool, u16, u16)> = voxels
                .into_iter()
                .enumerate()
                .map(|(k, (v, surface, _, second))| {
                    let by_block = (v[0] / 8 + v[1] / 8 * 2 + v[2] / 8) as u16 % 3 + 1;
                    let id = if k % 97 < stray { 4 } else { by_block };
                    (v, surface, id, if second == id { 0 } else { second })
                })
                .collect();
            let layer = layer_of(&voxels);
            let leader: BTreeMap<VoxelIndex, u16> = voxels
                .iter()
                .filter(|&&(_, surface, _, _)| surface)
                .map(|&(v, _, id, _)| (v, id))
                .collect();
            let mut expected: BTreeMap<(u16, u16), u32> = BTreeMap::new();
            for (v, &a) in &leader {
                for axis in 0..3 {
                    let mut n = *v;
                    n[axis] += 1;
                    if let Some(&b) = leader.get(&n).filter(|&&b| b != a) {
                        *expected.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                    }
                }
            }
            let found: BTreeMap<(u16, u16), u32> = layer.touching_instances().into_iter().collect();
            prop_assert_eq!(found, expected);
        }

        /// Relabelling for several merges at once (chains included) leaves every voxel as
        /// relabelling for them one at a time does.
        #[test]
        fn relabelling_many_merges_at_once_equals_one_at_a_time(
            voxels in voxels(),
            merges in proptest::collection::vec((1u16..5, 1u16..5), 0..4),
        ) {
            let merges: Vec<(u16, u16)> = merges.into_iter().filter(|(a, b)| a != b).collect();
            // As the tracker makes them: a merged-away id is never merged into again.
            let mut gone = Vec::new();
            let merges: Vec<(u16, u16)> = merges
                .into_iter()
                .filter(|&(from, into)| {
                    let ok = !gone.contains(&from) && !gone.contains(&into);
                    if ok {
                        gone.push(from);
                    }
                    ok
                })
                .collect();
            let mut together = layer_of(&voxels);
            together.relabel(&merges);
            let mut one_by_one = layer_of(&voxels);
            for &merge in &merges {
                one_by_one.relabel(&[merge]);
            }
            for (index, block) in together.iter() {
                let other = one_by_one.get(index).unwrap();
                for i in 0..super::VOXELS_PER_BLOCK {
                    prop_assert_eq!(block.labels[i], other.labels[i], "{:?} {}", Block::voxel_index(*index, i), i);
                }
            }
            prop_assert_eq!(together.surface_counts(), one_by_one.surface_counts());
            // Each block's counts follow the ids without a recount: they equal one, and the
            // block still lists every instance its labels hold.
            let sorted = |list: &[(u16, u16)]| {
                let mut list = list.to_vec();
                list.sort_unstable();
                list
            };
            for (index, block) in together.iter() {
                let mut recounted = block.clone();
                recounted.count_surface(together.truncation(), together.surface_limit());
                prop_assert_eq!(sorted(&block.surface), sorted(&recounted.surface), "{:?}", index);
                prop_assert_eq!(block.unlabelled_surface, recounted.unlabelled_surface);
                for id in &recounted.instances {
                    prop_assert!(block.instances.contains(id), "{:?} does not list {}", index, id);
                }
            }
            // No label holds a merged-away instance any more (a merge skips only blocks that
            // do not list it).
            for (index, block) in together.iter() {
                for i in 0..super::VOXELS_PER_BLOCK {
                    let l = block.labels[i];
                    for (id, n) in l.ids().into_iter().zip(l.counts()) {
                        prop_assert!(
                            n == 0 || !gone.contains(&id),
                            "{:?} still holds {}", Block::voxel_index(*index, i), id
                        );
                    }
                }
            }
        }
    }

    proptest! {
        /// A block's counts before, changed by [`surface_changes`], are its counts after.
        #[test]
        fn surface_changes_turn_one_count_list_into_the_other(
            before in proptest::collection::btree_map(1u16..8, 1u16..600, 0..5),
            after in proptest::collection::btree_map(1u16..8, 1u16..600, 0..5),
        ) {
            let b: Vec<(u16, u16)> = before.clone().into_iter().collect();
            let a: Vec<(u16, u16)> = after.clone().into_iter().collect();
            let mut totals: BTreeMap<u16, i32> =
                before.iter().map(|(&id, &n)| (id, n as i32)).collect();
            let changes = surface_changes(&b, &a);
            prop_assert!(changes.iter().all(|&(_, change)| change != 0));
            for (id, change) in changes {
                *totals.entry(id).or_insert(0) += change;
            }
            totals.retain(|_, n| *n != 0);
            let expected: BTreeMap<u16, i32> =
                after.iter().map(|(&id, &n)| (id, n as i32)).collect();
            prop_assert_eq!(totals, expected);
        }
    }

    #[test]
    fn floor_i32_is_floor_then_a_saturating_conversion() {
        let values = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            -1e-300,
            2.999_999,
            -2.000_001,
            1e12,
            -1e12,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            2147483647.5,
            -2147483648.0,
            -2147483648.5,
            -2147483649.0,
            2147483648.0,
        ];
        for x in values {
            assert_eq!(floor_i32(x), x.floor() as i32, "floor of {x}");
        }
        for k in -2000..2000 {
            let x = k as f64 * 0.013;
            assert_eq!(floor_i32(x), x.floor() as i32, "floor of {x}");
        }
    }
}
