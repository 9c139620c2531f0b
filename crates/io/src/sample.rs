//! Locating the shared sample of the flat dataset, and the models and ONNX Runtime library
//! `tools/yolo/fetch_weights.sh` fetches: the defaults of `voxpan bench` and the network
//! options, the benchmarks' and examples' data. Tests require them through
//! `voxpan-test-support`.

use std::path::PathBuf;

/// Environment variable that points at a flat-format dataset directory.
pub const FLAT_DIR_ENV: &str = "VOXPAN_FLAT_DIR";
/// Environment variable that points at the folder of fetched models.
pub const MODELS_DIR_ENV: &str = "VOXPAN_MODELS_DIR";
/// The ONNX Runtime library the `ort` backend loads (the variable `ort` itself reads).
pub const ORT_LIBRARY_ENV: &str = "ORT_DYLIB_PATH";

/// The checkout's root.
fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The flat sample: `$VOXPAN_FLAT_DIR`, else `../shared/data/flat` beside the checkout.
pub fn flat_sample_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os(FLAT_DIR_ENV) {
        return Some(PathBuf::from(dir)).filter(|d| d.join("run1").is_dir());
    }
    let dir = workspace().join("../shared/data/flat");
    dir.join("run1")
        .is_dir()
        .then(|| dir.canonicalize().unwrap_or(dir))
}

/// Where `tools/yolo/fetch_weights.sh` puts models: `$VOXPAN_MODELS_DIR`, else
/// `target/models` in the checkout (the script's default).
pub fn models_dir() -> PathBuf {
    match std::env::var_os(MODELS_DIR_ENV) {
        Some(dir) => PathBuf::from(dir),
        None => workspace().join("target/models"),
    }
}

/// The ONNX Runtime library: `$ORT_DYLIB_PATH`, else the one `tools/yolo/fetch_weights.sh`
/// installs into its Python environment (`$VOXPAN_TOOLS_VENV`, default `target/tools-venv`).
pub fn onnxruntime_library() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os(ORT_LIBRARY_ENV).filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(path));
    }
    let venv = std::env::var_os("VOXPAN_TOOLS_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target/tools-venv"));
    let mut found: Vec<PathBuf> = std::fs::read_dir(venv.join("lib"))
        .ok()?
        .flatten()
        .map(|python| python.path().join("site-packages/onnxruntime/capi"))
        .filter_map(|capi| std::fs::read_dir(capi).ok())
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("libonnxruntime.so"))
        })
        .collect();
    found.sort();
    found.pop()
}
