//! Mesh accuracy and completeness against a ground-truth surface.
//!
//! - accuracy: for every vertex of the reconstruction, the distance to the nearest ground-truth
//!   triangle (mean, and the share within a threshold);
//! - completeness: ground-truth surface samples (every `spacing` metres), the share with a
//!   reconstructed vertex within the threshold. The caller chooses which samples count
//!   (for example only those in observed space).
//!
//! Both use uniform grids, so they cost about linear time in the number of points.

use nalgebra::Point3;
use rustc_hash::FxHashMap;

type Cell = [i64; 3];

fn cell_of(p: &Point3<f64>, size: f64) -> Cell {
    [
        (p.x / size).floor() as i64,
        (p.y / size).floor() as i64,
        (p.z / size).floor() as i64,
    ]
}

/// Triangles binned by the grid cells their bounding boxes touch.
pub struct TriangleIndex {
    triangles: Vec<[Point3<f64>; 3]>,
    cells: FxHashMap<Cell, Vec<u32>>,
    size: f64,
    /// The lowest and highest occupied cell on each axis.
    extent: (Cell, Cell),
}

impl TriangleIndex {
    /// `cell` should be about the search radius.
    pub fn new(triangles: Vec<[Point3<f64>; 3]>, cell: f64) -> Self {
        let mut cells: FxHashMap<Cell, Vec<u32>> = FxHashMap::default();
        for (i, t) in triangles.iter().enumerate() {
            let lo = cell_of(
                &Point3::from(t[0].coords.inf(&t[1].coords).inf(&t[2].coords)),
                cell,
            );
            let hi = cell_of(
                &Point3::from(t[0].coords.sup(&t[1].coords).sup(&t[2].coords)),
                cell,
            );
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        cells.entry([x, y, z]).or_default().push(i as u32);
                    }
                }
            }
        }
        let extent = cells
            .keys()
            .fold(([i64::MAX; 3], [i64::MIN; 3]), |(lo, hi), k| {
                (
                    std::array::from_fn(|a| lo[a].min(k[a])),
                    std::array::from_fn(|a| hi[a].max(k[a])),
                )
            });
        Self {
            triangles,
            cells,
            size: cell,
            extent,
        }
    }

    /// Distance to the nearest triangle within one cell of `p`'s cell (`None` if none).
    pub fn distance(&self, p: &Point3<f64>) -> Option<f64> {
        self.nearest(p).map(|(d, _)| d)
    }

    /// The nearest triangle at any distance: cells are searched in growing shells around
    /// `p`'s cell until no unsearched cell can hold anything closer (every point outside
    /// shell `r` is at least `r` cells away). `None` only without triangles.
    pub fn nearest_exact(&self, p: &Point3<f64>) -> Option<(f64, usize)> {
        if self.triangles.is_empty() {
            return None;
        }
        let c = cell_of(p, self.size);
        let reach = self.max_shell(c);
        let mut best: Option<(f64, usize)> = None;
        for r in 0..=reach {
            for dx in -r..=r {
                for dy in -r..=r {
                    for dz in -r..=r {
                        // Only the shell's surface: the inside was searched already.
                        if dx.abs() != r && dy.abs() != r && dz.abs() != r {
                            continue;
                        }
                        let Some(list) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                            continue;
                        };
                        for &i in list {
                            let d = (closest_point_on_triangle(p, &self.triangles[i as usize]) - p)
                                .norm();
                            if best.is_none_or(|b| d < b.0) {
                                best = Some((d, i as usize));
                            }
                        }
                    }
                }
            }
            if best.is_some_and(|(d, _)| d <= r as f64 * self.size) {
                break;
            }
        }
        best
    }

    /// The shell radius (in cells) around `c` that covers every occupied cell.
    fn max_shell(&self, c: Cell) -> i64 {
        let (lo, hi) = self.extent;
        (0..3)
            .map(|a| (c[a] - lo[a]).abs().max((hi[a] - c[a]).abs()))
            .max()
            .unwrap_or(0)
    }

    /// The nearest triangle within one cell of `p`'s cell: distance and index.
    pub fn nearest(&self, p: &Point3<f64>) -> Option<(f64, usize)> {
        let c = cell_of(p, self.size);
        let mut best: Option<(f64, usize)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &i in list {
                        let d =
                            (closest_point_on_triangle(p, &self.triangles[i as usize]) - p).norm();
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, i as usize));
                        }
                    }
                }
            }
        }
        best
    }
}

/// Points binned in a grid, for nearest-neighbour distances.
pub struct PointIndex {
    cells: FxHashMap<Cell, Vec<Point3<f64>>>,
    size: f64,
}

impl PointIndex {
    pub fn new(points: impl IntoIterator<Item = Point3<f64>>, cell: f64) -> Self {
        let mut cells: FxHashMap<Cell, Vec<Point3<f64>>> = FxHashMap::default();
        for p in points {
            cells.entry(cell_of(&p, cell)).or_default().push(p);
        }
        Self { cells, size: cell }
    }

    /// Whether some point lies within `radius` (≤ the cell size) of `p`.
    pub fn any_within(&self, p: &Point3<f64>, radius: f64) -> bool {
        let c = cell_of(p, self.size);
        (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    self.cells
                        .get(&[c[0] + dx, c[1] + dy, c[2] + dz])
                        .is_some_and(|l| l.iter().any(|q| (q - p).norm() <= radius))
                })
            })
        })
    }
}

/// Points spread over each triangle about `spacing` apart (a barycentric grid).
pub fn sample_triangles(triangles: &[[Point3<f64>; 3]], spacing: f64) -> Vec<Point3<f64>> {
    let mut out = Vec::new();
    for t in triangles {
        let longest = [
            (t[1] - t[0]).norm(),
            (t[2] - t[1]).norm(),
            (t[0] - t[2]).norm(),
        ]
        .into_iter()
        .fold(0.0, f64::max);
        let n = ((longest / spacing).ceil() as usize).max(1);
        for i in 0..=n {
            for j in 0..=(n - i) {
                let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                out.push(t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b);
            }
        }
    }
    out
}

/// The closest point of triangle `t` to `p` (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn closest_point_on_triangle(p: &Point3<f64>, t: &[Point3<f64>; 3]) -> Point3<f64> {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Accuracy and completeness in one go.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceScores {
    /// Distance from each reconstructed vertex to the nearest true triangle, over every
    /// vertex (metres): mean, median and 95th percentile.
    pub accuracy_mean: f64,
    pub accuracy_median: f64,
    pub accuracy_p95: f64,
    /// Percent of reconstructed vertices within the threshold of the truth.
    pub accuracy_within: f64,
    /// Percent of the (selected) truth samples within the threshold of the reconstruction.
    pub completeness_within: f64,
}

/// The `q`-quantile of sorted values (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

/// Exact distance from every vertex to the nearest true triangle (see
/// [`TriangleIndex::nearest_exact`]); in parallel.
pub fn vertex_distances(vertices: &[Point3<f64>], index: &TriangleIndex) -> Vec<f64> {
    use rayon::prelude::*;
    vertices
        .par_iter()
        .map(|v| index.nearest_exact(v).map_or(f64::INFINITY, |(d, _)| d))
        .collect()
}

/// How far reconstructed vertices lie from the truth (metres; `within` in percent).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Accuracy {
    pub mean: f64,
    pub median: f64,
    pub p95: f64,
    /// Percent of vertices within the threshold.
    pub within: f64,
}

/// Exact distance statistics of every vertex to the nearest triangle of `index`.
pub fn accuracy(vertices: &[Point3<f64>], index: &TriangleIndex, threshold: f64) -> Accuracy {
    let mut distances = vertex_distances(vertices, index);
    distances.sort_by(f64::total_cmp);
    let within = distances.iter().filter(|&&d| d <= threshold).count();
    Accuracy {
        mean: if distances.is_empty() {
            f64::NAN
        } else {
            distances.iter().sum::<f64>() / distances.len() as f64
        },
        median: quantile(&distances, 0.5),
        p95: quantile(&distances, 0.95),
        within: if vertices.is_empty() {
            0.0
        } else {
            100.0 * within as f64 / vertices.len() as f64
        },
    }
}

/// Scores `vertices` against `truth`; `counts(sample)` selects the truth samples that should
/// have been reconstructed.
pub fn surface_scores(
    vertices: &[Point3<f64>],
    truth: Vec<[Point3<f64>; 3]>,
    threshold: f64,
    spacing: f64,
    counts: impl Fn(&Point3<f64>) -> bool,
) -> SurfaceScores {
    let samples: Vec<Point3<f64>> = sample_triangles(&truth, spacing)
        .into_iter()
        .filter(|p| counts(p))
        .collect();
    let index = TriangleIndex::new(truth, threshold.max(spacing) * 2.0);
    let accuracy = accuracy(vertices, &index, threshold);
    let points = PointIndex::new(vertices.iter().copied(), threshold);
    let covered = samples
        .iter()
        .filter(|s| points.any_within(s, threshold))
        .count();
    let pct = |a: usize, b: usize| {
        if b == 0 {
            0.0
        } else {
            100.0 * a as f64 / b as f64
        }
    };
    SurfaceScores {
        accuracy_mean: accuracy.mean,
        accuracy_median: accuracy.median,
        accuracy_p95: accuracy.p95,
        accuracy_within: accuracy.within,
        completeness_within: pct(covered, samples.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_search_equals_brute_force() {
        // Deterministic pseudo-random triangles and points (xorshift).
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rand = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut point = |scale: f64| Point3::new(rand() * scale, rand() * scale, rand() * scale);
        let triangles: Vec<[Point3<f64>; 3]> = (0..300)
            .map(|_| {
                let a = point(2.0);
                [a, a + point(0.2).coords, a + point(0.2).coords]
            })
            .collect();
        let points: Vec<Point3<f64>> = (0..300).map(|_| point(3.0)).collect();
        let index = TriangleIndex::new(triangles.clone(), 0.04);
        for p in &points {
            let brute = triangles
                .iter()
                .map(|t| (closest_point_on_triangle(p, t) - p).norm())
                .fold(f64::INFINITY, f64::min);
            let (d, _) = index.nearest_exact(p).unwrap();
            assert!((d - brute).abs() < 1e-12, "{d} vs {brute} at {p:?}");
        }
    }

    #[test]
    fn exact_search_reaches_beyond_the_first_cells() {
        let t = vec![[
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ]];
        let index = TriangleIndex::new(t, 0.05);
        let p = Point3::new(0.2, 0.2, 0.73);
        assert!(
            index.distance(&p).is_none(),
            "beyond the neighbouring cells"
        );
        let (d, i) = index.nearest_exact(&p).unwrap();
        assert!((d - 0.73).abs() < 1e-12 && i == 0);
        assert_eq!(quantile(&[1.0, 2.0, 3.0, 4.0], 0.5), 2.0);
        assert_eq!(quantile(&[1.0, 2.0, 3.0, 4.0], 0.95), 4.0);
    }

    #[test]
    fn closest_points_in_every_region() {
        let t = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ];
        let c = |x: f64, y: f64, z: f64| closest_point_on_triangle(&Point3::new(x, y, z), &t);
        let near = |a: Point3<f64>, b: Point3<f64>| (a - b).norm() < 1e-12;
        assert!(near(c(0.2, 0.2, 5.0), Point3::new(0.2, 0.2, 0.0))); // face
        assert!(near(c(-1.0, -1.0, 0.0), t[0])); // vertex a
        assert!(near(c(3.0, -1.0, 0.0), t[1])); // vertex b
        assert!(near(c(0.5, -2.0, 1.0), Point3::new(0.5, 0.0, 0.0))); // edge ab
        assert!(near(c(1.0, 1.0, 0.0), Point3::new(0.5, 0.5, 0.0))); // edge bc
    }

    #[test]
    fn scores_of_a_shifted_square() {
        let sq = |z: f64| {
            vec![
                [
                    Point3::new(0.0, 0.0, z),
                    Point3::new(1.0, 0.0, z),
                    Point3::new(1.0, 1.0, z),
                ],
                [
                    Point3::new(0.0, 0.0, z),
                    Point3::new(1.0, 1.0, z),
                    Point3::new(0.0, 1.0, z),
                ],
            ]
        };
        // The reconstruction: samples of the square lifted by 1 cm, covering only x < 0.5.
        let recon: Vec<Point3<f64>> = sample_triangles(&sq(0.01), 0.02)
            .into_iter()
            .filter(|p| p.x < 0.5)
            .collect();
        let s = surface_scores(&recon, sq(0.0), 0.03, 0.02, |_| true);
        assert!((s.accuracy_mean - 0.01).abs() < 1e-9);
        assert!((s.accuracy_median - 0.01).abs() < 1e-9 && (s.accuracy_p95 - 0.01).abs() < 1e-9);
        assert_eq!(s.accuracy_within, 100.0);
        assert!(
            (s.completeness_within - 52.0).abs() < 4.0,
            "{}",
            s.completeness_within
        );
    }
}
