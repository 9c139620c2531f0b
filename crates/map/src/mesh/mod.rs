//! Meshing: marching cubes per block (generated 256-case table, seams handled), re-extracted
//! incrementally where the map changed, and welded into one indexed mesh with smooth normals.

mod marching_cubes;

pub(crate) use marching_cubes::{BlockMesh, EdgeKey, mesh_block};

use rayon::prelude::*;
use std::collections::hash_map::Entry;

use rustc_hash::FxHashMap;
use voxpan_core::nalgebra::Vector3;
use voxpan_core::{Mesh, add_triangle_normals, unit_normal};

use crate::layer::{BlockIndex, Layer};

/// How a mesh's vertices are coloured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Coloring {
    /// The fused camera colour.
    Rgb,
    /// A distinct colour per map instance (grey where none).
    Instance,
    /// A distinct colour per semantic class (grey where unknown).
    Class,
}

impl std::str::FromStr for Coloring {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "rgb" => Ok(Self::Rgb),
            "instance" => Ok(Self::Instance),
            "class" => Ok(Self::Class),
            other => Err(format!(
                "unknown colouring {other:?} (expected rgb, instance or class)"
            )),
        }
    }
}

/// A distinct, stable colour for an id (golden-ratio hue steps); 0 is grey.
pub fn id_color(id: u32) -> [u8; 3] {
    if id == 0 {
        return [128, 128, 128];
    }
    let h = (id as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r, g, b].map(|c: f64| (40.0 + 200.0 * c) as u8)
}

/// Per-block meshes, re-extracted only where the map changed.
#[derive(Clone, Debug, Default)]
pub(crate) struct MeshLayer {
    blocks: FxHashMap<BlockIndex, BlockMesh>,
}

impl MeshLayer {
    /// Re-meshes `changed` blocks plus their −x/−y/−z neighbours (whose seam cubes read the
    /// changed blocks). Returns the re-meshed blocks, sorted.
    pub fn update(&mut self, layer: &Layer, changed: &[BlockIndex]) -> Vec<BlockIndex> {
        let mut dirty: Vec<BlockIndex> = Vec::with_capacity(changed.len() * 8);
        for index in changed {
            for d in 0..8 {
                dirty.push([
                    index[0] - (d & 1),
                    index[1] - ((d >> 1) & 1),
                    index[2] - ((d >> 2) & 1),
                ]);
            }
        }
        dirty.sort_unstable();
        dirty.dedup();
        dirty.retain(|i| layer.contains(i));
        let meshes: Vec<(BlockIndex, BlockMesh)> = dirty
            .par_iter()
            .map(|&i| (i, mesh_block(layer, i)))
            .collect();
        for (i, m) in meshes {
            if m.triangles.is_empty() {
                self.blocks.remove(&i);
            } else {
                self.blocks.insert(i, m);
            }
        }
        dirty
    }

    /// Forgets the meshes of `removed` blocks (no longer in `layer`) and re-meshes the
    /// neighbours whose seam cubes read them.
    pub fn remove(&mut self, layer: &Layer, removed: &[BlockIndex]) {
        for index in removed {
            self.blocks.remove(index);
        }
        self.update(layer, removed);
    }

    pub fn get(&self, index: &BlockIndex) -> Option<&BlockMesh> {
        self.blocks.get(index)
    }

    /// The blocks that have surface, sorted.
    pub fn indices(&self) -> Vec<BlockIndex> {
        let mut keys: Vec<BlockIndex> = self.blocks.keys().copied().collect();
        keys.sort_unstable();
        keys
    }

    /// All block meshes welded into one (seam vertices shared), with area-weighted normals.
    /// One serial pass decides which seam vertices an earlier block already made; the copying,
    /// most of the work and the first touch of the mesh's fresh memory, runs block-parallel.
    pub fn combined(&self) -> Mesh {
        let mut keys: Vec<BlockIndex> = self.blocks.keys().copied().collect();
        keys.sort_unstable();
        let blocks: Vec<&BlockMesh> = keys.iter().map(|k| &self.blocks[k]).collect();
        let welds = Welds::find(&keys, &blocks);
        // Zeroed allocations are fresh pages, first touched by the parallel copy below.
        let mut mesh = Mesh {
            vertices: vec![[0.0; 3]; welds.vertices],
            triangles: vec![[0; 3]; welds.triangles],
            normals: vec![[0.0; 3]; welds.vertices],
            colors: vec![[0; 3]; welds.vertices],
            instances: vec![0; welds.vertices],
        };
        // Normal sums a block owes to the seam vertices it reuses, one per reused vertex.
        let mut reused_sums = vec![[0.0f32; 3]; welds.reused.len()];
        let mut jobs = Vec::with_capacity(blocks.len());
        let mut out = BlockOutputs {
            vertices: &mut mesh.vertices,
            colors: &mut mesh.colors,
            instances: &mut mesh.instances,
            normals: &mut mesh.normals,
            triangles: &mut mesh.triangles,
            reused_sums: &mut reused_sums,
        };
        for (block, weld) in blocks.iter().zip(&welds.blocks) {
            let reused = weld.reused.len();
            let share = out.split_off(block.vertices.len() - reused, block.triangles.len(), reused);
            jobs.push((*block, weld, share));
        }
        jobs.into_par_iter().for_each_init(
            || (Vec::new(), Vec::new()),
            |(index_of, sums): &mut (Vec<u32>, Vec<[f32; 3]>), (block, weld, out)| {
                copy_block(block, weld, &welds.reused, out, index_of, sums);
            },
        );
        for (&(_, global), sum) in welds.reused.iter().zip(&reused_sums) {
            let n = &mut mesh.normals[global as usize];
            *n = (Vector3::from(*n) + Vector3::from(*sum)).into();
        }
        mesh.normals
            .par_iter_mut()
            .for_each(|n| *n = unit_normal(*n));
        mesh
    }
}

/// The parts of the welded mesh's arrays one block writes (or, before splitting, those not
/// handed out yet).
struct BlockOutputs<'a> {
    vertices: &'a mut [[f32; 3]],
    colors: &'a mut [[u8; 3]],
    instances: &'a mut [u16],
    normals: &'a mut [[f32; 3]],
    triangles: &'a mut [[u32; 3]],
    reused_sums: &'a mut [[f32; 3]],
}

impl<'a> BlockOutputs<'a> {
    /// Takes the next block's share off the front.
    fn split_off(&mut self, vertices: usize, triangles: usize, reused: usize) -> Self {
        fn front<'s, T>(slice: &mut &'s mut [T], n: usize) -> &'s mut [T] {
            let (head, tail) = std::mem::take(slice).split_at_mut(n);
            *slice = tail;
            head
        }
        BlockOutputs {
            vertices: front(&mut self.vertices, vertices),
            colors: front(&mut self.colors, vertices),
            instances: front(&mut self.instances, vertices),
            normals: front(&mut self.normals, vertices),
            triangles: front(&mut self.triangles, triangles),
            reused_sums: front(&mut self.reused_sums, reused),
        }
    }
}

/// Copies one block into the welded mesh: its own vertices, its triangles renumbered, and the
/// area-weighted normal sums of its triangles, those of reused seam vertices set aside for
/// their owner.
fn copy_block(
    block: &BlockMesh,
    weld: &BlockWeld,
    all_reused: &[(u32, u32)],
    out: BlockOutputs,
    index_of: &mut Vec<u32>,
    sums: &mut Vec<[f32; 3]>,
) {
    sums.clear();
    sums.resize(block.vertices.len(), [0.0; 3]);
    add_triangle_normals(&block.vertices, &block.triangles, sums);
    let mut reused = all_reused[weld.reused.clone()].iter().peekable();
    let (mut next, mut own, mut taken) = (weld.first_vertex, 0, 0);
    index_of.clear();
    for (local, sum) in sums.iter().enumerate() {
        if let Some(&(_, global)) = reused.next_if(|(l, _)| *l as usize == local) {
            index_of.push(global);
            out.reused_sums[taken] = *sum;
            taken += 1;
            continue;
        }
        index_of.push(next);
        next += 1;
        out.vertices[own] = block.vertices[local];
        out.colors[own] = block.colors[local];
        out.instances[own] = block.instances[local];
        out.normals[own] = *sum;
        own += 1;
    }
    debug_assert!(
        reused.next().is_none() && own == out.vertices.len(),
        "every reused seam vertex met, every own vertex copied"
    );
    for (slot, tri) in out.triangles.iter_mut().zip(&block.triangles) {
        *slot = tri.map(|j| index_of[j as usize]);
    }
}

/// Where each block's vertices and triangles go in the welded mesh.
struct Welds {
    /// Per block, in block order.
    blocks: Vec<BlockWeld>,
    /// `(local vertex, global vertex)` for the seam vertices a block takes from an earlier
    /// one, block after block, each block's in local order.
    reused: Vec<(u32, u32)>,
    /// Totals of the welded mesh.
    vertices: usize,
    triangles: usize,
}

struct BlockWeld {
    /// The global index of the block's first vertex of its own; the rest follow in order.
    first_vertex: u32,
    /// The block's entries of [`Welds::reused`].
    reused: std::ops::Range<usize>,
}

impl Welds {
    /// A seam vertex belongs to the first block (in the given order, sorted by index) that
    /// made it; later blocks reuse it.
    fn find(keys: &[BlockIndex], blocks: &[&BlockMesh]) -> Self {
        // Blocks sharing a seam are neighbours, so blocks in slab x (sorted first by x) reuse
        // only vertices made in slabs x - 1 and x: two slabs' tables stay small enough to
        // stay in cache, where one table of the whole map's seams does not.
        let mut made_in_previous_slab: FxHashMap<EdgeKey, u32> = FxHashMap::default();
        let mut made_in_this_slab: FxHashMap<EdgeKey, u32> = FxHashMap::default();
        let mut slab = keys.first().map_or(0, |k| k[0]);
        let mut out = Welds {
            blocks: Vec::with_capacity(blocks.len()),
            reused: Vec::new(),
            vertices: 0,
            triangles: 0,
        };
        for (key, block) in keys.iter().zip(blocks) {
            if key[0] != slab {
                std::mem::swap(&mut made_in_previous_slab, &mut made_in_this_slab);
                made_in_this_slab.clear();
                if key[0] != slab + 1 {
                    made_in_previous_slab.clear();
                }
                slab = key[0];
            }
            let (first_vertex, start) = (out.vertices, out.reused.len());
            // The block's own vertices take consecutive indices, so a new seam vertex's index
            // is its local index less the reused seam vertices before it (seams are listed in
            // local order; only seam vertices are ever reused).
            debug_assert!(
                block.seams.windows(2).all(|w| w[0].0 < w[1].0),
                "seams in ascending local order"
            );
            for &(local, edge) in &block.seams {
                let reused_before = out.reused.len() - start;
                if let Some(&global) = made_in_previous_slab.get(&edge) {
                    out.reused.push((local, global));
                    continue;
                }
                match made_in_this_slab.entry(edge) {
                    Entry::Occupied(global) => out.reused.push((local, *global.get())),
                    Entry::Vacant(slot) => {
                        slot.insert((first_vertex + local as usize - reused_before) as u32);
                    }
                }
            }
            out.blocks.push(BlockWeld {
                first_vertex: first_vertex as u32,
                reused: start..out.reused.len(),
            });
            out.vertices += block.vertices.len() - (out.reused.len() - start);
            out.triangles += block.triangles.len();
        }
        out
    }
}

impl BlockMesh {
    /// This block's mesh on its own (indexed within the block, no normals).
    pub fn to_mesh(&self) -> Mesh {
        Mesh {
            vertices: self.vertices.clone(),
            triangles: self.triangles.clone(),
            normals: Vec::new(),
            colors: self.colors.clone(),
            instances: self.instances.clone(),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
