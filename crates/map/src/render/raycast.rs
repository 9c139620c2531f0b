use rayon::prelude::*;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{ColorImage, DepthImage, Image, Intrinsics, LabelImage, Pose};

use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, TsdfVoxel, VoxelIndex};

/// What a camera sees of the map. Pixels whose ray meets no surface have depth 0, colour
/// black, instance 0 and a zero normal.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedView {
    /// Planar depth (along the optical axis), metres.
    pub depth: DepthImage,
    pub color: ColorImage,
    /// Map instance of the surface (0 = none).
    pub instances: LabelImage,
    /// Unit surface normal in the world frame, facing the camera.
    pub normals: Image<[f32; 3]>,
}

/// Where along each ray to look: distances from the camera centre, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RaySpan {
    pub near: f64,
    pub far: f64,
}

/// Voxel look-ups along a ray, remembering the last block (consecutive samples mostly fall
/// into the same block, so most look-ups skip the hash map).
struct Lookup<'a> {
    layer: &'a Layer,
    last: Option<(BlockIndex, Option<&'a Block>)>,
}

impl<'a> Lookup<'a> {
    fn new(layer: &'a Layer) -> Self {
        Self { layer, last: None }
    }

    fn block(&mut self, index: BlockIndex) -> Option<&'a Block> {
        match self.last {
            Some((i, b)) if i == index => b,
            _ => {
                let b = self.layer.get(&index);
                self.last = Some((index, b));
                b
            }
        }
    }

    /// The observed voxel `v` and its label, if any.
    fn voxel(&mut self, v: VoxelIndex) -> Option<(&'a TsdfVoxel, u16)> {
        let side = BLOCK_SIDE as i32;
        let block = self.block(v.map(|c| c.div_euclid(side)))?;
        let local = v.map(|c| c.rem_euclid(side) as usize);
        let i = Block::linear(local[0], local[1], local[2]);
        let voxel = &block.voxels[i];
        voxel
            .observed()
            .then(|| (voxel, block.labels[i].instance()))
    }

    /// Trilinear interpolation of distance and colour at `p` (metres), if all eight
    /// surrounding voxel centres are observed.
    fn trilinear(&mut self, p: &Point3<f64>, voxel_size: f64) -> Option<(f64, [f64; 3])> {
        let g = p.coords / voxel_size - Vector3::repeat(0.5);
        let base = g.map(f64::floor);
        let f = g - base;
        let base = [base.x as i32, base.y as i32, base.z as i32];
        let (mut distance, mut color) = (0.0, [0.0; 3]);
        for c in 0..8 {
            let o = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
            let (v, _) = self.voxel([base[0] + o[0], base[1] + o[1], base[2] + o[2]])?;
            let w = (0..3)
                .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                .product::<f64>();
            distance += w * v.distance as f64;
            for (k, channel) in color.iter_mut().enumerate() {
                *channel += w * v.color[k] as f64;
            }
        }
        Some((distance, color))
    }
}

/// Ray parameter at which the ray leaves the block containing `p`.
fn block_exit(p: &Point3<f64>, dir: &Vector3<f64>, block_size: f64) -> f64 {
    (0..3)
        .map(|a| {
            if dir[a].abs() < 1e-12 {
                return f64::INFINITY;
            }
            let cell = (p[a] / block_size).floor();
            let bound = if dir[a] > 0.0 { cell + 1.0 } else { cell } * block_size;
            (bound - p[a]) / dir[a]
        })
        .fold(f64::INFINITY, f64::min)
}

struct Hit {
    /// Distance from the camera centre along the unit ray.
    t: f64,
    color: [u8; 3],
    instance: u16,
    normal: [f32; 3],
}

/// Marches one ray from the camera centre `origin` along the unit `dir` to the first
/// front-facing zero crossing of the TSDF.
fn march(layer: &Layer, origin: &Point3<f64>, dir: &Vector3<f64>, span: RaySpan) -> Option<Hit> {
    let voxel_size = layer.voxel_size();
    let block_size = layer.block_size();
    let mut lookup = Lookup::new(layer);
    let mut t = span.near;
    // The last observed sample in front of the surface: (t, distance).
    let mut previous: Option<(f64, f64)> = None;
    while t < span.far {
        let p = origin + dir * t;
        let v = layer.voxel_index(&p);
        let side = BLOCK_SIDE as i32;
        if lookup.block(v.map(|c| c.div_euclid(side))).is_none() {
            // Nothing was ever observed in this block: skip it whole.
            previous = None;
            t += block_exit(&p, dir, block_size) + 1e-6;
            continue;
        }
        let Some((voxel, _)) = lookup.voxel(v) else {
            previous = None;
            t += 0.5 * voxel_size;
            continue;
        };
        let d = voxel.distance as f64;
        if let Some((t0, d0)) = previous {
            if d <= 0.0 {
                return Some(hit(&mut lookup, origin, dir, (t0, d0), (t, d), voxel_size));
            }
        }
        previous = (d > 0.0).then_some((t, d));
        // The stored distance is at most the truncation band and at least as long as the way
        // to the surface along any ray in front of it: stepping by it cannot jump through the
        // band behind the surface. Half a voxel keeps the march moving near the surface.
        t += d.max(0.5 * voxel_size);
    }
    None
}

/// The distance at `p`: trilinear where the eight surrounding voxels are observed, else the
/// containing voxel's.
fn distance_at(lookup: &mut Lookup, p: &Point3<f64>, voxel_size: f64) -> Option<f64> {
    lookup.trilinear(p, voxel_size).map(|(d, _)| d).or_else(|| {
        lookup
            .voxel(lookup_index(p, voxel_size))
            .map(|(v, _)| v.distance as f64)
    })
}

/// The crossing between samples `(t0, d0)` (in front) and `(t1, d1)` (behind). The coarse
/// march may have stepped up to the truncation distance; the bracket is re-marched in
/// quarter-voxel steps with interpolated distances, and the crossing placed by linear
/// interpolation inside the first step that changes sign.
fn hit(
    lookup: &mut Lookup,
    origin: &Point3<f64>,
    dir: &Vector3<f64>,
    (t0, d0): (f64, f64),
    (t1, d1): (f64, f64),
    voxel_size: f64,
) -> Hit {
    let at = |t: f64| origin + dir * t;
    let step = 0.25 * voxel_size;
    let (mut a, mut da) = (
        t0,
        distance_at(lookup, &at(t0), voxel_size)
            .filter(|d| *d > 0.0)
            .unwrap_or(d0),
    );
    let (mut b, mut db) = (t1, d1);
    let mut t = t0 + step;
    while t < t1 {
        if let Some(d) = distance_at(lookup, &at(t), voxel_size) {
            if d <= 0.0 {
                (b, db) = (t, d);
                break;
            }
            (a, da) = (t, d);
        }
        t += step;
    }
    if b == t1 {
        db = distance_at(lookup, &at(t1), voxel_size)
            .filter(|d| *d <= 0.0)
            .unwrap_or(d1);
    }
    let t = a + (b - a) * da / (da - db);
    let p = at(t);
    let nearest = lookup.voxel(lookup_index(&p, voxel_size));
    let color = match lookup.trilinear(&p, voxel_size) {
        Some((_, c)) => c.map(|x| x.round().clamp(0.0, 255.0) as u8),
        None => nearest.map_or([0; 3], |(v, _)| v.color),
    };
    // The label sits on the voxels nearest the surface, on either side of it.
    let instance = nearest
        .map(|(_, l)| l)
        .filter(|&l| l != 0)
        .or_else(|| {
            let back = at(t + 0.5 * voxel_size);
            let front = at(t - 0.5 * voxel_size);
            [front, back]
                .iter()
                .filter_map(|q| lookup.voxel(lookup_index(q, voxel_size)))
                .map(|(_, l)| l)
                .find(|&l| l != 0)
        })
        .unwrap_or(0);
    // Central differences of the interpolated distance; facing the camera.
    let h = 0.5 * voxel_size;
    let mut gradient = Vector3::zeros();
    for a in 0..3 {
        let mut e = Vector3::zeros();
        e[a] = h;
        match (
            lookup.trilinear(&(p + e), voxel_size),
            lookup.trilinear(&(p - e), voxel_size),
        ) {
            (Some((plus, _)), Some((minus, _))) => gradient[a] = plus - minus,
            _ => {
                gradient = -*dir;
                break;
            }
        }
    }
    let mut normal = gradient.try_normalize(1e-12).unwrap_or(-*dir);
    if normal.dot(dir) > 0.0 {
        normal = -normal;
    }
    Hit {
        t,
        color,
        instance,
        normal: [normal.x as f32, normal.y as f32, normal.z as f32],
    }
}

fn lookup_index(p: &Point3<f64>, voxel_size: f64) -> VoxelIndex {
    [
        (p.x / voxel_size).floor() as i32,
        (p.y / voxel_size).floor() as i32,
        (p.z / voxel_size).floor() as i32,
    ]
}

/// Ray-casts the layer into a camera with intrinsics `k` at `pose` (`T_world_camera`).
pub(crate) fn raycast(layer: &Layer, k: &Intrinsics, pose: &Pose, span: RaySpan) -> RenderedView {
    let (w, h) = (k.width, k.height);
    let origin = Point3::from(pose.translation.vector);
    let rows: Vec<Vec<Option<(f32, Hit)>>> = (0..h)
        .into_par_iter()
        .map(|v| {
            (0..w)
                .map(|u| {
                    let ray = k.ray(u as f64, v as f64);
                    // `ray` has z = 1: planar depth is distance / |ray|.
                    let length = ray.norm();
                    let dir = pose.rotation * (ray / length);
                    march(layer, &origin, &dir, span).map(|hit| ((hit.t / length) as f32, hit))
                })
                .collect()
        })
        .collect();
    let mut view = RenderedView {
        depth: Image::filled(w, h, 0.0),
        color: Image::filled(w, h, [0; 3]),
        instances: Image::filled(w, h, 0),
        normals: Image::filled(w, h, [0.0; 3]),
    };
    for (v, row) in rows.into_iter().enumerate() {
        for (u, sample) in row.into_iter().enumerate() {
            if let Some((depth, hit)) = sample {
                *view.depth.get_mut(u, v) = depth;
                *view.color.get_mut(u, v) = hit.color;
                *view.instances.get_mut(u, v) = hit.instance;
                *view.normals.get_mut(u, v) = hit.normal;
            }
        }
    }
    view
}
