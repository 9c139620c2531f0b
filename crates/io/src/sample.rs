//! Locating the shared sample of the flat dataset for tests and benchmarks.

use std::path::PathBuf;

/// Environment variable that points at a flat-format dataset directory.
pub const FLAT_DIR_ENV: &str = "VOXPAN_FLAT_DIR";
/// Set to `1` to let data-dependent tests skip (loudly) when the sample is missing.
pub const ALLOW_MISSING_ENV: &str = "VOXPAN_ALLOW_MISSING_DATA";

/// The flat sample: `$VOXPAN_FLAT_DIR`, else `../shared/data/flat` beside the checkout.
pub fn flat_sample_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os(FLAT_DIR_ENV) {
        return Some(PathBuf::from(dir)).filter(|d| d.join("run1").is_dir());
    }
    let workspace = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir = workspace.join("../shared/data/flat");
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
    let msg = format!(
        "{test}: the flat dataset sample is missing: expected ../shared/data/flat beside the \
         checkout, or set {FLAT_DIR_ENV}"
    );
    if std::env::var(ALLOW_MISSING_ENV).as_deref() == Ok("1") {
        eprintln!("SKIPPED {msg}");
        None
    } else {
        panic!("{msg} (or set {ALLOW_MISSING_ENV}=1 to skip)");
    }
}
