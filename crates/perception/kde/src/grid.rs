/// An equidistant grid of `len` points from `start` to `end`, both included.
///
/// Point `i` is `start + i × step` and the last point is exactly `end`, as NumPy's `linspace`
/// builds it (the KDEpy-compatible mode depends on that).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub start: f64,
    pub end: f64,
    pub len: usize,
}

impl Grid {
    /// A grid of `len >= 2` points; `len` below 2 is raised to 2 so that `step` stays finite.
    pub fn new(start: f64, end: f64, len: usize) -> Self {
        Self {
            start,
            end,
            len: len.max(2),
        }
    }

    /// Distance between neighbouring points.
    #[inline]
    pub fn step(&self) -> f64 {
        (self.end - self.start) / (self.len - 1) as f64
    }

    /// `end - start`.
    #[inline]
    pub fn range(&self) -> f64 {
        self.end - self.start
    }

    /// The `i`-th grid point.
    #[inline]
    pub fn point(&self, i: usize) -> f64 {
        if i + 1 == self.len {
            self.end
        } else {
            self.start + i as f64 * self.step()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_are_exact() {
        let g = Grid::new(-0.3, 1.7, 1024);
        assert_eq!(g.point(0), -0.3);
        assert_eq!(g.point(1023), 1.7);
        assert!((g.point(512) - (-0.3 + 512.0 * 2.0 / 1023.0)).abs() < 1e-15);
    }
}
