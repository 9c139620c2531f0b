use std::io::Write;
use std::path::Path;

use voxpan_core::nalgebra::{Point3, Vector3};

use crate::{Scene, Shape};

/// A triangle mesh whose vertices carry an instance id.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f32; 3]>,
    pub instances: Vec<u16>,
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    fn vertex(&mut self, p: Point3<f64>, id: u16) -> u32 {
        self.vertices.push([p.x as f32, p.y as f32, p.z as f32]);
        self.instances.push(id);
        (self.vertices.len() - 1) as u32
    }

    /// The triangles as corner points.
    pub fn triangle_points(&self) -> Vec<[Point3<f64>; 3]> {
        self.triangles
            .iter()
            .map(|t| t.map(|i| Point3::from(self.vertices[i as usize].map(f64::from))))
            .collect()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let p = t.map(|i| Vector3::from(self.vertices[i as usize].map(f64::from)));
                (p[1] - p[0]).cross(&(p[2] - p[0])).norm() / 2.0
            })
            .sum()
    }
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
            let v: Vec<u32> = (0..8).map(|i| mesh.vertex(corner(i), id)).collect();
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
                        mesh.vertex(
                            base + Vector3::new(radius * a.cos(), radius * a.sin(), z),
                            id,
                        )
                    })
                    .collect()
            };
            let (bottom, top) = (ring(0.0, mesh), ring(*height, mesh));
            let (cb, ct) = (
                mesh.vertex(*base, id),
                mesh.vertex(base + Vector3::new(0.0, 0.0, *height), id),
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
                    idx.push(mesh.vertex(p, id));
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

/// Reads a PLY written by [`write_ply`] (this exact layout; anything else is an error).
pub fn read_ply(path: &Path) -> std::io::Result<Mesh> {
    let bad = |m: &str| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{}: {m}", path.display()),
        )
    };
    let bytes = std::fs::read(path)?;
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| bad("no PLY header"))?
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("header is not text"))?;
    let count = |element: &str| -> std::io::Result<usize> {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("element {element} ")))
            .and_then(|n| n.trim().parse().ok())
            .ok_or_else(|| bad(&format!("no element {element}")))
    };
    if !header.contains("property ushort instance") || !header.contains("binary_little_endian") {
        return Err(bad("not a voxpan ground-truth mesh"));
    }
    let (nv, nf) = (count("vertex")?, count("face")?);
    let body = &bytes[end..];
    if body.len() != nv * 14 + nf * 13 {
        return Err(bad("size does not match the header"));
    }
    let mut mesh = Mesh::default();
    for v in body[..nv * 14].chunks_exact(14) {
        let f = |a: usize| f32::from_le_bytes(v[a..a + 4].try_into().expect("4 bytes"));
        mesh.vertices.push([f(0), f(4), f(8)]);
        mesh.instances.push(u16::from_le_bytes([v[12], v[13]]));
    }
    for t in body[nv * 14..].chunks_exact(13) {
        if t[0] != 3 {
            return Err(bad("only triangles are expected"));
        }
        let i = |a: usize| u32::from_le_bytes(t[a..a + 4].try_into().expect("4 bytes"));
        let tri = [i(1), i(5), i(9)];
        if tri.iter().any(|&k| k as usize >= nv) {
            return Err(bad("face index out of range"));
        }
        mesh.triangles.push(tri);
    }
    Ok(mesh)
}

/// Writes a binary little-endian PLY: float x, y, z and ushort `instance` per vertex.
pub fn write_ply(path: &Path, mesh: &Mesh) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment voxpan synthetic ground truth\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property ushort instance\nelement face {}\nproperty list uchar uint vertex_indices\n\
         end_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for (v, id) in mesh.vertices.iter().zip(&mesh.instances) {
        for c in v {
            out.write_all(&c.to_le_bytes())?;
        }
        out.write_all(&id.to_le_bytes())?;
    }
    for t in &mesh.triangles {
        out.write_all(&[3u8])?;
        for i in t {
            out.write_all(&i.to_le_bytes())?;
        }
    }
    out.flush()
}
