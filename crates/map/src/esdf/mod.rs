//! The Euclidean signed distance field a planner queries (voxblox's and nvblox's ESDF layer),
//! on the TSDF's own blocks and voxels, kept up to date from the TSDF blocks that changed.
//!
//! *Sites* are the TSDF's surface voxels: observed, with the centre within half a voxel of
//! the zero crossing, or the nearer of two face neighbours it passes between. Every voxel of
//! an allocated block carries the offset to its nearest site within `max_distance`, found by
//! vector propagation between face neighbours, and its distance is that offset's length:
//! Euclidean, not a sum of steps. Voxels the TSDF has not observed carry offsets too (a wave
//! is not stopped by a gap in the observations) but answer no distance.
//!
//! A voxel holds the nearest of the sites its six neighbours offer, and a neighbour offers its
//! site only outwards (to a voxel farther from that site than itself); ties go to the smaller
//! offset. Every offset is then vouched for by a chain of neighbours ever nearer to its site,
//! and the field has exactly one state in which every voxel holds its best offer: an update
//! after each frame and a rebuild from the saved map end in the same voxels, whatever order
//! the sites came in. An update runs in three passes:
//! 1. *mark*: the changed blocks' voxels become sites, stop being sites, are newly observed,
//!    or change sides (inside: behind the surface);
//! 2. *raise*: voxels whose site stopped being one forget it, block by block outwards from the
//!    lost sites while blocks still hold such voxels (voxblox's raise wave);
//! 3. *lower*: blocks relax their voxels against each other and their six neighbours' faces
//!    in rounds, every block of a round in parallel, until no face changes. A voxel that
//!    changed tells its neighbours; one that held what it offered before looks again at all
//!    its offers, so a voxel whose support went never keeps it.

mod slice;

pub use slice::{Costmap, CostmapCell};

use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};
use voxpan_core::nalgebra::{Point3, Vector3};

use crate::layer::{
    BLOCK_SIDE, Block, BlockIndex, Layer, VOXELS_PER_BLOCK, VoxelIndex, all_neighbours,
};

const OBSERVED: u8 = 1;
const INSIDE: u8 = 2;
const SITE: u8 = 4;
/// `site` holds the offset to the nearest site within `max_distance`.
const HAS_SITE: u8 = 8;

/// One voxel of the distance field: the offset (in voxels) to its nearest site, and flags.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct EsdfVoxel {
    site: [i16; 3],
    flags: u8,
}

impl EsdfVoxel {
    fn squared(&self) -> i32 {
        self.site.iter().map(|&c| c as i32 * c as i32).sum()
    }

    fn has(&self, flag: u8) -> bool {
        self.flags & flag != 0
    }
}

type EsdfBlock = Box<[EsdfVoxel; VOXELS_PER_BLOCK]>;

/// Bytes of one distance-field block in memory.
pub(crate) const ESDF_BLOCK_BYTES: u64 =
    (std::mem::size_of::<EsdfVoxel>() * VOXELS_PER_BLOCK) as u64;

fn empty_block() -> EsdfBlock {
    Box::new([EsdfVoxel::default(); VOXELS_PER_BLOCK])
}

/// The six face directions: `-x, +x, -y, +y, -z, +z`.
const DIRECTIONS: [[i32; 3]; 6] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
];

/// What one update did (for benchmarks and logs).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct EsdfStats {
    /// TSDF blocks the update was given.
    pub changed_blocks: usize,
    /// Of those, blocks whose sites, observations or sides changed.
    pub marked_blocks: usize,
    pub sites_added: usize,
    pub sites_removed: usize,
    /// Voxels that forgot a site that stopped being one.
    pub raised_voxels: usize,
    /// Block relaxations, over all rounds, and the rounds.
    pub relaxed_blocks: usize,
    pub rounds: usize,
    /// Milliseconds of each pass.
    pub mark_ms: f64,
    pub raise_ms: f64,
    pub lower_ms: f64,
}

/// The distance field: one block per TSDF block.
#[derive(Clone, Debug)]
pub(crate) struct Esdf {
    voxel_size: f64,
    max_distance: f32,
    /// `max_distance` in voxels, squared (offsets beyond it are not kept).
    max_squared: i32,
    blocks: FxHashMap<BlockIndex, EsdfBlock>,
}

impl Esdf {
    /// An empty field for voxels of `voxel_size` metres, propagating `max_distance` metres
    /// from the surface (at most 30 000 voxels: offsets are 16-bit).
    pub fn new(voxel_size: f64, max_distance: f64) -> Self {
        let voxels = (max_distance / voxel_size).min(30_000.0);
        Self {
            voxel_size,
            max_distance: max_distance as f32,
            max_squared: (voxels * voxels).floor() as i32,
            blocks: FxHashMap::default(),
        }
    }

    #[cfg(test)]
    pub fn max_distance(&self) -> f32 {
        self.max_distance
    }

    /// Blocks held (one per TSDF block).
    pub fn len(&self) -> usize {
        self.blocks.len()
    }

    /// Brings the field up to date with `layer` where the TSDF blocks `changed` changed
    /// (blocks no longer in the layer are dropped).
    pub fn update(&mut self, layer: &Layer, changed: &[BlockIndex]) -> EsdfStats {
        let mut stats = EsdfStats {
            changed_blocks: changed.len(),
            ..EsdfStats::default()
        };
        // 1. Mark.
        let t = std::time::Instant::now();
        let first: Vec<(BlockIndex, Option<Marked>, bool)> = changed
            .par_iter()
            .map(|&index| {
                let (marked, free) = self.mark(layer, index);
                (index, marked, free)
            })
            .collect();
        // A block's border voxels are sites by their neighbours across the face too: those of
        // a changed block's neighbours are told again, unless the block was and is free space
        // through and through (its voxels at the band's far edge, never the nearer of a pair).
        let mut neighbours: Vec<BlockIndex> = first
            .iter()
            .filter(|(_, marked, free)| marked.is_some() || !free)
            .flat_map(|(index, _, _)| DIRECTIONS.iter().map(move |&d| step(*index, d)))
            .filter(|n| changed.binary_search(n).is_err() && self.blocks.contains_key(n))
            .collect();
        neighbours.sort_unstable();
        neighbours.dedup();
        let second: Vec<Marked> = neighbours
            .par_iter()
            .filter_map(|&index| self.mark(layer, index).0)
            .collect();
        let marked = first
            .into_iter()
            .filter_map(|(_, marked, _)| marked)
            .chain(second);
        let mut lost = Vec::new();
        let mut dirty = Dirty::default();
        for m in marked {
            stats.marked_blocks += 1;
            stats.sites_added += m.added;
            stats.sites_removed += m.removed;
            if m.removed > 0 || m.block.is_none() {
                lost.push(m.index);
            }
            dirty.whole(m.index);
            let moved = if m.block.is_some() {
                m.moved
            } else {
                ALL_FACES
            };
            // A new block's faces held nothing before.
            let old = match self.blocks.get(&m.index) {
                Some(old) => old_faces(old, moved),
                None => old_faces(&[EsdfVoxel::default(); VOXELS_PER_BLOCK], moved),
            };
            dirty.faces_read(m.index, old);
            match m.block {
                Some(block) => {
                    self.blocks.insert(m.index, block);
                }
                None => {
                    self.blocks.remove(&m.index);
                    // Its neighbours may point into it.
                    lost.extend(all_neighbours(m.index));
                }
            }
        }
        stats.mark_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        // 2. Raise.
        let (raised, reset_blocks) = self.raise(lost);
        stats.raise_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        stats.raised_voxels = raised;
        for index in reset_blocks {
            dirty.whole(index);
        }
        // 3. Lower.
        let (relaxed, rounds) = self.lower(dirty);
        stats.relaxed_blocks = relaxed;
        stats.rounds = rounds;
        stats.lower_ms = t.elapsed().as_secs_f64() * 1e3;
        stats
    }

    /// The new state of block `index`'s voxels from the TSDF, or `None` when nothing about
    /// them changed; and whether the block is free space through and through (every voxel
    /// unobserved or at the band's far edge). A block gone from the layer comes back with
    /// `block: None`.
    fn mark(&self, layer: &Layer, index: BlockIndex) -> (Option<Marked>, bool) {
        let old = self.blocks.get(&index);
        let Some(tsdf) = layer.get(&index) else {
            let gone = old.map(|old| Marked {
                index,
                block: None,
                added: 0,
                removed: old.iter().filter(|v| v.has(SITE)).count(),
                moved: 0,
            });
            return (gone, false);
        };
        // What each voxel is now, first: most blocks a frame touches stay as they were.
        let (steps, weights) = tsdf.voxels.steps_and_weights();
        let free = steps
            .iter()
            .zip(weights)
            .all(|(&s, &w)| w == 0 || s == i16::MAX);
        let mut state = [0u8; VOXELS_PER_BLOCK];
        if free {
            // No site, nothing inside: the far edge is never the nearer of a pair.
            for (flags, &w) in state.iter_mut().zip(weights) {
                *flags = if w != 0 { OBSERVED } else { 0 };
            }
        } else {
            let around = Around::new(layer, index, tsdf);
            for (i, flags) in state.iter_mut().enumerate() {
                let d = around.distances[i];
                *flags = if d == UNSEEN {
                    0
                } else if around.is_site(i) {
                    OBSERVED | SITE
                } else if d < 0 {
                    OBSERVED | INSIDE
                } else {
                    OBSERVED
                };
            }
        }
        const STATE: u8 = OBSERVED | INSIDE | SITE;
        if let Some(old) = old
            && old.iter().zip(&state).all(|(v, &s)| v.flags & STATE == s)
        {
            return (None, free);
        }
        let mut block = old.cloned().unwrap_or_else(empty_block);
        let (mut added, mut removed) = (0, 0);
        let mut moved = if old.is_none() { 0b11_1111 } else { 0 };
        for (i, (voxel, &now)) in block.iter_mut().zip(&state).enumerate() {
            let before = *voxel;
            if now & SITE != 0 {
                *voxel = EsdfVoxel {
                    site: [0; 3],
                    flags: OBSERVED | SITE | HAS_SITE,
                };
                added += usize::from(!before.has(SITE));
            } else {
                if before.has(SITE) {
                    // It pointed at itself.
                    *voxel = EsdfVoxel::default();
                    removed += 1;
                }
                voxel.flags = voxel.flags & HAS_SITE | now;
            }
            if *voxel != before {
                moved |= faces_of(i);
            }
        }
        let marked = Marked {
            index,
            block: Some(block),
            added,
            removed,
            moved,
        };
        (Some(marked), free)
    }

    /// Whether global voxel `v` is a site.
    #[cfg(test)]
    fn is_site(&self, v: VoxelIndex) -> bool {
        let (block, local) = crate::layer::split(v);
        self.blocks.get(&block).is_some_and(|b| b[local].has(SITE))
    }

    /// Forgets every site offset that points at a voxel which is no longer a site, flooding
    /// out from `seeds` through blocks that held such offsets. Returns the voxels reset and
    /// the blocks they are in.
    fn raise(&mut self, seeds: Vec<BlockIndex>) -> (usize, Vec<BlockIndex>) {
        let mut visited: FxHashSet<BlockIndex> = seeds.iter().copied().collect();
        let mut frontier: Vec<BlockIndex> = visited.iter().copied().collect();
        let (mut raised, mut reset_blocks) = (0, Vec::new());
        while !frontier.is_empty() {
            let stale: Vec<(BlockIndex, Vec<u16>)> = frontier
                .par_iter()
                .filter_map(|&index| {
                    let block = self.blocks.get(&index)?;
                    // A block's voxels point at sites in a few blocks nearby: the last one
                    // looked up is kept.
                    let mut cached: Option<(BlockIndex, Option<&EsdfBlock>)> = None;
                    let mut is_site = |v: VoxelIndex| {
                        let (at, local) = crate::layer::split(v);
                        let site_block = match cached {
                            Some((index, b)) if index == at => b,
                            _ => {
                                let b = self.blocks.get(&at);
                                cached = Some((at, b));
                                b
                            }
                        };
                        site_block.is_some_and(|b| b[local].has(SITE))
                    };
                    let stale: Vec<u16> = (0..VOXELS_PER_BLOCK)
                        .filter(|&i| {
                            let v = block[i];
                            v.has(HAS_SITE) && !v.has(SITE) && {
                                let at = Block::voxel_index(index, i);
                                !is_site(std::array::from_fn(|a| at[a] + v.site[a] as i32))
                            }
                        })
                        .map(|i| i as u16)
                        .collect();
                    (!stale.is_empty()).then_some((index, stale))
                })
                .collect();
            frontier.clear();
            for (index, voxels) in stale {
                let block = self.blocks.get_mut(&index).expect("found above");
                for &i in &voxels {
                    let v = &mut block[i as usize];
                    v.flags &= !HAS_SITE;
                    v.site = [0; 3];
                }
                raised += voxels.len();
                reset_blocks.push(index);
                for n in all_neighbours(index) {
                    if self.blocks.contains_key(&n) && visited.insert(n) {
                        frontier.push(n);
                    }
                }
            }
        }
        (raised, reset_blocks)
    }

    /// Relaxes the `dirty` blocks against their neighbours in rounds, every block of a round
    /// in parallel, until no block's face changes. Returns the relaxations done and the
    /// rounds.
    fn lower(&mut self, mut dirty: Dirty) -> (usize, usize) {
        let (mut relaxed, mut rounds) = (0, 0);
        loop {
            let mut work: Vec<(BlockIndex, Seeds)> = dirty
                .0
                .drain()
                .filter(|(i, _)| self.blocks.contains_key(i))
                .collect();
            if work.is_empty() {
                return (relaxed, rounds);
            }
            work.sort_unstable_by_key(|(index, _)| *index);
            rounds += 1;
            relaxed += work.len();
            let max_squared = self.max_squared;
            let results: Vec<(BlockIndex, EsdfBlock, OldFaces)> = work
                .par_iter()
                .filter_map(|(index, seeds)| {
                    let block = self.blocks.get(index)?;
                    let faces: [Option<Face>; 6] = std::array::from_fn(|d| {
                        let n = step(*index, DIRECTIONS[d]);
                        self.blocks.get(&n).map(|b| Face::of(b, d ^ 1))
                    });
                    let mut next = block.clone();
                    let moved = relax(&mut next, &faces, seeds, max_squared)?;
                    Some((*index, next, old_faces(block, moved)))
                })
                .collect();
            for (index, block, old) in results {
                self.blocks.insert(index, block);
                dirty.faces_read(index, old);
            }
        }
    }

    /// Signed distance (metres) at global voxel `v`: `None` where the TSDF has not observed
    /// it; `max_distance` (signed) where no site is within it.
    pub fn voxel_distance(&self, v: VoxelIndex) -> Option<f32> {
        let (block, local) = crate::layer::split(v);
        self.distance_of(self.blocks.get(&block)?[local])
    }

    /// [`Self::voxel_distance`] of a voxel at hand.
    fn distance_of(&self, voxel: EsdfVoxel) -> Option<f32> {
        if !voxel.has(OBSERVED) {
            return None;
        }
        let magnitude = if voxel.has(HAS_SITE) {
            (voxel.squared() as f32).sqrt() * self.voxel_size as f32
        } else {
            self.max_distance
        };
        Some(if voxel.has(INSIDE) {
            -magnitude
        } else {
            magnitude
        })
    }

    /// Signed distance at `p` (its voxel's).
    pub fn distance(&self, p: &Point3<f64>) -> Option<f32> {
        self.voxel_distance(voxel_of(p, self.voxel_size)?)
    }

    /// Signed distance at `p` interpolated trilinearly between the eight voxel centres around
    /// it, and its gradient (metres per metre); `None` unless all eight are observed.
    pub fn distance_and_gradient(&self, p: &Point3<f64>) -> Option<(f32, Vector3<f32>)> {
        voxel_of(p, self.voxel_size)?;
        let s = self.voxel_size;
        let g = p.coords / s - Vector3::repeat(0.5);
        let base = g.map(|c| c.floor());
        let f = (g - base).cast::<f32>();
        let mut d = [0.0f32; 8];
        for (c, slot) in d.iter_mut().enumerate() {
            let v = std::array::from_fn(|a| base[a] as i32 + (c >> a & 1) as i32);
            *slot = self.voxel_distance(v)?;
        }
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        // Corner c has bit a set where it is the upper voxel along axis a.
        let along_x = |c: usize| lerp(d[c], d[c | 1], f.x);
        let (x00, x10, x01, x11) = (along_x(0), along_x(2), along_x(4), along_x(6));
        let (y0, y1) = (lerp(x00, x10, f.y), lerp(x01, x11, f.y));
        let distance = lerp(y0, y1, f.z);
        let dx = |c: usize| d[c | 1] - d[c];
        let ddx = lerp(lerp(dx(0), dx(2), f.y), lerp(dx(4), dx(6), f.y), f.z);
        let ddy = lerp(x10 - x00, x11 - x01, f.z);
        let ddz = y1 - y0;
        Some((distance, Vector3::new(ddx, ddy, ddz) / s as f32))
    }

    /// Every voxel with a distance: its index and signed distance.
    pub fn voxels(&self) -> impl Iterator<Item = (VoxelIndex, f32)> + '_ {
        self.voxels_of_blocks(|_| true)
    }

    /// [`Self::voxels`] of the blocks `wanted` accepts (each block read once, not looked up
    /// per voxel).
    fn voxels_of_blocks<'a>(
        &'a self,
        wanted: impl Fn(&BlockIndex) -> bool + 'a,
    ) -> impl Iterator<Item = (VoxelIndex, f32)> + 'a {
        self.blocks
            .iter()
            .filter(move |(index, _)| wanted(index))
            .flat_map(move |(&index, block)| {
                block.iter().enumerate().filter_map(move |(i, &voxel)| {
                    self.distance_of(voxel)
                        .map(|d| (Block::voxel_index(index, i), d))
                })
            })
    }

    #[cfg(test)]
    pub fn site(&self, v: VoxelIndex) -> bool {
        self.is_site(v)
    }

    /// The blocks held, sorted.
    #[cfg(test)]
    pub fn block_indices(&self) -> Vec<BlockIndex> {
        let mut indices: Vec<BlockIndex> = self.blocks.keys().copied().collect();
        indices.sort_unstable();
        indices
    }
}

/// Stands for an unobserved voxel's distance in [`Around`].
const UNSEEN: i32 = i32::MIN;

/// A TSDF block's distances (in steps, [`UNSEEN`] where unobserved) and its six face
/// neighbours' facing layers, for telling its sites.
struct Around {
    distances: [i32; VOXELS_PER_BLOCK],
    /// Per direction, the neighbour's 64 voxels touching this block, as [`Face`] orders them.
    faces: [[i32; BLOCK_SIDE * BLOCK_SIDE]; 6],
    /// Half a voxel in steps.
    half_voxel: i32,
}

impl Around {
    fn new(layer: &Layer, index: BlockIndex, block: &Block) -> Self {
        // A voxel's stored distance in steps, or UNSEEN.
        let seen = |b: &Block, i: usize| {
            let (steps, weights) = b.voxels.steps_and_weights();
            if weights[i] != 0 {
                steps[i] as i32
            } else {
                UNSEEN
            }
        };
        let distances = std::array::from_fn(|i| seen(block, i));
        let mut faces = [[UNSEEN; BLOCK_SIDE * BLOCK_SIDE]; 6];
        for (d, face) in faces.iter_mut().enumerate() {
            let Some(n) = layer.get(&step(index, DIRECTIONS[d])) else {
                continue;
            };
            let layer_of = if d % 2 == 0 { BLOCK_SIDE - 1 } else { 0 };
            for (k, e) in face.iter_mut().enumerate() {
                *e = seen(
                    n,
                    face_voxel(d / 2, layer_of, k % BLOCK_SIDE, k / BLOCK_SIDE),
                );
            }
        }
        let half_voxel = 0.5 * layer.voxel_size() as f32 / layer.truncation();
        Self {
            distances,
            faces,
            half_voxel: (half_voxel * crate::layer::TSDF_STEPS) as i32,
        }
    }

    /// Whether voxel `i` is a site: observed, and its centre within half a voxel of the
    /// surface or the nearer of two face neighbours the surface passes between (distances of
    /// opposite signs; at equal distances, the one inside). Projective distances overstate the
    /// distance to a surface seen at a slant, so a band of fixed width would leave holes where
    /// the mesh has none.
    fn is_site(&self, i: usize) -> bool {
        let d = self.distances[i];
        if d == UNSEEN {
            return false;
        }
        if d.abs() < self.half_voxel {
            return true;
        }
        // Of a pair at equal distances, the inside one.
        let crosses = |e: i32| {
            e != UNSEEN
                && (d < 0) != (e < 0)
                && (d.abs() < e.abs() || (d.abs() == e.abs() && d < 0))
        };
        let (x, y, z) = Block::coords(i);
        let at = [x, y, z];
        (0..3).any(|axis| {
            let stride = STRIDES[axis];
            let face = face_slot(axis, at);
            let below = if at[axis] == 0 {
                self.faces[2 * axis][face]
            } else {
                self.distances[i - stride]
            };
            let above = if at[axis] == BLOCK_SIDE - 1 {
                self.faces[2 * axis + 1][face]
            } else {
                self.distances[i + stride]
            };
            crosses(below) || crosses(above)
        })
    }
}

/// What [`Esdf::mark`] found in one block.
struct Marked {
    index: BlockIndex,
    /// The block's new voxels; `None` when it left the layer.
    block: Option<EsdfBlock>,
    added: usize,
    removed: usize,
    /// Faces whose voxels changed (bits by [`DIRECTIONS`] index).
    moved: u8,
}

/// The voxel holding `p`; `None` for a point no voxel index reaches (NaN, infinite, or
/// farther than `i32` voxels), which a cast would have clamped onto a real voxel.
fn voxel_of(p: &Point3<f64>, voxel_size: f64) -> Option<VoxelIndex> {
    let limit = (i32::MAX / 2) as f64;
    let scaled = p.coords.map(|c| (c / voxel_size).floor());
    scaled
        .iter()
        .all(|c| c.abs() < limit)
        .then(|| std::array::from_fn(|a| scaled[a] as i32))
}

/// Every face bit of [`DIRECTIONS`].
const ALL_FACES: u8 = 0b11_1111;

/// Where a block's relaxation starts.
#[derive(Default)]
struct Seeds {
    /// Every voxel offers its site around, and the neighbours' faces offer theirs: its
    /// voxels changed outside relaxation.
    whole: bool,
    /// Per direction, the neighbour's facing voxels as this block last read them, where they
    /// have changed since.
    read: [Option<Box<Face>>; 6],
}

/// The blocks to relax in the next round.
#[derive(Default)]
struct Dirty(FxHashMap<BlockIndex, Seeds>);

impl Dirty {
    fn whole(&mut self, index: BlockIndex) {
        self.0.entry(index).or_default().whole = true;
    }

    /// Block `index`'s faces changed from `old` (where given): the neighbours across them are
    /// told what they read before (the earliest, if told twice).
    fn faces_read(&mut self, index: BlockIndex, old: OldFaces) {
        for (d, face) in old.into_iter().enumerate() {
            if let Some(face) = face {
                let seeds = self.0.entry(step(index, DIRECTIONS[d])).or_default();
                seeds.read[d ^ 1].get_or_insert(face);
            }
        }
    }
}

/// A block's faces as they were, where they changed.
type OldFaces = [Option<Box<Face>>; 6];

/// The faces `moved` of `block`.
fn old_faces(block: &[EsdfVoxel; VOXELS_PER_BLOCK], moved: u8) -> OldFaces {
    std::array::from_fn(|d| (moved >> d & 1 != 0).then(|| Box::new(Face::of(block, d))))
}

fn step(index: BlockIndex, direction: [i32; 3]) -> BlockIndex {
    std::array::from_fn(|a| index[a] + direction[a])
}

/// The 64 voxels of one face of a block, indexed by the other two coordinates.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Face([EsdfVoxel; BLOCK_SIDE * BLOCK_SIDE]);

impl Face {
    /// The face of `block` towards direction `d` (an index into [`DIRECTIONS`]).
    fn of(block: &[EsdfVoxel; VOXELS_PER_BLOCK], d: usize) -> Face {
        let layer = if d.is_multiple_of(2) {
            0
        } else {
            BLOCK_SIDE - 1
        };
        Face(std::array::from_fn(|k| {
            block[face_voxel(d / 2, layer, k % BLOCK_SIDE, k / BLOCK_SIDE)]
        }))
    }
}

/// Where voxel `at` (block coordinates) sits in a [`Face`] across `axis`: its other two
/// coordinates in increasing axis order ([`face_voxel`] the other way).
fn face_slot(axis: usize, [x, y, z]: [usize; 3]) -> usize {
    let (u, v) = match axis {
        0 => (y, z),
        1 => (x, z),
        _ => (x, y),
    };
    u + BLOCK_SIDE * v
}

/// The linear index of the voxel at `layer` along `axis` and `(u, v)` along the other two
/// axes in increasing order.
fn face_voxel(axis: usize, layer: usize, u: usize, v: usize) -> usize {
    match axis {
        0 => Block::linear(layer, u, v),
        1 => Block::linear(u, layer, v),
        _ => Block::linear(u, v, layer),
    }
}

/// The site `from` offers its face neighbour one voxel along `axis` on the `step` side of it
/// (-1 or 1): `from`'s site as seen from there, when that lies farther from the site than
/// `from` does and within `max_squared`; with its squared length.
#[inline(always)]
fn offer(from: EsdfVoxel, axis: usize, step: i16, max_squared: i32) -> Option<(i32, [i16; 3])> {
    if from.flags & HAS_SITE == 0 {
        return None;
    }
    // Offers only go outwards (away from the site, or sideways), so every offset held is
    // vouched for by a neighbour nearer to its site, back to the site itself: an offset whose
    // support is gone cannot keep itself, and the field has one fixed point.
    if from.site[axis] * step > 0 {
        return None;
    }
    // Built by selection, not by writing one element at a run-time index: that write sent
    // the array through memory and stalled the reads after it.
    let site: [i16; 3] = std::array::from_fn(|a| from.site[a] - if a == axis { step } else { 0 });
    let squared: i32 = site.iter().map(|&c| c as i32 * c as i32).sum();
    (squared <= max_squared).then_some((squared, site))
}

/// Voxel index strides along x, y and z within a block.
const STRIDES: [usize; 3] = [1, BLOCK_SIDE, BLOCK_SIDE * BLOCK_SIDE];

/// The faces (bits by [`DIRECTIONS`] index) voxel `i` of a block lies on.
fn faces_of(i: usize) -> u8 {
    let (x, y, z) = Block::coords(i);
    let last = BLOCK_SIDE - 1;
    [x, y, z].iter().enumerate().fold(0, |bits, (axis, &c)| {
        bits | u8::from(c == 0) << (2 * axis) | u8::from(c == last) << (2 * axis + 1)
    })
}

/// The state of `voxel`, voxel `i` of `block`, with the nearest site its six face neighbours
/// offer (those in `block`, or across its faces in `faces`); a site stays itself.
fn evaluate(
    block: &[EsdfVoxel; VOXELS_PER_BLOCK],
    faces: &[Option<Face>; 6],
    i: usize,
    voxel: EsdfVoxel,
    max_squared: i32,
) -> EsdfVoxel {
    if voxel.has(SITE) {
        return voxel;
    }
    let (x, y, z) = Block::coords(i);
    let at = [x, y, z];
    let mut best: Option<(i32, [i16; 3])> = None;
    for (axis, &stride) in STRIDES.iter().enumerate() {
        for (side, step) in [(0usize, -1i16), (1, 1)] {
            // The neighbour lies `step` along `axis`: inside the block or across its face.
            let inside = if step < 0 {
                at[axis] > 0
            } else {
                at[axis] < BLOCK_SIDE - 1
            };
            let neighbour = if inside {
                block[if step < 0 { i - stride } else { i + stride }]
            } else {
                match &faces[2 * axis + side] {
                    Some(face) => face.0[face_slot(axis, at)],
                    None => continue,
                }
            };
            // It lies on the `-step` side of the voxel it offers to.
            if let Some(candidate) = offer(neighbour, axis, -step, max_squared)
                && best.is_none_or(|b| candidate < b)
            {
                best = Some(candidate);
            }
        }
    }
    match best {
        Some((_, site)) => EsdfVoxel {
            site,
            flags: voxel.flags | HAS_SITE,
        },
        None => EsdfVoxel {
            site: [0; 3],
            flags: voxel.flags & !HAS_SITE,
        },
    }
}

/// Brings a block's voxels to the nearest site their face neighbours offer (the block's own,
/// and the `faces` of its six neighbours, their voxels touching this block), from `seeds`.
/// A voxel that changed passes its new site on to its neighbours, first-in first-out; a
/// neighbour that held what it offered before is evaluated afresh. Returns the faces whose
/// voxels changed, or `None` when none did.
fn relax(
    block: &mut [EsdfVoxel; VOXELS_PER_BLOCK],
    faces: &[Option<Face>; 6],
    seeds: &Seeds,
    max_squared: i32,
) -> Option<u8> {
    // What each voxel's neighbours were told of it: evaluations read this, and a change is
    // told when its voxel leaves the queue, so a neighbour never holds an unannounced value.
    let mut told = *block;
    let mut queue = VoxelQueue::default();
    let (mut changed, mut moved) = (false, 0u8);
    let mut take =
        |block: &mut [EsdfVoxel; VOXELS_PER_BLOCK], queue: &mut VoxelQueue, j, update| {
            if update != block[j] {
                block[j] = update;
                queue.push(j);
                changed = true;
                moved |= faces_of(j);
            }
        };
    if seeds.whole {
        for (i, voxel) in block.iter().enumerate() {
            if voxel.has(HAS_SITE) {
                queue.push(i);
            }
        }
    }
    let empty = Face([EsdfVoxel::default(); BLOCK_SIDE * BLOCK_SIDE]);
    for d in 0..6 {
        let read = seeds.read[d].as_deref();
        if !(seeds.whole || read.is_some()) {
            continue;
        }
        let now = faces[d].as_ref().unwrap_or(&empty);
        let layer = if d % 2 == 0 { 0 } else { BLOCK_SIDE - 1 };
        // The neighbour's voxel lies `step` along the axis from the facing one.
        let (axis, step) = (d / 2, if d % 2 == 0 { -1 } else { 1 });
        for k in 0..BLOCK_SIDE * BLOCK_SIDE {
            let before = read.map_or(now.0[k], |r| r.0[k]);
            if before == now.0[k] && !seeds.whole {
                continue;
            }
            let j = face_voxel(axis, layer, k % BLOCK_SIDE, k / BLOCK_SIDE);
            let told_now = Told {
                before,
                next: now.0[k],
                axis,
                step: -step,
            };
            if let Some(update) = passed_on(&told, faces, j, block[j], told_now, max_squared) {
                take(block, &mut queue, j, update);
            }
        }
    }
    while let Some(i) = queue.pop() {
        let (before, next) = (told[i], block[i]);
        told[i] = next;
        let (x, y, z) = Block::coords(i);
        let at = [x, y, z];
        for (axis, &stride) in STRIDES.iter().enumerate() {
            for step in [-1i16, 1] {
                let j = match step {
                    -1 if at[axis] > 0 => i - stride,
                    1 if at[axis] < BLOCK_SIDE - 1 => i + stride,
                    _ => continue,
                };
                let news = Told {
                    before,
                    next,
                    axis,
                    step,
                };
                if let Some(update) = passed_on(&told, faces, j, block[j], news, max_squared) {
                    take(block, &mut queue, j, update);
                }
            }
        }
    }
    changed.then_some(moved)
}

/// A neighbour's change as a voxel hears of it: it held `before` and holds `next`, and lies
/// on the `-step` side of the voxel along `axis`.
#[derive(Clone, Copy)]
struct Told {
    before: EsdfVoxel,
    next: EsdfVoxel,
    axis: usize,
    step: i16,
}

/// What `voxel`, voxel `j` of the block whose voxels its neighbours were `told`, holds after
/// hearing of a neighbour's change: evaluated afresh where it held what the neighbour offered
/// before, the neighbour's new offer where that is nearer; `None` when it keeps what it holds.
#[inline(always)]
fn passed_on(
    told: &[EsdfVoxel; VOXELS_PER_BLOCK],
    faces: &[Option<Face>; 6],
    j: usize,
    voxel: EsdfVoxel,
    news: Told,
    max_squared: i32,
) -> Option<EsdfVoxel> {
    if voxel.has(SITE) {
        return None;
    }
    let Told {
        before,
        next,
        axis,
        step,
    } = news;
    let held = voxel.has(HAS_SITE).then(|| (voxel.squared(), voxel.site));
    if let Some(offered) = offer(next, axis, step, max_squared)
        && held.is_none_or(|h| offered < h)
    {
        // Nearer than the best of its other offers, which it held.
        return Some(EsdfVoxel {
            site: offered.1,
            flags: voxel.flags | HAS_SITE,
        });
    }
    // It held what its neighbour no longer offers.
    (held.is_some() && before != next && offer(before, axis, step, max_squared) == held)
        .then(|| evaluate(told, faces, j, voxel, max_squared))
}

/// A first-in first-out queue of a block's voxels, each in it at most once at a time.
struct VoxelQueue {
    slots: [u16; VOXELS_PER_BLOCK],
    queued: [u64; VOXELS_PER_BLOCK / 64],
    head: usize,
    len: usize,
}

impl Default for VoxelQueue {
    fn default() -> Self {
        Self {
            slots: [0; VOXELS_PER_BLOCK],
            queued: [0; VOXELS_PER_BLOCK / 64],
            head: 0,
            len: 0,
        }
    }
}

impl VoxelQueue {
    fn push(&mut self, i: usize) {
        let (word, bit) = (i / 64, 1u64 << (i % 64));
        if self.queued[word] & bit == 0 {
            self.queued[word] |= bit;
            self.slots[(self.head + self.len) % VOXELS_PER_BLOCK] = i as u16;
            self.len += 1;
        }
    }

    fn pop(&mut self) -> Option<usize> {
        (self.len > 0).then(|| {
            let i = self.slots[self.head] as usize;
            self.head = (self.head + 1) % VOXELS_PER_BLOCK;
            self.len -= 1;
            self.queued[i / 64] &= !(1u64 << (i % 64));
            i
        })
    }
}

#[cfg(test)]
mod tests;
