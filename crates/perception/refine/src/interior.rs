//! How deep inside its own mask each pixel lies.

use voxpan_core::{LabelImage, widest};

/// City-block distance (in pixels) from every pixel to the nearest pixel of its mask's
/// outline: a pixel with a 4-neighbour carrying another label. The image border is not an
/// outline (a mask cut by the frame continues beyond it). Saturates at `u16::MAX`. The exact
/// metric hardly matters for its use (weighing a mask's core against its rim); the 4-neighbour
/// one is the cheapest to propagate.
pub fn interior_depth(labels: &LabelImage, out: &mut Vec<u16>) {
    // Its row passes vectorise twice as wide with AVX2.
    widest!(interior_depth_with(labels, out))
}

#[inline(always)]
fn interior_depth_with(labels: &LabelImage, out: &mut Vec<u16>) {
    let (w, h) = labels.dims();
    let l = labels.pixels();
    out.clear();
    out.resize(w * h, u16::MAX);
    if w == 0 || h == 0 {
        return;
    }
    // Outline: the pixels with a 4-neighbour of another label. Whole rows are compared with
    // their shifted selves and their neighbour rows, branch-free, so the compares vectorise.
    #[inline(always)]
    fn mark_unlike(out: &mut [u16], a: &[u16], b: &[u16]) {
        for ((o, &a), &b) in out.iter_mut().zip(a).zip(b) {
            *o = if a != b { 0 } else { *o };
        }
    }
    for (y, o) in out.chunks_exact_mut(w).enumerate() {
        let row = &l[y * w..(y + 1) * w];
        mark_unlike(&mut o[1..], &row[1..], row);
        mark_unlike(o, row, &row[1..]);
        if y > 0 {
            mark_unlike(o, row, &l[(y - 1) * w..]);
        }
        if y + 1 < h {
            mark_unlike(o, row, &l[(y + 1) * w..]);
        }
    }
    // The city-block distance is separable: the distance along each column first (every
    // column at once, row by row), then along each row. The rows' chains are serial, so
    // `LANES` rows go side by side for the processor to overlap (4, 8 and 16 time alike).
    for y in 1..h {
        let (before, rest) = out.split_at_mut(y * w);
        for (d, &u) in rest[..w].iter_mut().zip(&before[(y - 1) * w..]) {
            *d = (*d).min(u.saturating_add(1));
        }
    }
    for y in (0..h - 1).rev() {
        let (rest, after) = out.split_at_mut((y + 1) * w);
        for (d, &b) in rest[y * w..].iter_mut().zip(&after[..w]) {
            *d = (*d).min(b.saturating_add(1));
        }
    }
    const LANES: usize = 8;
    let mut rows = out.chunks_exact_mut(w * LANES);
    for block in rows.by_ref() {
        let mut lanes: [&mut [u16]; LANES] = {
            let mut it = block.chunks_exact_mut(w);
            std::array::from_fn(|_| it.next().expect("LANES rows"))
        };
        along_rows(&mut lanes);
    }
    for row in rows.into_remainder().chunks_exact_mut(w) {
        along_rows(&mut [row]);
    }
}

/// The distance along each of `rows` (equal lengths), given each pixel's distance along its
/// column: a forward and a backward pass, the rows interleaved.
#[inline(always)]
fn along_rows<const N: usize>(rows: &mut [&mut [u16]; N]) {
    let w = rows[0].len();
    let mut run: [u16; N] = std::array::from_fn(|r| rows[r][0]);
    for x in 1..w {
        for (run, row) in run.iter_mut().zip(rows.iter_mut()) {
            *run = row[x].min(run.saturating_add(1));
            row[x] = *run;
        }
    }
    let mut run: [u16; N] = std::array::from_fn(|r| rows[r][w - 1]);
    for x in (0..w - 1).rev() {
        for (run, row) in run.iter_mut().zip(rows.iter_mut()) {
            *run = row[x].min(run.saturating_add(1));
            row[x] = *run;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_has_its_exact_distance_to_the_outline() {
        // A 9×9 square of 1s in a 15×15 field of 0s: its outline is its outermost ring, so a
        // pixel k steps inside it is k away (city-block: diagonal steps count twice).
        let labels = LabelImage::from_fn(15, 15, |x, y| {
            ((3..12).contains(&x) && (3..12).contains(&y)) as u16
        });
        let mut d = Vec::new();
        interior_depth(&labels, &mut d);
        let at = |x: usize, y: usize| d[y * 15 + x];
        assert_eq!(at(3, 7), 0);
        assert_eq!(at(4, 7), 1);
        assert_eq!(at(7, 7), 4);
        assert_eq!(at(5, 6), 2);
        // Outside, the field is measured from its own outline (the ring around the square);
        // the image border is no outline. The ring's corners touch the square only
        // diagonally, so from (0, 0) the nearest outline pixel is (2, 3) or (3, 2): 5 steps.
        assert_eq!(at(2, 7), 0);
        assert_eq!(at(0, 7), 2);
        assert_eq!(at(0, 0), 5);
    }

    /// The distance by its definition: the nearest outline pixel, searched over the image.
    fn brute_force(labels: &LabelImage) -> Vec<u16> {
        let (w, h) = labels.dims();
        let at = |x: usize, y: usize| *labels.get(x, y);
        let outline: Vec<(usize, usize)> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                (x > 0 && at(x - 1, y) != at(x, y))
                    || (x + 1 < w && at(x + 1, y) != at(x, y))
                    || (y > 0 && at(x, y - 1) != at(x, y))
                    || (y + 1 < h && at(x, y + 1) != at(x, y))
            })
            .collect();
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                outline
                    .iter()
                    .map(|&(ox, oy)| x.abs_diff(ox) + y.abs_diff(oy))
                    .min()
                    .map_or(u16::MAX, |d| d as u16)
            })
            .collect()
    }

    #[test]
    fn matches_the_nearest_outline_pixel_by_search() {
        // Blobby labels from a small hash; sizes with and without whole groups of 8 rows, one
        // column, one row, and one label everywhere (no outline: saturated).
        for (w, h, kinds) in [(23, 17, 4), (40, 8, 3), (1, 13, 2), (19, 1, 3), (9, 9, 1)] {
            let labels = LabelImage::from_fn(w, h, |x, y| {
                let cell = (x / 3 * 31 + y / 4 * 17) as u32;
                (cell.wrapping_mul(2_654_435_761) >> 13) as u16 % kinds
            });
            let mut d = Vec::new();
            interior_depth(&labels, &mut d);
            assert_eq!(d, brute_force(&labels), "{w}x{h}");
        }
    }

    #[test]
    fn every_pixel_is_one_step_from_a_neighbour_nearer_the_outline() {
        // The defining property of a city-block distance map, on an irregular label image.
        let labels = LabelImage::from_fn(40, 30, |x, y| {
            ((x * 7 + y * 3) / 11 % 3 + (x > 25) as usize) as u16
        });
        let mut d = Vec::new();
        interior_depth(&labels, &mut d);
        for y in 0..30 {
            for x in 0..40 {
                let v = d[y * 40 + x];
                if v == 0 {
                    continue;
                }
                let mut nbrs = vec![];
                if x > 0 {
                    nbrs.push(d[y * 40 + x - 1]);
                }
                if x + 1 < 40 {
                    nbrs.push(d[y * 40 + x + 1]);
                }
                if y > 0 {
                    nbrs.push(d[(y - 1) * 40 + x]);
                }
                if y + 1 < 30 {
                    nbrs.push(d[(y + 1) * 40 + x]);
                }
                assert_eq!(nbrs.iter().min().unwrap() + 1, v, "({x}, {y})");
            }
        }
    }
}
