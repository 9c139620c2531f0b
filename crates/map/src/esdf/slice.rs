//! A 2-D costmap cut from the distance field between two heights: what Nav2 and move_base
//! plan on, in ROS map_server's PGM + YAML form or as a `nav_msgs/OccupancyGrid`.

use rustc_hash::FxHashMap;

use super::Esdf;
use crate::UpAxis;

/// One cell of a [`Costmap`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CostmapCell {
    /// No voxel of the cell's column within the height band was observed.
    Unknown,
    Free,
    /// A surface (or the inside of an object) lies within the robot's radius.
    Occupied,
}

/// A grid over the plane normal to the up axis: per cell, the least signed distance to the
/// surface among the observed voxels of its column within the height band.
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
    /// Row-major, row 0 at the lowest second coordinate; `None` where unknown.
    pub clearance: Vec<Option<f32>>,
    /// Cells whose clearance is at most this (metres) are occupied.
    pub robot_radius: f32,
}

impl Costmap {
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
        format!(
            "image: {image}\nmode: trinary\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            self.resolution, self.origin[0], self.origin[1]
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
        let mut columns: FxHashMap<[i32; 2], f32> = FxHashMap::default();
        for (v, d) in self.voxels() {
            let height = (v[up_axis] as f64 + 0.5) * s * if negative { -1.0 } else { 1.0 };
            if height < band[0] || height > band[1] {
                continue;
            }
            let key = [v[axes[0]], v[axes[1]]];
            let least = columns.entry(key).or_insert(f32::INFINITY);
            *least = least.min(d);
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
        let mut clearance = vec![None; width * height];
        for (key, d) in columns {
            let (column, row) = ((key[0] - low[0]) as usize, (key[1] - low[1]) as usize);
            clearance[row * width + column] = Some(d);
        }
        Some(Costmap {
            resolution: s,
            axes,
            origin: [low[0] as f64 * s, low[1] as f64 * s],
            width,
            height,
            clearance,
            robot_radius,
        })
    }
}
