//! Locating the shared sample of the flat dataset, and the models and ONNX Runtime library
//! `tools/yolo/fetch_weights.sh` fetches, for tests and benchmarks.

use std::path::PathBuf;

/// Environment variable that points at a flat-format dataset directory.
pub const FLAT_DIR_ENV: &str = "VOXPAN_FLAT_DIR";
/// Set to `1` to let data-dependent tests skip (loudly) when the sample is missing.
pub const ALLOW_MISSING_ENV: &str = "VOXPAN_ALLOW_MISSING_DATA";
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

/// For tests that need the flat sample: its directory, or a panic that says how to provide it.
/// With `VOXPAN_ALLOW_MISSING_DATA=1` the test is skipped instead, with a message on stderr.
pub fn require_flat_sample(test: &str) -> Option<PathBuf> {
    if let Some(dir) = flat_sample_dir() {
        return Some(dir);
    }
    missing(format!(
        "{test}: the flat dataset sample is missing: expected ../shared/data/flat beside the \
         checkout, or set {FLAT_DIR_ENV}"
    ))
}

/// Whether tests may skip (saying so) what they need and cannot find: exactly
/// `VOXPAN_ALLOW_MISSING_DATA=1`. Unset or any other value: a missing prerequisite fails the
/// test. Every test reads the switch through this.
pub fn missing_data_allowed() -> bool {
    std::env::var(ALLOW_MISSING_ENV).as_deref() == Ok("1")
}

/// Skips (with `VOXPAN_ALLOW_MISSING_DATA=1`) or fails a test whose data is missing.
fn missing<T>(msg: String) -> Option<T> {
    if missing_data_allowed() {
        eprintln!("SKIPPED {msg}");
        None
    } else {
        panic!("{msg} (or set {ALLOW_MISSING_ENV}=1 to skip)");
    }
}

/// For tests that run an installed program (`chromium`): its path on `PATH`, or a panic that
/// names it and how to install it (`install`). With `VOXPAN_ALLOW_MISSING_DATA=1` the test is
/// skipped instead.
pub fn require_program(program: &str, install: &str, test: &str) -> Option<PathBuf> {
    let found = std::env::var_os("PATH").and_then(|path| {
        std::env::split_paths(&path)
            .map(|dir| dir.join(program))
            .find(|p| p.is_file())
    });
    if found.is_some() {
        return found;
    }
    missing(format!("{test}: `{program}` is not on PATH: {install}"))
}

/// Where `tools/yolo/fetch_weights.sh` puts models: `$VOXPAN_MODELS_DIR`, else
/// `target/models` in the checkout (the script's default).
pub fn models_dir() -> PathBuf {
    match std::env::var_os(MODELS_DIR_ENV) {
        Some(dir) => PathBuf::from(dir),
        None => workspace().join("target/models"),
    }
}

/// For tests that need a fetched model (`file` in [`models_dir`], e.g.
/// `yolov5s-seg-640.onnx`, GPL weights that are never committed): its path, or a panic that
/// says how to fetch it. With `VOXPAN_ALLOW_MISSING_DATA=1` the test is skipped instead.
pub fn require_model(file: &str, test: &str) -> Option<PathBuf> {
    let path = models_dir().join(file);
    if path.is_file() {
        return Some(path.canonicalize().unwrap_or(path));
    }
    missing(format!(
        "{test}: model {} is missing: run tools/yolo/fetch_weights.sh, or set {MODELS_DIR_ENV}",
        path.display()
    ))
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

/// For tests of the ONNX Runtime backend: the library ([`onnxruntime_library`]), or a panic
/// that says how to get it. With `VOXPAN_ALLOW_MISSING_DATA=1` the test is skipped instead.
pub fn require_onnxruntime(test: &str) -> Option<PathBuf> {
    match onnxruntime_library() {
        Some(path) if path.is_file() => Some(path),
        other => missing(format!(
            "{test}: the ONNX Runtime library is missing ({}): run tools/yolo/fetch_weights.sh \
             and set {ORT_LIBRARY_ENV} to the path it prints",
            other.map_or_else(
                || format!("{ORT_LIBRARY_ENV} unset and no tools venv"),
                |p| format!("{} is not a file", p.display())
            )
        )),
    }
}
