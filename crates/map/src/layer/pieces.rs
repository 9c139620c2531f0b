//! Pieces of an instance's surface: its surface voxels linked through steps within the TSDF
//! truncation distance, the range within which integration fuses measurements into one
//! surface. An object is one piece of surface; an instance out-voted almost everywhere it was
//! seen keeps a few voxels scattered over the region its masks covered.

use std::collections::VecDeque;

use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use super::{Block, BlockIndex, Layer, VOXELS_PER_BLOCK, VoxelIndex, split};

impl Layer {
    /// The instances none of whose pieces (see the module) holds `min_voxels` surface voxels,
    /// sorted. Instances leading fewer than `min_voxels` surface voxels in all are left out
    /// (their size already says it). Each instance is searched from its first surface voxel
    /// and the search stops at the first piece large enough, so a large instance costs about
    /// `min_voxels` voxels' neighbourhoods.
    pub fn scattered_instances(&self, min_voxels: usize) -> Vec<u16> {
        if min_voxels <= 1 {
            return Vec::new();
        }
        let mut blocks_of: FxHashMap<u16, Vec<BlockIndex>> = FxHashMap::default();
        for (&index, block) in &self.blocks {
            for &(id, _) in &block.surface {
                if self.surface_totals.get(&id).copied().unwrap_or(0) >= min_voxels {
                    blocks_of.entry(id).or_default().push(index);
                }
            }
        }
        let mut scattered: Vec<u16> = blocks_of
            .into_par_iter()
            .filter_map(|(id, blocks)| (!self.has_piece(id, blocks, min_voxels)).then_some(id))
            .collect();
        scattered.sort_unstable();
        scattered
    }

    /// How many voxels one step of a piece may span along each axis: the truncation distance,
    /// at least one voxel.
    fn piece_reach(&self) -> i32 {
        ((self.truncation as f64 / self.voxel_size).round() as i32).max(1)
    }

    /// Whether `v` is a surface voxel that `id` leads.
    fn led_by(&self, v: VoxelIndex, id: u16) -> bool {
        let (block, i) = split(v);
        self.blocks
            .get(&block)
            .is_some_and(|b| self.surface_leader(b, i) == id)
    }

    /// Whether some piece of instance `id`, whose surface voxels lie in `blocks`, holds
    /// `min_voxels` of them.
    fn has_piece(&self, id: u16, blocks: Vec<BlockIndex>, min_voxels: usize) -> bool {
        let reach = self.piece_reach();
        let mut visited: FxHashSet<VoxelIndex> = FxHashSet::default();
        let mut queue = VecDeque::new();
        for index in blocks {
            let block = &self.blocks[&index];
            for i in 0..VOXELS_PER_BLOCK {
                let start = Block::voxel_index(index, i);
                if self.surface_leader(block, i) != id || visited.contains(&start) {
                    continue;
                }
                visited.insert(start);
                queue.clear();
                queue.push_back(start);
                let mut size = 0;
                while let Some(v) = queue.pop_front() {
                    size += 1;
                    if size >= min_voxels {
                        return true;
                    }
                    for dz in -reach..=reach {
                        for dy in -reach..=reach {
                            for dx in -reach..=reach {
                                let w = [v[0] + dx, v[1] + dy, v[2] + dz];
                                if !visited.contains(&w) && self.led_by(w, id) {
                                    visited.insert(w);
                                    queue.push_back(w);
                                }
                            }
                        }
                    }
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeMap, BTreeSet};

    use proptest::prelude::*;

    use super::super::{LabelVoxel, Layer, VoxelIndex, split};

    /// A layer of 2 cm voxels and a 6 cm truncation distance (pieces link voxels up to 3 apart
    /// along each axis) with `voxels` set: each a surface voxel or one far from the surface,
    /// led by its instance.
    fn layer_of(voxels: &[(VoxelIndex, bool, u16)]) -> Layer {
        let mut layer = Layer::new(0.02, 0.06);
        for &(v, surface, id) in voxels {
            let voxel = layer.voxel(if surface { 0.0 } else { 0.06 }, 1.0, [0; 3]);
            let (index, i) = split(v);
            let (block, _) = layer.get_or_allocate(index);
            block.voxels.set(i, voxel);
            block.labels[i] = LabelVoxel::from_parts([id, 0], [1, 0]);
        }
        layer.count_surfaces();
        layer
    }

    #[test]
    fn a_patch_is_one_piece_and_voxels_spread_apart_are_not() {
        let mut voxels = Vec::new();
        // Instance 1: 13 voxels in a row, a piece above 12.
        voxels.extend((0..13).map(|x| ([x, 0, 0], true, 1)));
        // Instance 2: 30 voxels 4 apart, beyond the truncation distance: 30 pieces of one.
        voxels.extend((0..30).map(|x| ([4 * x, 10, 0], true, 2)));
        // Instance 3: 12 voxels 3 apart, within it: one piece.
        voxels.extend((0..12).map(|x| ([3 * x, 20, 0], true, 3)));
        // Instance 4, a lamp flush with its ceiling (instance 5): the two lead every other
        // voxel of one patch, and the lamp's are one piece.
        for x in 0..8 {
            for y in 0..8 {
                let id = if (x + y) % 2 == 0 { 4 } else { 5 };
                voxels.push(([x, 30 + y, 0], true, id));
            }
        }
        // Instance 6: 20 voxels 4 apart, but the ones off the surface do not count and the
        // surface ones are 8 apart.
        voxels.extend((0..20).map(|x| ([4 * x, 40, 0], x % 2 == 0, 6)));
        // Instance 7: 5 voxels in all, too few to judge.
        voxels.extend((0..5).map(|x| ([10 * x, 50, 0], true, 7)));
        let layer = layer_of(&voxels);
        assert_eq!(layer.scattered_instances(12), vec![2]);
        assert_eq!(layer.scattered_instances(10), vec![2, 6]);
        assert!(layer.scattered_instances(1).is_empty());
        assert!(layer.scattered_instances(0).is_empty());
    }

    fn voxels() -> impl Strategy<Value = Vec<(VoxelIndex, bool, u16)>> {
        proptest::collection::btree_map(
            (0i32..24, 0i32..24, 0i32..6),
            (prop::bool::weighted(0.9), 1u16..5),
            0..300,
        )
        .prop_map(|m| {
            m.into_iter()
                .map(|((x, y, z), (s, id))| ([x, y, z], s, id))
                .collect()
        })
    }

    proptest! {
        /// The scattered instances equal those a brute-force reading finds: pieces joined
        /// pair by pair over every two surface voxels of an instance at most 3 voxels apart
        /// along each axis, none holding `min_voxels`, though the instance holds as many.
        #[test]
        fn scattered_instances_match_a_pairwise_reading(voxels in voxels(), min_voxels in 2usize..16) {
            let layer = layer_of(&voxels);
            let mut by_id: BTreeMap<u16, Vec<VoxelIndex>> = BTreeMap::new();
            for &(v, surface, id) in &voxels {
                if surface {
                    by_id.entry(id).or_default().push(v);
                }
            }
            let mut expected = Vec::new();
            for (&id, list) in &by_id {
                // Pieces by repeated relabelling to the smallest linked label.
                let mut piece: Vec<usize> = (0..list.len()).collect();
                loop {
                    let mut changed = false;
                    for a in 0..list.len() {
                        for b in 0..list.len() {
                            let near = (0..3).all(|k| (list[a][k] - list[b][k]).abs() <= 3);
                            if near && piece[b] < piece[a] {
                                piece[a] = piece[b];
                                changed = true;
                            }
                        }
                    }
                    if !changed {
                        break;
                    }
                }
                let mut sizes: BTreeMap<usize, usize> = BTreeMap::new();
                for p in piece {
                    *sizes.entry(p).or_default() += 1;
                }
                let largest = sizes.values().copied().max().unwrap_or(0);
                if list.len() >= min_voxels && largest < min_voxels {
                    expected.push(id);
                }
            }
            let found: BTreeSet<u16> = layer.scattered_instances(min_voxels).into_iter().collect();
            prop_assert_eq!(found, expected.into_iter().collect::<BTreeSet<u16>>());
        }
    }
}
