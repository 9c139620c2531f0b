//! Marching cubes on exact distance fields.

use std::collections::HashMap;

use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_map::{mesh_block, Block, Layer, MeshLayer, TsdfVoxel, VOXELS_PER_BLOCK};

/// A layer holding the exact (truncated) signed distance of a sphere, in every block that the
/// band touches; positive outside, as integration makes it.
fn sphere_layer(center: Point3<f64>, r: f64, voxel: f64) -> Layer {
    let mut layer = Layer::new(voxel);
    let trunc = 3.0 * voxel;
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
                    if d.abs() <= trunc {
                        block.voxels[i] = TsdfVoxel::new(d as f32, 1.0, [10, 200, 30]);
                        any = true;
                    } else {
                        // Far voxels are observed too (truncated), as in a fused map.
                        block.voxels[i] =
                            TsdfVoxel::new(d.clamp(-trunc, trunc) as f32, 1.0, [10, 200, 30]);
                    }
                }
                if any {
                    block.updated = true;
                    layer.blocks.insert(index, block);
                }
            }
        }
    }
    layer
}

#[test]
fn a_sphere_mesh_has_the_right_area_and_lies_on_the_surface() {
    let (c, r, voxel) = (Point3::new(0.13, -0.27, 1.05), 0.5, 0.02);
    let mut layer = sphere_layer(c, r, voxel);
    let mut meshes = MeshLayer::default();
    meshes.update(&mut layer);
    let mesh = meshes.combined();
    let area = mesh.area();
    let expected = 4.0 * std::f64::consts::PI * r * r;
    assert!(
        (area / expected - 1.0).abs() < 0.02,
        "area {area} vs {expected}"
    );
    for v in &mesh.vertices {
        let p = Point3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        assert!(((p - c).norm() - r).abs() < 0.1 * voxel);
    }
    // Outward normals.
    for t in mesh.vertices.chunks_exact(3) {
        let p = |i: usize| Vector3::new(t[i][0] as f64, t[i][1] as f64, t[i][2] as f64);
        let n = (p(1) - p(0)).cross(&(p(2) - p(0)));
        if n.norm() > 1e-12 {
            assert!(n.dot(&(p(0) - c.coords)) > 0.0, "inward-facing triangle");
        }
    }
    assert!(mesh.colors.iter().all(|&c| c == [10, 200, 30]));
}

#[test]
fn the_sphere_mesh_is_watertight_across_block_seams() {
    let mut layer = sphere_layer(Point3::new(0.0, 0.0, 0.0), 0.3, 0.02);
    let mut meshes = MeshLayer::default();
    meshes.update(&mut layer);
    let mesh = meshes.combined();
    // Every edge (by quantised endpoints) is shared by exactly two triangles.
    let key = |v: &[f32; 3]| v.map(|x| (x * 1e5).round() as i64);
    let mut edges: HashMap<([i64; 3], [i64; 3]), usize> = HashMap::new();
    for t in mesh.vertices.chunks_exact(3) {
        for (a, b) in [(0, 1), (1, 2), (2, 0)] {
            let (ka, kb) = (key(&t[a]), key(&t[b]));
            if ka == kb {
                continue; // degenerate edge of a zero-area triangle
            }
            *edges
                .entry(if ka < kb { (ka, kb) } else { (kb, ka) })
                .or_default() += 1;
        }
    }
    let open = edges.values().filter(|&&n| n != 2).count();
    assert_eq!(
        open,
        0,
        "{open} of {} edges are not shared by two triangles",
        edges.len()
    );
}

#[test]
fn incremental_meshing_equals_full_meshing() {
    let mut layer = sphere_layer(Point3::new(0.05, 0.0, 0.0), 0.3, 0.02);
    let mut meshes = MeshLayer::default();
    meshes.update(&mut layer);
    assert_eq!(
        meshes.update(&mut layer),
        0,
        "nothing changed, nothing re-meshed"
    );
    // Change one block: only it and its lower neighbours are re-meshed.
    let index = *layer.blocks.keys().next().unwrap();
    let block = layer.blocks.get_mut(&index).unwrap();
    for v in block.voxels.iter_mut() {
        v.distance = -v.distance;
    }
    block.updated = true;
    let remeshed = meshes.update(&mut layer);
    assert!((1..=8).contains(&remeshed));
    for (i, m) in &meshes.blocks {
        assert_eq!(*m, mesh_block(&layer, *i), "block {i:?}");
    }
}
