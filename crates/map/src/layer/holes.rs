//! Label holes: surface the map fused but never labelled, inside an instance's surface.
//!
//! Frames between keyframes integrate geometry with the labels the map already holds, so
//! surface that came into view after one keyframe and left before the next is fused without
//! a label, and so is a pixel no mask covered. Where such a patch is a hole in one instance
//! (only that instance around it, and smaller than it), it takes that instance. A patch
//! larger than the instance around it is a region of its own (walls a things-only network
//! never labels), and one between two instances does not say where either ends: both stay
//! unlabelled.

use std::collections::VecDeque;

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::{
    Block, BlockIndex, Layer, UpdateBits, VOXELS_PER_BLOCK, VoxelIndex, all_neighbours, on_surface,
    split,
};

impl Layer {
    /// Gives each unlabelled surface voxel of a hole (see the module) the instance around it;
    /// `shown(id)` says which instances may fill (hidden fragments do not spread). Each filled
    /// voxel holds its instance as one observation, which any later frame outweighs. Returns
    /// the voxels filled; marks their blocks changed for every consumer.
    pub fn fill_label_holes(&mut self, shown: impl Fn(u16) -> bool) -> usize {
        let (truncation, limit) = (self.truncation, self.surface_limit());
        // The unlabelled surface voxels, in a fixed order (the fill is then reproducible).
        let mut by_block: Vec<(BlockIndex, Vec<VoxelIndex>)> = self
            .blocks
            .par_iter()
            .filter(|(_, block)| block.unlabelled_surface > 0)
            .filter_map(|(&index, block)| {
                let found: Vec<VoxelIndex> = (0..VOXELS_PER_BLOCK)
                    .filter(|&i| {
                        block.labels[i].instance() == 0
                            && on_surface(&block.voxels.get(i), truncation, limit)
                    })
                    .map(|i| Block::voxel_index(index, i))
                    .collect();
                (!found.is_empty()).then_some((index, found))
            })
            .collect();
        by_block.sort_unstable_by_key(|(index, _)| *index);
        let unlabelled: Vec<VoxelIndex> = by_block.into_iter().flat_map(|(_, v)| v).collect();
        if unlabelled.is_empty() {
            return 0;
        }
        let slot: FxHashMap<VoxelIndex, usize> = unlabelled
            .iter()
            .enumerate()
            .map(|(n, &v)| (v, n))
            .collect();
        // The shown instance leading a labelled surface voxel at `v`, if any.
        let labelled = |v: VoxelIndex| {
            let (block, i) = split(v);
            let id = self.surface_leader(self.blocks.get(&block)?, i);
            (id != 0 && shown(id)).then_some(id)
        };

        // Connected patches of unlabelled surface. A patch is a hole in an instance when every
        // labelled surface voxel around it is that instance's and the instance leads more
        // surface voxels than the patch holds. A patch between two instances (a band of wall
        // below a ceiling, the underside of a table above its floor) says nothing about where
        // one ends: it stays unlabelled.
        let mut patch = vec![usize::MAX; unlabelled.len()];
        let mut fills: Vec<u16> = Vec::new();
        let mut queue = VecDeque::new();
        for start in 0..unlabelled.len() {
            if patch[start] != usize::MAX {
                continue;
            }
            let p = fills.len();
            let (mut size, mut border, mut mixed) = (0usize, 0u16, false);
            patch[start] = p;
            queue.push_back(start);
            while let Some(n) = queue.pop_front() {
                size += 1;
                for v in all_neighbours(unlabelled[n]) {
                    match slot.get(&v) {
                        Some(&m) if patch[m] == usize::MAX => {
                            patch[m] = p;
                            queue.push_back(m);
                        }
                        Some(_) => {}
                        None => match labelled(v) {
                            Some(id) if border == 0 => border = id,
                            Some(id) => mixed |= id != border,
                            None => {}
                        },
                    }
                }
            }
            let larger = self.surface_totals.get(&border).is_some_and(|&n| n > size);
            fills.push(if mixed || !larger { 0 } else { border });
        }

        let mut filled = 0;
        let mut changed: Vec<BlockIndex> = Vec::new();
        for (&v, &p) in unlabelled.iter().zip(&patch) {
            let id = fills[p];
            if id == 0 {
                continue;
            }
            let (index, i) = split(v);
            let block = self
                .blocks
                .get_mut(&index)
                .expect("a surface voxel's block");
            block.labels[i].observe(id);
            block.note_instance(id);
            filled += 1;
            // `unlabelled` runs block by block: a block's voxels are consecutive.
            if changed.last() != Some(&index) {
                changed.push(index);
            }
        }
        for index in changed {
            let block = self.blocks.get_mut(&index).expect("listed");
            block.updates = UpdateBits::ALL;
            super::untally(&mut self.surface_totals, &block.surface);
            block.count_surface(truncation, limit);
            super::tally(&mut self.surface_totals, &block.surface);
        }
        filled
    }
}

#[cfg(test)]
mod tests {
    use super::super::{LabelVoxel, Layer, split};

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

    #[test]
    fn hidden_instances_fill_nothing() {
        let mut layer = plane(|x, y| if (x, y) == (5, 5) { 0 } else { 4 });
        assert_eq!(layer.fill_label_holes(|id| id != 4), 0);
        assert_eq!(layer.fill_label_holes(|_| true), 1);
    }
}
