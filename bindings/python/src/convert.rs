//! numpy arrays and Python values ⇄ voxpan's types. Every check names the Python argument, so a
//! wrong array is a `ValueError` saying which one and why, never a crash.

use nalgebra::Matrix4;
use numpy::ndarray::{Array2, Array3};
use numpy::{
    Element, IntoPyArray, PyArray2, PyArray3, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use voxpan_core::{ColorImage, DepthImage, Image, Intrinsics, LabelImage, Pose, Segment};

fn err(name: &str, why: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{name}: {why}"))
}

/// The array's elements, copied once by `copy` into what voxpan takes (its images own their
/// pixels), after checking dtype, rank, shape (`trailing`: fixed sizes of the last axes) and
/// C-contiguity.
fn elements<'py, T: Element, U>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    what: &str,
    ndim: usize,
    trailing: &[usize],
    copy: impl FnOnce(&[T]) -> U,
) -> PyResult<(Vec<usize>, U)> {
    let py = obj.py();
    let array = obj.cast::<PyUntypedArray>().map_err(|_| {
        let found = obj
            .get_type()
            .name()
            .map_or_else(|_| "?".to_owned(), |n| n.to_string());
        err(
            name,
            format!("expected a numpy array ({what}), found {found}"),
        )
    })?;
    let shape = array.shape().to_vec();
    if !array.dtype().is_equiv_to(&numpy::dtype::<T>(py)) {
        return Err(err(
            name,
            format!(
                "expected {what}, found dtype {} (convert with .astype)",
                array.dtype()
            ),
        ));
    }
    let shape_ok = shape.len() == ndim && shape[ndim - trailing.len()..] == *trailing;
    if !shape_ok || shape.iter().product::<usize>() == 0 {
        return Err(err(name, format!("expected {what}, found shape {shape:?}")));
    }
    if !array.is_c_contiguous() {
        return Err(err(
            name,
            "the array is not C-contiguous (pass numpy.ascontiguousarray(...))",
        ));
    }
    // dtype and contiguity were checked above, so the cast and the slice cannot fail but for a
    // concurrent mutable borrow, which is reported rather than waited for.
    let typed = array
        .cast::<numpy::PyArrayDyn<T>>()
        .map_err(|e| err(name, e))?;
    let data = typed.try_readonly().map_err(|e| err(name, e))?;
    let data = copy(data.as_slice().map_err(|e| err(name, e))?);
    Ok((shape, data))
}

/// A float32 `H×W` depth image in metres.
pub fn depth_image(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DepthImage> {
    let (shape, data) = elements(
        obj,
        name,
        "float32 of shape (H, W)",
        2,
        &[],
        <[f32]>::to_vec,
    )?;
    Ok(Image::from_vec(shape[1], shape[0], data).expect("shape checked"))
}

/// A uint16 `H×W` label image (0 = void).
pub fn label_image(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<LabelImage> {
    let (shape, data) = elements(obj, name, "uint16 of shape (H, W)", 2, &[], <[u16]>::to_vec)?;
    Ok(Image::from_vec(shape[1], shape[0], data).expect("shape checked"))
}

/// A uint8 `H×W×3` RGB image.
pub fn color_image(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<ColorImage> {
    // Straight into pixels: copying the bytes first cost another 0.3 ms or so per 640×480
    // frame.
    let (shape, pixels) = elements(
        obj,
        name,
        "uint8 of shape (H, W, 3)",
        3,
        &[3],
        |d: &[u8]| d.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    )?;
    Ok(Image::from_vec(shape[1], shape[0], pixels).expect("shape checked"))
}

/// A 1-D float64 or float32 array, as f64.
pub fn float_values(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let what = "float64 or float32 of shape (N,)";
    match elements(obj, name, what, 1, &[], <[f64]>::to_vec) {
        Ok((_, v)) => Ok(v),
        Err(e64) => match elements(obj, name, what, 1, &[], |d: &[f32]| {
            d.iter().copied().map(f64::from).collect::<Vec<_>>()
        }) {
            Ok((_, v)) => Ok(v),
            Err(_) => Err(e64),
        },
    }
}

/// An `N×3` float64 or float32 array of points.
pub fn points(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<nalgebra::Point3<f64>>> {
    let what = "float64 or float32 of shape (N, 3)";
    let of = |c: &[f64]| nalgebra::Point3::new(c[0], c[1], c[2]);
    match elements(obj, name, what, 2, &[3], |d: &[f64]| {
        d.chunks_exact(3).map(of).collect::<Vec<_>>()
    }) {
        Ok((_, v)) => Ok(v),
        Err(e64) => match elements(obj, name, what, 2, &[3], |d: &[f32]| {
            d.chunks_exact(3)
                .map(|c| of(&[c[0] as f64, c[1] as f64, c[2] as f64]))
                .collect::<Vec<_>>()
        }) {
            Ok((_, v)) => Ok(v),
            Err(_) => Err(e64),
        },
    }
}

/// An image as an `H×W` array; the pixel buffer moves into numpy without a copy.
pub fn image_to_py<T: Element>(
    py: Python<'_>,
    image: Image<T>,
) -> PyResult<Bound<'_, PyArray2<T>>> {
    let (w, h) = image.dims();
    let array = Array2::from_shape_vec((h, w), image.into_vec()).expect("an image is h×w");
    Ok(array.into_pyarray(py))
}

/// `N` triples (RGB pixels, vertices) as an `…×3` array, without a copy.
pub fn triples_to_py<T: Element>(
    py: Python<'_>,
    rows: Vec<[T; 3]>,
    shape: (usize, usize),
) -> Bound<'_, PyArray3<T>> {
    let array = Array3::from_shape_vec((shape.0, shape.1, 3), rows.into_flattened())
        .expect("shape matches");
    array.into_pyarray(py)
}

/// `N×3` array of triples, without a copy.
pub fn rows_to_py<T: Element>(py: Python<'_>, rows: Vec<[T; 3]>) -> Bound<'_, PyArray2<T>> {
    let n = rows.len();
    Array2::from_shape_vec((n, 3), rows.into_flattened())
        .expect("n×3")
        .into_pyarray(py)
}

/// `(fx, fy, cx, cy)` or a 3×3 camera matrix K, for an image of `width × height`.
pub fn intrinsics(
    obj: &Bound<'_, PyAny>,
    name: &str,
    (width, height): (usize, usize),
) -> PyResult<Intrinsics> {
    let values: Vec<f64> = if let Ok(v) = obj.extract::<[f64; 4]>() {
        v.to_vec()
    } else if let Ok(k) = obj.extract::<[[f64; 3]; 3]>() {
        vec![k[0][0], k[1][1], k[0][2], k[1][2]]
    } else {
        return Err(err(
            name,
            "expected (fx, fy, cx, cy) or a 3×3 camera matrix",
        ));
    };
    let k = Intrinsics {
        width,
        height,
        fx: values[0],
        fy: values[1],
        cx: values[2],
        cy: values[3],
    };
    k.check().map_err(|e| err(name, e))?;
    Ok(k)
}

/// A 4×4 rigid `T_world_camera` (any numeric array or nested sequence).
pub fn pose(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Pose> {
    let rows: [[f64; 4]; 4] = match obj.cast::<PyUntypedArray>() {
        // Arrays of any float dtype and layout: a pose is 16 numbers, so converting is free.
        Ok(a) => {
            if a.shape() != [4, 4] {
                return Err(err(
                    name,
                    format!("expected a 4×4 matrix, found shape {:?}", a.shape()),
                ));
            }
            obj.call_method0("tolist")?
                .extract()
                .map_err(|_| err(name, "expected a 4×4 matrix of numbers"))?
        }
        Err(_) => obj
            .extract()
            .map_err(|_| err(name, "expected a 4×4 matrix of numbers"))?,
    };
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    if m.iter().any(|v| !v.is_finite()) {
        return Err(err(name, "the matrix has a non-finite entry"));
    }
    voxpan_core::pose_from_matrix(&m).map_err(|e| err(name, e))
}

/// A pose as its 4×4 float64 matrix.
pub fn pose_to_py<'py>(py: Python<'py>, pose: &Pose) -> Bound<'py, PyArray2<f64>> {
    let m = pose.to_homogeneous();
    Array2::from_shape_fn((4, 4), |(r, c)| m[(r, c)]).into_pyarray(py)
}

/// Segments from a list of dicts `{"id", "class_id"?, "is_thing"?, "score"?}`.
pub fn segments_from_py(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Segment>> {
    let mut out = Vec::new();
    for (i, item) in obj
        .try_iter()
        .map_err(|_| err(name, "expected a list of dicts"))?
        .enumerate()
    {
        let item = item?;
        let d = item
            .cast::<PyDict>()
            .map_err(|_| err(name, format!("item {i} is not a dict")))?;
        let field = |key: &str| d.get_item(key).map(|v| v.filter(|v| !v.is_none()));
        let id: u16 = field("id")?
            .ok_or_else(|| err(name, format!("item {i} has no \"id\"")))?
            .extract()
            .map_err(|_| {
                err(
                    name,
                    format!("item {i}: \"id\" must be an integer 1..65535"),
                )
            })?;
        if id == 0 {
            return Err(err(name, format!("item {i}: id 0 is void, not a segment")));
        }
        let bad = |key: &str| err(name, format!("item {i}: \"{key}\" has the wrong type"));
        out.push(Segment {
            id,
            class_id: field("class_id")?
                .map(|v| v.extract())
                .transpose()
                .map_err(|_| bad("class_id"))?,
            is_thing: field("is_thing")?
                .map(|v| v.extract())
                .transpose()
                .map_err(|_| bad("is_thing"))?,
            score: field("score")?
                .map(|v| v.extract())
                .transpose()
                .map_err(|_| bad("score"))?,
        });
    }
    Ok(out)
}

/// A JSON value (what voxpan's reports serialise to) as plain Python objects.
pub fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(u)) => u.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let items: Vec<_> = a
                .iter()
                .map(|x| json_to_py(py, x))
                .collect::<PyResult<_>>()?;
            PyList::new(py, items)?.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}
