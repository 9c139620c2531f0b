//! Marching cubes on the TSDF, with block seams handled and incremental re-meshing.
//!
//! The 256-case triangle table is generated, not typed in: on every cube face the edges where
//! the sign changes are joined in pairs (on an ambiguous face, the two inside corners are kept
//! apart; the choice depends on the face alone, so the two cubes sharing a face agree and the
//! surface is watertight), the segments are chained into loops, and each loop is
//! fan-triangulated and oriented to face the outside (positive distance).

use std::sync::OnceLock;

use rustc_hash::FxHashMap;
use voxpan_core::nalgebra::{Point3, Vector3};

use crate::{Block, BlockIndex, Layer, TsdfVoxel, BLOCK_SIDE};

/// Corner `c` of a cube sits at offset `(c & 1, c >> 1 & 1, c >> 2 & 1)`.
fn corner_offset(c: usize) -> Vector3<f64> {
    Vector3::new((c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64)
}

/// The 12 edges as corner pairs.
const EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7), // along x
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7), // along y
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7), // along z
];

/// The 6 faces as corner cycles.
const FACES: [[usize; 4]; 6] = [
    [0, 2, 6, 4], // x = 0
    [1, 3, 7, 5], // x = 1
    [0, 1, 5, 4], // y = 0
    [2, 3, 7, 6], // y = 1
    [0, 1, 3, 2], // z = 0
    [4, 5, 7, 6], // z = 1
];

fn edge_between(a: usize, b: usize) -> usize {
    EDGES
        .iter()
        .position(|&(p, q)| (p, q) == (a, b) || (p, q) == (b, a))
        .expect("face corners are cube edges")
}

/// Triangles (as edge triples) for each of the 256 inside/outside corner patterns.
pub fn triangle_table() -> &'static [Vec<[u8; 3]>; 256] {
    static TABLE: OnceLock<[Vec<[u8; 3]>; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(triangulate_case))
}

fn triangulate_case(case: usize) -> Vec<[u8; 3]> {
    let inside = |c: usize| case >> c & 1 == 1;
    // Segments between crossing edges, face by face.
    let mut segments: Vec<(usize, usize)> = Vec::new();
    for face in FACES {
        let edges: Vec<usize> = (0..4)
            .map(|k| edge_between(face[k], face[(k + 1) % 4]))
            .collect();
        let crossing: Vec<usize> = (0..4)
            .filter(|&k| inside(face[k]) != inside(face[(k + 1) % 4]))
            .collect();
        match crossing.len() {
            2 => segments.push((edges[crossing[0]], edges[crossing[1]])),
            4 => {
                // Ambiguous face: cut off each inside corner on its own.
                for k in (0..4).filter(|&k| inside(face[k])) {
                    segments.push((edges[(k + 3) % 4], edges[k]));
                }
            }
            _ => {}
        }
    }
    // Chain segments into loops (every crossing edge is shared by exactly two faces).
    let mut triangles = Vec::new();
    while let Some((start, mut current)) = segments.pop() {
        let mut lp = vec![start];
        while current != start {
            lp.push(current);
            let k = segments
                .iter()
                .position(|&(a, b)| a == current || b == current)
                .expect("segments close into loops");
            let (a, b) = segments.swap_remove(k);
            current = if a == current { b } else { a };
        }
        // Orient: the fan's normal must point from the inside corners to the outside ones.
        let midpoint = |e: usize| (corner_offset(EDGES[e].0) + corner_offset(EDGES[e].1)) / 2.0;
        let mut outward = Vector3::zeros();
        for &e in &lp {
            let (a, b) = EDGES[e];
            let (i, o) = if inside(a) { (a, b) } else { (b, a) };
            outward += corner_offset(o) - corner_offset(i);
        }
        let normal: Vector3<f64> = (1..lp.len() - 1)
            .map(|k| {
                (midpoint(lp[k]) - midpoint(lp[0])).cross(&(midpoint(lp[k + 1]) - midpoint(lp[0])))
            })
            .sum();
        if normal.dot(&outward) < 0.0 {
            lp.reverse();
        }
        for k in 1..lp.len() - 1 {
            triangles.push([lp[0] as u8, lp[k] as u8, lp[k + 1] as u8]);
        }
    }
    triangles
}

/// A coloured triangle mesh (three vertices per triangle, no sharing); each vertex also carries
/// the map instance of its nearer voxel (0 = none).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 3]>,
    pub instances: Vec<u16>,
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

impl Mesh {
    pub fn triangles(&self) -> usize {
        self.vertices.len() / 3
    }

    pub fn area(&self) -> f64 {
        self.vertices
            .chunks_exact(3)
            .map(|t| {
                let p = |i: usize| Vector3::from(t[i].map(f64::from));
                (p(1) - p(0)).cross(&(p(2) - p(0))).norm() / 2.0
            })
            .sum()
    }

    pub fn append(&mut self, other: &Mesh) {
        self.vertices.extend_from_slice(&other.vertices);
        self.colors.extend_from_slice(&other.colors);
        self.instances.extend_from_slice(&other.instances);
    }

    /// The same mesh with every vertex coloured by `color(instance)`.
    pub fn colored_by(&self, color: impl Fn(u16) -> [u8; 3]) -> Mesh {
        Mesh {
            colors: self.instances.iter().map(|&i| color(i)).collect(),
            ..self.clone()
        }
    }

    /// One mesh per instance (a triangle belongs to the instance most of its vertices carry).
    pub fn split_by_instance(&self) -> std::collections::BTreeMap<u16, Mesh> {
        let mut out: std::collections::BTreeMap<u16, Mesh> = Default::default();
        for t in 0..self.triangles() {
            let ids = &self.instances[3 * t..3 * t + 3];
            let id = if ids[1] == ids[2] { ids[1] } else { ids[0] };
            if id == 0 {
                continue;
            }
            let m = out.entry(id).or_default();
            m.vertices
                .extend_from_slice(&self.vertices[3 * t..3 * t + 3]);
            m.colors.extend_from_slice(&self.colors[3 * t..3 * t + 3]);
            m.instances.extend_from_slice(ids);
        }
        out
    }

    /// Writes a binary little-endian PLY with per-vertex colour.
    pub fn write_ply(&self, path: &std::path::Path) -> std::io::Result<()> {
        use std::io::Write;
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        write!(
            out,
            "ply\nformat binary_little_endian 1.0\ncomment voxpan TSDF mesh\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
             property uchar green\nproperty uchar blue\nelement face {}\n\
             property list uchar uint vertex_indices\nend_header\n",
            self.vertices.len(),
            self.triangles()
        )?;
        for (v, c) in self.vertices.iter().zip(&self.colors) {
            for x in v {
                out.write_all(&x.to_le_bytes())?;
            }
            out.write_all(c)?;
        }
        for t in 0..self.triangles() as u32 {
            out.write_all(&[3])?;
            for i in 0..3 {
                out.write_all(&(3 * t + i).to_le_bytes())?;
            }
        }
        out.flush()
    }
}

/// The block's voxels plus the first layer of its +x/+y/+z neighbours: `(side + 1)³` voxels,
/// gathered with eight hash look-ups instead of one per cube corner.
fn padded_voxels(layer: &Layer, index: BlockIndex) -> Vec<Option<(TsdfVoxel, u16)>> {
    const P: usize = BLOCK_SIDE + 1;
    let mut out = vec![None; P * P * P];
    for d in 0..8usize {
        let offset = [(d & 1) as i32, ((d >> 1) & 1) as i32, ((d >> 2) & 1) as i32];
        let Some(block) = layer.blocks.get(&[
            index[0] + offset[0],
            index[1] + offset[1],
            index[2] + offset[2],
        ]) else {
            continue;
        };
        // From the neighbour, only the slab at its low faces (coordinate 0) along offset axes.
        let range = |o: i32| if o == 0 { 0..BLOCK_SIDE } else { 0..1 };
        for z in range(offset[2]) {
            for y in range(offset[1]) {
                for x in range(offset[0]) {
                    let i = Block::linear(x, y, z);
                    let v = block.voxels[i];
                    let (px, py, pz) = (
                        x + offset[0] as usize * BLOCK_SIDE,
                        y + offset[1] as usize * BLOCK_SIDE,
                        z + offset[2] as usize * BLOCK_SIDE,
                    );
                    out[px + P * (py + P * pz)] =
                        v.observed().then_some((v, block.labels[i].instance()));
                }
            }
        }
    }
    out
}

/// The surface inside one block: every cube whose lowest corner is a voxel of the block (cubes
/// on the +x/+y/+z seams read the neighbouring blocks).
pub fn mesh_block(layer: &Layer, index: BlockIndex) -> Mesh {
    const P: usize = BLOCK_SIDE + 1;
    let mut mesh = Mesh::default();
    let table = triangle_table();
    let voxel_size = layer.voxel_size();
    let padded = padded_voxels(layer, index);
    let base = index.map(|c| c as i64 * BLOCK_SIDE as i64);
    for z in 0..BLOCK_SIDE {
        for y in 0..BLOCK_SIDE {
            for x in 0..BLOCK_SIDE {
                let mut corners = [TsdfVoxel::default(); 8];
                let mut labels = [0u16; 8];
                let mut complete = true;
                for (c, slot) in corners.iter_mut().enumerate() {
                    let (cx, cy, cz) = (x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1));
                    match padded[cx + P * (cy + P * cz)] {
                        Some((v, l)) => {
                            *slot = v;
                            labels[c] = l;
                        }
                        None => {
                            complete = false;
                            break;
                        }
                    }
                }
                if !complete {
                    continue;
                }
                let case = (0..8).fold(0, |acc, c| {
                    acc | ((corners[c].distance < 0.0) as usize) << c
                });
                if case == 0 || case == 255 {
                    continue;
                }
                let g = [base[0] + x as i64, base[1] + y as i64, base[2] + z as i64];
                let origin = Point3::new(g[0] as f64 + 0.5, g[1] as f64 + 0.5, g[2] as f64 + 0.5)
                    * voxel_size;
                for tri in &table[case] {
                    for &e in tri {
                        let (a, b) = EDGES[e as usize];
                        let (da, db) = (corners[a].distance as f64, corners[b].distance as f64);
                        let t = if (da - db).abs() > 1e-12 {
                            da / (da - db)
                        } else {
                            0.5
                        };
                        let p = origin
                            + (corner_offset(a) + (corner_offset(b) - corner_offset(a)) * t)
                                * voxel_size;
                        mesh.vertices.push([p.x as f32, p.y as f32, p.z as f32]);
                        mesh.instances
                            .push(if t < 0.5 { labels[a] } else { labels[b] });
                        let (ca, cb) = (corners[a].color, corners[b].color);
                        mesh.colors.push(std::array::from_fn(|k| {
                            (ca[k] as f64 + (cb[k] as f64 - ca[k] as f64) * t).round() as u8
                        }));
                    }
                }
            }
        }
    }
    mesh
}

/// Per-block meshes, re-extracted only where the map changed.
#[derive(Clone, Debug, Default)]
pub struct MeshLayer {
    pub blocks: FxHashMap<BlockIndex, Mesh>,
}

impl MeshLayer {
    /// Re-meshes every block integration touched since the last call, plus its −x/−y/−z
    /// neighbours (their seam cubes read the touched block), and clears the flags. Returns how
    /// many blocks were meshed.
    pub fn update(&mut self, layer: &mut Layer) -> usize {
        let mut dirty: Vec<BlockIndex> = Vec::new();
        for (index, block) in layer.blocks.iter_mut().filter(|(_, b)| b.updated) {
            block.updated = false;
            for d in 0..8 {
                let n = [
                    index[0] - (d & 1),
                    index[1] - ((d >> 1) & 1),
                    index[2] - ((d >> 2) & 1),
                ];
                dirty.push(n);
            }
        }
        dirty.sort_unstable();
        dirty.dedup();
        dirty.retain(|i| layer.blocks.contains_key(i));
        let layer: &Layer = layer;
        use rayon::prelude::*;
        let meshes: Vec<(BlockIndex, Mesh)> = dirty
            .par_iter()
            .map(|&i| (i, mesh_block(layer, i)))
            .collect();
        let count = meshes.len();
        for (i, m) in meshes {
            self.blocks.insert(i, m);
        }
        count
    }

    /// All block meshes in one.
    pub fn combined(&self) -> Mesh {
        let mut keys: Vec<_> = self.blocks.keys().copied().collect();
        keys.sort_unstable();
        let mut mesh = Mesh::default();
        for k in keys {
            mesh.append(&self.blocks[&k]);
        }
        mesh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_complementary_and_closed() {
        let table = triangle_table();
        assert!(table[0].is_empty() && table[255].is_empty());
        // One inside corner: one triangle.
        for c in 0..8 {
            assert_eq!(table[1 << c].len(), 1);
        }
        // A half-cube split by a plane: a quad (two triangles).
        assert_eq!(table[0b0000_1111].len(), 2);
        // Every edge used by a case's triangles crosses the surface, and is shared by exactly two
        // triangles within closed loops of the case (each crossing edge appears an even number
        // of times counting all fans).
        for (case, tris) in table.iter().enumerate() {
            for tri in tris {
                for &e in tri {
                    let (a, b) = EDGES[e as usize];
                    assert_ne!(
                        case >> a & 1,
                        case >> b & 1,
                        "case {case}: edge {e} does not cross"
                    );
                }
            }
        }
    }
}
