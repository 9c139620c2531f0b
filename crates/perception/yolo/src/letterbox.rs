//! The letterbox: an image scaled to fit the network's input with its aspect kept, centred on
//! gray, as YOLO models are trained; and the map between image and input pixels.
//!
//! Integer-exact like `tools/yolo/yolo_common.py` (the goldens' pre-processing): resized size
//! `round(w r) × round(h r)` with `r = min(H / h, W / w)` (ties to even, as Python rounds),
//! pads `(W - nw) / 2` left and `(H - nh) / 2` top (floored), bilinear resampling with
//! half-pixel centres and edge clamp, rounded back to 8 bits as an 8-bit resize would.

use voxpan_core::ColorImage;

/// The gray of the padding (YOLO's training letterbox).
pub const PAD_VALUE: u8 = 114;

/// Where an image lies in the network's input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Letterbox {
    /// The image's size, `(width, height)`.
    pub image: (usize, usize),
    /// The network input's size, `(width, height)`.
    pub input: (usize, usize),
    /// The image's size once scaled, `(width, height)`.
    pub resized: (usize, usize),
    /// Input columns left of the image.
    pub left: usize,
    /// Input rows above the image.
    pub top: usize,
}

impl Letterbox {
    /// The letterbox of an `image_w × image_h` image in an `input_w × input_h` input; `None`
    /// when a size is zero.
    pub fn new(image_w: usize, image_h: usize, input_w: usize, input_h: usize) -> Option<Self> {
        if image_w == 0 || image_h == 0 || input_w == 0 || input_h == 0 {
            return None;
        }
        let r = f64::min(
            input_h as f64 / image_h as f64,
            input_w as f64 / image_w as f64,
        );
        // At least one pixel, at most the input: a 1×1000 image still maps somewhere.
        let nw = ((image_w as f64 * r).round_ties_even() as usize).clamp(1, input_w);
        let nh = ((image_h as f64 * r).round_ties_even() as usize).clamp(1, input_h);
        Some(Self {
            image: (image_w, image_h),
            input: (input_w, input_h),
            resized: (nw, nh),
            left: (input_w - nw) / 2,
            top: (input_h - nh) / 2,
        })
    }

    /// Input pixels per image pixel, per axis (`resized / image`; the two differ from `r` by
    /// the rounding of the resized size only).
    pub fn scale(&self) -> (f64, f64) {
        (
            self.resized.0 as f64 / self.image.0 as f64,
            self.resized.1 as f64 / self.image.1 as f64,
        )
    }

    /// An image point (continuous pixel coordinates: pixel `(u, v)` covers `[u, u+1) ×
    /// [v, v+1)`) in input pixels.
    pub fn to_input(&self, x: f64, y: f64) -> (f64, f64) {
        let (sx, sy) = self.scale();
        (x * sx + self.left as f64, y * sy + self.top as f64)
    }

    /// An input point in image pixels (the inverse of [`to_input`](Self::to_input)).
    pub fn to_image(&self, x: f64, y: f64) -> (f64, f64) {
        let (sx, sy) = self.scale();
        ((x - self.left as f64) / sx, (y - self.top as f64) / sy)
    }

    /// The network input for `image`: `[1, 3, H, W]` float32, RGB planes, values `/ 255`,
    /// written into `out` (resized to `3 H W`). `image` must be `self.image` in size.
    pub fn fill_input(&self, image: &ColorImage, out: &mut Vec<f32>) {
        assert_eq!(
            image.dims(),
            self.image,
            "image size differs from the letterbox's"
        );
        let (w_in, h_in) = self.input;
        let plane = w_in * h_in;
        out.clear();
        out.resize(3 * plane, PAD_VALUE as f32 / 255.0);
        let (nw, nh) = self.resized;
        let mut put = |x: usize, y: usize, rgb: [f32; 3]| {
            let at = (y + self.top) * w_in + x + self.left;
            for (c, v) in rgb.into_iter().enumerate() {
                out[c * plane + at] = v / 255.0;
            }
        };
        if (nw, nh) == self.image {
            for (y, row) in (0..nh).map(|y| (y, image.row(y))) {
                for (x, p) in row.iter().enumerate() {
                    put(x, y, p.map(|v| v as f32));
                }
            }
            return;
        }
        let cols = axis_weights(nw, self.image.0);
        let rows = axis_weights(nh, self.image.1);
        for (y, &(y0, y1, fy)) in rows.iter().enumerate() {
            let (r0, r1) = (image.row(y0), image.row(y1));
            for (x, &(x0, x1, fx)) in cols.iter().enumerate() {
                let mut rgb = [0f32; 3];
                for (c, v) in rgb.iter_mut().enumerate() {
                    let px = |row: &[[u8; 3]], i: usize| row[i][c] as f32;
                    // Same operations in the same order as the Python reference (float32, no
                    // fused multiply-add), so that the goldens' inputs are reproduced bit for bit.
                    let top = px(r0, x0) * (1.0 - fx) + px(r0, x1) * fx;
                    let bottom = px(r1, x0) * (1.0 - fx) + px(r1, x1) * fx;
                    let value = top * (1.0 - fy) + bottom * fy;
                    *v = value.round_ties_even().clamp(0.0, 255.0);
                }
                put(x, y, rgb);
            }
        }
    }
}

/// Bilinear sampling of `n_in` samples at `n_out` positions with half-pixel centres and edge
/// clamp: per output index, the two source indices and the weight of the second.
pub(crate) fn axis_weights(n_out: usize, n_in: usize) -> Vec<(usize, usize, f32)> {
    let step = n_in as f64 / n_out as f64;
    (0..n_out)
        .map(|i| sample_at((i as f64 + 0.5) * step - 0.5, n_in))
        .collect()
}

/// The two source indices around continuous index `src` (clamped into `0..n`) and the weight
/// of the second.
#[inline]
pub(crate) fn sample_at(src: f64, n: usize) -> (usize, usize, f32) {
    let src = src.clamp(0.0, (n - 1) as f64);
    let i0 = src.floor() as usize;
    (i0, (i0 + 1).min(n - 1), (src - i0 as f64) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_of_the_flat_frame() {
        // 640×480 into 640×640: no scaling, 80 rows of padding above and below.
        let lb = Letterbox::new(640, 480, 640, 640).unwrap();
        assert_eq!((lb.resized, lb.left, lb.top), ((640, 480), 0, 80));
        // Into 320×320: half size; into the tiny models' 160×128: a quarter, 4 rows on top.
        let lb = Letterbox::new(640, 480, 320, 320).unwrap();
        assert_eq!((lb.resized, lb.left, lb.top), ((320, 240), 0, 40));
        let lb = Letterbox::new(640, 480, 160, 128).unwrap();
        assert_eq!((lb.resized, lb.left, lb.top), ((160, 120), 0, 4));
        // A portrait image pads left and right; odd slack floors on the left.
        let lb = Letterbox::new(300, 600, 640, 640).unwrap();
        assert_eq!((lb.resized, lb.left, lb.top), ((320, 640), 160, 0));
        let lb = Letterbox::new(101, 100, 64, 64).unwrap();
        assert_eq!((lb.resized, lb.left, lb.top), ((64, 63), 0, 0));
        assert!(Letterbox::new(0, 10, 64, 64).is_none());
    }

    #[test]
    fn rounding_ties_go_to_even_like_python() {
        // 5 × 0.5 = 2.5 rounds to 2 in Python (banker's rounding), not 3.
        let lb = Letterbox::new(10, 5, 5, 5).unwrap();
        assert_eq!(lb.resized, (5, 2));
        assert_eq!(lb.top, 1);
    }

    #[test]
    fn coordinates_round_trip_exactly() {
        for (w, h, iw, ih) in [
            (640, 480, 640, 640),
            (640, 480, 320, 320),
            (333, 517, 160, 128),
        ] {
            let lb = Letterbox::new(w, h, iw, ih).unwrap();
            for &(x, y) in &[
                (0.0, 0.0),
                (w as f64, h as f64),
                (204.25, 259.5),
                (17.0, 3.75),
            ] {
                let (xi, yi) = lb.to_input(x, y);
                let (xb, yb) = lb.to_image(xi, yi);
                assert!((xb - x).abs() < 1e-9 && (yb - y).abs() < 1e-9, "{x},{y}");
            }
            // The image's corners land on the resized area's corners.
            assert_eq!(lb.to_input(0.0, 0.0), (lb.left as f64, lb.top as f64));
            let (x1, y1) = lb.to_input(w as f64, h as f64);
            assert!((x1 - (lb.left + lb.resized.0) as f64).abs() < 1e-9);
            assert!((y1 - (lb.top + lb.resized.1) as f64).abs() < 1e-9);
        }
    }

    #[test]
    fn unscaled_pixels_come_back_exactly_and_padding_is_gray() {
        let image = ColorImage::from_fn(6, 4, |x, y| [(x * 40) as u8, (y * 60) as u8, 255]);
        let lb = Letterbox::new(6, 4, 6, 6).unwrap();
        let mut t = Vec::new();
        lb.fill_input(&image, &mut t);
        assert_eq!(t.len(), 3 * 36);
        let at = |c: usize, x: usize, y: usize| t[c * 36 + y * 6 + x];
        for y in 0..6 {
            for x in 0..6 {
                for c in 0..3 {
                    let want = if (1..5).contains(&y) {
                        image.get(x, y - 1)[c]
                    } else {
                        PAD_VALUE
                    };
                    // The input holds v / 255; times 255 and rounded it is the byte again.
                    assert_eq!((at(c, x, y) * 255.0).round() as u8, want, "{c} {x} {y}");
                    assert_eq!(at(c, x, y), want as f32 / 255.0);
                }
            }
        }
    }

    #[test]
    fn halving_averages_pixel_pairs() {
        // Half-pixel centres: output pixel i samples source 2i + 0.5, the mean of 2i and 2i+1.
        let image = ColorImage::from_fn(4, 2, |x, _| [(x * 10) as u8, 0, 0]);
        let lb = Letterbox::new(4, 2, 2, 2).unwrap();
        assert_eq!((lb.resized, lb.top), ((2, 1), 0));
        let mut t = Vec::new();
        lb.fill_input(&image, &mut t);
        // Row 0 is the image (5 and 25 rounded to even stay 5 and 25), row 1 padding.
        assert_eq!((t[0], t[1]), (5.0 / 255.0, 25.0 / 255.0));
        assert_eq!(t[2], PAD_VALUE as f32 / 255.0);
    }
}
