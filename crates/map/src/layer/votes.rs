//! What the voxels' label counts say of each instance as a whole: where its own observations
//! won (it leads the voxel) and where another thing's won over them (it is the runner-up under
//! a thing). An object's masks win most of the voxels they label; a fragment of a mask that a
//! network also merged into a neighbouring thing loses most of them to that thing.

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::Layer;

/// An instance's label counts summed over the map's surface voxels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LabelVotes {
    /// Its counts where it leads.
    pub won: u32,
    /// Its counts where it is the runner-up to a thing.
    pub lost_to_things: u32,
}

impl Layer {
    /// Every instance's [`LabelVotes`] over the surface voxels; `is_thing` says which leaders
    /// are things. Losses under stuff are not counted: a network's masks spill over the wall
    /// or floor behind a thing, and those votes say nothing against the thing.
    pub fn label_votes(&self, is_thing: impl Fn(u16) -> bool + Sync) -> FxHashMap<u16, LabelVotes> {
        let add = |mut all: FxHashMap<u16, LabelVotes>, part: FxHashMap<u16, LabelVotes>| {
            for (id, v) in part {
                let e = all.entry(id).or_default();
                e.won += v.won;
                e.lost_to_things += v.lost_to_things;
            }
            all
        };
        self.blocks
            .par_iter()
            .filter(|(_, block)| !block.surface.is_empty())
            .fold(
                FxHashMap::default,
                |mut votes: FxHashMap<u16, LabelVotes>, (_, block)| {
                    for i in 0..block.labels.len() {
                        let leader = self.surface_leader(block, i);
                        if leader == 0 {
                            continue;
                        }
                        let label = &block.labels[i];
                        let counts = label.counts();
                        votes.entry(leader).or_default().won += u32::from(counts[0]);
                        let runner_up = label.challenger();
                        if runner_up != 0 && is_thing(leader) {
                            votes.entry(runner_up).or_default().lost_to_things +=
                                u32::from(counts[1]);
                        }
                    }
                    votes
                },
            )
            .reduce(FxHashMap::default, add)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{LabelVoxel, Layer, split};
    use super::LabelVotes;

    #[test]
    fn counts_are_summed_where_an_instance_leads_and_where_it_trails_a_thing() {
        // (voxel, on the surface, leader and runner-up with their counts)
        let voxels = [
            ([0, 0, 0], true, [1, 2], [5, 3]),
            ([1, 0, 0], true, [1, 2], [4, 1]),
            // Instance 3 is stuff: 2's count under it is not a loss.
            ([20, 0, 0], true, [3, 2], [6, 2]),
            ([21, 0, 0], true, [2, 0], [2, 0]),
            // Off the surface: not counted at all.
            ([40, 0, 0], false, [1, 2], [7, 7]),
        ];
        let mut layer = Layer::new(0.02, 0.06);
        for (v, surface, ids, counts) in voxels {
            let voxel = layer.voxel(if surface { 0.0 } else { 0.06 }, 1.0, [0; 3]);
            let (index, i) = split(v);
            let (block, _) = layer.get_or_allocate(index);
            block.voxels.set(i, voxel);
            block.labels[i] = LabelVoxel::from_parts(ids, counts);
        }
        layer.count_surfaces();
        let votes = layer.label_votes(|id| id != 3);
        let of = |id| votes.get(&id).copied().unwrap_or_default();
        assert_eq!(
            of(1),
            LabelVotes {
                won: 9,
                lost_to_things: 0
            }
        );
        assert_eq!(
            of(2),
            LabelVotes {
                won: 2,
                lost_to_things: 4
            }
        );
        assert_eq!(
            of(3),
            LabelVotes {
                won: 6,
                lost_to_things: 0
            }
        );
        assert_eq!(votes.len(), 3);
    }
}
