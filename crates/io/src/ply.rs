//! PLY meshes: one writer and one reader for every mesh voxpan handles (map meshes, per-instance
//! meshes, the synthetic world's ground truth).
//!
//! Written as binary little-endian with `x y z` and, when present, `nx ny nz`, `red green
//! blue` and `instance` (ushort) per vertex and `vertex_indices` per face: the names Open3D,
//! trimesh, MeshLab and Blender read. Reading accepts any PLY (ASCII or binary, either byte
//! order, any scalar types) through `ply-rs-bw`.

use std::io::{BufReader, Write};
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{BeginList, Property, PropertyAccess, PropertyAccessResult};
use voxpan_core::Mesh;

use crate::{IoError, write_atomically};

/// Writes `mesh` as a binary PLY, atomically (a temporary file renamed into place, so a crash
/// never leaves a half-written mesh). `comment` goes into the header.
pub fn write_ply(path: &Path, mesh: &Mesh, comment: &str) -> Result<(), IoError> {
    mesh.check()
        .map_err(|e| IoError::format(path, format!("cannot write mesh: {e}")))?;
    write_atomically(path, |out| write_ply_to(out, mesh, comment))
}

/// Writes `mesh` as a binary PLY into any writer.
pub fn write_ply_to(out: &mut dyn Write, mesh: &Mesh, comment: &str) -> std::io::Result<()> {
    let (normals, colors, instances) = (
        !mesh.normals.is_empty(),
        !mesh.colors.is_empty(),
        !mesh.instances.is_empty(),
    );
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment {}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n",
        comment.replace('\n', " "),
        mesh.vertices.len()
    );
    if normals {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if colors {
        header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    }
    if instances {
        header += "property ushort instance\n";
    }
    header += &format!(
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.triangles.len()
    );
    out.write_all(header.as_bytes())?;
    let mut record = Vec::with_capacity(32);
    for i in 0..mesh.vertices.len() {
        record.clear();
        record.extend(mesh.vertices[i].iter().flat_map(|c| c.to_le_bytes()));
        if normals {
            record.extend(mesh.normals[i].iter().flat_map(|c| c.to_le_bytes()));
        }
        if colors {
            record.extend_from_slice(&mesh.colors[i]);
        }
        if instances {
            record.extend_from_slice(&mesh.instances[i].to_le_bytes());
        }
        out.write_all(&record)?;
    }
    for t in &mesh.triangles {
        record.clear();
        record.push(3);
        record.extend(t.iter().flat_map(|i| i.to_le_bytes()));
        out.write_all(&record)?;
    }
    out.flush()
}

/// One vertex as read: position plus whatever optional properties the file has.
#[derive(Default)]
struct Vertex {
    position: [f32; 3],
    normal: [f32; 3],
    color: [u8; 3],
    instance: u16,
    has: [bool; 3],
}

fn as_f32(p: &Property) -> Option<f32> {
    match *p {
        Property::Float(v) => Some(v),
        Property::Double(v) => Some(v as f32),
        Property::Char(v) => Some(v as f32),
        Property::UChar(v) => Some(v as f32),
        Property::Short(v) => Some(v as f32),
        Property::UShort(v) => Some(v as f32),
        Property::Int(v) => Some(v as f32),
        Property::UInt(v) => Some(v as f32),
        _ => None,
    }
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let Some(v) = as_f32(&property) else {
            return PropertyAccessResult::Ignored;
        };
        match name {
            "x" => self.position[0] = v,
            "y" => self.position[1] = v,
            "z" => self.position[2] = v,
            "nx" | "ny" | "nz" => {
                self.normal[(name.as_bytes()[1] - b'x') as usize] = v;
                self.has[0] = true;
            }
            "red" | "green" | "blue" => {
                let k = ["red", "green", "blue"].iter().position(|c| *c == name);
                // Float colours (0..1) are scaled; integer ones taken as they are.
                let byte = match property {
                    Property::Float(_) | Property::Double(_) => (v * 255.0).round(),
                    _ => v,
                };
                self.color[k.unwrap_or(0)] = byte.clamp(0.0, 255.0) as u8;
                self.has[1] = true;
            }
            "instance" => {
                self.instance = v.clamp(0.0, u16::MAX as f32) as u16;
                self.has[2] = true;
            }
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

/// One face as read (any index type; converted to `u32` afterwards).
#[derive(Default)]
struct Face {
    indices: Vec<i64>,
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if name != "vertex_indices" && name != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        self.indices = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }

    fn begin_list_uint(&mut self, _name: &str, _len: usize) -> BeginList<'_, u32> {
        BeginList::UseSetter
    }

    fn begin_list_int(&mut self, _name: &str, _len: usize) -> BeginList<'_, i32> {
        BeginList::UseSetter
    }
}

/// Reads a triangle mesh (polygons are fan-triangulated). Errors name the file.
pub fn read_ply(path: &Path) -> Result<Mesh, IoError> {
    let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let mut reader = Reader::new(BufReader::new(file));
    let bad = |e: &dyn std::fmt::Display| IoError::format(path, format!("not a readable PLY: {e}"));
    let header = Parser::<Vertex>::new()
        .read_header(&mut reader)
        .map_err(|e| bad(&e))?;
    let mut mesh = Mesh::default();
    let mut faces: Vec<Face> = Vec::new();
    let mut has = [false; 3];
    for element in header.elements.values() {
        match element.name.as_str() {
            "vertex" => {
                let vertices = Parser::<Vertex>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| bad(&e))?;
                has = vertices.first().map_or([false; 3], |v| v.has);
                for v in vertices {
                    mesh.vertices.push(v.position);
                    if has[0] {
                        mesh.normals.push(v.normal);
                    }
                    if has[1] {
                        mesh.colors.push(v.color);
                    }
                    if has[2] {
                        mesh.instances.push(v.instance);
                    }
                }
            }
            "face" => {
                faces = Parser::<Face>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| bad(&e))?;
            }
            // Other elements (edges, materials) are read past and ignored.
            _ => {
                Parser::<Face>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| bad(&e))?;
            }
        }
    }
    let n = mesh.vertices.len() as i64;
    for (k, face) in faces.iter().enumerate() {
        if let Some(&i) = face.indices.iter().find(|&&i| i < 0 || i >= n) {
            return Err(IoError::format(
                path,
                format!("face {k} names vertex {i}, but there are {n} vertices"),
            ));
        }
        for j in 1..face.indices.len().saturating_sub(1) {
            mesh.triangles.push([
                face.indices[0] as u32,
                face.indices[j] as u32,
                face.indices[j + 1] as u32,
            ]);
        }
    }
    let _ = has;
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh() -> Mesh {
        let mut m = Mesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.5],
                [0.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            colors: vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [7, 8, 9]],
            instances: vec![1, 1, 2, 65535],
            ..Mesh::default()
        };
        m.compute_normals();
        m
    }

    #[test]
    fn binary_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        write_ply(&path, &mesh(), "test").unwrap();
        assert_eq!(read_ply(&path).unwrap(), mesh());
        // Without optional attributes, none come back.
        let bare = Mesh {
            vertices: mesh().vertices,
            triangles: mesh().triangles,
            ..Mesh::default()
        };
        write_ply(&path, &bare, "bare").unwrap();
        assert_eq!(read_ply(&path).unwrap(), bare);
    }

    #[test]
    fn ascii_quads_are_triangulated_and_bad_indices_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("q.ply");
        let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\n\
                    property double y\nproperty double z\nelement face 1\n\
                    property list uchar int vertex_index\nend_header\n\
                    0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        std::fs::write(&path, text).unwrap();
        let m = read_ply(&path).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        std::fs::write(&path, text.replace("4 0 1 2 3", "3 0 1 9")).unwrap();
        let e = read_ply(&path).unwrap_err().to_string();
        assert!(e.contains("q.ply") && e.contains("vertex 9"), "{e}");
        std::fs::write(&path, "not a ply").unwrap();
        assert!(read_ply(&path).unwrap_err().to_string().contains("q.ply"));
    }
}
