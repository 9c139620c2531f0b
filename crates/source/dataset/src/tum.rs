//! TUM RGB-D benchmark layout: `rgb.txt` and `depth.txt` (`timestamp filename`),
//! `groundtruth.txt` (`timestamp tx ty tz qx qy qz qw`), 16-bit depth PNGs in units of 1/5000 m.
//! Each depth image is paired with the nearest colour image and pose within 20 ms.

use std::path::{Path, PathBuf};

use voxpan_core::nalgebra::{Quaternion, Translation3, UnitQuaternion};
use voxpan_core::{Frame, Intrinsics, Pose};
use voxpan_io::{read_color_png, read_depth_png};

use crate::{DatasetError, FrameSource};

/// Pairing tolerance (the benchmark's own association tool uses 20 ms).
const MAX_DIFFERENCE_S: f64 = 0.02;
/// TUM depth PNGs store 5000 units per metre.
const DEPTH_UNITS_PER_METRE: f32 = 5000.0;

struct TumFrame {
    id: String,
    timestamp: f64,
    depth: PathBuf,
    color: PathBuf,
    pose: Pose,
}

/// An opened TUM RGB-D sequence.
pub struct TumDataset {
    intrinsics: Intrinsics,
    frames: Vec<TumFrame>,
    skipped: Vec<(String, String)>,
}

impl TumDataset {
    pub fn looks_like(path: &Path) -> bool {
        path.join("rgb.txt").is_file() && path.join("depth.txt").is_file()
    }

    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    pub fn open(path: &Path) -> Result<Self, DatasetError> {
        let rgb = read_list(&path.join("rgb.txt"), 1)?;
        let depth = read_list(&path.join("depth.txt"), 1)?;
        let gt_path = path.join("groundtruth.txt");
        let poses = parse_trajectory(&read_text(&gt_path)?, &gt_path)?;
        let mut frames = Vec::new();
        let mut skipped = Vec::new();
        for (t, files) in &depth {
            let id = format!("{t:.6}");
            let color = nearest(&rgb, *t);
            let pose = nearest(&poses, *t);
            match (color, pose) {
                (Some((_, c)), Some((_, p))) => frames.push(TumFrame {
                    id,
                    timestamp: *t,
                    depth: path.join(&files[0]),
                    color: path.join(&c[0]),
                    pose: *p,
                }),
                (None, _) => skipped.push((id, "no colour image within 20 ms".into())),
                (_, None) => skipped.push((id, "no ground-truth pose within 20 ms".into())),
            }
        }
        if frames.is_empty() {
            return Err(DatasetError::NoFrames(path.to_owned()));
        }
        Ok(Self {
            intrinsics: intrinsics_for(path),
            frames,
            skipped,
        })
    }
}

impl FrameSource for TumDataset {
    fn kind(&self) -> &'static str {
        "tum"
    }

    fn len(&self) -> usize {
        self.frames.len()
    }

    fn frame_id(&self, index: usize) -> &str {
        &self.frames[index].id
    }

    fn load(&self, index: usize) -> Result<Frame, DatasetError> {
        let f = &self.frames[index];
        let (color, depth) = rayon::join(
            || read_color_png(&f.color),
            || read_depth_png(&f.depth, DEPTH_UNITS_PER_METRE),
        );
        let (color, depth) = (color?, depth?);
        if color.dims() != depth.dims() {
            return Err(DatasetError::invalid(
                &f.depth,
                format!(
                    "size mismatch: depth is {}x{}, colour {}x{}",
                    depth.width(),
                    depth.height(),
                    color.width(),
                    color.height()
                ),
            )
            .in_frame(&f.id));
        }
        let mut intrinsics = self.intrinsics;
        (intrinsics.width, intrinsics.height) = depth.dims();
        Ok(Frame {
            id: f.id.clone(),
            timestamp: f.timestamp,
            color,
            depth,
            segments: None,
            ground_truth: None,
            pose: f.pose,
            intrinsics,
        })
    }

    fn skipped(&self) -> &[(String, String)] {
        &self.skipped
    }
}

/// The sequence's published calibration, by camera (`freiburg1/2/3` in the folder name), else
/// the ROS default the benchmark recommends.
fn intrinsics_for(path: &Path) -> Intrinsics {
    let name = path
        .canonicalize()
        .unwrap_or_else(|_| path.to_owned())
        .to_string_lossy()
        .to_string();
    let (fx, fy, cx, cy) = if name.contains("freiburg1") {
        (517.3, 516.5, 318.6, 255.3)
    } else if name.contains("freiburg2") {
        (520.9, 521.0, 325.1, 249.7)
    } else if name.contains("freiburg3") {
        (535.4, 539.2, 320.1, 247.6)
    } else {
        (525.0, 525.0, 319.5, 239.5)
    };
    Intrinsics {
        width: 640,
        height: 480,
        fx,
        fy,
        cx,
        cy,
    }
}

fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path)
        .map_err(|e| DatasetError::invalid(path, format!("cannot read: {e}")))
}

/// `timestamp field...` lines (comments `#` skipped), sorted by time.
fn read_list(path: &Path, fields: usize) -> Result<Vec<(f64, Vec<String>)>, DatasetError> {
    parse_list(&read_text(path)?, path, fields)
}

/// A `groundtruth.txt` trajectory (`timestamp tx ty tz qx qy qz qw` lines), sorted by time;
/// `path` names it in errors.
pub fn parse_trajectory(text: &str, path: &Path) -> Result<Vec<(f64, Pose)>, DatasetError> {
    parse_list(text, path, 7)?
        .into_iter()
        .map(|(t, f)| {
            let v: Vec<f64> = f.iter().map(|s| s.parse().unwrap_or(f64::NAN)).collect();
            if v.iter().any(|x| !x.is_finite()) {
                return Err(DatasetError::invalid(
                    path,
                    format!("pose at {t} is not 7 finite numbers"),
                ));
            }
            let raw = Quaternion::new(v[6], v[3], v[4], v[5]);
            // A quaternion far from unit length is no rotation (all zeros: a placeholder
            // some tools write for unknown poses); within 1 % it is rounding.
            if (raw.norm() - 1.0).abs() > 0.01 {
                return Err(DatasetError::invalid(
                    path,
                    format!(
                        "pose at {t}: quaternion ({} {} {} {}) has length {:.3}, not 1",
                        v[3],
                        v[4],
                        v[5],
                        v[6],
                        raw.norm()
                    ),
                ));
            }
            let q = UnitQuaternion::from_quaternion(raw);
            Ok((t, Pose::from_parts(Translation3::new(v[0], v[1], v[2]), q)))
        })
        .collect()
}

/// `timestamp field...` lines of `text` (comments `#` skipped), sorted by time.
pub fn parse_list(
    text: &str,
    path: &Path,
    fields: usize,
) -> Result<Vec<(f64, Vec<String>)>, DatasetError> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let parts: Vec<&str> = line.split_whitespace().collect();
        let time = parts.first().and_then(|t| t.parse::<f64>().ok());
        match time.filter(|t| t.is_finite()) {
            Some(t) if parts.len() > fields => {
                out.push((t, parts[1..=fields].iter().map(|s| s.to_string()).collect()))
            }
            _ => {
                return Err(DatasetError::invalid(
                    path,
                    format!(
                        "line {}: expected a timestamp and {fields} field(s), got {line:?}",
                        n + 1
                    ),
                ));
            }
        }
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// The entry nearest `t` within the tolerance (list sorted by time).
fn nearest<T>(list: &[(f64, T)], t: f64) -> Option<&(f64, T)> {
    let i = list.partition_point(|(s, _)| *s < t);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|j| list.get(j))
        .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
        .filter(|(s, _)| (s - t).abs() <= MAX_DIFFERENCE_S)
}
