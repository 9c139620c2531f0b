//! `voxpan.open_dataset`: a flat or TUM RGB-D folder as a sequence of frame dicts.

use std::path::PathBuf;
use std::sync::Arc;

use pyo3::exceptions::PyIndexError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use voxpan_core::Frame;
use voxpan_dataset::FrameSource;

use crate::convert::{image_to_py, json_to_py, pose_to_py, triples_to_py};
use crate::voxpan_error;

/// Frames of a dataset, loaded on access: `len(ds)`, `ds[i]`, `for frame in ds`.
#[pyclass(module = "voxpan", frozen)]
pub struct Dataset {
    pub(crate) source: Arc<dyn FrameSource>,
}

/// Iterates a dataset's frames in order.
#[pyclass(module = "voxpan")]
pub struct DatasetIter {
    source: Arc<dyn FrameSource>,
    next: usize,
}

/// Opens a flat (panoptic_mapping) or TUM RGB-D folder.
#[pyfunction]
pub fn open_dataset(py: Python<'_>, path: PathBuf) -> PyResult<Dataset> {
    let source = py
        .detach(|| voxpan_dataset::open_dataset(&path))
        .map_err(voxpan_error)?;
    Ok(Dataset {
        source: Arc::from(source),
    })
}

/// One frame as a dict of arrays: id, timestamp, depth (float32 H×W, metres), color (uint8
/// H×W×3), pose (float64 4×4 T_world_camera), intrinsics ((fx, fy, cx, cy)), size ((w, h)),
/// and, when the dataset has them, labels (uint16 H×W, the stored network masks) with
/// segments (list of dicts) and ground_truth (uint16 H×W).
fn frame_to_py(py: Python<'_>, frame: Frame) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    let k = frame.intrinsics;
    d.set_item("id", &frame.id)?;
    d.set_item("timestamp", frame.timestamp)?;
    d.set_item("intrinsics", (k.fx, k.fy, k.cx, k.cy))?;
    d.set_item("size", (k.width, k.height))?;
    d.set_item("pose", pose_to_py(py, &frame.pose))?;
    let (w, h) = frame.color.dims();
    d.set_item("color", triples_to_py(py, frame.color.into_vec(), (h, w)))?;
    d.set_item("depth", image_to_py(py, frame.depth)?)?;
    if let Some(s) = frame.segments {
        let list: Vec<_> = s
            .segments
            .iter()
            .map(|x| json_to_py(py, &serde_json::to_value(x).expect("plain data")))
            .collect::<PyResult<_>>()?;
        d.set_item("segments", PyList::new(py, list)?)?;
        d.set_item("labels", image_to_py(py, s.labels)?)?;
    }
    if let Some(g) = frame.ground_truth {
        d.set_item("ground_truth", image_to_py(py, g)?)?;
    }
    Ok(d)
}

fn load<'py>(
    py: Python<'py>,
    source: &Arc<dyn FrameSource>,
    i: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let frame = py.detach(|| source.load(i)).map_err(voxpan_error)?;
    frame_to_py(py, frame)
}

#[pymethods]
impl Dataset {
    fn __len__(&self) -> usize {
        self.source.len()
    }

    /// Frame `index` (negative counts from the end).
    fn __getitem__<'py>(&self, py: Python<'py>, index: isize) -> PyResult<Bound<'py, PyDict>> {
        let n = self.source.len();
        let i = if index < 0 { index + n as isize } else { index };
        if i < 0 || i as usize >= n {
            return Err(PyIndexError::new_err(format!(
                "frame index {index} out of range ({n} frames)"
            )));
        }
        load(py, &self.source, i as usize)
    }

    fn __iter__(&self) -> DatasetIter {
        DatasetIter {
            source: self.source.clone(),
            next: 0,
        }
    }

    /// "flat" or "tum".
    #[getter]
    fn kind(&self) -> &'static str {
        self.source.kind()
    }

    /// The frames' ids in order (flat: "000042").
    #[getter]
    fn frame_ids(&self) -> Vec<String> {
        (0..self.source.len())
            .map(|i| self.source.frame_id(i).to_owned())
            .collect()
    }

    /// The network's class names by class id (what `segments`' class_id index), if known;
    /// pass them to `PanopticMap(class_names=...)`.
    #[getter]
    fn class_names(&self) -> std::collections::BTreeMap<u32, String> {
        self.source
            .network_classes()
            .map(|t| t.names())
            .unwrap_or_default()
    }

    /// Frames left out when the dataset was opened: (frame, reason) pairs.
    #[getter]
    fn skipped(&self) -> Vec<(String, String)> {
        self.source.skipped().to_vec()
    }

    fn __repr__(&self) -> String {
        format!(
            "Dataset(kind={:?}, frames={})",
            self.source.kind(),
            self.source.len()
        )
    }
}

#[pymethods]
impl DatasetIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&mut self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        if self.next >= self.source.len() {
            return Ok(None);
        }
        self.next += 1;
        load(py, &self.source, self.next - 1).map(Some)
    }
}
