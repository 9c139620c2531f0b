//! Marching cubes on the TSDF, with block seams handled and incremental re-meshing.
//!
//! The 256-case triangle table is generated, not typed in: on every cube face the edges where
//! the sign changes are joined in pairs (on an ambiguous face, the two inside corners are kept
//! apart; the choice depends on the face alone, so the two cubes sharing a face agree and the
//! surface is watertight), the segments are chained into loops, and each loop is
//! fan-triangulated and oriented to face the outside (positive distance).

use std::sync::OnceLock;

use voxpan_core::nalgebra::{Point3, Vector3};

use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, NO_TSDF_STEPS, TsdfVoxel};

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

/// The block's voxels plus the first layer of its +x/+y/+z neighbours, `(side + 1)³` of them,
/// gathered with eight hash look-ups instead of one per cube corner.
struct Padded {
    /// Each voxel's stored distance ([`NO_TSDF_STEPS`] where unobserved): all that the cube
    /// tests read, two bytes a voxel.
    steps: Vec<i16>,
    /// Each voxel with its instance, read only where a vertex is made.
    voxels: Vec<(TsdfVoxel, u16)>,
}

fn padded_voxels(layer: &Layer, index: BlockIndex) -> Padded {
    const P: usize = BLOCK_SIDE + 1;
    let mut out = Padded {
        steps: vec![NO_TSDF_STEPS; P * P * P],
        voxels: vec![(TsdfVoxel::default(), 0); P * P * P],
    };
    for d in 0..8usize {
        let offset = [(d & 1) as i32, ((d >> 1) & 1) as i32, ((d >> 2) & 1) as i32];
        let Some(block) = layer.get(&[
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
                    if !v.observed() {
                        continue;
                    }
                    let (px, py, pz) = (
                        x + offset[0] as usize * BLOCK_SIDE,
                        y + offset[1] as usize * BLOCK_SIDE,
                        z + offset[2] as usize * BLOCK_SIDE,
                    );
                    let k = px + P * (py + P * pz);
                    out.steps[k] = v.tsdf_steps();
                    out.voxels[k] = (v, block.labels[i].instance());
                }
            }
        }
    }
    out
}

/// Marching cubes over every cube whose lowest corner is a voxel of the block (cubes on the
/// +x/+y/+z seams read the neighbouring blocks). Cubes with an unobserved corner are skipped.
pub(crate) fn mesh_block(layer: &Layer, index: BlockIndex) -> BlockMesh {
    const P: usize = BLOCK_SIDE + 1;
    let mut mesh = BlockMesh::default();
    let table = triangle_table();
    let voxel_size = layer.voxel_size();
    let padded = padded_voxels(layer, index);
    let base = index.map(|c| c * BLOCK_SIDE as i32);
    // Vertex of each (local lower corner, axis) edge, so triangles of neighbouring cubes share
    // their vertices.
    let mut vertex_of_edge = vec![u32::MAX; P * P * P * 3];
    for z in 0..BLOCK_SIDE {
        for y in 0..BLOCK_SIDE {
            for x in 0..BLOCK_SIDE {
                // The cube's case from the corners' signs; skipped if a corner is unobserved.
                let mut slots = [0usize; 8];
                let mut case = 0;
                let mut complete = true;
                for (c, slot) in slots.iter_mut().enumerate() {
                    let (cx, cy, cz) = (x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1));
                    *slot = cx + P * (cy + P * cz);
                    let steps = padded.steps[*slot];
                    if steps == NO_TSDF_STEPS {
                        complete = false;
                        break;
                    }
                    case |= ((steps < 0) as usize) << c;
                }
                if !complete || case == 0 || case == 255 {
                    continue;
                }
                let corners: [TsdfVoxel; 8] = slots.map(|k| padded.voxels[k].0);
                let labels: [u16; 8] = slots.map(|k| padded.voxels[k].1);
                let cube = [x, y, z];
                for tri in &table[case] {
                    let triangle = tri.map(|e| {
                        let (a, b) = EDGES[e as usize];
                        // Every edge runs from its lower corner `a` along one axis.
                        let axis = e as usize / 4;
                        let low = [
                            cube[0] + (a & 1),
                            cube[1] + ((a >> 1) & 1),
                            cube[2] + ((a >> 2) & 1),
                        ];
                        let slot = (low[0] + P * (low[1] + P * low[2])) * 3 + axis;
                        if vertex_of_edge[slot] == u32::MAX {
                            vertex_of_edge[slot] = mesh.vertices.len() as u32;
                            push_vertex(
                                &mut mesh, &corners, &labels, a, b, base, low, axis, voxel_size,
                            );
                        }
                        vertex_of_edge[slot]
                    });
                    mesh.triangles.push(triangle);
                }
            }
        }
    }
    mesh
}

/// Adds the vertex where the surface crosses the edge between cube corners `a` and `b`
/// (lower corner at block-local voxel `low`, running along `axis`).
#[allow(clippy::too_many_arguments)]
fn push_vertex(
    mesh: &mut BlockMesh,
    corners: &[TsdfVoxel; 8],
    labels: &[u16; 8],
    a: usize,
    b: usize,
    base: [i32; 3],
    low: [usize; 3],
    axis: usize,
    voxel_size: f64,
) {
    let (da, db) = (corners[a].tsdf() as f64, corners[b].tsdf() as f64);
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
    mesh.instances
        .push(if t < 0.5 { labels[a] } else { labels[b] });
    let (ca, cb) = (corners[a].color(), corners[b].color());
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
