/// A dense, row-major image of `width × height` pixels of type `T`.
#[derive(Clone, Debug, PartialEq)]
pub struct Image<T> {
    width: usize,
    height: usize,
    data: Vec<T>,
}

/// Depth in metres along the optical axis; `0` (or any non-finite / negative value) is invalid.
pub type DepthImage = Image<f32>;

/// Per-pixel segment ids; `0` is void.
pub type LabelImage = Image<u16>;

/// 8-bit RGB.
pub type ColorImage = Image<[u8; 3]>;

/// The one place that says what a usable depth measurement is: finite and positive.
///
/// As bits: the positive finite floats are exactly 1..=0x7f7f_ffff (zero, infinities, NaNs and
/// negatives all fall outside), one subtraction and one comparison. It is called per pixel
/// and per voxel by every stage; `is_finite() && > 0.0` cost about twice as much.
#[inline]
pub fn is_valid_depth(d: f32) -> bool {
    d.to_bits().wrapping_sub(1) < f32::MAX.to_bits()
}

/// A usable depth ([`is_valid_depth`]) within `[near, far]`. Spelled with the float tests, which
/// the compiler folds into the range comparisons (in the integrator's voxel loop the bit test
/// cost 10 instructions a voxel more).
#[inline]
pub fn is_depth_within(d: f32, near: f32, far: f32) -> bool {
    d.is_finite() && d > 0.0 && d >= near && d <= far
}

impl<T: Clone> Image<T> {
    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: T) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }
}

impl<T> Image<T> {
    /// Wraps `data` (row-major). Returns `None` when its length is not `width × height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// An image whose pixel `(x, y)` is `f(x, y)`.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Self {
            width,
            height,
            data,
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// `(width, height)`, handy for comparing shapes.
    pub fn dims(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    pub fn pixels(&self) -> &[T] {
        &self.data
    }

    pub fn pixels_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    pub fn into_vec(self) -> Vec<T> {
        self.data
    }

    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Pixel `(x, y)`; panics when out of bounds, like slice indexing.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> &T {
        &self.data[y * self.width + x]
    }

    #[inline]
    pub fn get_mut(&mut self, x: usize, y: usize) -> &mut T {
        &mut self.data[y * self.width + x]
    }

    /// A new image of the same size with `f` applied to every pixel.
    pub fn map<U>(&self, f: impl FnMut(&T) -> U) -> Image<U> {
        Image {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(f).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_vec_checks_length() {
        assert!(Image::from_vec(3, 2, vec![0u8; 6]).is_some());
        assert!(Image::from_vec(3, 2, vec![0u8; 5]).is_none());
    }

    #[test]
    fn indexing_is_row_major() {
        let img = Image::from_fn(4, 3, |x, y| (10 * y + x) as u16);
        assert_eq!(*img.get(3, 2), 23);
        assert_eq!(img.row(1), &[10, 11, 12, 13]);
    }

    #[test]
    fn depth_validity() {
        assert!(is_valid_depth(0.5));
        assert!(!is_valid_depth(0.0));
        assert!(!is_valid_depth(-1.0));
        assert!(!is_valid_depth(f32::NAN));
        assert!(!is_valid_depth(f32::INFINITY));
        // The bit test agrees with the definition on every boundary and special value.
        let cases = [
            0.0,
            -0.0,
            f32::from_bits(1),
            f32::MIN_POSITIVE,
            1e-30,
            7.5,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7fc0_0001),
            -f32::from_bits(1),
            -f32::MAX,
        ];
        for d in cases {
            assert_eq!(is_valid_depth(d), d.is_finite() && d > 0.0, "{d:?}");
        }
        // And on a sweep of bit patterns across the whole range.
        for bits in (0..=u32::MAX).step_by(65_537) {
            let d = f32::from_bits(bits);
            assert_eq!(is_valid_depth(d), d.is_finite() && d > 0.0, "{bits:#x}");
        }
    }
}
