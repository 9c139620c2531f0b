//! What runs the ONNX graph: a [`Backend`] takes the input tensor and returns the outputs.
//! Two are built in, each behind a cargo feature: ONNX Runtime (`ort`, the fast path, loaded
//! from a shared library at run time) and tract (`tract`, pure Rust).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::YoloError;

/// Why a backend failed (its own error, as text for messages).
pub type BackendError = Box<dyn std::error::Error + Send + Sync>;

/// A dense float32 tensor, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// An ONNX inference engine with one model loaded.
pub trait Backend: Send {
    /// The engine and its version, for messages ("onnxruntime", "tract").
    fn name(&self) -> &str;
    /// The model's declared input shape; `None` for a dynamic dimension.
    fn input_shape(&self) -> &[Option<usize>];
    /// The model's metadata properties (`names`, `stride`, `imgsz`, `layout`, ...).
    fn metadata(&self) -> &BTreeMap<String, String>;
    /// Runs the model on one `[1, 3, H, W]` input; returns every output, in the model's order.
    fn run(&mut self, input: &[f32], shape: [usize; 4]) -> Result<Vec<Tensor>, BackendError>;
}

/// Which backend runs the model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// ONNX Runtime when built in, else tract.
    #[default]
    Auto,
    /// ONNX Runtime (cargo feature `ort`).
    Ort,
    /// tract (cargo feature `tract`).
    Tract,
}

impl BackendKind {
    /// The backends this build has.
    pub fn built() -> Vec<BackendKind> {
        let mut v = Vec::new();
        if cfg!(feature = "ort") {
            v.push(Self::Ort);
        }
        if cfg!(feature = "tract") {
            v.push(Self::Tract);
        }
        v
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Ort => "ort",
            Self::Tract => "tract",
        }
    }

    /// How to build a voxpan with this backend (`Auto`: with either).
    fn how_to_build(self) -> String {
        let ort = "`--features ort` (ONNX Runtime, loaded from ORT_DYLIB_PATH)";
        let tract = "`--features tract` (pure Rust)";
        match self {
            Self::Ort => format!("{ort}: `cargo build --release --features ort`"),
            Self::Tract => format!("{tract}: `cargo build --release --features tract`"),
            Self::Auto => {
                format!("{ort} or {tract}, e.g. `cargo build --release --features ort`")
            }
        }
    }

    /// The backend `self` stands for in this build, or why there is none.
    pub fn resolve(self) -> Result<BackendKind, YoloError> {
        let built = Self::built();
        match self {
            Self::Auto => built.first().copied().ok_or_else(|| YoloError::NotBuilt {
                backend: "a network backend".into(),
                build: self.how_to_build(),
            }),
            kind if built.contains(&kind) => Ok(kind),
            kind => Err(YoloError::NotBuilt {
                backend: format!("the {} backend", kind.name()),
                build: kind.how_to_build(),
            }),
        }
    }
}

impl std::fmt::Display for BackendKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for BackendKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "ort" | "onnxruntime" => Ok(Self::Ort),
            "tract" => Ok(Self::Tract),
            other => Err(format!(
                "unknown backend {other:?} (expected auto, ort or tract)"
            )),
        }
    }
}

/// How a backend is set up.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BackendOptions {
    /// Threads for inference; 0: the backend's default (ONNX Runtime: one per core).
    pub threads: usize,
    /// The ONNX Runtime shared library (`libonnxruntime.so.1.x`); default `$ORT_DYLIB_PATH`,
    /// else the system's `libonnxruntime.so`.
    pub ort_library: Option<PathBuf>,
    /// The input size `(width, height)` for a model whose input size is not fixed.
    pub input_size: Option<(usize, usize)>,
}

/// Loads `model` into the backend `kind` stands for.
pub fn open_backend(
    kind: BackendKind,
    model: &Path,
    options: &BackendOptions,
) -> Result<Box<dyn Backend>, YoloError> {
    match kind.resolve()? {
        #[cfg(feature = "ort")]
        BackendKind::Ort => Ok(Box::new(crate::ort_backend::OrtBackend::open(
            model, options,
        )?)),
        #[cfg(feature = "tract")]
        BackendKind::Tract => Ok(Box::new(crate::tract_backend::TractBackend::open(
            model, options,
        )?)),
        other => {
            // `resolve` only returns built backends; this arm is for builds without any.
            let _ = (model, options);
            Err(YoloError::NotBuilt {
                backend: format!("the {other} backend"),
                build: other.how_to_build(),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::BackendKind;

    /// `--backend tract` on a build with ort only names the tract feature, and back.
    #[test]
    fn a_missing_backend_names_its_own_feature() {
        let tract = BackendKind::Tract.how_to_build();
        assert!(tract.contains("--features tract") && !tract.contains("--features ort"));
        let ort = BackendKind::Ort.how_to_build();
        assert!(ort.contains("--features ort") && !ort.contains("--features tract"));
        let auto = BackendKind::Auto.how_to_build();
        assert!(auto.contains("--features ort") && auto.contains("--features tract"));
    }
}
