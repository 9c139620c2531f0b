use rayon::prelude::*;
use voxpan_core::nalgebra::{Point3, Vector3};
use voxpan_core::{ColorImage, DepthImage, Image, Intrinsics, LabelImage, Pose};

use crate::layer::{
    BLOCK_SIDE, Block, BlockIndex, Layer, TsdfVoxel, VoxelIndex, block_of, floor_i32, voxel_of,
};

/// What a camera sees of the map. Pixels whose ray meets no surface have depth 0, colour
/// black, instance 0 and a zero normal.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedView {
    /// Planar depth (along the optical axis), metres.
    pub depth: DepthImage,
    pub color: ColorImage,
    /// Map instance of the surface (0 = none).
    pub instances: LabelImage,
    /// Unit surface normal in the world frame, facing the camera (from the rendered depth's
    /// neighbours; zero where a pixel has no neighbour on its own surface).
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
    #[inline]
    fn voxel(&mut self, v: VoxelIndex) -> Option<(TsdfVoxel, u16)> {
        let block = self.block(block_of(v))?;
        let local = v.map(|c| (c & (BLOCK_SIDE as i32 - 1)) as usize);
        let i = Block::linear(local[0], local[1], local[2]);
        let voxel = block.voxels.get(i);
        voxel
            .observed()
            .then(|| (voxel, block.labels[i].instance()))
    }

    /// Trilinear interpolation of distance and colour at `p` (metres), if all eight
    /// surrounding voxel centres are observed.
    fn trilinear(&mut self, p: &Point3<f64>, voxel_size: f64) -> Option<(f64, [f64; 3])> {
        let g = p.coords / voxel_size - Vector3::repeat(0.5);
        let base = [floor_i32(g.x), floor_i32(g.y), floor_i32(g.z)];
        let f = g - Vector3::new(base[0] as f64, base[1] as f64, base[2] as f64);
        let (mut distance, mut color) = (0.0, [0.0; 3]);
        for c in 0..8 {
            let o = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
            let (v, _) = self.voxel([base[0] + o[0], base[1] + o[1], base[2] + o[2]])?;
            let w = (0..3)
                .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                .product::<f64>();
            distance += w * self.layer.distance(&v) as f64;
            for (k, channel) in color.iter_mut().enumerate() {
                *channel += w * v.color()[k] as f64;
            }
        }
        Some((distance, color))
    }
}

/// How far along the ray (from `p`) it leaves `p`'s block, given the block index of `p`
/// and `1 / dir` per axis (infinite along axes the ray does not move on).
#[inline]
fn block_exit(p: &Point3<f64>, block: BlockIndex, inv_dir: &[f64; 3], block_size: f64) -> f64 {
    let mut exit = f64::INFINITY;
    for a in 0..3 {
        if inv_dir[a].is_finite() {
            let bound = (block[a] + (inv_dir[a] > 0.0) as i32) as f64 * block_size;
            exit = exit.min((bound - p[a]) * inv_dir[a]);
        }
    }
    exit
}

struct Hit {
    /// Distance from the camera centre along the unit ray.
    t: f64,
    color: [u8; 3],
    instance: u16,
}

/// Marches one ray from the camera centre `origin` along the unit `dir` to the first
/// front-facing zero crossing of the TSDF.
fn march(layer: &Layer, origin: &Point3<f64>, dir: &Vector3<f64>, span: RaySpan) -> Option<Hit> {
    let voxel_size = layer.voxel_size();
    let inv_voxel = 1.0 / voxel_size;
    let block_size = layer.block_size();
    let inv_dir = [0, 1, 2].map(|a| {
        if dir[a].abs() < 1e-12 {
            f64::INFINITY
        } else {
            1.0 / dir[a]
        }
    });
    let mut lookup = Lookup::new(layer);
    let mut t = span.near;
    // The last observed sample in front of the surface: (t, distance).
    let mut previous: Option<(f64, f64)> = None;
    while t < span.far {
        let p = origin + dir * t;
        let v = voxel_of(&p, inv_voxel);
        let block = block_of(v);
        if lookup.block(block).is_none() {
            // Nothing was ever observed in this block: skip it whole.
            previous = None;
            t += block_exit(&p, block, &inv_dir, block_size).max(0.0) + 1e-6;
            continue;
        }
        let Some((voxel, _)) = lookup.voxel(v) else {
            previous = None;
            t += 0.5 * voxel_size;
            continue;
        };
        let d = layer.distance(&voxel) as f64;
        if let Some((t0, d0)) = previous
            && d <= 0.0
        {
            return Some(hit(&mut lookup, origin, dir, (t0, d0), (t, d), voxel_size));
        }
        previous = (d > 0.0).then_some((t, d));
        // The stored distance is at most the truncation band and at least as long as the way
        // to the surface along any ray in front of it: stepping by it cannot jump through the
        // band behind the surface. Half a voxel keeps the march moving near the surface.
        t += d.max(0.5 * voxel_size);
    }
    None
}

/// The crossing between samples `(t0, d0)` (in front) and `(t1, d1)` (behind). The coarse
/// march may have stepped up to the truncation distance: the bracket is first narrowed to half
/// a voxel with voxel values, then the crossing placed by linear interpolation of trilinear
/// distances (or, where the neighbourhood is not fully observed, of the voxel values).
fn hit(
    lookup: &mut Lookup,
    origin: &Point3<f64>,
    dir: &Vector3<f64>,
    (t0, d0): (f64, f64),
    (t1, d1): (f64, f64),
    voxel_size: f64,
) -> Hit {
    let at = |t: f64| origin + dir * t;
    let step = 0.5 * voxel_size;
    let (mut a, mut b) = (t0, t1);
    let (mut da, mut db) = (d0, d1);
    let mut t = t0 + step;
    while t < t1 {
        if let Some((v, _)) = lookup.voxel(lookup_index(&at(t), voxel_size)) {
            let d = lookup.layer.distance(&v) as f64;
            if d <= 0.0 {
                (b, db) = (t, d);
                break;
            }
            (a, da) = (t, d);
        }
        t += step;
    }
    // Voxel values are samples at voxel centres, not at the ray's points: with trilinear
    // values, look for the sign change from half a step before the bracket to half a step
    // after it.
    // The bracket's own ends first (most crossings lie between them), then its surroundings.
    let mut trilinear = |t: f64| lookup.trilinear(&at(t), voxel_size).map(|(d, _)| (t, d));
    match (trilinear(a), trilinear(b)) {
        (Some((_, sa)), Some((_, sb))) if sa > 0.0 && sb <= 0.0 => (da, db) = (sa, sb),
        _ => {
            let samples: Vec<(f64, f64)> = [a - 0.5 * step, a, 0.5 * (a + b), b, b + 0.5 * step]
                .into_iter()
                .filter_map(&mut trilinear)
                .collect();
            if let Some(w) = samples.windows(2).find(|w| w[0].1 > 0.0 && w[1].1 <= 0.0) {
                (a, da, b, db) = (w[0].0, w[0].1, w[1].0, w[1].1);
            }
        }
    }
    let t = a + (b - a) * da / (da - db);
    let p = at(t);
    let nearest = lookup.voxel(lookup_index(&p, voxel_size));
    let color = nearest
        .or_else(|| lookup.voxel(lookup_index(&at(a), voxel_size)))
        .map_or([0; 3], |(v, _)| v.color());
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
    Hit { t, color, instance }
}

fn lookup_index(p: &Point3<f64>, voxel_size: f64) -> VoxelIndex {
    voxel_of(p, 1.0 / voxel_size)
}

/// Unit normals (world frame, facing the camera) from a depth image: the cross product of the
/// back-projected neighbours' differences along u and v. A neighbour across a depth jump of
/// more than `jump` (relative) is not used; a pixel without two usable directions gets zero.
fn normals_from_depth(depth: &DepthImage, k: &Intrinsics, pose: &Pose) -> Image<[f32; 3]> {
    let (w, h) = depth.dims();
    let point = |u: usize, v: usize| -> Option<Vector3<f64>> {
        let z = *depth.get(u, v) as f64;
        (z > 0.0).then(|| k.ray(u as f64, v as f64) * z)
    };
    // Neighbours further apart than this (relative depth) lie on different surfaces.
    let jump = 0.05;
    let along = |c: &Vector3<f64>, before: Option<Vector3<f64>>, after: Option<Vector3<f64>>| {
        let near = |q: &Option<Vector3<f64>>| q.filter(|q| (q.z - c.z).abs() <= jump * c.z);
        match (near(&before), near(&after)) {
            (Some(b), Some(a)) => Some(a - b),
            (Some(b), None) => Some(c - b),
            (None, Some(a)) => Some(a - c),
            (None, None) => None,
        }
    };
    Image::from_fn(w, h, |u, v| {
        let Some(c) = point(u, v) else {
            return [0.0; 3];
        };
        let du = along(
            &c,
            (u > 0).then(|| point(u - 1, v)).flatten(),
            (u + 1 < w).then(|| point(u + 1, v)).flatten(),
        );
        let dv = along(
            &c,
            (v > 0).then(|| point(u, v - 1)).flatten(),
            (v + 1 < h).then(|| point(u, v + 1)).flatten(),
        );
        let (Some(du), Some(dv)) = (du, dv) else {
            return [0.0; 3];
        };
        let mut n = du.cross(&dv);
        if n.dot(&c) > 0.0 {
            n = -n;
        }
        match n.try_normalize(1e-18) {
            Some(n) => {
                let n = pose.rotation * n;
                [n.x as f32, n.y as f32, n.z as f32]
            }
            None => [0.0; 3],
        }
    })
}

/// Pixels per side of the tiles whose depth spans bound each ray's march.
const TILE: usize = 8;

/// For each `TILE × TILE` tile of the image, the range of planar depths at which an allocated
/// block can be seen (nvblox's block projection): rays march only through it, and tiles no
/// block covers are not marched at all. Each block is bounded by its eight corners.
fn tile_spans(
    layer: &Layer,
    k: &Intrinsics,
    pose: &Pose,
    span: RaySpan,
) -> Vec<Option<(f64, f64)>> {
    let (tw, th) = (k.width.div_ceil(TILE), k.height.div_ceil(TILE));
    let mut tiles: Vec<Option<(f64, f64)>> = vec![None; tw * th];
    let world_to_camera = pose.inverse();
    let size = layer.block_size();
    for (index, _) in layer.iter() {
        let origin = Vector3::new(index[0] as f64, index[1] as f64, index[2] as f64) * size;
        let corners: [Point3<f64>; 8] = std::array::from_fn(|c| {
            let o = Vector3::new((c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64);
            world_to_camera * Point3::from(origin + o * size)
        });
        let (near, far) = corners
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.z), b.max(p.z))
            });
        if far < span.near {
            continue;
        }
        // A block reaching behind the image plane projects without bounds: all tiles.
        let (mut u0, mut v0, mut u1, mut v1) = (0.0, 0.0, k.width as f64, k.height as f64);
        if near > 1e-3 {
            (u0, v0, u1, v1) = (
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            );
            for p in &corners {
                let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
                (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
            }
        }
        // Pixel centres are at integer coordinates: a pixel's footprint reaches ±0.5.
        let to_tile = |x: f64, n: usize| ((x + 0.5).floor().max(0.0) as usize / TILE).min(n - 1);
        if u1 < -0.5 || v1 < -0.5 || u0 > k.width as f64 - 0.5 || v0 > k.height as f64 - 0.5 {
            continue;
        }
        let (near, far) = (near.max(span.near), far);
        for ty in to_tile(v0, th)..=to_tile(v1, th) {
            for tx in to_tile(u0, tw)..=to_tile(u1, tw) {
                let t = &mut tiles[ty * tw + tx];
                *t = Some(match *t {
                    Some((a, b)) => (a.min(near), b.max(far)),
                    None => (near, far),
                });
            }
        }
    }
    tiles
}

/// Ray-casts the layer into a camera with intrinsics `k` at `pose` (`T_world_camera`).
/// The instance label of the voxel each pixel's measured depth lands in (0 where the depth is
/// invalid or outside `span`, or the voxel is unobserved or unlabelled): what the map knows of
/// the surface the camera measures, at one voxel look-up per pixel. A ray cast finds the
/// same surface by marching; here the frame's depth says where it is.
pub(crate) fn instances_at_depth(
    layer: &Layer,
    depth: &DepthImage,
    k: &Intrinsics,
    pose: &Pose,
    span: RaySpan,
) -> LabelImage {
    let (w, h) = depth.dims();
    let inv_voxel = 1.0 / layer.voxel_size();
    // The world ray through pixel (u, v) at unit depth is `start + u * along_row` for its
    // row: one rotation per row instead of a division and a quaternion product per pixel.
    let rotation = pose.rotation.to_rotation_matrix();
    let origin = Point3::from(pose.translation.vector);
    let along_row = rotation * Vector3::new(1.0 / k.fx, 0.0, 0.0);
    let mut pixels = vec![0u16; w * h];
    pixels
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(v, row)| {
            let mut lookup = Lookup::new(layer);
            let start = rotation * k.ray(0.0, v as f64);
            let depths = &depth.pixels()[v * w..(v + 1) * w];
            for (u, (id, &z)) in row.iter_mut().zip(depths).enumerate() {
                let z = z as f64;
                if !(z.is_finite() && z >= span.near && z <= span.far) {
                    continue;
                }
                let p = origin + (start + along_row * u as f64) * z;
                *id = lookup
                    .voxel(voxel_of(&p, inv_voxel))
                    .map_or(0, |(_, id)| id);
            }
        });
    LabelImage::from_vec(w, h, pixels).expect("a label per pixel")
}

pub(crate) fn raycast(layer: &Layer, k: &Intrinsics, pose: &Pose, span: RaySpan) -> RenderedView {
    let (w, h) = (k.width, k.height);
    let origin = Point3::from(pose.translation.vector);
    let tiles = tile_spans(layer, k, pose, span);
    let tw = w.div_ceil(TILE);
    let rows: Vec<Vec<Option<(f32, Hit)>>> = (0..h)
        .into_par_iter()
        .map(|v| {
            (0..w)
                .map(|u| {
                    let (near, far) = tiles[(v / TILE) * tw + u / TILE]?;
                    let ray = k.ray(u as f64, v as f64);
                    // `ray` has z = 1: distance along the ray is planar depth × |ray|.
                    let length = ray.norm();
                    let dir = pose.rotation * (ray / length);
                    let span = RaySpan {
                        near: (near * length).max(span.near),
                        far: (far * length).min(span.far),
                    };
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
            }
        }
    }
    view.normals = normals_from_depth(&view.depth, k, pose);
    view
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use voxpan_core::nalgebra::{Translation3, UnitQuaternion};

    use super::*;
    use crate::layer::VOXELS_PER_BLOCK;

    /// Blocks `[-4, 4)³` of 5 cm voxels, all observed, each voxel labelled by its position.
    fn labelled_layer() -> Layer {
        let mut layer = Layer::new(0.05, 0.15);
        for bx in -4..4 {
            for by in -4..4 {
                for bz in -4..4 {
                    let voxel = layer.voxel(0.0, 1.0, [0; 3]);
                    let (block, _) = layer.get_or_allocate([bx, by, bz]);
                    for i in 0..VOXELS_PER_BLOCK {
                        block.voxels.set(i, voxel);
                        let [x, y, z] = Block::voxel_index([bx, by, bz], i);
                        block.labels[i]
                            .observe(((x * 7 + y * 131 + z * 1031).rem_euclid(999) + 1) as u16);
                    }
                }
            }
        }
        layer
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]

        /// The per-row ray of `instances_at_depth` lands each pixel in the voxel the pose and
        /// the pinhole model put it in, but where the point lies within a hair of a voxel's
        /// face (the two sums round differently there).
        #[test]
        fn each_pixel_takes_the_label_of_the_voxel_its_depth_lands_in(
            axis in (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64),
            angle in 0.0..3.1f64,
            at in (-0.3..0.3f64, -0.3..0.3f64, -0.3..0.3f64),
            depths in prop::collection::vec(0.0..1.2f32, 37 * 29),
        ) {
            let layer = labelled_layer();
            let k = Intrinsics { width: 37, height: 29, fx: 30.0, fy: 31.5, cx: 18.2, cy: 13.7 };
            let rotation = UnitQuaternion::from_scaled_axis(
                Vector3::new(axis.0, axis.1, axis.2).normalize() * angle,
            );
            let pose = Pose::from_parts(Translation3::new(at.0, at.1, at.2), rotation);
            let depth = DepthImage::from_vec(37, 29, depths).unwrap();
            let span = RaySpan { near: 0.1, far: 1.1 };
            let labels = instances_at_depth(&layer, &depth, &k, &pose, span);
            let mut lookup = Lookup::new(&layer);
            for v in 0..29 {
                for u in 0..37 {
                    let z = *depth.get(u, v) as f64;
                    let got = *labels.get(u, v);
                    if !(span.near..=span.far).contains(&z) {
                        prop_assert_eq!(got, 0);
                        continue;
                    }
                    let p = pose * Point3::from(k.ray(u as f64, v as f64) * z);
                    let scaled = p.coords * 20.0;
                    let on_face = scaled.iter().any(|c| (c - c.round()).abs() < 1e-9);
                    let want = lookup.voxel(voxel_of(&p, 20.0)).map_or(0, |(_, id)| id);
                    prop_assert!(got == want || on_face, "({u}, {v}): {got} against {want}");
                }
            }
        }
    }
}
