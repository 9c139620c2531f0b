//! voxpan from Python (`import voxpan`). Thin: every function converts numpy arrays and Python
//! values into voxpan's types, calls the libraries with the GIL released, and converts back.
//! Algorithms live in the library crates only.

mod convert;
mod dataset;
mod eval;
mod map;

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyList;

use voxpan_core::{Image, Segment, Segments, segment_ids};
use voxpan_fill::{FillConfig, HoleFiller};
use voxpan_kde::{Kde, KdeMethod};
use voxpan_refine::{PlaneTrimmer, RefineConfig, Refiner, Rule};

use convert::{depth_image, json_to_py, label_image, segments_from_py};

pyo3::create_exception!(
    voxpan,
    VoxpanError,
    pyo3::exceptions::PyRuntimeError,
    "An error reported by voxpan's libraries (the message is theirs)."
);

/// A library error as a Python exception carrying the library's message.
pub(crate) fn voxpan_error(e: impl std::fmt::Display) -> PyErr {
    VoxpanError::new_err(e.to_string())
}

/// Refines every segment of `labels` on the measured `depth` (voxpan refine).
///
/// `things`: ids of the segments that are things (the others are stuff); `segments`: the
/// segment list as `open_dataset` gives it (dicts with `id`, `class_id`, `is_thing`, `score`).
/// Without either, every non-zero id is a segment of unknown kind (as `voxpan refine` without
/// `--labels`). Returns the refined label image and one report dict per segment.
#[pyfunction]
#[pyo3(signature = (depth, labels, rule = "default", things = None, segments = None, things_only = false, kde = None))]
#[allow(clippy::too_many_arguments)] // mirrors the Python signature
fn refine<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    labels: &Bound<'py, PyAny>,
    rule: &str,
    things: Option<Vec<u16>>,
    segments: Option<&Bound<'py, PyAny>>,
    things_only: bool,
    kde: Option<&str>,
) -> PyResult<(Bound<'py, PyArray2<u16>>, Bound<'py, PyList>)> {
    let depth = depth_image(depth, "depth")?;
    let mut labels = label_image(labels, "labels")?;
    if labels.dims() != depth.dims() {
        return Err(PyValueError::new_err(format!(
            "labels: shape {:?} differs from depth's {:?}",
            (labels.height(), labels.width()),
            (depth.height(), depth.width())
        )));
    }
    let rule: Rule = rule
        .parse()
        .map_err(|e: String| PyValueError::new_err(format!("rule: {e}")))?;
    let mut config = RefineConfig::new(rule);
    config.things_only = things_only;
    config.kde = kde.map(kde_method).transpose()?;
    let list = match (things, segments) {
        (Some(_), Some(_)) => {
            return Err(PyValueError::new_err(
                "things and segments: give one of them (segments carry is_thing)",
            ));
        }
        (_, Some(s)) => segments_from_py(s, "segments")?,
        (things, None) => segment_ids(&labels)
            .into_iter()
            .map(|id| Segment {
                is_thing: things.as_ref().map(|t| t.contains(&id)),
                ..Segment::bare(id)
            })
            .collect(),
    };
    let reports = py.detach(|| {
        let mut refiner = Refiner::new(config);
        refiner
            .refine_frame(&depth, &mut labels, &list)
            .map_err(|e| e.to_string())
    });
    let reports = reports.map_err(PyValueError::new_err)?;
    let reports: Vec<_> = reports
        .iter()
        .map(|r| json_to_py(py, &serde_json::to_value(r).expect("plain data")))
        .collect::<PyResult<_>>()?;
    Ok((convert::image_to_py(py, labels)?, PyList::new(py, reports)?))
}

/// Trims thing masks off the frame's stuff planes, as `voxpan run` does before refinement:
/// thing pixels on a plane fitted to a stuff segment go to that segment, unless the thing lies
/// flat on the planes. `segments` as `open_dataset` gives them (their `is_thing` decides).
/// Returns the trimmed label image and one report dict per thing (id, pixels, on_stuff,
/// removed).
#[pyfunction]
fn trim_stuff_planes<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    labels: &Bound<'py, PyAny>,
    segments: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyArray2<u16>>, Bound<'py, PyList>)> {
    let depth = depth_image(depth, "depth")?;
    let mut labels = label_image(labels, "labels")?;
    let list = segments_from_py(segments, "segments")?;
    let reports = py
        .detach(|| PlaneTrimmer::new().trim(&depth, &mut labels, &list))
        .map_err(|e| PyValueError::new_err(format!("labels: {e}")))?;
    let reports: Vec<_> = reports
        .iter()
        .map(|r| json_to_py(py, &serde_json::to_value(r).expect("plain data")))
        .collect::<PyResult<_>>()?;
    Ok((convert::image_to_py(py, labels)?, PyList::new(py, reports)?))
}

fn kde_method(name: &str) -> PyResult<KdeMethod> {
    match name {
        "isj" => Ok(KdeMethod::Isj),
        "kdepy" => Ok(KdeMethod::Kdepy),
        other => Err(PyValueError::new_err(format!(
            "method: unknown KDE {other:?} (expected \"isj\" or \"kdepy\")"
        ))),
    }
}

/// The density of `values` (1-D float64 or float32; non-finite values are ignored) on a grid
/// of 1024 points: `(grid, density, bandwidth)`. `method`: "isj" (Botev's ISJ) or "kdepy"
/// (KDEpy 1.1's FFTKDE with bw="ISJ", as the original code).
#[pyfunction]
#[pyo3(signature = (values, method = "isj"))]
#[allow(clippy::type_complexity)] // the tuple is the Python return value
fn kde<'py>(
    py: Python<'py>,
    values: &Bound<'py, PyAny>,
    method: &str,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>, f64)> {
    let method = kde_method(method)?;
    let values = convert::float_values(values, "values")?;
    let density = py
        .detach(|| Kde::new(method).estimate(&values))
        .map_err(|e| PyValueError::new_err(format!("values: {e}")))?;
    let grid: Vec<f64> = (0..density.values.len()).map(|i| density.x(i)).collect();
    Ok((
        grid.into_pyarray(py),
        density.values.into_pyarray(py),
        density.bandwidth.value,
    ))
}

/// Fills depth holes (0, negative or non-finite pixels) with the Gaussian-weighted average of
/// the valid pixels in a `k × k` window (σ = k / 4 unless given). Returns a new array.
#[pyfunction]
#[pyo3(signature = (depth, k = 5, sigma = None))]
fn fill_holes<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    k: usize,
    sigma: Option<f32>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let config = FillConfig {
        enabled: true,
        kernel_size: k,
        sigma,
    };
    // The library's own check; its message names the configuration key.
    config.validate().map_err(|e| {
        PyValueError::new_err(e.replace("fill.kernel_size", "k").replace("fill.", ""))
    })?;
    let params = config.params();
    let mut depth = depth_image(depth, "depth")?;
    py.detach(|| HoleFiller::new(params).fill(&mut depth));
    convert::image_to_py(py, depth)
}

/// Scores predicted masks against ground truth with voxpan's 2-D protocol (Hungarian matching
/// of IoUs per frame, pooled): `pred` and `gt` are uint16 label images or equally long lists
/// of them (pred 0 = void; every gt id is a segment). Returns the summary dict (percentages).
#[pyfunction]
fn eval_masks<'py>(
    py: Python<'py>,
    pred: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let frames = |obj: &Bound<'py, PyAny>, name: &str| -> PyResult<Vec<Image<u16>>> {
        if obj.cast::<PyList>().is_ok() || obj.cast::<pyo3::types::PyTuple>().is_ok() {
            obj.try_iter()?
                .enumerate()
                .map(|(i, item)| label_image(&item?, &format!("{name}[{i}]")))
                .collect()
        } else {
            Ok(vec![label_image(obj, name)?])
        }
    };
    let (pred, gt) = (frames(pred, "pred")?, frames(gt, "gt")?);
    if pred.len() != gt.len() {
        return Err(PyValueError::new_err(format!(
            "pred and gt: {} and {} frames",
            pred.len(),
            gt.len()
        )));
    }
    for (i, (p, g)) in pred.iter().zip(&gt).enumerate() {
        if p.dims() != g.dims() {
            return Err(PyValueError::new_err(format!(
                "gt: frame {i} is {}x{} but pred is {}x{}",
                g.width(),
                g.height(),
                p.width(),
                p.height()
            )));
        }
    }
    let summary = py.detach(|| {
        let mut scores = voxpan_eval::MaskScores::default();
        for (p, g) in pred.iter().zip(&gt) {
            scores.add(&voxpan_eval::match_frame(p, g));
        }
        scores.summary()
    });
    json_to_py(py, &serde_json::to_value(summary).expect("plain data"))
}

/// Segments as voxpan's type, from a label image and an optional list (shared with the map).
pub(crate) fn segments_for(
    labels: Image<u16>,
    list: Option<&Bound<'_, PyAny>>,
) -> PyResult<Segments> {
    let segments = match list {
        Some(l) => segments_from_py(l, "segments")?,
        None => segment_ids(&labels)
            .into_iter()
            .map(Segment::bare)
            .collect(),
    };
    Ok(Segments { labels, segments })
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("VoxpanError", m.py().get_type::<VoxpanError>())?;
    m.add_function(wrap_pyfunction!(refine, m)?)?;
    m.add_function(wrap_pyfunction!(trim_stuff_planes, m)?)?;
    m.add_function(wrap_pyfunction!(kde, m)?)?;
    m.add_function(wrap_pyfunction!(fill_holes, m)?)?;
    m.add_function(wrap_pyfunction!(eval_masks, m)?)?;
    m.add_function(wrap_pyfunction!(eval::voxel_pq, m)?)?;
    m.add_function(wrap_pyfunction!(eval::reference_map, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::open_dataset, m)?)?;
    m.add_class::<map::PyPanopticMap>()?;
    m.add_class::<dataset::Dataset>()?;
    m.add_class::<dataset::DatasetIter>()?;
    Ok(())
}
