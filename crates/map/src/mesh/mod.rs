//! Meshing: marching cubes per block (generated 256-case table, seams handled), re-extracted
//! incrementally where the map changed, and welded into one indexed mesh with smooth normals.

mod marching_cubes;

pub(crate) use marching_cubes::{BlockMesh, EdgeKey, mesh_block};

use rayon::prelude::*;
use std::collections::hash_map::Entry;

use rustc_hash::FxHashMap;
use voxpan_core::Mesh;

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
    pub fn combined(&self) -> Mesh {
        let mut keys: Vec<BlockIndex> = self.blocks.keys().copied().collect();
        keys.sort_unstable();
        let blocks: Vec<&BlockMesh> = keys.iter().map(|k| &self.blocks[k]).collect();
        let (vertices, triangles, seams) = blocks.iter().fold((0, 0, 0), |(v, t, s), m| {
            (
                v + m.vertices.len(),
                t + m.triangles.len(),
                s + m.seams.len(),
            )
        });
        let mut mesh = Mesh {
            vertices: Vec::with_capacity(vertices),
            triangles: Vec::with_capacity(triangles),
            normals: Vec::new(),
            colors: Vec::with_capacity(vertices),
            instances: Vec::with_capacity(vertices),
        };
        let mut seam_vertex: FxHashMap<EdgeKey, u32> =
            FxHashMap::with_capacity_and_hasher(seams, Default::default());
        let mut index_of: Vec<u32> = Vec::new();
        for block in &blocks {
            index_of.clear();
            index_of.resize(block.vertices.len(), u32::MAX);
            // New vertices are appended in block order, so a new vertex's index is known before
            // it is added: the vertices so far, plus its local index, less the seam vertices
            // before it that another block already added (seams are listed in local order).
            let first = mesh.vertices.len();
            let mut reused = 0;
            for &(local, edge) in &block.seams {
                match seam_vertex.entry(edge) {
                    Entry::Occupied(global) => {
                        index_of[local as usize] = *global.get();
                        reused += 1;
                    }
                    Entry::Vacant(slot) => {
                        slot.insert((first + local as usize - reused) as u32);
                    }
                }
            }
            for (local, slot) in index_of.iter_mut().enumerate() {
                if *slot == u32::MAX {
                    *slot = mesh.vertices.len() as u32;
                    mesh.vertices.push(block.vertices[local]);
                    mesh.colors.push(block.colors[local]);
                    mesh.instances.push(block.instances[local]);
                }
            }
            debug_assert!(
                block
                    .seams
                    .iter()
                    .all(|(local, edge)| seam_vertex[edge] == index_of[*local as usize]),
                "seam vertices are listed in local order"
            );
            mesh.triangles.extend(
                block
                    .triangles
                    .iter()
                    .map(|t| t.map(|i| index_of[i as usize])),
            );
        }
        mesh.compute_normals();
        mesh
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
