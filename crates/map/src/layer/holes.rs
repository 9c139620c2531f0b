//! Label holes: surface the map fused but never labelled, inside an instance's surface.
//!
//! Frames between keyframes integrate geometry with the labels the map already holds, so
//! surface that came into view after one keyframe and left before the next is fused without
//! a label, and so is a pixel no mask covered. Where such a patch is a hole in one instance
//! (only that instance around it, and smaller than it), it takes that instance. A patch
//! larger than the instance around it is a region of its own (walls a things-only network
//! never labels), and one between two instances does not say where either ends: both stay
//! unlabelled.

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::{
    BLOCK_SIDE, Block, BlockIndex, Layer, NEIGHBOUR_STEPS, UpdateBits, VOXELS_PER_BLOCK, on_surface,
};

/// Marks a voxel that is no unlabelled surface voxel, in [`BlockPatches::patch`].
const NO_PATCH: u32 = u32::MAX;

/// [`NEIGHBOUR_STEPS`] as steps of a voxel's index inside its block.
const NEIGHBOUR_OFFSETS: [isize; 26] = {
    let side = BLOCK_SIDE as isize;
    let mut offsets = [0isize; 26];
    let mut n = 0;
    while n < 26 {
        let [x, y, z] = NEIGHBOUR_STEPS[n];
        offsets[n] = x as isize + side * (y as isize + side * z as isize);
        n += 1;
    }
    offsets
};

/// The instances around (part of) a patch: the first shown instance found, and whether
/// another was found too.
#[derive(Clone, Copy, Default)]
struct Border {
    id: u16,
    mixed: bool,
}

impl Border {
    fn add(&mut self, id: u16) {
        if self.id == 0 {
            self.id = id;
        } else {
            self.mixed |= id != self.id;
        }
    }

    fn join(&mut self, other: Border) {
        self.mixed |= other.mixed;
        if other.id != 0 {
            self.add(other.id);
        }
    }
}

/// One block's unlabelled surface, cut into the patches it forms inside the block.
struct BlockPatches {
    /// Each voxel's patch within the block, or [`NO_PATCH`].
    patch: Box<[u32; VOXELS_PER_BLOCK]>,
    /// Each patch's voxels and the instances around it.
    patches: Vec<(u32, Border)>,
    /// Unlabelled surface voxels of other candidate blocks next to a patch: (patch, that
    /// block's position among the candidates, its voxel).
    links: Vec<(u32, u32, u16)>,
}

/// A union-find forest over patches (path halving, union by index: the lower root wins, so
/// the result does not depend on the order of unions).
fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        parent[a as usize] = parent[parent[a as usize] as usize];
        a = parent[a as usize];
    }
    a
}

impl Layer {
    /// Gives each unlabelled surface voxel of a hole (see the module) the instance around it;
    /// `shown(id)` says which instances may fill (hidden fragments do not spread). Each filled
    /// voxel holds its instance as one observation, which any later frame outweighs. Returns
    /// the voxels filled; marks their blocks changed for every consumer.
    ///
    /// Patches (connected through the 26 neighbours) are found block by block in parallel,
    /// then joined across block boundaries; the result is the same as one search over the
    /// map.
    pub fn fill_label_holes(&mut self, shown: impl Fn(u16) -> bool + Sync) -> usize {
        let mut candidates: Vec<BlockIndex> = self
            .blocks
            .iter()
            .filter(|(_, block)| block.unlabelled_surface > 0)
            .map(|(&index, _)| index)
            .collect();
        if candidates.is_empty() {
            return 0;
        }
        candidates.sort_unstable();
        let position: FxHashMap<BlockIndex, u32> = candidates
            .iter()
            .enumerate()
            .map(|(n, &index)| (index, n as u32))
            .collect();
        let found: Vec<BlockPatches> = candidates
            .par_iter()
            .map(|&index| self.block_patches(index, &position, &shown))
            .collect();

        // Patches joined across blocks.
        let mut first = Vec::with_capacity(found.len());
        let mut total = 0u32;
        for block in &found {
            first.push(total);
            total += block.patches.len() as u32;
        }
        let mut parent: Vec<u32> = (0..total).collect();
        for (n, block) in found.iter().enumerate() {
            for &(patch, other, voxel) in &block.links {
                let there = found[other as usize].patch[usize::from(voxel)];
                let (a, b) = (
                    find(&mut parent, first[n] + patch),
                    find(&mut parent, first[other as usize] + there),
                );
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut joined: Vec<(usize, Border)> = vec![(0, Border::default()); total as usize];
        for (n, block) in found.iter().enumerate() {
            for (p, &(size, border)) in block.patches.iter().enumerate() {
                let root = find(&mut parent, first[n] + p as u32) as usize;
                joined[root].0 += size as usize;
                joined[root].1.join(border);
            }
        }
        // A patch is a hole in an instance when every labelled surface voxel around it is that
        // instance's and the instance leads more surface voxels than the patch holds. A patch
        // between two instances (a band of wall below a ceiling, the underside of a table
        // above its floor) says nothing about where one ends: it stays unlabelled.
        let fill_of = |root: usize| {
            let (size, border) = joined[root];
            let larger = self
                .surface_totals
                .get(&border.id)
                .is_some_and(|&n| n > size);
            if border.mixed || !larger {
                0
            } else {
                border.id
            }
        };
        let fills: Vec<u16> = (0..total as usize)
            .map(|p| {
                let root = find(&mut parent, p as u32) as usize;
                fill_of(root)
            })
            .collect();

        let mut filled = 0;
        for ((index, block_patches), &start) in candidates.iter().zip(&found).zip(&first) {
            let start = start as usize;
            let block_fills = &fills[start..start + block_patches.patches.len()];
            if block_fills.iter().all(|&id| id == 0) {
                continue;
            }
            let block = self.blocks.get_mut(index).expect("a candidate block");
            for i in 0..VOXELS_PER_BLOCK {
                let id = match block_patches.patch[i] {
                    NO_PATCH => 0,
                    p => block_fills[p as usize],
                };
                if id == 0 {
                    continue;
                }
                block.labels[i].observe(id);
                block.note_instance(id);
                filled += 1;
                // One observation makes `id` the leader of a label holding no counts; a label a
                // map file gave a count on no instance stays unlabelled, as a recount says.
                if block.labels[i].instance() == id {
                    block.move_surface_voxel(0, id);
                    block.unlabelled_surface = block.unlabelled_surface.saturating_sub(1);
                    *self.surface_totals.entry(id).or_insert(0) += 1;
                }
            }
            block.updates = UpdateBits::ALL;
        }
        filled
    }

    /// The patches of unlabelled surface inside the block at `index`, with the shown
    /// instances around each and the unlabelled voxels of other candidate blocks (`position`)
    /// that continue them.
    fn block_patches(
        &self,
        index: BlockIndex,
        position: &FxHashMap<BlockIndex, u32>,
        shown: &(impl Fn(u16) -> bool + Sync),
    ) -> BlockPatches {
        let (truncation, limit) = (self.truncation, self.surface_limit());
        // The block and its 26 neighbours, by offset (-1..=1 along each axis, x fastest).
        let around: [Option<(&Block, Option<u32>)>; 27] = std::array::from_fn(|k| {
            let at = [
                index[0] + k as i32 % 3 - 1,
                index[1] + k as i32 / 3 % 3 - 1,
                index[2] + k as i32 / 9 - 1,
            ];
            self.blocks
                .get(&at)
                .map(|b| (b, position.get(&at).copied()))
        });
        let block = around[13].expect("the block itself").0;
        let unlabelled = |b: &Block, i: usize| {
            b.labels[i].instance() == 0 && on_surface(&b.voxels.get(i), truncation, limit)
        };
        let border_id = |b: &Block, i: usize| {
            let id = self.surface_leader(b, i);
            if id != 0 && shown(id) { id } else { 0 }
        };
        // The block's own voxels read once: whether each is unlabelled surface, else the shown
        // instance leading it (0: none).
        let own_unlabelled: [bool; VOXELS_PER_BLOCK] =
            std::array::from_fn(|i| unlabelled(block, i));
        let own_border: [u16; VOXELS_PER_BLOCK] = std::array::from_fn(|i| {
            if own_unlabelled[i] {
                0
            } else {
                border_id(block, i)
            }
        });
        let side = BLOCK_SIDE as i32;
        let mut patch = Box::new([NO_PATCH; VOXELS_PER_BLOCK]);
        let mut patches: Vec<(u32, Border)> = Vec::new();
        let mut links = Vec::new();
        let mut stack = Vec::new();
        for start in 0..VOXELS_PER_BLOCK {
            if patch[start] != NO_PATCH || !own_unlabelled[start] {
                continue;
            }
            let p = patches.len() as u32;
            let (mut size, mut border) = (0u32, Border::default());
            patch[start] = p;
            stack.push(start);
            while let Some(i) = stack.pop() {
                size += 1;
                let (x, y, z) = Block::coords(i);
                let inside = |c: usize| (1..BLOCK_SIDE - 1).contains(&c);
                let interior = inside(x) && inside(y) && inside(z);
                for (step, offset) in NEIGHBOUR_STEPS.iter().zip(NEIGHBOUR_OFFSETS) {
                    // A voxel away from the block's faces has every neighbour in the block.
                    let j = if interior {
                        i.wrapping_add_signed(offset)
                    } else {
                        let v = [x as i32 + step[0], y as i32 + step[1], z as i32 + step[2]];
                        let shift = v.map(|c| c.div_euclid(side) + 1);
                        let local = v.map(|c| c.rem_euclid(side) as usize);
                        let j = Block::linear(local[0], local[1], local[2]);
                        if shift != [1, 1, 1] {
                            let at = (shift[0] + 3 * shift[1] + 9 * shift[2]) as usize;
                            if let Some((b, there)) = around[at] {
                                if unlabelled(b, j) {
                                    if let Some(there) = there {
                                        links.push((p, there, j as u16));
                                    }
                                } else {
                                    let id = border_id(b, j);
                                    if id != 0 {
                                        border.add(id);
                                    }
                                }
                            }
                            continue;
                        }
                        j
                    };
                    if own_unlabelled[j] {
                        if patch[j] == NO_PATCH {
                            patch[j] = p;
                            stack.push(j);
                        }
                    } else if own_border[j] != 0 {
                        border.add(own_border[j]);
                    }
                }
            }
            patches.push((size, border));
        }
        BlockPatches {
            patch,
            patches,
            links,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeMap, BTreeSet, VecDeque};

    use proptest::prelude::*;

    use super::super::{LabelVoxel, Layer, VoxelIndex, all_neighbours, split};

    /// A layer of 2 cm voxels holding one flat surface of 20 x 20 voxels, each led by
    /// `label(x, y)` (0: unlabelled).
    fn plane(label: impl Fn(i32, i32) -> u16) -> Layer {
        let mut layer = Layer::new(0.02, 0.08);
        for x in 0..20 {
            for y in 0..20 {
                let voxel = layer.voxel(0.0, 1.0, [0; 3]);
                let (index, i) = split([x, y, 0]);
                let (block, _) = layer.get_or_allocate(index);
                block.voxels.set(i, voxel);
                let id = label(x, y);
                block.labels[i] = LabelVoxel::from_parts([id, 0], [u16::from(id != 0) * 3, 0]);
            }
        }
        layer.count_surfaces();
        layer
    }

    fn label_at(layer: &Layer, x: i32, y: i32) -> u16 {
        let (block, i) = layer.locate([x, y, 0]).expect("allocated");
        block.labels[i].instance()
    }

    #[test]
    fn a_hole_inside_one_instance_takes_it() {
        let hole = |x: i32, y: i32| (8..11).contains(&x) && (8..11).contains(&y);
        let mut layer = plane(|x, y| if hole(x, y) { 0 } else { 7 });
        assert_eq!(layer.surface_counts()[&7], 391);
        assert_eq!(layer.fill_label_holes(|_| true), 9);
        assert_eq!(label_at(&layer, 9, 9), 7);
        assert_eq!(layer.surface_counts()[&7], 400);
        // One observation: the first frame that sees the voxel as something else outweighs it.
        let (block, i) = layer.locate([9, 9, 0]).unwrap();
        assert_eq!(block.labels[i].counts(), [1, 0]);
        // Nothing is left to fill.
        assert_eq!(layer.fill_label_holes(|_| true), 0);
    }

    #[test]
    fn a_band_between_two_instances_stays_unlabelled() {
        let mut layer = plane(|x, _| match x {
            0..9 => 1,
            9..12 => 0,
            _ => 2,
        });
        assert_eq!(layer.fill_label_holes(|_| true), 0);
        assert_eq!(label_at(&layer, 10, 5), 0);
    }

    /// A network that labels only things leaves every wall unlabelled: a wall around a
    /// picture is no hole in the picture.
    #[test]
    fn a_region_larger_than_the_instance_it_surrounds_stays_unlabelled() {
        let picture = |x: i32, y: i32| (8..11).contains(&x) && (8..11).contains(&y);
        let mut layer = plane(|x, y| if picture(x, y) { 3 } else { 0 });
        assert_eq!(layer.fill_label_holes(|_| true), 0);
        assert_eq!(layer.surface_counts()[&3], 9);
    }

    /// What filling should give, read with one search over the whole map (the way the fill
    /// was first written): each unlabelled surface voxel of a hole and the instance it takes.
    fn reference_fills(layer: &Layer, shown: impl Fn(u16) -> bool) -> BTreeMap<VoxelIndex, u16> {
        let mut unlabelled = BTreeSet::new();
        for (&index, block) in layer.iter() {
            for i in 0..super::VOXELS_PER_BLOCK {
                if block.labels[i].instance() == 0 && layer.is_surface(&block.voxels.get(i)) {
                    unlabelled.insert(super::Block::voxel_index(index, i));
                }
            }
        }
        let leader = |v: VoxelIndex| {
            let (block, i) = layer.locate(v)?;
            let id = layer.surface_leader(block, i);
            (id != 0 && shown(id)).then_some(id)
        };
        let mut fills = BTreeMap::new();
        let mut seen = BTreeSet::new();
        for &start in &unlabelled {
            if !seen.insert(start) {
                continue;
            }
            let (mut patch, mut border) = (vec![start], BTreeSet::new());
            let mut queue = VecDeque::from([start]);
            while let Some(v) = queue.pop_front() {
                for w in all_neighbours(v) {
                    if unlabelled.contains(&w) {
                        if seen.insert(w) {
                            patch.push(w);
                            queue.push_back(w);
                        }
                    } else if let Some(id) = leader(w) {
                        border.insert(id);
                    }
                }
            }
            let fill = match border.iter().collect::<Vec<_>>()[..] {
                [&id]
                    if layer
                        .surface_counts()
                        .get(&id)
                        .is_some_and(|&n| n > patch.len()) =>
                {
                    id
                }
                _ => 0,
            };
            fills.extend(patch.into_iter().map(|v| (v, fill)));
        }
        fills
    }

    proptest! {
        /// Patches found block by block and joined across blocks fill as one search over the
        /// map does, and every block's surface counts stay what a recount gives.
        #[test]
        fn filling_equals_one_search_over_the_map(
            voxels in proptest::collection::btree_map(
                (-10i32..10, -10i32..10, -5i32..5),
                (
                    prop::bool::weighted(0.8),
                    prop_oneof![3 => Just(0u16), 1 => 1u16..5],
                    prop::bool::weighted(0.05),
                ),
                0..1500,
            ),
            hidden in 0u16..5,
        ) {
            let mut layer = Layer::new(0.02, 0.08);
            for (&(x, y, z), &(surface, id, odd)) in &voxels {
                let voxel = layer.voxel(if surface { 0.0 } else { 0.08 }, 1.0, [0; 3]);
                let (index, i) = split([x, y, z]);
                let (block, _) = layer.get_or_allocate(index);
                block.voxels.set(i, voxel);
                // `odd`: a count on no instance, as a map file may hold; still unlabelled.
                block.labels[i] = match (id, odd) {
                    (0, true) => LabelVoxel::from_parts([0, 2], [2, 1]),
                    _ => LabelVoxel::from_parts([id, 0], [u16::from(id != 0) * 3, 0]),
                };
            }
            layer.count_surfaces();
            let shown = |id: u16| id != hidden;
            let expected = reference_fills(&layer, shown);
            let filled = layer.fill_label_holes(shown);
            prop_assert_eq!(filled, expected.values().filter(|&&id| id != 0).count());
            for (&v, &id) in &expected {
                let (block, i) = layer.locate(v).unwrap();
                let odd = voxels[&(v[0], v[1], v[2])].2 && voxels[&(v[0], v[1], v[2])].1 == 0;
                prop_assert_eq!(block.labels[i].instance(), if odd { 0 } else { id }, "{:?}", v);
            }
            let mut totals = BTreeMap::new();
            for (index, block) in layer.iter() {
                let mut recounted = block.clone();
                recounted.count_surface(layer.truncation(), layer.surface_limit());
                let sorted = |list: &[(u16, u16)]| {
                    let mut list = list.to_vec();
                    list.sort_unstable();
                    list
                };
                prop_assert_eq!(sorted(&block.surface), sorted(&recounted.surface), "{:?}", index);
                prop_assert_eq!(block.unlabelled_surface, recounted.unlabelled_surface);
                for &(id, n) in &block.surface {
                    *totals.entry(id).or_insert(0usize) += usize::from(n);
                }
            }
            let kept: BTreeMap<u16, usize> =
                layer.surface_counts().iter().map(|(&id, &n)| (id, n)).collect();
            prop_assert_eq!(kept, totals);
        }
    }

    #[test]
    fn hidden_instances_fill_nothing() {
        let mut layer = plane(|x, y| if (x, y) == (5, 5) { 0 } else { 4 });
        assert_eq!(layer.fill_label_holes(|id| id != 4), 0);
        assert_eq!(layer.fill_label_holes(|_| true), 1);
    }
}
