//! `voxpan.eval.voxel_pq` and `voxpan.eval.reference_map`: the 3-D protocol of
//! `voxpan eval --3d` (and of the scores `voxpan run` reports), on maps built in Python.

use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;

use voxpan_pipeline::Config;

use crate::convert::json_to_py;
use crate::dataset::Dataset;
use crate::map::PyPanopticMap;
use crate::voxpan_error;

/// Scores `map`'s instances against `reference`'s objects over voxels (voxpan-eval's
/// `panoptic_scores`): the dict `voxpan run` writes as "panoptic" into metrics.json and
/// `voxpan eval --3d --json` prints per map (percentages; all, things, stuff, and counts).
#[pyfunction]
pub fn voxel_pq<'py>(
    py: Python<'py>,
    map: &PyPanopticMap,
    reference: &PyPanopticMap,
) -> PyResult<Bound<'py, PyAny>> {
    let scores = py.detach(|| {
        if std::ptr::eq(map, reference) {
            // One lock: taking the same mutex twice would deadlock.
            let m = map.lock();
            return Ok(voxpan_eval::volume::panoptic_scores(&m, &m));
        }
        // Both locks in address order, so two threads scoring (a, b) and (b, a) cannot
        // deadlock.
        let (m, r) = if (map as *const PyPanopticMap) < (reference as *const PyPanopticMap) {
            let m = map.lock();
            (m, reference.lock())
        } else {
            let r = reference.lock();
            (map.lock(), r)
        };
        // Surface voxels are compared by index: other grids never coincide.
        if m.voxel_size() != r.voxel_size() {
            return Err(format!(
                "reference: voxel size {} differs from the map's {}",
                r.voxel_size(),
                m.voxel_size()
            ));
        }
        Ok(voxpan_eval::volume::panoptic_scores(&m, &r))
    });
    let scores = scores.map_err(PyValueError::new_err)?;
    json_to_py(py, &serde_json::to_value(scores).expect("plain data"))
}

/// The tracker-free reference of `voxpan eval --3d`: the dataset's ground-truth segmentation
/// fused with its own ids as instances (no association), over `indices` (all frames when
/// None). `like`: a map whose configuration (voxel size, truncation, ranges) the reference
/// takes, so that their voxels coincide; voxpan's defaults otherwise.
#[pyfunction]
#[pyo3(signature = (dataset, indices = None, like = None))]
pub fn reference_map(
    py: Python<'_>,
    dataset: &Dataset,
    indices: Option<Vec<isize>>,
    like: Option<&PyPanopticMap>,
) -> PyResult<PyPanopticMap> {
    let source = dataset.source.clone();
    let n = source.len();
    let selected: Vec<usize> = match indices {
        None => (0..n).collect(),
        Some(list) => list
            .into_iter()
            .map(|index| {
                let i = if index < 0 { index + n as isize } else { index };
                if i < 0 || i as usize >= n {
                    return Err(PyIndexError::new_err(format!(
                        "indices: frame index {index} out of range ({n} frames)"
                    )));
                }
                Ok(i as usize)
            })
            .collect::<PyResult<_>>()?,
    };
    if selected.is_empty() {
        return Err(PyValueError::new_err("indices: no frame selected"));
    }
    let mut config = Config::default();
    if let Some(like) = like {
        let c = *like.lock().config();
        config.tsdf = c.tsdf;
        config.tracking = c.tracking;
    }
    let map = py.detach(|| {
        // Without ground truth the reference would be empty and every score 0: say so.
        let has_truth = selected
            .iter()
            .find_map(|&i| source.load(i).ok())
            .is_some_and(|f| f.ground_truth.is_some());
        if !has_truth {
            return Err(PyValueError::new_err(
                "dataset: the selected frames have no ground-truth segmentation",
            ));
        }
        voxpan_pipeline::protocols::reference_map(&source, &selected, &config).map_err(voxpan_error)
    })?;
    Ok(PyPanopticMap::wrap(map))
}
