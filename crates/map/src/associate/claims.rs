//! Where a flush thing's observation takes its voxels from the stuff leading them.
//!
//! A picture or a TV on its wall lies within the truncation distance of the wall, so depth
//! refinement cannot cut the wall's mask off it. In every frame where the network misses it,
//! the wall's mask covers it, and those votes land on the same voxels as its own. Counted
//! alike, they kept three quarters of flat's TV as wall (docs/design/association.md). A
//! stuff mask over a thing is the network missing the thing, so once the map shows a flush
//! thing, its observations take the lead of the stuff-led voxels under the inside of its
//! mask ([`LabelVoxel::observe_over`](crate::layer::LabelVoxel::observe_over)).

use voxpan_core::{DepthImage, LabelImage};

/// The pixels of `instances` (map instance per pixel, at the depth image's resolution) whose
/// instance `claims` names and that lie at least one voxel inside that instance's mask:
/// every pixel within one voxel's footprint (`voxel` metres at the pixel's depth, focal
/// length `fx` in pixels) shows the same instance. A mask's rim is where it and the surface
/// disagree (its pixels see the wall beside the picture, and a flush thing's mask grew by
/// that ring in every view), so only its inside takes voxels over. `None` when no pixel of
/// the frame shows a claiming instance.
pub(crate) fn claiming_pixels(
    instances: &LabelImage,
    depth: &DepthImage,
    fx: f64,
    voxel: f64,
    claims: &[bool],
) -> Option<Vec<bool>> {
    let (w, h) = instances.dims();
    let ids = instances.pixels();
    // The rows' runs of claiming instances `(row, first, last)`, and per pixel of them how far
    // its run reaches on its nearer side.
    let mut runs = Vec::new();
    let mut reach = vec![0u16; w * h];
    for (row, line) in ids.chunks_exact(w).enumerate() {
        let mut start = 0;
        for run in line.chunk_by(|a, b| a == b) {
            let end = start + run.len() - 1;
            if claims[run[0] as usize] {
                for x in start..=end {
                    reach[row * w + x] = (x - start).min(end - x).min(u16::MAX as usize) as u16;
                }
                runs.push((row, start, end));
            }
            start = end + 1;
        }
    }
    if runs.is_empty() {
        return None;
    }
    let mut out = vec![false; w * h];
    for (y, first, last) in runs {
        for x in first..=last {
            let id = ids[y * w + x];
            let z = *depth.get(x, y);
            if !(z > 0.0 && z.is_finite()) {
                continue;
            }
            let r = (voxel * fx / f64::from(z)).ceil().max(1.0) as usize;
            if y < r || y + r >= h || usize::from(reach[y * w + x]) < r {
                continue;
            }
            out[y * w + x] = (y - r..=y + r)
                .all(|yy| ids[yy * w + x] == id && usize::from(reach[yy * w + x]) >= r);
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxpan_core::Image;

    #[test]
    fn only_pixels_one_voxel_inside_a_claiming_mask_claim() {
        // A 20x10 image, instance 2 a 10x6 block at x 5..15, y 2..8; depth 1 m, fx 100 px,
        // voxel 2 cm: one voxel spans 2 px, so claiming pixels lie 2 px inside the block.
        let instances = Image::from_fn(20, 10, |x, y| {
            if (5..15).contains(&x) && (2..8).contains(&y) {
                2
            } else {
                1
            }
        });
        let depth = Image::filled(20, 10, 1.0f32);
        let mut claims = vec![false; u16::MAX as usize + 1];
        claims[2] = true;
        let out = claiming_pixels(&instances, &depth, 100.0, 0.02, &claims).unwrap();
        for y in 0..10 {
            for x in 0..20 {
                let inside = (7..13).contains(&x) && (4..6).contains(&y);
                assert_eq!(out[y * 20 + x], inside, "pixel {x}, {y}");
            }
        }
        // The wall (instance 1) does not claim, and nothing claims without depth.
        claims[1] = true;
        claims[2] = false;
        let none = claiming_pixels(
            &instances,
            &Image::filled(20, 10, 0.0f32),
            100.0,
            0.02,
            &claims,
        )
        .unwrap();
        assert!(none.iter().all(|&c| !c));
        // A frame showing no claiming instance has nothing to claim.
        claims[1] = false;
        assert_eq!(
            claiming_pixels(&instances, &depth, 100.0, 0.02, &claims),
            None
        );
    }
}
