use std::collections::BTreeMap;

use nalgebra::{Point3, Vector3};

/// An indexed triangle mesh. Per-vertex attributes are optional: each attribute vector is
/// either empty or holds one entry per vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f32; 3]>,
    /// Counter-clockwise seen from outside (the side the normals point to).
    pub triangles: Vec<[u32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 3]>,
    /// Map (or ground-truth) instance per vertex, 0 = none.
    pub instances: Vec<u16>,
}

/// Why a mesh's arrays do not fit together.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MeshError {
    /// A per-vertex attribute with neither zero nor one entry per vertex.
    AttributeLength {
        attribute: &'static str,
        found: usize,
        vertices: usize,
    },
    /// A triangle that names a vertex that does not exist.
    IndexOutOfRange { triangle: usize, index: u32 },
}

impl std::fmt::Display for MeshError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::AttributeLength {
                attribute,
                found,
                vertices,
            } => write!(
                f,
                "{found} {attribute} for {vertices} vertices (expected none or one per vertex)"
            ),
            Self::IndexOutOfRange { triangle, index } => {
                write!(
                    f,
                    "triangle {triangle} names vertex {index}, which does not exist"
                )
            }
        }
    }
}

impl std::error::Error for MeshError {}

/// A vertex normal from the sum of its triangles' area-weighted normals: that sum scaled to
/// unit length, or zero where the triangles cancel (or have no area).
pub fn unit_normal(sum: [f32; 3]) -> [f32; 3] {
    let v = Vector3::from(sum);
    let len = v.norm();
    if len > 0.0 {
        (v / len).into()
    } else {
        [0.0; 3]
    }
}

/// Adds each triangle's area-weighted normal to the `sums` of its three corners. The cross
/// product of two edges is twice the area long: the weighting comes for free.
pub fn add_triangle_normals(vertices: &[[f32; 3]], triangles: &[[u32; 3]], sums: &mut [[f32; 3]]) {
    for t in triangles {
        let [a, b, c] = t.map(|i| Vector3::from(vertices[i as usize]));
        let n: Vector3<f32> = (b - a).cross(&(c - a));
        for &i in t {
            let sum = &mut sums[i as usize];
            *sum = [sum[0] + n.x, sum[1] + n.y, sum[2] + n.z];
        }
    }
}

impl Mesh {
    /// Checks attribute lengths and triangle indices.
    pub fn check(&self) -> Result<(), MeshError> {
        let n = self.vertices.len();
        for (attribute, found) in [
            ("normals", self.normals.len()),
            ("colours", self.colors.len()),
            ("instances", self.instances.len()),
        ] {
            if found != 0 && found != n {
                return Err(MeshError::AttributeLength {
                    attribute,
                    found,
                    vertices: n,
                });
            }
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange { triangle: t, index });
            }
        }
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    fn point(&self, i: u32) -> Point3<f64> {
        Point3::from(self.vertices[i as usize].map(f64::from))
    }

    /// The triangles as corner points.
    pub fn triangle_points(&self) -> Vec<[Point3<f64>; 3]> {
        self.triangles
            .iter()
            .map(|t| t.map(|i| self.point(i)))
            .collect()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.point(i));
                (b - a).cross(&(c - a)).norm() / 2.0
            })
            .sum()
    }

    /// Sets each vertex normal to the area-weighted mean of its triangles' normals (the
    /// smooth shading viewers expect of a welded mesh), summed in f32 like the vertices.
    pub fn compute_normals(&mut self) {
        // Summed in place, in f32: a vertex has a handful of triangles, and a second,
        // f64 array the size of the mesh costs more in fresh memory than it gains.
        let mut normals = std::mem::take(&mut self.normals);
        normals.clear();
        normals.resize(self.vertices.len(), [0.0; 3]);
        add_triangle_normals(&self.vertices, &self.triangles, &mut normals);
        for n in &mut normals {
            *n = unit_normal(*n);
        }
        self.normals = normals;
    }

    /// Appends `other`, renumbering its triangles. Attributes present in only one of the two
    /// are dropped (a mixed mesh would be inconsistent).
    pub fn append(&mut self, other: &Mesh) {
        let offset = self.vertices.len() as u32;
        let keep = |mine: bool, theirs: bool| (mine || offset == 0) && theirs;
        let (normals, colors, instances) = (
            keep(!self.normals.is_empty(), !other.normals.is_empty()),
            keep(!self.colors.is_empty(), !other.colors.is_empty()),
            keep(!self.instances.is_empty(), !other.instances.is_empty()),
        );
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + offset)));
        if normals {
            self.normals.extend_from_slice(&other.normals);
        } else {
            self.normals.clear();
        }
        if colors {
            self.colors.extend_from_slice(&other.colors);
        } else {
            self.colors.clear();
        }
        if instances {
            self.instances.extend_from_slice(&other.instances);
        } else {
            self.instances.clear();
        }
    }

    /// The same mesh with every vertex coloured by `color(instance)` (grey without instances).
    pub fn colored_by(&self, color: impl Fn(u16) -> [u8; 3]) -> Mesh {
        let colors = if self.instances.is_empty() {
            vec![color(0); self.vertices.len()]
        } else {
            self.instances.iter().map(|&i| color(i)).collect()
        };
        Mesh {
            colors,
            ..self.clone()
        }
    }

    /// One mesh per instance: a triangle belongs to the instance at least two of its corners
    /// carry (else its first corner's); instance 0 is left out. Only the vertices a part uses
    /// are kept.
    pub fn split_by_instance(&self) -> BTreeMap<u16, Mesh> {
        let mut out: BTreeMap<u16, (Mesh, Vec<u32>)> = BTreeMap::new();
        if self.instances.is_empty() {
            return BTreeMap::new();
        }
        for t in &self.triangles {
            let ids = t.map(|i| self.instances[i as usize]);
            let id = if ids[1] == ids[2] { ids[1] } else { ids[0] };
            if id == 0 {
                continue;
            }
            let (part, new_index) = out
                .entry(id)
                .or_insert_with(|| (Mesh::default(), vec![u32::MAX; self.vertices.len()]));
            let tri = t.map(|i| {
                let slot = &mut new_index[i as usize];
                if *slot == u32::MAX {
                    *slot = part.vertices.len() as u32;
                    let i = i as usize;
                    part.vertices.push(self.vertices[i]);
                    if !self.normals.is_empty() {
                        part.normals.push(self.normals[i]);
                    }
                    if !self.colors.is_empty() {
                        part.colors.push(self.colors[i]);
                    }
                    part.instances.push(self.instances[i]);
                }
                *slot
            });
            part.triangles.push(tri);
        }
        out.into_iter().map(|(id, (m, _))| (id, m)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing an edge: a unit square in the z = 0 plane, facing +z.
    fn square() -> Mesh {
        Mesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            instances: vec![1, 1, 2, 2],
            ..Mesh::default()
        }
    }

    #[test]
    fn normals_of_a_flat_square_point_up() {
        let mut m = square();
        m.compute_normals();
        assert!(m.normals.iter().all(|n| *n == [0.0, 0.0, 1.0]));
        assert!((m.area() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn split_keeps_only_used_vertices() {
        let parts = square().split_by_instance();
        // Triangle [0,1,2] carries ids [1,1,2] → 1; [0,2,3] carries [1,2,2] → 2.
        assert_eq!(parts.len(), 2);
        assert_eq!(parts[&1].vertices.len(), 3);
        assert_eq!(parts[&2].triangles, vec![[0, 1, 2]]);
        assert!(parts[&2].check().is_ok());
    }

    #[test]
    fn append_renumbers_and_check_catches_bad_indices() {
        let mut m = square();
        m.append(&square());
        assert_eq!(m.triangles[2], [4, 5, 6]);
        assert!(m.check().is_ok());
        m.triangles.push([0, 1, 99]);
        assert_eq!(
            m.check(),
            Err(MeshError::IndexOutOfRange {
                triangle: 4,
                index: 99
            })
        );
    }
}
