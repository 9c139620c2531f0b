use voxpan_core::Mesh;
use voxpan_core::nalgebra::{Point3, Vector3};

use crate::{Scene, Shape};

/// Adds a vertex carrying instance `id`; returns its index.
fn vertex(mesh: &mut Mesh, p: Point3<f64>, id: u16) -> u32 {
    mesh.vertices.push([p.x as f32, p.y as f32, p.z as f32]);
    mesh.instances.push(id);
    (mesh.vertices.len() - 1) as u32
}

const SEGMENTS: usize = 24;

/// The ground-truth surface of every object, triangulated.
pub fn scene_mesh(scene: &Scene) -> Mesh {
    let mut mesh = Mesh::default();
    for object in &scene.objects {
        for shape in &object.shapes {
            add_shape(&mut mesh, shape, object.instance_id);
        }
    }
    mesh
}

fn add_shape(mesh: &mut Mesh, shape: &Shape, id: u16) {
    match shape {
        Shape::Cuboid { center, half, yaw } => {
            let (s, c) = yaw.sin_cos();
            let corner = |i: usize| {
                let l = Vector3::new(
                    if i & 1 == 0 { -half.x } else { half.x },
                    if i & 2 == 0 { -half.y } else { half.y },
                    if i & 4 == 0 { -half.z } else { half.z },
                );
                center + Vector3::new(c * l.x - s * l.y, s * l.x + c * l.y, l.z)
            };
            let v: Vec<u32> = (0..8).map(|i| vertex(mesh, corner(i), id)).collect();
            // Faces as quads of corner indices, wound outwards.
            for q in [
                [0, 2, 3, 1],
                [4, 5, 7, 6],
                [0, 1, 5, 4],
                [2, 6, 7, 3],
                [0, 4, 6, 2],
                [1, 3, 7, 5],
            ] {
                mesh.triangles.push([v[q[0]], v[q[1]], v[q[2]]]);
                mesh.triangles.push([v[q[0]], v[q[2]], v[q[3]]]);
            }
        }
        Shape::Cylinder {
            base,
            radius,
            height,
        } => {
            let ring = |z: f64, mesh: &mut Mesh| -> Vec<u32> {
                (0..SEGMENTS)
                    .map(|k| {
                        let a = std::f64::consts::TAU * k as f64 / SEGMENTS as f64;
                        vertex(
                            mesh,
                            base + Vector3::new(radius * a.cos(), radius * a.sin(), z),
                            id,
                        )
                    })
                    .collect()
            };
            let (bottom, top) = (ring(0.0, mesh), ring(*height, mesh));
            let (cb, ct) = (
                vertex(mesh, *base, id),
                vertex(mesh, base + Vector3::new(0.0, 0.0, *height), id),
            );
            for k in 0..SEGMENTS {
                let n = (k + 1) % SEGMENTS;
                mesh.triangles.push([bottom[k], bottom[n], top[n]]);
                mesh.triangles.push([bottom[k], top[n], top[k]]);
                mesh.triangles.push([cb, bottom[n], bottom[k]]);
                mesh.triangles.push([ct, top[k], top[n]]);
            }
        }
        Shape::Sphere { center, radius } => {
            let (rings, segs) = (SEGMENTS / 2, SEGMENTS);
            let mut idx = Vec::new();
            for i in 0..=rings {
                let phi = std::f64::consts::PI * i as f64 / rings as f64;
                for k in 0..segs {
                    let a = std::f64::consts::TAU * k as f64 / segs as f64;
                    let p = center
                        + Vector3::new(phi.sin() * a.cos(), phi.sin() * a.sin(), phi.cos())
                            * *radius;
                    idx.push(vertex(mesh, p, id));
                }
            }
            for i in 0..rings {
                for k in 0..segs {
                    let n = (k + 1) % segs;
                    let (a, b, c, d) = (
                        idx[i * segs + k],
                        idx[i * segs + n],
                        idx[(i + 1) * segs + n],
                        idx[(i + 1) * segs + k],
                    );
                    mesh.triangles.push([a, d, c]);
                    mesh.triangles.push([a, c, b]);
                }
            }
        }
    }
}
