//! What the map says about the surface each pixel of a frame measures: the instance labels
//! (leader and runner-up) of the voxel its depth lands in. This is the evidence association
//! reads (Voxblox++'s voxel votes): it needs no rendering, sees exactly the surface the frame
//! sees, and costs one voxel look-up per sampled pixel.

use voxpan_core::nalgebra::{Matrix3, Point3, Vector3};
use voxpan_core::{DepthImage, Intrinsics, Pose, is_valid_depth};

use crate::TsdfConfig;
use crate::layer::{BLOCK_SIDE, Block, BlockIndex, Layer, block_of, voxel_of, with_neighbours};

/// The map's labels at a frame's measured surface, sampled every `step` pixels per axis.
pub(crate) struct Observation {
    pub width: usize,
    pub height: usize,
    pub step: usize,
    /// Row by row.
    pub samples: Vec<Sample>,
    /// The largest depth step, in metres, between neighbouring samples of one continuous
    /// surface: the TSDF's truncation distance, within which integration fuses both sides
    /// into one surface.
    pub surface_step: f32,
}

impl Observation {
    /// Whether samples `a` and `b` (neighbours) both measure depth and lie on one continuous
    /// surface; `None` when either has no measurement.
    pub fn continuous(&self, a: &Sample, b: &Sample) -> Option<bool> {
        (a.label.is_some() && b.label.is_some())
            .then(|| (a.depth - b.depth).abs() <= self.surface_step)
    }

    /// The centre pixel of sample `(sx, sy)` in an image of `dims` (width, height).
    pub fn pixel(&self, sx: usize, sy: usize, dims: (usize, usize)) -> (usize, usize) {
        sample_pixel(sx, sy, self.step, dims)
    }
}

/// The centre pixel of sample `(sx, sy)` on a grid `step` pixels apart, in an image of `dims`.
fn sample_pixel(sx: usize, sy: usize, step: usize, dims: (usize, usize)) -> (usize, usize) {
    (
        (sx * step + step / 2).min(dims.0 - 1),
        (sy * step + step / 2).min(dims.1 - 1),
    )
}

/// `n` more on instance `id` in a short per-instance list of counts.
pub(crate) fn count_on(counts: &mut Vec<(u16, usize)>, id: u16, n: usize) {
    match counts.iter_mut().find(|(i, _)| *i == id) {
        Some((_, m)) => *m += n,
        None => counts.push((id, n)),
    }
}

/// The map's labels at one pixel's measured surface.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Sample {
    /// `None` without a usable measurement, `Some(0)` on an unlabelled (or never mapped)
    /// surface, `Some(id)` on instance `id` (the voxel's leading candidate).
    pub label: Option<u16>,
    /// The voxel's runner-up instance, 0 when it has none.
    pub challenger: u16,
    /// The depth lies within the integration range, so integration maps it.
    pub integrated: bool,
    /// The block the measurement lands in (meaningful when `label` is `Some`).
    pub block: BlockIndex,
    /// The measured depth in metres (meaningful when `label` is `Some`).
    pub depth: f32,
}

/// A voxel's leading and runner-up instances, `(0, 0)` where no block is allocated. Labels
/// are only ever recorded on observed voxels: no need to read the voxel itself.
fn instances_at(voxel: Option<(&Block, usize)>) -> (u16, u16) {
    voxel.map_or((0, 0), |(block, i)| {
        let evidence = &block.labels[i];
        (evidence.instance(), evidence.challenger())
    })
}

/// Finds the voxel a pixel's measured depth lands in.
pub(crate) struct Surface<'a> {
    layer: &'a Layer,
    depth: &'a DepthImage,
    k: &'a Intrinsics,
    tsdf: &'a TsdfConfig,
    inv_voxel: f64,
    // The rotation as a matrix: one product per sample instead of a quaternion rotation.
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
    // Neighbouring samples revisit the same blocks: a small direct-mapped cache of block
    // look-ups saves most of the hash-map probes.
    cache: [Option<([i32; 3], Option<&'a Block>)>; CACHE],
}

const CACHE: usize = 64;

/// Where a pixel's measurement lands: `None` without a usable one, else whether integration
/// maps it, its block's index and the voxel (its block, if allocated, and index in it).
type Landing<'a> = Option<(bool, BlockIndex, Option<(&'a Block, usize)>)>;

impl<'a> Surface<'a> {
    /// The instances whose surface voxels lie in `blocks` or the blocks around them (26
    /// neighbours each), with how many of those blocks hold each.
    pub fn instances_near(&self, blocks: &[BlockIndex]) -> Vec<(u16, usize)> {
        let mut around: Vec<BlockIndex> = blocks.iter().flat_map(|&b| with_neighbours(b)).collect();
        around.sort_unstable();
        around.dedup();
        let mut near: Vec<(u16, usize)> = Vec::new();
        for index in &around {
            let Some(block) = self.layer.get(index) else {
                continue;
            };
            for &(id, _) in &block.surface {
                count_on(&mut near, id, 1);
            }
        }
        near
    }

    /// Whether instance `id` has surface voxels in `blocks` or the blocks around them (26
    /// neighbours each): [`Self::instances_near`] for one instance, stopping at the first.
    pub fn instance_near(&self, id: u16, blocks: &[BlockIndex]) -> bool {
        blocks.iter().any(|&b| {
            with_neighbours(b).any(|index| {
                self.layer
                    .get(&index)
                    .is_some_and(|block| block.surface.iter().any(|&(i, _)| i == id))
            })
        })
    }

    /// The frame's depth image.
    pub fn depth(&self) -> &'a DepthImage {
        self.depth
    }

    pub fn new(
        layer: &'a Layer,
        depth: &'a DepthImage,
        pose: &Pose,
        k: &'a Intrinsics,
        tsdf: &'a TsdfConfig,
    ) -> Self {
        Self {
            layer,
            depth,
            k,
            tsdf,
            inv_voxel: 1.0 / layer.voxel_size(),
            rotation: pose.rotation.to_rotation_matrix().into_inner(),
            translation: pose.translation.vector,
            cache: [None; CACHE],
        }
    }

    fn land(&mut self, x: usize, y: usize) -> Landing<'a> {
        let z = *self.depth.get(x, y);
        // Past the range a depth is too noisy to integrate, but where it lands on voxels that
        // closer frames labelled it still says which instance it sees (a picture mapped once
        // up close and seen from across the room confirms it).
        if !(is_valid_depth(z) && (z as f64) >= self.tsdf.min_range) {
            return None;
        }
        let integrated = (z as f64) <= self.tsdf.max_range;
        let c = self.k.ray(x as f64, y as f64) * z as f64;
        let p = self.rotation * c + self.translation;
        let v = voxel_of(&Point3::from(p), self.inv_voxel);
        let index = block_of(v);
        let slot = (index[0].wrapping_mul(73_856_093)
            ^ index[1].wrapping_mul(19_349_663)
            ^ index[2].wrapping_mul(83_492_791)) as usize
            % CACHE;
        let block = match self.cache[slot] {
            Some((i, b)) if i == index => b,
            _ => {
                let b = self.layer.get(&index);
                self.cache[slot] = Some((index, b));
                b
            }
        };
        let side = BLOCK_SIDE as i32;
        let l = v.map(|c| (c & (side - 1)) as usize);
        Some((
            integrated,
            index,
            block.map(|b| (b, Block::linear(l[0], l[1], l[2]))),
        ))
    }

    /// The map's labels at pixel `(x, y)`'s measured surface.
    pub fn sample(&mut self, x: usize, y: usize) -> Sample {
        let Some((integrated, block, voxel)) = self.land(x, y) else {
            return Sample::default();
        };
        let (label, challenger) = instances_at(voxel);
        Sample {
            label: Some(label),
            challenger,
            integrated,
            block,
            depth: *self.depth.get(x, y),
        }
    }
}

/// Samples the measured surface of `depth` (seen from `pose`) every `step` pixels.
pub(crate) fn observe(surface: &mut Surface, step: usize) -> Observation {
    let depth = surface.depth;
    let step = step.max(1);
    let (w, h) = (depth.width().div_ceil(step), depth.height().div_ceil(step));
    let mut samples = Vec::with_capacity(w * h);
    // A row of samples is located first and its voxels read after: the reads (cache misses
    // into blocks all over the map, mostly) then overlap instead of each waiting behind the
    // next sample's arithmetic.
    let mut located: Vec<Option<(&Block, usize)>> = Vec::with_capacity(w);
    for sy in 0..h {
        located.clear();
        for sx in 0..w {
            let (x, y) = sample_pixel(sx, sy, step, (depth.width(), depth.height()));
            let Some((integrated, block, voxel)) = surface.land(x, y) else {
                samples.push(Sample::default());
                located.push(None);
                continue;
            };
            // A placeholder label, set below once the row's voxels are read.
            samples.push(Sample {
                label: Some(0),
                challenger: 0,
                integrated,
                block,
                depth: *depth.get(x, y),
            });
            located.push(voxel);
        }
        let row = samples.len() - w..;
        for (sample, &voxel) in samples[row].iter_mut().zip(&located) {
            if let Some(label) = sample.label.as_mut() {
                (*label, sample.challenger) = instances_at(voxel);
            }
        }
    }
    Observation {
        width: w,
        height: h,
        step,
        samples,
        surface_step: surface.tsdf.truncation() as f32,
    }
}
