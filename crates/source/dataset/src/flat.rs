//! The panoptic_mapping "flat" format (see `../shared/data/flat/README.md`).
//!
//! Layout: a dataset root with `Intrinsics.txt` and the label CSVs, and a run folder (`run1`)
//! with, per frame `NNNNNN`: `_color.png`, `_depth.tiff` (float metres), `_pose.txt` (4×4
//! row-major `T_world_camera`), optionally `_predicted.png` + `_labels.json` (network segments)
//! and `_segmentation.png` (ground truth), plus `timestamps.csv` (`ImageID,TimeStamp` in ns,
//! unsorted).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use voxpan_core::nalgebra::Matrix4;
use voxpan_core::{
    Annotations, ClassTable, Frame, Intrinsics, Pose, Segment, Segments, pose_from_matrix,
    segment_ids,
};
use voxpan_io::{
    read_class_csv, read_color_png, read_depth_tiff, read_label_png, read_segments_json,
    write_color_png, write_depth_tiff, write_label_png, write_segments_json,
};

use crate::{DatasetError, FrameSource};

/// An opened flat dataset: the list of usable frames and the shared metadata.
pub struct FlatDataset {
    root: PathBuf,
    run: PathBuf,
    intrinsics: Intrinsics,
    /// `(id, timestamp in seconds)`, sorted by time.
    frames: Vec<(String, f64)>,
    skipped: Vec<(String, String)>,
    /// `detectron_labels.csv`: the network's categories (when present).
    pub network_classes: Option<ClassTable>,
    /// `groundtruth_labels.csv`: ground-truth instances (when present).
    pub ground_truth_classes: Option<ClassTable>,
    /// `groundtruth_labels_classes.csv`: names of the ground truth's classes (when present).
    pub ground_truth_class_names: Option<BTreeMap<u32, String>>,
}

const REQUIRED: [&str; 3] = ["color.png", "depth.tiff", "pose.txt"];

impl FlatDataset {
    /// A dataset root (with `Intrinsics.txt` and a run folder) or a run folder itself.
    pub fn looks_like(path: &Path) -> bool {
        find_run(path).is_some()
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Opens `path`; frames missing a required file are skipped (see [`FrameSource::skipped`]).
    pub fn open(path: &Path) -> Result<Self, DatasetError> {
        let (root, run) =
            find_run(path).ok_or_else(|| DatasetError::Unrecognised(path.to_owned()))?;
        let intrinsics = read_intrinsics(&root.join("Intrinsics.txt"))?;
        let optional_table = |name: &str| {
            let p = root.join(name);
            p.is_file().then(|| read_class_csv(&p)).transpose()
        };
        let network_classes = optional_table("detectron_labels.csv")?;
        let ground_truth_classes = optional_table("groundtruth_labels.csv")?;
        let names = root.join("groundtruth_labels_classes.csv");
        let ground_truth_class_names = names
            .is_file()
            .then(|| read_class_names(&names))
            .transpose()?;

        let mut candidates = match read_timestamps(&run.join("timestamps.csv"))? {
            Some(list) => list,
            // Without timestamps: every frame with a depth file, at 30 Hz.
            None => list_ids(&run)?
                .into_iter()
                .enumerate()
                .map(|(i, id)| (id, i as f64 / 30.0))
                .collect(),
        };
        candidates.sort_by(|a, b| a.1.total_cmp(&b.1).then_with(|| a.0.cmp(&b.0)));
        let mut frames = Vec::new();
        let mut skipped = Vec::new();
        for (id, t) in candidates {
            match REQUIRED
                .iter()
                .find(|s| !run.join(format!("{id}_{s}")).is_file())
            {
                Some(missing) => skipped.push((id.clone(), format!("missing {id}_{missing}"))),
                None => frames.push((id, t)),
            }
        }
        if frames.is_empty() {
            return Err(DatasetError::NoFrames(run));
        }
        Ok(Self {
            root,
            run,
            intrinsics,
            frames,
            skipped,
            network_classes,
            ground_truth_classes,
            ground_truth_class_names,
        })
    }

    fn file(&self, id: &str, suffix: &str) -> PathBuf {
        self.run.join(format!("{id}_{suffix}"))
    }

    fn load_frame(&self, index: usize, wanted: Annotations) -> Result<Frame, DatasetError> {
        let (id, timestamp) = &self.frames[index];
        let segments = || match wanted.segments {
            true => self.read_segments(id),
            false => Ok(None),
        };
        let ground_truth = || match wanted.ground_truth {
            true => self.read_ground_truth(id),
            false => Ok(None),
        };
        let ((color, depth), ((segments, ground_truth), pose)) = rayon::join(
            || {
                rayon::join(
                    || read_color_png(&self.file(id, "color.png")),
                    || read_depth_tiff(&self.file(id, "depth.tiff")),
                )
            },
            || {
                rayon::join(
                    || rayon::join(segments, ground_truth),
                    || read_pose(&self.file(id, "pose.txt")),
                )
            },
        );
        let frame = Frame {
            id: id.clone(),
            timestamp: *timestamp,
            color: color?,
            depth: depth?,
            segments: segments?,
            ground_truth: ground_truth?,
            pose: pose?,
            intrinsics: self.intrinsics,
        };
        let expected = (self.intrinsics.width, self.intrinsics.height);
        let mut sizes = vec![
            ("color.png", frame.color.dims()),
            ("depth.tiff", frame.depth.dims()),
        ];
        if let Some(s) = &frame.segments {
            sizes.push(("predicted.png", s.labels.dims()));
        }
        if let Some(g) = &frame.ground_truth {
            sizes.push(("segmentation.png", g.dims()));
        }
        for (suffix, (w, h)) in sizes {
            if (w, h) != expected {
                return Err(DatasetError::invalid(
                    &self.file(id, suffix),
                    format!(
                        "size mismatch: {w}x{h}, but Intrinsics.txt says {}x{}",
                        expected.0, expected.1
                    ),
                ));
            }
        }
        Ok(frame)
    }

    fn read_segments(&self, id: &str) -> Result<Option<Segments>, DatasetError> {
        let png = self.file(id, "predicted.png");
        if !png.is_file() {
            return Ok(None);
        }
        let labels = read_label_png(&png)?;
        let json = self.file(id, "labels.json");
        let segments = if json.is_file() {
            let segments = read_segments_json(&json)?;
            if let Some(table) = &self.network_classes
                && let Some(bad) = segments
                    .iter()
                    .find(|s| s.class_id.is_some_and(|c| table.get(c).is_none()))
            {
                return Err(DatasetError::invalid(
                    &json,
                    format!(
                        "segment {} has unknown label id {} (not in detectron_labels.csv)",
                        bad.id,
                        bad.class_id.unwrap_or_default()
                    ),
                ));
            }
            // Every id the image holds must be described: a segment without an entry would
            // silently never be refined nor mapped.
            let listed: std::collections::BTreeSet<u16> = segments.iter().map(|s| s.id).collect();
            let missing: Vec<u16> = segment_ids(&labels)
                .into_iter()
                .filter(|id| !listed.contains(id))
                .collect();
            if !missing.is_empty() {
                return Err(DatasetError::invalid(
                    &json,
                    format!(
                        "does not describe segment id(s) {missing:?} of {}",
                        png.file_name().unwrap_or_default().to_string_lossy()
                    ),
                ));
            }
            segments
        } else {
            segment_ids(&labels)
                .into_iter()
                .map(Segment::bare)
                .collect()
        };
        Ok(Some(Segments { labels, segments }))
    }

    fn read_ground_truth(&self, id: &str) -> Result<Option<voxpan_core::LabelImage>, DatasetError> {
        let png = self.file(id, "segmentation.png");
        if !png.is_file() {
            return Ok(None);
        }
        let labels = read_label_png(&png)?;
        if let Some(table) = &self.ground_truth_classes
            && let Some(bad) = segment_ids(&labels)
                .into_iter()
                .find(|&i| table.get(i as u32).is_none())
        {
            return Err(DatasetError::invalid(
                &png,
                format!("unknown label id {bad} (not in groundtruth_labels.csv)"),
            ));
        }
        Ok(Some(labels))
    }
}

impl FrameSource for FlatDataset {
    fn kind(&self) -> &'static str {
        "flat"
    }

    fn len(&self) -> usize {
        self.frames.len()
    }

    fn frame_id(&self, index: usize) -> &str {
        &self.frames[index].0
    }

    fn load(&self, index: usize) -> Result<Frame, DatasetError> {
        self.load_with(index, Annotations::ALL)
    }

    fn load_with(&self, index: usize, wanted: Annotations) -> Result<Frame, DatasetError> {
        self.load_frame(index, wanted)
            .map_err(|e| e.in_frame(&self.frames[index].0))
    }

    fn skipped(&self) -> &[(String, String)] {
        &self.skipped
    }

    fn network_classes(&self) -> Option<&ClassTable> {
        self.network_classes.as_ref()
    }

    fn ground_truth_classes(&self) -> Option<&ClassTable> {
        self.ground_truth_classes.as_ref()
    }

    fn ground_truth_class_names(&self) -> Option<&BTreeMap<u32, String>> {
        self.ground_truth_class_names.as_ref()
    }
}

/// `(root, run folder)` for a dataset root or a run folder.
fn find_run(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let has_frames = |dir: &Path| {
        std::fs::read_dir(dir).ok().is_some_and(|entries| {
            entries
                .flatten()
                .any(|e| e.file_name().to_string_lossy().ends_with("_depth.tiff"))
        })
    };
    if has_frames(path) {
        let root = match path.parent() {
            Some(parent) if parent.join("Intrinsics.txt").is_file() => parent.to_owned(),
            _ => path.to_owned(),
        };
        return Some((root, path.to_owned()));
    }
    if !path.join("Intrinsics.txt").is_file() {
        return None;
    }
    if has_frames(&path.join("run1")) {
        return Some((path.to_owned(), path.join("run1")));
    }
    let mut runs: Vec<PathBuf> = std::fs::read_dir(path)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir() && has_frames(p))
        .collect();
    runs.sort();
    runs.into_iter().next().map(|run| (path.to_owned(), run))
}

fn list_ids(run: &Path) -> Result<Vec<String>, DatasetError> {
    let entries = std::fs::read_dir(run).map_err(|e| DatasetError::invalid(run, e.to_string()))?;
    let mut ids: Vec<String> = entries
        .flatten()
        .filter_map(|e| {
            e.file_name()
                .to_string_lossy()
                .strip_suffix("_depth.tiff")
                .map(str::to_owned)
        })
        .collect();
    ids.sort();
    Ok(ids)
}

/// `timestamps.csv`: `ImageID,TimeStamp` (nanoseconds). `None` when the file is absent.
fn read_timestamps(path: &Path) -> Result<Option<Vec<(String, f64)>>, DatasetError> {
    if !path.is_file() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(path).map_err(|e| DatasetError::invalid(path, e.to_string()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let mut fields = line.split(',').map(str::trim);
        match (
            fields.next(),
            fields.next().and_then(|t| t.parse::<u64>().ok()),
        ) {
            (Some(id), Some(ns)) if !id.is_empty() => out.push((id.to_owned(), ns as f64 * 1e-9)),
            _ => {
                return Err(DatasetError::invalid(
                    path,
                    format!(
                        "line {}: expected ImageID,TimeStamp(ns), got {line:?}",
                        n + 1
                    ),
                ));
            }
        }
    }
    Ok(Some(out))
}

/// `groundtruth_labels_classes.csv`: `ClassID,Name` per line after a header.
fn read_class_names(path: &Path) -> Result<BTreeMap<u32, String>, DatasetError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| DatasetError::invalid(path, format!("cannot read: {e}")))?;
    let mut out = BTreeMap::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let (id, name) = line
            .split_once(',')
            .and_then(|(id, name)| Some((id.trim().parse::<u32>().ok()?, name.trim())))
            .ok_or_else(|| {
                DatasetError::invalid(path, format!("line {}: expected ClassID,Name", n + 1))
            })?;
        out.insert(id, name.to_owned());
    }
    Ok(out)
}

/// `Intrinsics.txt`: `Res_x`, `Res_y`, `u`, `v`, `f_x`, `f_y` as `key: value` lines.
pub fn read_intrinsics(path: &Path) -> Result<Intrinsics, DatasetError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| DatasetError::invalid(path, format!("cannot read: {e}")))?;
    parse_intrinsics(&text, path)
}

/// [`read_intrinsics`] on a file's text; `path` names it in errors.
pub fn parse_intrinsics(text: &str, path: &Path) -> Result<Intrinsics, DatasetError> {
    let value = |key: &str| -> Result<f64, DatasetError> {
        text.lines()
            .filter_map(|l| l.split_once(':'))
            .find(|(k, _)| k.trim() == key)
            .and_then(|(_, v)| v.split_whitespace().next()?.parse().ok())
            .ok_or_else(|| DatasetError::invalid(path, format!("no numeric {key}")))
    };
    let (w, h) = (value("Res_x")?, value("Res_y")?);
    if !(1.0..=65536.0).contains(&w) || !(1.0..=65536.0).contains(&h) {
        return Err(DatasetError::invalid(
            path,
            format!("image size {w}x{h}: expected 1 to 65536 pixels per side"),
        ));
    }
    let k = Intrinsics {
        width: w as usize,
        height: h as usize,
        fx: value("f_x")?,
        fy: value("f_y")?,
        cx: value("u")?,
        cy: value("v")?,
    };
    k.check()
        .map_err(|why| DatasetError::invalid(path, format!("unusable intrinsics: {why}")))?;
    Ok(k)
}

/// A `_pose.txt`: 16 numbers, row-major, a rigid transform.
pub fn read_pose(path: &Path) -> Result<Pose, DatasetError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| DatasetError::invalid(path, format!("cannot read: {e}")))?;
    parse_pose(&text, path)
}

/// [`read_pose`] on a file's text; `path` names it in errors.
pub fn parse_pose(text: &str, path: &Path) -> Result<Pose, DatasetError> {
    let numbers: Vec<f64> = text
        .split_whitespace()
        .map(|t| t.parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| DatasetError::invalid(path, format!("not a 4x4 matrix: {e}")))?;
    if numbers.len() != 16 {
        return Err(DatasetError::invalid(
            path,
            format!(
                "not a 4x4 matrix: 16 numbers expected, found {}",
                numbers.len()
            ),
        ));
    }
    if let Some(k) = numbers.iter().position(|v| !v.is_finite()) {
        return Err(DatasetError::invalid(
            path,
            format!(
                "not a camera pose: entry ({}, {}) is {}",
                k / 4 + 1,
                k % 4 + 1,
                numbers[k]
            ),
        ));
    }
    pose_from_matrix(&Matrix4::from_row_slice(&numbers))
        .map_err(|e| DatasetError::invalid(path, format!("not a camera pose: {e}")))
}

/// Writes one frame in the flat layout into `run` (ids: `frame.id`).
pub fn write_frame(run: &Path, frame: &Frame) -> Result<(), DatasetError> {
    let file = |suffix: &str| run.join(format!("{}_{suffix}", frame.id));
    write_color_png(&file("color.png"), &frame.color)?;
    write_depth_tiff(&file("depth.tiff"), &frame.depth)?;
    if let Some(s) = &frame.segments {
        write_label_png(&file("predicted.png"), &s.labels)?;
        write_segments_json(&file("labels.json"), &s.segments)?;
    }
    if let Some(g) = &frame.ground_truth {
        write_label_png(&file("segmentation.png"), g)?;
    }
    let m = frame.pose.to_homogeneous();
    let text: String = (0..4)
        .map(|r| format!("{} {} {} {}\n", m[(r, 0)], m[(r, 1)], m[(r, 2)], m[(r, 3)]))
        .collect();
    let path = file("pose.txt");
    std::fs::write(&path, text).map_err(|e| DatasetError::invalid(&path, e.to_string()))
}

/// Writes `Intrinsics.txt` into a dataset root.
pub fn write_intrinsics(root: &Path, k: &Intrinsics) -> Result<(), DatasetError> {
    let path = root.join("Intrinsics.txt");
    let text = format!(
        "Res_x: {}\nRes_y: {}\nu: {}\nv: {}\nf_x: {} (px)\nf_y: {}\n",
        k.width, k.height, k.cx, k.cy, k.fx, k.fy
    );
    std::fs::write(&path, text).map_err(|e| DatasetError::invalid(&path, e.to_string()))
}

/// Writes `timestamps.csv` (seconds → nanoseconds) into a run folder.
pub fn write_timestamps(run: &Path, frames: &[(String, f64)]) -> Result<(), DatasetError> {
    let path = run.join("timestamps.csv");
    let mut text = String::from("ImageID,TimeStamp\n");
    for (id, t) in frames {
        text += &format!("{id},{}\n", (t * 1e9).round() as u64);
    }
    std::fs::write(&path, text).map_err(|e| DatasetError::invalid(&path, e.to_string()))
}
