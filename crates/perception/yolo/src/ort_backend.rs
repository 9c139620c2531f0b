//! The ONNX Runtime backend (cargo feature `ort`). ONNX Runtime is a shared library loaded at
//! run time (`ort`'s `load-dynamic`): nothing is downloaded at build time. The library comes
//! from [`BackendOptions::ort_library`], else `$ORT_DYLIB_PATH`, else the system's
//! `libonnxruntime.so`; `tools/yolo/fetch_weights.sh` prints the path of the one it installs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use ort::environment::Environment;
use ort::session::Session;
use ort::value::TensorRef;

use crate::YoloError;
use crate::backend::{Backend, BackendError, BackendOptions, Tensor};

/// ONNX Runtime allows one library and one environment per process: the first load wins and
/// is shared by every session.
static ENVIRONMENT: Mutex<Option<(PathBuf, Environment)>> = Mutex::new(None);

/// The shared ONNX Runtime environment, loading the library on first use.
fn environment(options: &BackendOptions) -> Result<Environment, YoloError> {
    let library = options
        .ort_library
        .clone()
        .or_else(|| {
            std::env::var_os("ORT_DYLIB_PATH")
                .filter(|p| !p.is_empty())
                .map(PathBuf::from)
        })
        .unwrap_or_else(|| {
            PathBuf::from(format!(
                "{}onnxruntime{}",
                std::env::consts::DLL_PREFIX,
                std::env::consts::DLL_SUFFIX
            ))
        });
    let hint = "set ORT_DYLIB_PATH to libonnxruntime.so (tools/yolo/fetch_weights.sh installs \
                one and prints its path)";
    // A path that names a file must exist; a bare name is left to the system's search.
    if library.components().count() > 1 && !library.is_file() {
        return Err(YoloError::Library {
            path: library,
            message: format!("no such file; {hint}"),
        });
    }
    let mut env = ENVIRONMENT.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((loaded, environment)) = env.as_ref() {
        if *loaded != library {
            return Err(YoloError::Library {
                path: library,
                message: format!(
                    "ONNX Runtime is already loaded from {} in this process",
                    loaded.display()
                ),
            });
        }
        return Ok(environment.clone());
    }
    let builder = ort::init_from(&library).map_err(|e| YoloError::Library {
        path: library.clone(),
        message: format!("{e}; {hint}"),
    })?;
    let environment = builder
        .with_name("voxpan")
        .build()
        .map_err(|e| YoloError::Library {
            path: library.clone(),
            message: e.to_string(),
        })?;
    *env = Some((library, environment.clone()));
    Ok(environment)
}

/// One model in an ONNX Runtime session.
pub struct OrtBackend {
    session: Session,
    name: String,
    input_shape: Vec<Option<usize>>,
    metadata: BTreeMap<String, String>,
}

impl OrtBackend {
    pub fn open(model: &Path, options: &BackendOptions) -> Result<Self, YoloError> {
        let environment = environment(options)?;
        let bad_model = |message: String| YoloError::Model {
            path: model.to_owned(),
            message,
        };
        let mut builder =
            Session::builder(&environment).map_err(|e| bad_model(format!("ONNX Runtime: {e}")))?;
        if options.threads > 0 {
            builder = builder
                .with_intra_threads(options.threads)
                .map_err(|e| bad_model(format!("ONNX Runtime: {e}")))?;
        }
        let session = builder
            .commit_from_file(model)
            .map_err(|e| bad_model(format!("ONNX Runtime cannot load it: {e}")))?;
        let [input] = session.inputs() else {
            return Err(bad_model(format!(
                "expected one input (the image), the model has {}",
                session.inputs().len()
            )));
        };
        let input_shape = input
            .dtype()
            .tensor_shape()
            .ok_or_else(|| bad_model(format!("input {} is not a tensor", input.name())))?
            .iter()
            .map(|&d| usize::try_from(d).ok())
            .collect();
        let meta = session
            .metadata()
            .map_err(|e| bad_model(format!("cannot read its metadata: {e}")))?;
        let mut metadata = BTreeMap::new();
        for key in meta.custom_keys().unwrap_or_default() {
            if let Some(value) = meta.custom(&key) {
                metadata.insert(key, value);
            }
        }
        drop(meta);
        Ok(Self {
            session,
            name: "onnxruntime".into(),
            input_shape,
            metadata,
        })
    }
}

impl Backend for OrtBackend {
    fn name(&self) -> &str {
        &self.name
    }

    fn input_shape(&self) -> &[Option<usize>] {
        &self.input_shape
    }

    fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    fn run(&mut self, input: &[f32], shape: [usize; 4]) -> Result<Vec<Tensor>, BackendError> {
        let tensor = TensorRef::from_array_view((shape, input))?;
        let outputs = self.session.run(ort::inputs![tensor])?;
        let mut out = Vec::with_capacity(outputs.len());
        for (name, value) in &outputs {
            let (shape, data) = value
                .try_extract_tensor::<f32>()
                .map_err(|e| format!("output {name}: {e}"))?;
            out.push(Tensor {
                shape: shape.iter().map(|&d| d.max(0) as usize).collect(),
                data: data.to_vec(),
            });
        }
        Ok(out)
    }
}
