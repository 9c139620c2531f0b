//! Marching cubes on exact distance fields: area, surface, orientation, welding, seams and
//! incremental updates.

use std::collections::HashMap;

use voxpan_core::nalgebra::{Point3, Vector3};

use super::{MeshLayer, mesh_block};
use crate::layer::{Block, Layer, VOXELS_PER_BLOCK};

/// A layer holding the exact (truncated) signed distance of a sphere, in every block that the
/// band touches; positive outside, as integration makes it.
pub(crate) fn sphere_layer(center: Point3<f64>, r: f64, voxel: f64) -> Layer {
    sphere_layer_banded(center, r, voxel, 3.0)
}

/// [`sphere_layer`] with a truncation band of `truncation_voxels`.
pub(crate) fn sphere_layer_banded(
    center: Point3<f64>,
    r: f64,
    voxel: f64,
    truncation_voxels: f64,
) -> Layer {
    let trunc = truncation_voxels * voxel;
    let mut layer = Layer::new(voxel, trunc);
    let reach = ((r + trunc) / layer.block_size()).ceil() as i32 + 1;
    let cb = layer.block_index(&center);
    for bx in -reach..=reach {
        for by in -reach..=reach {
            for bz in -reach..=reach {
                let index = [cb[0] + bx, cb[1] + by, cb[2] + bz];
                let mut block = Block::default();
                let mut any = false;
                for i in 0..VOXELS_PER_BLOCK {
                    let d = (Block::voxel_center(index, i, voxel) - center).norm() - r;
                    any |= d.abs() <= trunc;
                    // Far voxels are observed too (truncated), as in a fused map.
                    block
                        .voxels
                        .set(i, layer.voxel(d as f32, 1.0, [10, 200, 30]));
                }
                if any {
                    layer.insert(index, block);
                }
            }
        }
    }
    layer
}

fn full_mesh(layer: &Layer) -> voxpan_core::Mesh {
    let mut meshes = MeshLayer::default();
    meshes.update(layer, &layer.sorted_indices());
    meshes.combined()
}

#[test]
fn a_sphere_mesh_has_the_right_area_and_lies_on_the_surface() {
    let (c, r, voxel) = (Point3::new(0.13, -0.27, 1.05), 0.5, 0.02);
    let mesh = full_mesh(&sphere_layer(c, r, voxel));
    assert!(mesh.check().is_ok());
    let expected = 4.0 * std::f64::consts::PI * r * r;
    assert!(
        (mesh.area() / expected - 1.0).abs() < 0.02,
        "area {} vs {expected}",
        mesh.area()
    );
    for v in &mesh.vertices {
        let p = Point3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        assert!(((p - c).norm() - r).abs() < 0.1 * voxel);
    }
    // Triangles and vertex normals face outwards, the normals within a few degrees of the
    // true ones.
    for t in &mesh.triangles {
        let p = t.map(|i| Vector3::from(mesh.vertices[i as usize].map(f64::from)));
        let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
        if n.norm() > 1e-12 {
            assert!(n.dot(&(p[0] - c.coords)) > 0.0, "inward-facing triangle");
        }
    }
    for (v, n) in mesh.vertices.iter().zip(&mesh.normals) {
        let radial = (Vector3::from(v.map(f64::from)) - c.coords).normalize();
        let n = Vector3::from(n.map(f64::from));
        assert!(n.dot(&radial) > 0.99, "normal {n:?} at {v:?}");
    }
    assert!(mesh.colors.iter().all(|&c| c == [10, 200, 30]));
}

#[test]
fn the_welded_sphere_is_closed_across_block_seams() {
    let mesh = full_mesh(&sphere_layer(Point3::new(0.0, 0.0, 0.0), 0.3, 0.02));
    // Welded: every edge (by vertex index) is shared by exactly two triangles, and no two
    // vertices sit at the same place.
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for t in &mesh.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            if a != b {
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
    }
    let open = edges.values().filter(|&&n| n != 2).count();
    assert_eq!(
        open,
        0,
        "{open} of {} edges are not shared by two triangles",
        edges.len()
    );
    let mut positions: Vec<[u32; 3]> = mesh.vertices.iter().map(|v| v.map(f32::to_bits)).collect();
    positions.sort_unstable();
    positions.dedup();
    assert_eq!(positions.len(), mesh.vertices.len(), "duplicate vertices");
    // Euler characteristic of a sphere: V - E + F = 2.
    let euler = mesh.vertices.len() as i64 - edges.len() as i64 + mesh.triangles.len() as i64;
    assert_eq!(euler, 2);
}

#[test]
fn incremental_meshing_equals_full_meshing() {
    let mut layer = sphere_layer(Point3::new(0.05, 0.0, 0.0), 0.3, 0.02);
    let mut meshes = MeshLayer::default();
    meshes.update(&layer, &layer.sorted_indices());
    assert!(
        meshes.update(&layer, &[]).is_empty(),
        "nothing changed, nothing re-meshed"
    );
    // Change one block: only it and its lower neighbours are re-meshed.
    let index = layer.sorted_indices()[7];
    let (block, _) = layer.get_or_allocate(index);
    for i in 0..block.voxels.len() {
        let mut v = block.voxels.get(i);
        v.set_tsdf(-v.tsdf());
        block.voxels.set(i, v);
    }
    let remeshed = meshes.update(&layer, &[index]);
    assert!((1..=8).contains(&remeshed.len()));
    for i in layer.sorted_indices() {
        let fresh = mesh_block(&layer, i);
        match meshes.get(&i) {
            Some(m) => assert_eq!(*m, fresh, "block {i:?}"),
            None => assert!(fresh.triangles.is_empty(), "block {i:?}"),
        }
    }
    let mut fresh = MeshLayer::default();
    fresh.update(&layer, &layer.sorted_indices());
    assert_eq!(meshes.combined(), fresh.combined());
}

/// The welded mesh as a plain serial weld makes it: blocks in index order, each vertex
/// appended unless a seam vertex on the same edge came before.
fn serial_weld(meshes: &MeshLayer) -> voxpan_core::Mesh {
    let mut keys: Vec<_> = meshes.blocks.keys().copied().collect();
    keys.sort_unstable();
    let mut first_on_edge = HashMap::new();
    let mut mesh = voxpan_core::Mesh::default();
    for key in keys {
        let block = &meshes.blocks[&key];
        let edge_of: HashMap<u32, _> = block.seams.iter().copied().collect();
        let mut index_of = Vec::new();
        for (local, vertex) in block.vertices.iter().enumerate() {
            let edge = edge_of.get(&(local as u32));
            let index = match edge.and_then(|e| first_on_edge.get(e)) {
                Some(&earlier) => earlier,
                None => {
                    let index = mesh.vertices.len() as u32;
                    mesh.vertices.push(*vertex);
                    mesh.colors.push(block.colors[local]);
                    mesh.instances.push(block.instances[local]);
                    if let Some(&e) = edge {
                        first_on_edge.insert(e, index);
                    }
                    index
                }
            };
            index_of.push(index);
        }
        let renumbered = block
            .triangles
            .iter()
            .map(|t| t.map(|j| index_of[j as usize]));
        mesh.triangles.extend(renumbered);
    }
    mesh.compute_normals();
    mesh
}

#[test]
fn the_parallel_weld_equals_a_serial_one() {
    // Two spheres with empty x-slabs between them (the seam tables restart), one sphere big
    // enough to span several slabs.
    let mut layer = sphere_layer(Point3::new(0.01, 0.02, -0.03), 0.35, 0.02);
    let far = sphere_layer(Point3::new(1.5, 0.0, 0.0), 0.2, 0.02);
    for (index, block) in far.iter() {
        assert!(layer.get(index).is_none());
        layer.insert(*index, block.clone());
    }
    let mut meshes = MeshLayer::default();
    meshes.update(&layer, &layer.sorted_indices());
    let (welded, reference) = (meshes.combined(), serial_weld(&meshes));
    assert!(welded.vertices.len() > 1000);
    assert_eq!(welded.vertices, reference.vertices);
    assert_eq!(welded.triangles, reference.triangles);
    assert_eq!(welded.colors, reference.colors);
    assert_eq!(welded.instances, reference.instances);
    // Normals are summed per block, seam vertices' across blocks: the same up to rounding.
    for (i, (a, b)) in welded.normals.iter().zip(&reference.normals).enumerate() {
        let (a, b) = (Vector3::from(*a), Vector3::from(*b));
        assert!((a - b).norm() < 1e-5, "vertex {i}: {a:?} vs {b:?}");
    }
}
