//! `voxpan.PanopticMap`: voxpan_map::PanopticMap with numpy frames.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Mutex;

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use voxpan_core::RgbdView;
use voxpan_map::{Coloring, MapConfig, MapError, PanopticMap};

use crate::convert::{
    color_image, depth_image, image_to_py, json_to_py, label_image, rows_to_py, triples_to_py,
};
use crate::{segments_for, voxpan_error};

/// Configuration errors are the caller's values (`ValueError`); the rest are voxpan's.
fn map_error(e: MapError) -> PyErr {
    match e {
        MapError::Config(_) => PyValueError::new_err(e.to_string()),
        other => voxpan_error(other),
    }
}

/// A panoptic TSDF map: depth, colour and instances fused on hashed voxel blocks.
///
/// Every argument is optional; `None` means voxpan's default (the `[tsdf]` and `[tracking]`
/// sections of its configuration file).
#[pyclass(name = "PanopticMap", module = "voxpan")]
pub struct PyPanopticMap {
    // The GIL is released while the map works; the lock keeps a second Python thread out.
    map: Mutex<PanopticMap>,
    /// Frames integrated so far: names frames in error messages.
    frames: Mutex<u64>,
}

impl PyPanopticMap {
    pub(crate) fn wrap(map: PanopticMap) -> Self {
        Self {
            map: Mutex::new(map),
            frames: Mutex::new(0),
        }
    }

    pub(crate) fn lock(&self) -> std::sync::MutexGuard<'_, PanopticMap> {
        // A panic inside the library (a bug) poisons the lock; the map is still readable.
        self.map.lock().unwrap_or_else(|p| p.into_inner())
    }
}

fn coloring(by: &str) -> PyResult<Coloring> {
    match by {
        "rgb" => Ok(Coloring::Rgb),
        "instance" => Ok(Coloring::Instance),
        "class" => Ok(Coloring::Class),
        other => Err(PyValueError::new_err(format!(
            "by: {other:?} (expected \"rgb\", \"instance\" or \"class\")"
        ))),
    }
}

#[pymethods]
impl PyPanopticMap {
    #[new]
    #[pyo3(signature = (
        voxel_size = None, truncation_voxels = None, max_range = None, min_range = None,
        max_weight = None, min_overlap = None, min_pixels = None, downscale = None,
        min_observations = None, min_voxels = None, merge_votes = None,
        class_aware_things = None, max_memory_gb = None, class_names = None, esdf = None,
        esdf_max_distance = None, consolidate_every = None,
    ))]
    #[allow(clippy::too_many_arguments)] // one keyword per configuration key
    fn new(
        voxel_size: Option<f64>,
        truncation_voxels: Option<f64>,
        max_range: Option<f64>,
        min_range: Option<f64>,
        max_weight: Option<f32>,
        min_overlap: Option<f64>,
        min_pixels: Option<usize>,
        downscale: Option<usize>,
        min_observations: Option<u32>,
        min_voxels: Option<usize>,
        merge_votes: Option<u32>,
        class_aware_things: Option<bool>,
        max_memory_gb: Option<f64>,
        class_names: Option<BTreeMap<u32, String>>,
        esdf: Option<bool>,
        esdf_max_distance: Option<f64>,
        consolidate_every: Option<u32>,
    ) -> PyResult<Self> {
        let mut c = MapConfig::default();
        let (t, k) = (&mut c.tsdf, &mut c.tracking);
        t.voxel_size = voxel_size.unwrap_or(t.voxel_size);
        t.truncation_voxels = truncation_voxels.unwrap_or(t.truncation_voxels);
        t.max_range = max_range.unwrap_or(t.max_range);
        t.min_range = min_range.unwrap_or(t.min_range);
        t.max_weight = max_weight.unwrap_or(t.max_weight);
        k.min_overlap = min_overlap.unwrap_or(k.min_overlap);
        k.min_pixels = min_pixels.unwrap_or(k.min_pixels);
        k.downscale = downscale.unwrap_or(k.downscale);
        k.min_observations = min_observations.unwrap_or(k.min_observations);
        k.min_voxels = min_voxels.unwrap_or(k.min_voxels);
        k.merge_votes = merge_votes.unwrap_or(k.merge_votes);
        k.class_aware_things = class_aware_things.unwrap_or(k.class_aware_things);
        k.consolidate_every = consolidate_every.unwrap_or(k.consolidate_every);
        c.esdf.enabled = esdf.unwrap_or(c.esdf.enabled);
        c.esdf.max_distance = esdf_max_distance.unwrap_or(c.esdf.max_distance);
        let mut map = PanopticMap::new(c).map_err(map_error)?;
        if let Some(gb) = max_memory_gb {
            voxpan_map::check_range("max_memory_gb", gb, 0.01, 1e6)
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            map.set_memory_limit(Some((gb * 1e9) as u64));
        }
        if let Some(names) = class_names {
            map.set_class_names(names);
        }
        Ok(Self::wrap(map))
    }

    /// Fuses one frame: `depth` float32 H×W metres, `color` uint8 H×W×3, `intrinsics`
    /// (fx, fy, cx, cy) or 3×3 K, `pose` 4×4 T_world_camera. With `labels` (uint16 H×W,
    /// 0 = void) the segments are matched to map instances first; `segments` (dicts as
    /// `open_dataset` gives) say what each id is. `identified=True`: the label ids already
    /// identify objects across frames (no association; an instance still shows once seen in
    /// `min_observations` frames). Returns the frame's report.
    #[pyo3(signature = (depth, color, intrinsics, pose, labels = None, segments = None, identified = false))]
    #[allow(clippy::too_many_arguments)] // mirrors the Python signature
    fn integrate<'py>(
        &self,
        py: Python<'py>,
        depth: &Bound<'py, PyAny>,
        color: &Bound<'py, PyAny>,
        intrinsics: &Bound<'py, PyAny>,
        pose: &Bound<'py, PyAny>,
        labels: Option<&Bound<'py, PyAny>>,
        segments: Option<&Bound<'py, PyAny>>,
        identified: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let depth = depth_image(depth, "depth")?;
        let color = color_image(color, "color")?;
        let k = crate::convert::intrinsics(intrinsics, "intrinsics", depth.dims())?;
        let pose = crate::convert::pose(pose, "pose")?;
        if color.dims() != depth.dims() {
            return Err(PyValueError::new_err(format!(
                "color: {}x{} pixels, depth {}x{}",
                color.width(),
                color.height(),
                depth.width(),
                depth.height()
            )));
        }
        let segments = match (labels, segments) {
            (Some(l), s) => {
                let l = label_image(l, "labels")?;
                if l.dims() != depth.dims() {
                    return Err(PyValueError::new_err(format!(
                        "labels: {}x{} pixels, depth {}x{}",
                        l.width(),
                        l.height(),
                        depth.width(),
                        depth.height()
                    )));
                }
                Some(segments_for(l, s)?)
            }
            (None, Some(_)) => {
                return Err(PyValueError::new_err(
                    "segments: given without labels (the label image they describe)",
                ));
            }
            (None, None) => None,
        };
        if identified && segments.is_none() {
            return Err(PyValueError::new_err("identified: needs labels"));
        }
        let id = {
            let mut n = self.frames.lock().unwrap_or_else(|p| p.into_inner());
            *n += 1;
            format!("#{}", *n - 1)
        };
        let view = RgbdView {
            depth: &depth,
            color: &color,
            intrinsics: &k,
            pose: &pose,
        };
        let report = py.detach(|| {
            let mut map = self.lock();
            match (&segments, identified) {
                (Some(s), true) => map.integrate_identified(view, s),
                (s, _) => map.integrate(view, s.as_ref()),
            }
        });
        let report = report.map_err(|e| match e {
            MapError::Config(_) => map_error(e),
            other => voxpan_error(format!("frame {id}: {other}")),
        })?;
        json_to_py(py, &serde_json::to_value(report).expect("plain data"))
    }

    /// The whole map's mesh, welded: `(vertices N×3 float32, triangles M×3 uint32, colors
    /// N×3 uint8, normals N×3 float32)`, coloured by "rgb", "instance" or "class".
    #[pyo3(signature = (by = "rgb"))]
    #[allow(clippy::type_complexity)] // the tuple is the Python return value
    fn mesh<'py>(
        &self,
        py: Python<'py>,
        by: &str,
    ) -> PyResult<(
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray2<u32>>,
        Bound<'py, PyArray2<u8>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let coloring = coloring(by)?;
        let mesh = py.detach(|| self.lock().mesh(coloring));
        Ok((
            rows_to_py(py, mesh.vertices),
            rows_to_py(py, mesh.triangles),
            rows_to_py(py, mesh.colors),
            rows_to_py(py, mesh.normals),
        ))
    }

    /// Every map instance: dicts with id, class_id, class_name, is_thing, voxels, bounds,
    /// frames_seen.
    fn instances<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = py.detach(|| self.lock().instances());
        let items: Vec<_> = list
            .iter()
            .map(|i| json_to_py(py, &serde_json::to_value(i).expect("plain data")))
            .collect::<PyResult<_>>()?;
        PyList::new(py, items)
    }

    /// The map seen from a camera (`size` = (width, height)): a dict with "depth" (float32
    /// H×W, metres, 0 where nothing), "color" (uint8 H×W×3), "instances" (uint16 H×W) and
    /// "normals" (float32 H×W×3, world frame).
    #[pyo3(signature = (intrinsics, pose, size))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        intrinsics: &Bound<'py, PyAny>,
        pose: &Bound<'py, PyAny>,
        size: (usize, usize),
    ) -> PyResult<Bound<'py, PyDict>> {
        if size.0 == 0 || size.1 == 0 || size.0 > 16384 || size.1 > 16384 {
            return Err(PyValueError::new_err(format!(
                "size: {size:?} (expected (width, height), 1 to 16384 pixels each)"
            )));
        }
        let k = crate::convert::intrinsics(intrinsics, "intrinsics", size)?;
        let pose = crate::convert::pose(pose, "pose")?;
        let view = py.detach(|| self.lock().render(&k, &pose));
        let (w, h) = size;
        let d = PyDict::new(py);
        d.set_item("depth", image_to_py(py, view.depth)?)?;
        d.set_item("color", triples_to_py(py, view.color.into_vec(), (h, w)))?;
        d.set_item("instances", image_to_py(py, view.instances)?)?;
        d.set_item(
            "normals",
            triples_to_py(py, view.normals.into_vec(), (h, w)),
        )?;
        Ok(d)
    }

    /// Brings the Euclidean signed distance field up to date (built from the whole map on the
    /// first call, then from the blocks that changed); returns what the update did. Free
    /// space is known where the map was built with `esdf=True`.
    fn update_esdf<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let stats = py.detach(|| self.lock().update_esdf());
        json_to_py(py, &serde_json::to_value(stats).expect("plain data"))
    }

    /// Signed distances (float32 `(N,)`, metres; negative inside objects, NaN where the map
    /// has not observed the point) at `points` (`N×3`), as of the last `update_esdf`.
    fn distance<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let points = crate::convert::points(points, "points")?;
        let d = py.detach(|| self.lock().distances(&points));
        Ok(d.into_iter()
            .map(|d| d.unwrap_or(f32::NAN))
            .collect::<Vec<_>>()
            .into_pyarray(py))
    }

    /// Signed distances interpolated trilinearly (`(N,)`) and their gradients (`N×3`) at
    /// `points`; NaN unless the eight voxels around a point are observed.
    fn distance_and_gradient<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyArray2<f32>>)> {
        let points = crate::convert::points(points, "points")?;
        let found = py.detach(|| self.lock().distances_and_gradients(&points));
        let (mut distances, mut gradients) = (Vec::new(), Vec::new());
        for f in found {
            let (d, g) = f.map_or((f32::NAN, [f32::NAN; 3]), |(d, g)| (d, [g.x, g.y, g.z]));
            distances.push(d);
            gradients.push(g);
        }
        Ok((distances.into_pyarray(py), rows_to_py(py, gradients)))
    }

    /// Every voxel of the distance field with a distance: `(indices M×3 int32, distances
    /// (M,) float32)`; voxel `v` spans `[v, v + 1) × voxel_size`, sites read 0.
    fn esdf_voxels<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray2<i32>>, Bound<'py, PyArray1<f32>>) {
        let voxels = py.detach(|| self.lock().esdf_voxels());
        let (indices, distances): (Vec<[i32; 3]>, Vec<f32>) = voxels.into_iter().unzip();
        (rows_to_py(py, indices), distances.into_pyarray(py))
    }

    /// The 2-D costmap between `min_z` and `max_z` (metres along world z), obstacles
    /// inflated by `robot_radius`, as of the last `update_esdf`: a dict with "occupancy"
    /// (int8 rows × columns: 100 occupied, 0 free, -1 unknown, row 0 at the lowest y),
    /// "resolution" and "origin" (x, y of cell (0, 0)'s corner); None when nothing observed
    /// lies between the heights.
    #[pyo3(signature = (min_z, max_z, robot_radius = 0.0))]
    fn costmap<'py>(
        &self,
        py: Python<'py>,
        min_z: f64,
        max_z: f64,
        robot_radius: f64,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let costmap = {
            let mut map = self.lock();
            let mut esdf = map.config().esdf;
            (esdf.slice_min_z, esdf.slice_max_z, esdf.robot_radius) = (min_z, max_z, robot_radius);
            esdf.up_axis = voxpan_map::UpAxis::Z;
            map.set_esdf_config(esdf).map_err(map_error)?;
            map.costmap()
        };
        let Some(c) = costmap else { return Ok(None) };
        let d = PyDict::new(py);
        let occupancy = numpy::ndarray::Array2::from_shape_vec((c.height, c.width), c.occupancy())
            .expect("height × width");
        d.set_item("occupancy", occupancy.into_pyarray(py))?;
        d.set_item("resolution", c.resolution)?;
        d.set_item("origin", (c.origin[0], c.origin[1]))?;
        Ok(Some(d))
    }

    /// Writes the map file (atomically; versioned, checksummed, compressed).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.lock().save(&path)).map_err(map_error)
    }

    /// Reads a map file written by `save` or `voxpan run`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        py.detach(|| PanopticMap::load(&path))
            .map(Self::wrap)
            .map_err(map_error)
    }

    /// Joins instances the whole map shows to be one object (instances of any class meeting
    /// along a seam, not told apart by the frames), then fills label holes (unlabelled surface
    /// that one instance alone borders and outsizes takes it); `voxpan run` does it after its
    /// last frame. Returns the merges made.
    fn consolidate(&self, py: Python<'_>) -> usize {
        py.detach(|| self.lock().consolidate())
    }

    /// Names of the class ids the segments carry (kept in the map file).
    fn set_class_names(&self, names: BTreeMap<u32, String>) {
        self.lock().set_class_names(names);
    }

    /// Allocated voxel blocks.
    #[getter]
    fn block_count(&self) -> usize {
        self.lock().block_count()
    }

    /// Shown instances (re-observed at least `min_observations` times, and leading at least
    /// `min_voxels` surface voxels).
    #[getter]
    fn instance_count(&self) -> usize {
        self.lock().instance_count()
    }

    /// Bytes of voxel blocks held.
    #[getter]
    fn memory_bytes(&self) -> u64 {
        self.lock().memory_bytes()
    }

    /// The effective configuration, as nested dicts (`tsdf`, `tracking`).
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let c = *self.lock().config();
        json_to_py(py, &serde_json::to_value(c).expect("plain data"))
    }

    fn __repr__(&self) -> String {
        let map = self.lock();
        format!(
            "PanopticMap(voxel_size={}, blocks={}, instances={})",
            map.voxel_size(),
            map.block_count(),
            map.instance_count()
        )
    }
}
