//! How deep inside its own mask each pixel lies.

use voxpan_core::LabelImage;

/// City-block distance (in pixels) from every pixel to the nearest pixel of its mask's
/// outline: a pixel with a 4-neighbour carrying another label. The image border is not an
/// outline (a mask cut by the frame continues beyond it). Two raster passes; saturates at
/// `u16::MAX`. The exact metric hardly matters for its use (weighing a mask's core against its
/// rim); the 4-neighbour one is the cheapest to propagate.
pub fn interior_depth(labels: &LabelImage, out: &mut Vec<u16>) {
    let (w, h) = labels.dims();
    let l = labels.pixels();
    out.clear();
    out.resize(w * h, u16::MAX);
    if w == 0 || h == 0 {
        return;
    }
    // Outline: both pixels of every unequal horizontal or vertical pair.
    for y in 0..h {
        let row = &l[y * w..(y + 1) * w];
        for x in 1..w {
            if row[x] != row[x - 1] {
                out[y * w + x] = 0;
                out[y * w + x - 1] = 0;
            }
        }
        if y > 0 {
            let up = &l[(y - 1) * w..y * w];
            for x in 0..w {
                if row[x] != up[x] {
                    out[y * w + x] = 0;
                    out[(y - 1) * w + x] = 0;
                }
            }
        }
    }
    // Forward pass (from above, then from the left), then backward (below, right).
    for y in 0..h {
        let (before, rest) = out.split_at_mut(y * w);
        let row = &mut rest[..w];
        if y > 0 {
            for (d, &u) in row.iter_mut().zip(&before[(y - 1) * w..]) {
                *d = (*d).min(u.saturating_add(1));
            }
        }
        for x in 1..w {
            row[x] = row[x].min(row[x - 1].saturating_add(1));
        }
    }
    for y in (0..h).rev() {
        let (rest, after) = out.split_at_mut((y + 1) * w);
        let row = &mut rest[y * w..];
        if y + 1 < h {
            for (d, &b) in row.iter_mut().zip(&after[..w]) {
                *d = (*d).min(b.saturating_add(1));
            }
        }
        for x in (0..w - 1).rev() {
            row[x] = row[x].min(row[x + 1].saturating_add(1));
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
