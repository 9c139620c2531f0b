//! What voxpan's tests share and no product needs: each `require_*` finds a prerequisite
//! (the flat sample, a fetched model, ONNX Runtime, an installed program) or fails the test
//! saying how to provide it; with `VOXPAN_ALLOW_MISSING_DATA=1` exactly, the test is skipped
//! instead, saying so (`SKIPPED ...` on stderr).

use std::path::PathBuf;

use voxpan_io::{
    FLAT_DIR_ENV, MODELS_DIR_ENV, ORT_LIBRARY_ENV, flat_sample_dir, models_dir, onnxruntime_library,
};

/// Set to `1` to let data-dependent tests skip (loudly) when the sample is missing.
pub const ALLOW_MISSING_ENV: &str = "VOXPAN_ALLOW_MISSING_DATA";
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

/// The checkout's README.md.
pub fn readme() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md");
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The README's section under the line `heading` (`## Configuration`), up to the next `## `.
pub fn readme_section<'a>(readme: &'a str, heading: &str) -> &'a str {
    let after = readme
        .split_once(&format!("\n{heading}\n"))
        .unwrap_or_else(|| panic!("README.md has no {heading:?}"))
        .1;
    after
        .split_once("\n## ")
        .map_or(after, |(section, _)| section)
}

/// The body of the first code block of `section` opened by ```` ```lang ```` (`lang` empty:
/// a block without a language).
pub fn code_block<'a>(section: &'a str, lang: &str) -> &'a str {
    let body = section
        .split_once(&format!("```{lang}\n"))
        .unwrap_or_else(|| panic!("no ```{lang} block in the section"))
        .1;
    body.split_once("\n```").expect("the block is closed").0
}
