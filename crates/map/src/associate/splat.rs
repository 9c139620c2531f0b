//! The map's instances as a camera sees them, splatted from the labelled surface voxels: the
//! cheap rendering association needs every frame (the TSDF ray cast in `render` is the exact
//! one).

use voxpan_core::{Intrinsics, LabelImage, Pose};

use crate::layer::{Block, Layer, VOXELS_PER_BLOCK};

/// Intrinsics of the same camera with `factor` times fewer pixels per axis (pixel centres stay
/// at integer coordinates). Tracking renders at a quarter resolution: IoU barely changes, the
/// rendering costs a sixteenth.
pub fn downscaled(k: &Intrinsics, factor: usize) -> Intrinsics {
    let f = factor.max(1) as f64;
    Intrinsics {
        width: k.width.div_ceil(factor.max(1)),
        height: k.height.div_ceil(factor.max(1)),
        fx: k.fx / f,
        fy: k.fy / f,
        cx: (k.cx + 0.5) / f - 0.5,
        cy: (k.cy + 0.5) / f - 0.5,
    }
}

/// The map's instances as seen from `pose`: every labelled surface voxel (|distance| < one
/// voxel) splatted over its projected footprint, nearest first.
pub(crate) fn render_instances(layer: &Layer, pose: &Pose, k: &Intrinsics) -> LabelImage {
    let (w, h) = (k.width, k.height);
    let mut depth = vec![f32::INFINITY; w * h];
    let mut out = LabelImage::filled(w, h, 0);
    let world_to_camera = pose.inverse();
    let voxel = layer.voxel_size();
    for (&index, block) in layer.iter() {
        // Skip blocks behind the camera or outside the image (a block fits in a sphere of
        // radius block size around its centre).
        let centre = world_to_camera * Block::voxel_center(index, VOXELS_PER_BLOCK / 2, voxel);
        let reach = layer.block_size();
        if centre.z < -reach {
            continue;
        }
        if centre.z > reach {
            let (u, v) = (
                k.fx * centre.x / centre.z + k.cx,
                k.fy * centre.y / centre.z + k.cy,
            );
            let r = k.fx.max(k.fy) * reach / (centre.z - reach).max(1e-6);
            if u < -r || v < -r || u > w as f64 + r || v > h as f64 + r {
                continue;
            }
        }
        for i in block.surface_voxels() {
            let id = block.labels[i].instance();
            let p = world_to_camera * Block::voxel_center(index, i, voxel);
            let Some((u, vv)) = k.project(&p) else {
                continue;
            };
            let radius = (0.5 * k.fx * voxel / p.z).ceil().max(1.0) as i64;
            let (u, vv) = (u.round() as i64, vv.round() as i64);
            for y in (vv - radius).max(0)..(vv + radius).min(h as i64) {
                for x in (u - radius).max(0)..(u + radius).min(w as i64) {
                    let j = y as usize * w + x as usize;
                    if (p.z as f32) < depth[j] {
                        depth[j] = p.z as f32;
                        out.pixels_mut()[j] = id;
                    }
                }
            }
        }
    }
    out
}
