//! Golden files (ONNX Runtime's outputs from `tools/yolo/golden.py`), a backend that replays
//! them, and the backends this build has.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;
use voxpan_yolo::{Backend, BackendError, BackendKind, Tensor, Yolo, YoloOptions};

/// The committed tiny random-weight models (ours) and their goldens.
pub fn tiny(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(file)
}

/// `MODEL.golden.json` and `MODEL.golden.bin` beside a model.
pub struct Golden {
    pub json: Value,
    bin: Vec<u8>,
}

impl Golden {
    pub fn load(model: &Path) -> Self {
        let stem = model.with_extension("");
        let json_path = stem.with_extension("golden.json");
        let json: Value = serde_json::from_str(
            &std::fs::read_to_string(&json_path)
                .unwrap_or_else(|e| panic!("{}: {e}", json_path.display())),
        )
        .unwrap();
        let bin = std::fs::read(stem.with_extension("golden.bin")).unwrap();
        Self { json, bin }
    }

    pub fn cases(&self) -> &[Value] {
        self.json["cases"].as_array().unwrap()
    }

    pub fn case(&self, name: &str) -> &Value {
        self.cases().iter().find(|c| c["name"] == name).unwrap()
    }

    pub fn tensor(&self, case: &Value, name: &str) -> Tensor {
        let t = &case["tensors"][name];
        let shape: Vec<usize> = t["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d.as_u64().unwrap() as usize)
            .collect();
        let offset = t["offset"].as_u64().unwrap() as usize;
        let n: usize = shape.iter().product();
        let data = self.bin[offset..offset + 4 * n]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Tensor { shape, data }
    }

    pub fn metadata(&self) -> BTreeMap<String, String> {
        self.json["metadata"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(k, v)| (k.clone(), v.as_str().unwrap().to_owned()))
            .collect()
    }
}

/// A backend that answers every input with one golden case's outputs: post-processing on
/// ONNX Runtime's numbers, without any inference engine.
pub struct Replay {
    shape: Vec<Option<usize>>,
    metadata: BTreeMap<String, String>,
    outputs: Vec<Tensor>,
}

impl Replay {
    pub fn new(golden: &Golden, case: &Value) -> Self {
        let input = golden.tensor(case, "images");
        Self {
            shape: input.shape.iter().map(|&d| Some(d)).collect(),
            metadata: golden.metadata(),
            outputs: vec![
                golden.tensor(case, "output0"),
                golden.tensor(case, "output1"),
            ],
        }
    }
}

impl Backend for Replay {
    fn name(&self) -> &str {
        "replay"
    }
    fn input_shape(&self) -> &[Option<usize>] {
        &self.shape
    }
    fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }
    fn run(&mut self, _: &[f32], _: [usize; 4]) -> Result<Vec<Tensor>, BackendError> {
        Ok(self.outputs.clone())
    }
}

/// The golden detections' settings (confidence 0.25, NMS 0.45, no cap).
pub fn golden_options() -> YoloOptions {
    YoloOptions {
        max_detections: 1000,
        ..YoloOptions::default()
    }
}

/// The backends built in, each with the options that load it (ONNX Runtime's library from
/// `$ORT_DYLIB_PATH` or the tools venv). Empty when the test must be skipped.
#[allow(dead_code)]
pub fn backends(test: &str) -> Vec<YoloOptions> {
    let mut out = Vec::new();
    for kind in BackendKind::built() {
        let mut options = golden_options();
        options.backend = kind;
        if kind == BackendKind::Ort {
            match voxpan_test_support::require_onnxruntime(test) {
                Some(lib) => options.ort_library = Some(lib),
                None => continue,
            }
        }
        out.push(options);
    }
    out
}

/// Opens a model on a backend, panicking with the error's message.
#[allow(dead_code)]
pub fn open(path: &Path, options: &YoloOptions) -> Yolo {
    Yolo::open(path, options).unwrap_or_else(|e| panic!("{e}"))
}
