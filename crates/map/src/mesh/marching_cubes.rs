//! Marching cubes on the TSDF, with block seams handled and incremental re-meshing.
//!
//! The 256-case triangle table is generated, not typed in: on every cube face the edges where
//! the sign changes are joined in pairs (on an ambiguous face, the two inside corners are kept
//! apart; the choice depends on the face alone, so the two cubes sharing a face agree and the
//! surface is watertight), the segments are chained into loops, and each loop is
//! fan-triangulated and oriented to face the outside (positive distance).

use std::sync::OnceLock;

use voxpan_core::nalgebra::{Point3, Vector3};

use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, TsdfVoxel};

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
pub(crate) fn triangle_table() -> &'static [Vec<[u8; 3]>; 256] {
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

/// A vertex's identity in the whole map: the edge it lies on, as the global voxel at the edge's
/// lower end and the edge's axis. Blocks that share an edge produce the same key, so their
/// meshes weld.
pub(crate) type EdgeKey = ([i32; 3], u8);

/// The surface inside one block, welded within the block: each vertex once, triangles by
/// index. Vertices on edges shared with a neighbouring block also carry their [`EdgeKey`], so
/// the whole map's mesh can weld across seams.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct BlockMesh {
    pub vertices: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 3]>,
    pub instances: Vec<u16>,
    pub triangles: Vec<[u32; 3]>,
    /// `(vertex, key)` for the vertices on the block's seams.
    pub seams: Vec<(u32, EdgeKey)>,
}

/// Voxels along a padded block's edge: the block plus the first layer of its +x/+y/+z
/// neighbours.
const P: usize = BLOCK_SIDE + 1;

/// The signs of the block's voxels plus the first layer of its +x/+y/+z neighbours',
/// `(side + 1)³` of them, gathered with eight hash look-ups instead of one per cube corner, as
/// one bit per voxel: a padded row along x is a `u16`, so the 8 cubes between four rows are
/// tested at once (most have no crossing and cost nothing more). The few voxels a vertex is
/// made from are read from the blocks.
struct Padded<'a> {
    /// Per padded row `y + P z`: bit `x` set where voxel `(x, y, z)` is observed.
    observed: [u16; P * P],
    /// Per padded row: bit `x` set where the voxel is observed and inside (negative distance).
    inside: [u16; P * P],
    /// The block and its neighbours, by offset `dx + 2 dy + 4 dz`.
    blocks: [Option<&'a Block>; 8],
}

impl<'a> Padded<'a> {
    fn new(layer: &'a Layer, index: BlockIndex) -> Self {
        let mut out = Padded {
            observed: [0; P * P],
            inside: [0; P * P],
            blocks: [None; 8],
        };
        for d in 0..8usize {
            let offset = [d & 1, (d >> 1) & 1, (d >> 2) & 1];
            let Some(block) = layer.get(&[
                index[0] + offset[0] as i32,
                index[1] + offset[1] as i32,
                index[2] + offset[2] as i32,
            ]) else {
                continue;
            };
            out.blocks[d] = Some(block);
            // From the neighbour, only the slab at its low faces (coordinate 0) along offset axes.
            let range = |o: usize| if o == 0 { 0..BLOCK_SIDE } else { 0..1 };
            for z in range(offset[2]) {
                for y in range(offset[1]) {
                    let row = y + offset[1] * BLOCK_SIDE + P * (z + offset[2] * BLOCK_SIDE);
                    let (mut observed, mut inside) = (0u16, 0u16);
                    for x in range(offset[0]) {
                        let v = block.voxels.get(Block::linear(x, y, z));
                        let bit = 1 << (x + offset[0] * BLOCK_SIDE);
                        if v.observed() {
                            observed |= bit;
                            if v.tsdf_steps() < 0 {
                                inside |= bit;
                            }
                        }
                    }
                    out.observed[row] |= observed;
                    out.inside[row] |= inside;
                }
            }
        }
        out
    }

    /// The four padded rows holding the corners of the cubes `(x, y, z)`, x = 0..side: corner
    /// `c` lies in row `c >> 1` (at `y + (c >> 1 & 1)`, `z + (c >> 2)`), bit `x + (c & 1)`.
    fn corner_rows(y: usize, z: usize) -> [usize; 4] {
        [
            y + P * z,
            y + 1 + P * z,
            y + P * (z + 1),
            y + 1 + P * (z + 1),
        ]
    }

    /// Bit `x` set where the surface crosses cube `(x, y, z)`: all 8 corners observed, some
    /// inside and some not.
    fn crossing_cubes(&self, y: usize, z: usize) -> u16 {
        let rows = Self::corner_rows(y, z);
        let observed = rows.map(|r| self.observed[r]);
        let inside = rows.map(|r| self.inside[r]);
        let pair = |bits: u16| bits & (bits >> 1);
        let complete = pair(observed[0] & observed[1] & observed[2] & observed[3]);
        let any_inside = inside[0] | inside[1] | inside[2] | inside[3];
        let all_inside = pair(inside[0] & inside[1] & inside[2] & inside[3]);
        complete & (any_inside | any_inside >> 1) & !all_inside & ((1 << BLOCK_SIDE) - 1)
    }

    /// Cube `(x, y, z)`'s case: bit `c` set where corner `c` is inside.
    fn case(&self, x: usize, y: usize, z: usize) -> usize {
        Self::corner_rows(y, z)
            .iter()
            .enumerate()
            .fold(0, |case, (k, &r)| {
                case | ((self.inside[r] as usize >> x) & 3) << (2 * k)
            })
    }

    /// The voxel at padded coordinates `p` and its instance; only for observed voxels (whose
    /// block is present).
    fn voxel(&self, p: [usize; 3]) -> (TsdfVoxel, u16) {
        let d = p[0] / BLOCK_SIDE + 2 * (p[1] / BLOCK_SIDE) + 4 * (p[2] / BLOCK_SIDE);
        let block = self.blocks[d].expect("an observed voxel's block is in the map");
        let i = Block::linear(p[0] % BLOCK_SIDE, p[1] % BLOCK_SIDE, p[2] % BLOCK_SIDE);
        (block.voxels.get(i), block.labels[i].instance())
    }
}

thread_local! {
    /// Per thread: the vertex made on each (padded lower corner, axis) edge of the block being
    /// meshed, `u32::MAX` where none. Kept between blocks (only the used slots are reset):
    /// allocating and filling it per block cost more than meshing a block with little surface.
    static VERTEX_OF_EDGE: std::cell::RefCell<Vec<u32>> =
        std::cell::RefCell::new(vec![u32::MAX; P * P * P * 3]);
}

/// Marching cubes over every cube whose lowest corner is a voxel of the block (cubes on the
/// +x/+y/+z seams read the neighbouring blocks). Cubes with an unobserved corner are skipped.
pub(crate) fn mesh_block(layer: &Layer, index: BlockIndex) -> BlockMesh {
    VERTEX_OF_EDGE.with(|slots| mesh_block_with(layer, index, &mut slots.borrow_mut()))
}

fn mesh_block_with(layer: &Layer, index: BlockIndex, vertex_of_edge: &mut [u32]) -> BlockMesh {
    let table = triangle_table();
    let voxel_size = layer.voxel_size();
    let padded = Padded::new(layer, index);
    let base = index.map(|c| c * BLOCK_SIDE as i32);
    // First the cubes the surface crosses, and how many triangles they make: the block's
    // vectors are sized once (growing them push by push was a fifth of meshing).
    let mut crossings = [0u16; BLOCK_SIDE * BLOCK_SIDE];
    let mut triangle_count = 0;
    for (row, crossing) in crossings.iter_mut().enumerate() {
        *crossing = padded.crossing_cubes(row % BLOCK_SIDE, row / BLOCK_SIDE);
        let mut bits = *crossing;
        while bits != 0 {
            let x = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            triangle_count += table[padded.case(x, row % BLOCK_SIDE, row / BLOCK_SIDE)].len();
        }
    }
    // A block's surface patch has about half as many vertices as triangles, plus its rim.
    let vertex_estimate = triangle_count / 2 + triangle_count / 8 + 4;
    let mut mesh = BlockMesh {
        vertices: Vec::with_capacity(vertex_estimate),
        colors: Vec::with_capacity(vertex_estimate),
        instances: Vec::with_capacity(vertex_estimate),
        triangles: Vec::with_capacity(triangle_count),
        seams: Vec::new(),
    };
    // The edge slots this block used, to reset afterwards.
    let mut used: Vec<usize> = Vec::with_capacity(vertex_estimate);
    for (row, &crossing) in crossings.iter().enumerate() {
        let (y, z) = (row % BLOCK_SIDE, row / BLOCK_SIDE);
        let mut bits = crossing;
        while bits != 0 {
            let x = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let cube_slot = (x + P * (y + P * z)) * 3;
            let case = padded.case(x, y, z);
            // Each crossed edge's vertex once per cube (made by the first cube that needs
            // it), then the case's triangles index them.
            let mut edge_vertex = [0u32; 12];
            let mut edges = CROSSED_EDGES[case];
            while edges != 0 {
                let e = edges.trailing_zeros() as usize;
                edges &= edges - 1;
                let slot = cube_slot + EDGE_SLOT[e];
                if vertex_of_edge[slot] == u32::MAX {
                    vertex_of_edge[slot] = mesh.vertices.len() as u32;
                    used.push(slot);
                    // The edge runs from padded voxel `low`, its lower corner, along `axis`.
                    let (corner, axis) = (EDGES[e].0, e / 4);
                    let low = [x + (corner & 1), y + ((corner >> 1) & 1), z + (corner >> 2)];
                    let mut high = low;
                    high[axis] += 1;
                    let ends = (padded.voxel(low), padded.voxel(high));
                    push_vertex(&mut mesh, ends, base, low, axis, voxel_size);
                }
                edge_vertex[e] = vertex_of_edge[slot];
            }
            mesh.triangles.extend(
                table[case]
                    .iter()
                    .map(|t| [0, 1, 2].map(|k| edge_vertex[t[k] as usize])),
            );
        }
    }
    for slot in used {
        vertex_of_edge[slot] = u32::MAX;
    }
    mesh
}

/// Per case: bit `e` set where edge `e` joins an inside and an outside corner, i.e. carries a
/// vertex of the case's triangles.
const CROSSED_EDGES: [u16; 256] = {
    let mut out = [0; 256];
    let mut case = 0;
    while case < 256 {
        let mut e = 0;
        while e < 12 {
            let (a, b) = EDGES[e];
            if (case >> a ^ case >> b) & 1 == 1 {
                out[case] |= 1 << e;
            }
            e += 1;
        }
        case += 1;
    }
    out
};

/// Per edge: its slot in the vertex-of-edge table relative to its cube's lowest corner
/// (`(padded voxel) × 3 + axis`, the edge running from its lower corner along one axis).
const EDGE_SLOT: [usize; 12] = {
    let mut out = [0; 12];
    let mut e = 0;
    while e < 12 {
        let a = EDGES[e].0;
        out[e] = ((a & 1) + P * (((a >> 1) & 1) + P * ((a >> 2) & 1))) * 3 + e / 4;
        e += 1;
    }
    out
};

/// Adds the vertex where the surface crosses the edge from voxel `ends.0` (at block-local
/// voxel `low`) to `ends.1`, one voxel further along `axis`; each end with its instance.
fn push_vertex(
    mesh: &mut BlockMesh,
    ends: ((TsdfVoxel, u16), (TsdfVoxel, u16)),
    base: [i32; 3],
    low: [usize; 3],
    axis: usize,
    voxel_size: f64,
) {
    let ((a, label_a), (b, label_b)) = ends;
    let (da, db) = (a.tsdf() as f64, b.tsdf() as f64);
    let t = if (da - db).abs() > 1e-12 {
        da / (da - db)
    } else {
        0.5
    };
    let global = [
        base[0] + low[0] as i32,
        base[1] + low[1] as i32,
        base[2] + low[2] as i32,
    ];
    let mut p = Point3::new(
        global[0] as f64 + 0.5,
        global[1] as f64 + 0.5,
        global[2] as f64 + 0.5,
    );
    p[axis] += t;
    let p = p * voxel_size;
    let index = mesh.vertices.len() as u32;
    mesh.vertices.push([p.x as f32, p.y as f32, p.z as f32]);
    mesh.instances.push(if t < 0.5 { label_a } else { label_b });
    let (ca, cb) = (a.color(), b.color());
    mesh.colors.push(std::array::from_fn(|k| {
        // Between two bytes, so not negative: adding 0.5 and truncating rounds (`round` is a
        // libm call on baseline x86-64).
        (ca[k] as f64 + (cb[k] as f64 - ca[k] as f64) * t + 0.5) as u8
    }));
    // Cubes of another block share this edge when it lies on a block face it runs along.
    let on_seam = (0..3).any(|i| i != axis && (low[i] == 0 || low[i] == BLOCK_SIDE));
    if on_seam {
        mesh.seams.push((index, (global, axis as u8)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_crossed_edges_are_those_the_triangles_use() {
        for (case, triangles) in triangle_table().iter().enumerate() {
            let used = triangles.iter().flatten().fold(0u16, |m, &e| m | 1 << e);
            assert_eq!(CROSSED_EDGES[case], used, "case {case:08b}");
        }
    }

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
