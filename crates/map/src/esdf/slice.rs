//! A 2-D costmap cut from the distance field between two heights: what Nav2 and move_base
//! plan on, in ROS map_server's PGM + YAML form or as a `nav_msgs/OccupancyGrid`.

use rustc_hash::FxHashMap;
use voxpan_core::nalgebra::Vector3;

use super::Esdf;
use crate::UpAxis;
use crate::layer::BlockIndex;

/// One cell of a [`Costmap`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CostmapCell {
    /// No voxel of the cell's column within the height band was observed.
    Unknown,
    Free,
    /// A surface (or the inside of an object) lies within the robot's radius.
    Occupied,
}

/// A grid over the plane normal to the up axis. A cell is an obstacle where an observed voxel
/// of its column within the height band is a surface (or inside an object); its clearance is
/// the distance in the plane to the nearest obstacle cell (a 2-D exact Euclidean distance
/// transform of the slice, as a costmap's inflation reads it: the floor or a ceiling just
/// outside the band does not narrow a corridor).
#[derive(Clone, Debug, PartialEq)]
pub struct Costmap {
    /// Cell edge in metres (the voxel size).
    pub resolution: f64,
    /// The world axes the grid's columns and rows run along (the up axis's successors, so
    /// that the grid seen from above is right-handed).
    pub axes: [usize; 2],
    /// World coordinates, along `axes`, of the corner of cell `(0, 0)`.
    pub origin: [f64; 2],
    pub width: usize,
    pub height: usize,
    /// Per cell, row-major, row 0 at the lowest second coordinate: metres to the nearest
    /// obstacle cell's centre (0 on obstacles, infinite with none); `None` where unknown.
    pub clearance: Vec<Option<f32>>,
    /// Cells whose clearance is at most this (metres) are occupied.
    pub robot_radius: f32,
    /// The band's lower height, metres along the up axis: where the grid lies.
    pub elevation: f64,
}

impl Costmap {
    /// Where cell `(0, 0)`'s corner lies in the world and how the grid is turned: its
    /// columns along the pose's x axis, its rows along y, up along z (a
    /// `nav_msgs/MapMetaData` origin).
    pub fn origin_pose(&self) -> voxpan_core::Pose {
        use voxpan_core::nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};
        let [a, b, up] = self.frame();
        let corner = self.world(self.origin[0], self.origin[1]);
        let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[a, b, up]));
        voxpan_core::Pose::from_parts(
            Translation3::from(corner),
            UnitQuaternion::from_rotation_matrix(&rotation),
        )
    }

    /// The grid's column and row directions and its up direction, in world coordinates.
    fn frame(&self) -> [Vector3<f64>; 3] {
        let unit = |axis: usize| {
            let mut v = Vector3::zeros();
            v[axis] = 1.0;
            v
        };
        let (a, b) = (unit(self.axes[0]), unit(self.axes[1]));
        [a, b, a.cross(&b)]
    }

    /// The world point at plane coordinates `(u, v)` (along `axes`) on the grid.
    fn world(&self, u: f64, v: f64) -> Vector3<f64> {
        let [a, b, up] = self.frame();
        a * u + b * v + up * self.elevation
    }

    /// The centre of cell `(column, row)` in the world, on the grid's plane.
    pub fn cell_centre(&self, column: usize, row: usize) -> [f64; 3] {
        let centre = |origin: f64, i: usize| origin + (i as f64 + 0.5) * self.resolution;
        let p = self.world(centre(self.origin[0], column), centre(self.origin[1], row));
        [p.x, p.y, p.z]
    }

    /// Every known cell's centre and clearance (metres, at most `cap`), row-major from the
    /// origin: the distance slice nvblox publishes as a point cloud.
    pub fn clearance_points(&self, cap: f32) -> Vec<([f64; 3], f32)> {
        (0..self.height)
            .flat_map(|row| (0..self.width).map(move |column| (column, row)))
            .filter_map(|(column, row)| {
                let clearance = self.clearance[row * self.width + column]?;
                Some((self.cell_centre(column, row), clearance.min(cap)))
            })
            .collect()
    }

    pub fn cell(&self, column: usize, row: usize) -> CostmapCell {
        match self.clearance[row * self.width + column] {
            None => CostmapCell::Unknown,
            Some(d) if d <= self.robot_radius => CostmapCell::Occupied,
            Some(_) => CostmapCell::Free,
        }
    }

    /// Cells counted by kind: `(unknown, free, occupied)`.
    pub fn counts(&self) -> (usize, usize, usize) {
        let mut counts = (0, 0, 0);
        for row in 0..self.height {
            for column in 0..self.width {
                match self.cell(column, row) {
                    CostmapCell::Unknown => counts.0 += 1,
                    CostmapCell::Free => counts.1 += 1,
                    CostmapCell::Occupied => counts.2 += 1,
                }
            }
        }
        counts
    }

    /// `nav_msgs/OccupancyGrid` data: 100 occupied, 0 free, -1 unknown, row-major from the
    /// origin.
    pub fn occupancy(&self) -> Vec<i8> {
        (0..self.height)
            .flat_map(|row| (0..self.width).map(move |column| (column, row)))
            .map(|(column, row)| match self.cell(column, row) {
                CostmapCell::Unknown => -1,
                CostmapCell::Free => 0,
                CostmapCell::Occupied => 100,
            })
            .collect()
    }

    /// A binary PGM (P5) as map_server reads it: black occupied, white free, grey unknown,
    /// the first image row at the grid's highest row (images run top-down).
    pub fn pgm(&self) -> Vec<u8> {
        let mut out = format!(
            "P5\n# voxpan costmap\n{} {}\n255\n",
            self.width, self.height
        )
        .into_bytes();
        for row in (0..self.height).rev() {
            out.extend((0..self.width).map(|column| match self.cell(column, row) {
                CostmapCell::Unknown => 205,
                CostmapCell::Free => 254,
                CostmapCell::Occupied => 0,
            }));
        }
        out
    }

    /// map_server's YAML for the PGM saved as `image` beside it (trinary mode: the PGM's
    /// three shades read back as occupied, free and unknown).
    pub fn yaml(&self, image: &str) -> String {
        // To the micrometre: `-5.6`, not `-5.6000000000000005`.
        let micro = |x: f64| (x * 1e6).round() / 1e6;
        format!(
            "image: {image}\nmode: trinary\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            self.resolution,
            micro(self.origin[0]),
            micro(self.origin[1])
        )
    }
}

/// The grid's two axes for `up`: the up axis's successors (swapped when up is negative, so
/// that the grid seen from above stays right-handed).
fn plane(up: UpAxis) -> [usize; 2] {
    let (axis, negative) = up.axis();
    let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
    if negative { [b, a] } else { [a, b] }
}

impl Esdf {
    /// The costmap of the voxels whose centres lie between heights `band[0]` and `band[1]`
    /// (metres along `up`); `None` when no observed voxel does.
    pub(crate) fn costmap(&self, band: [f64; 2], up: UpAxis, robot_radius: f32) -> Option<Costmap> {
        let s = self.voxel_size;
        let axes = plane(up);
        let (up_axis, negative) = up.axis();
        // Per column of the band: whether any voxel was observed, and whether one is an
        // obstacle (a site, or inside).
        let mut columns: FxHashMap<[i32; 2], bool> = FxHashMap::default();
        // Only blocks reaching into the band are read.
        let block = s * crate::layer::BLOCK_SIDE as f64;
        let reaches_band = |index: &BlockIndex| {
            let (low, high) = (
                index[up_axis] as f64 * block,
                (index[up_axis] + 1) as f64 * block,
            );
            let (low, high) = if negative { (-high, -low) } else { (low, high) };
            high >= band[0] && low <= band[1]
        };
        for (v, d) in self.voxels_of_blocks(reaches_band) {
            let height = (v[up_axis] as f64 + 0.5) * s * if negative { -1.0 } else { 1.0 };
            if height < band[0] || height > band[1] {
                continue;
            }
            *columns.entry([v[axes[0]], v[axes[1]]]).or_default() |= d <= 0.0;
        }
        let low = columns
            .keys()
            .copied()
            .reduce(|a, b| [a[0].min(b[0]), a[1].min(b[1])])?;
        let high = columns
            .keys()
            .copied()
            .reduce(|a, b| [a[0].max(b[0]), a[1].max(b[1])])?;
        let (width, height) = (
            (high[0] - low[0] + 1) as usize,
            (high[1] - low[1] + 1) as usize,
        );
        let mut obstacle = vec![false; width * height];
        let mut known = vec![false; width * height];
        for (key, is_obstacle) in columns {
            let at = (key[1] - low[1]) as usize * width + (key[0] - low[0]) as usize;
            known[at] = true;
            obstacle[at] = is_obstacle;
        }
        let squared = squared_distance_transform(&obstacle, width, height);
        let clearance = known
            .iter()
            .zip(squared)
            .map(|(&k, d2)| k.then(|| d2.sqrt() as f32 * s as f32))
            .collect();
        Some(Costmap {
            resolution: s,
            axes,
            origin: [low[0] as f64 * s, low[1] as f64 * s],
            width,
            height,
            clearance,
            robot_radius,
            elevation: band[0],
        })
    }
}

/// Per cell of a `width × height` grid (row-major), the squared distance in cells to the
/// nearest `obstacle` cell (infinite with none): exact, by Felzenszwalb and Huttenlocher's
/// lower envelope of parabolas along rows, then along columns.
pub(crate) fn squared_distance_transform(
    obstacle: &[bool],
    width: usize,
    height: usize,
) -> Vec<f64> {
    let mut grid: Vec<f64> = obstacle
        .iter()
        .map(|&o| if o { 0.0 } else { f64::INFINITY })
        .collect();
    let mut line = Vec::new();
    for row in 0..height {
        line.clear();
        line.extend_from_slice(&grid[row * width..(row + 1) * width]);
        let out = envelope(&line);
        grid[row * width..(row + 1) * width].copy_from_slice(&out);
    }
    for column in 0..width {
        line.clear();
        line.extend((0..height).map(|row| grid[row * width + column]));
        for (row, d) in envelope(&line).into_iter().enumerate() {
            grid[row * width + column] = d;
        }
    }
    grid
}

/// The 1-D squared distance transform of `f` (`min over q of (p - q)² + f(q)`), infinite
/// entries being no sample.
fn envelope(f: &[f64]) -> Vec<f64> {
    let n = f.len();
    // Parabola apexes in the envelope, and where each begins to be the lowest.
    let mut apex: Vec<usize> = Vec::with_capacity(n);
    let mut from: Vec<f64> = Vec::with_capacity(n + 1);
    for q in (0..n).filter(|&q| f[q].is_finite()) {
        loop {
            let Some(&last) = apex.last() else {
                apex.push(q);
                from.push(f64::NEG_INFINITY);
                break;
            };
            let (qf, lf) = (q as f64, last as f64);
            let cross = ((f[q] + qf * qf) - (f[last] + lf * lf)) / (2.0 * (qf - lf));
            if cross <= *from.last().expect("one per apex") {
                apex.pop();
                from.pop();
            } else {
                apex.push(q);
                from.push(cross);
                break;
            }
        }
    }
    if apex.is_empty() {
        return vec![f64::INFINITY; n];
    }
    let mut k = 0;
    (0..n)
        .map(|p| {
            let pf = p as f64;
            while k + 1 < apex.len() && from[k + 1] <= pf {
                k += 1;
            }
            let q = apex[k] as f64;
            (pf - q) * (pf - q) + f[apex[k]]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The transform against brute force on random grids.
    #[test]
    fn the_distance_transform_is_exact() {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        for (width, height, density) in [(1, 1, 2), (7, 1, 3), (23, 17, 10), (40, 31, 50)] {
            let obstacle: Vec<bool> = (0..width * height).map(|_| next() % density == 0).collect();
            let ours = squared_distance_transform(&obstacle, width, height);
            for (p, &distance) in ours.iter().enumerate() {
                let (px, py) = ((p % width) as i64, (p / width) as i64);
                let exact = (0..width * height)
                    .filter(|&q| obstacle[q])
                    .map(|q| {
                        let (qx, qy) = ((q % width) as i64, (q / width) as i64);
                        ((px - qx).pow(2) + (py - qy).pow(2)) as f64
                    })
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(distance, exact, "{width}x{height} cell {p}");
            }
        }
    }
}
