//! The segmentation network's options, shared by `run`, `segment` and `bench`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use voxpan_yolo::{BackendKind, YoloOptions, YoloSegmenter};

#[derive(clap::Args, Clone, Debug, Default)]
pub struct NetworkArgs {
    /// YOLO instance-segmentation model (ONNX: YOLOv5-seg or Ultralytics YOLOv8/11-seg
    /// export). Needs a voxpan built with `--features ort` (ONNX Runtime, loaded from
    /// $ORT_DYLIB_PATH) or `--features tract` (pure Rust).
    #[arg(long, value_name = "M.onnx")]
    pub model: Option<PathBuf>,
    /// Network input size in pixels (square), e.g. 320 or 640 [default: the model's]. A model
    /// exported at a fixed size only takes that size.
    #[arg(long, requires = "model", value_name = "320|640")]
    pub input_size: Option<usize>,
    /// Inference backend: auto (ONNX Runtime when built in, else tract), ort or tract.
    #[arg(long, requires = "model", default_value = "auto")]
    pub backend: BackendKind,
    /// Detections scoring at most this are dropped.
    #[arg(long, requires = "model", default_value_t = 0.25)]
    pub confidence: f32,
    /// A class of the model to map as stuff (repeatable; every other class is a thing).
    #[arg(long, requires = "model", value_name = "CLASS")]
    pub stuff: Vec<String>,
}

impl NetworkArgs {
    /// The library's options for this command line.
    pub fn options(&self) -> YoloOptions {
        YoloOptions {
            backend: self.backend,
            input_size: self.input_size,
            confidence: self.confidence,
            ort_library: ort_library(),
            ..YoloOptions::default()
        }
    }

    /// Loads `--model` (on `--backend`); `None` without `--model`. Errors name the option
    /// and the file.
    pub fn open(&self) -> Result<Option<YoloSegmenter>> {
        let Some(model) = &self.model else {
            return Ok(None);
        };
        self.open_on(model, self.backend).map(Some)
    }

    /// Loads `model` on `backend` with the other options of this command line.
    pub fn open_on(&self, model: &std::path::Path, backend: BackendKind) -> Result<YoloSegmenter> {
        let options = YoloOptions {
            backend,
            ..self.options()
        };
        options
            .validate()
            .map_err(|e| anyhow::anyhow!("invalid option: {e}"))?;
        // The library's errors name the file (or the feature to build with).
        YoloSegmenter::open(model, &options, &self.stuff).context("--model")
    }
}

/// ONNX Runtime's library: `$ORT_DYLIB_PATH`, else the one `tools/yolo/fetch_weights.sh`
/// installed into this checkout's `target/tools-venv` (so that `cargo run --features ort`
/// works right after it), else `None`: the system's `libonnxruntime.so`.
pub fn ort_library() -> Option<PathBuf> {
    voxpan_io::onnxruntime_library()
}
