//! What a person reads: the report of a run (`metrics.json`, `report.md`, `report.html`) and of
//! an evaluation (tables, IoU per frame, depth densities with the kept interval, a mask's depth
//! before and after refinement).
//!
//! ```
//! use voxpan_pipeline::{Config, Outputs, RunReport};
//! use voxpan_report::{write_run_report, RunSummary};
//!
//! let dir = tempfile::tempdir()?;
//! let mut folder = voxpan_pipeline::RunFolder::open(dir.path())?;
//! let report = RunReport { frames: 10, fps: 30.0, ..RunReport::default() };
//! write_run_report(&mut folder, &RunSummary {
//!     input: "example",
//!     config: &Config::default(),
//!     report: &report,
//!     outputs: &Outputs::default(),
//!     surface: None,
//!     panoptic: None,
//!     map: None,
//!     sample: None,
//! })?;
//! // Nothing is in place before the commit.
//! assert!(!dir.path().join("metrics.json").exists());
//! folder.commit(voxpan_pipeline::Manifest {
//!     voxpan: "doc".into(), input: "example".into(), completed: true, frames: 10,
//!     skipped: 0, files: vec![], config: toml::Value::Table(Default::default()),
//! })?;
//! let metrics: serde_json::Value =
//!     serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json"))?)?;
//! assert_eq!(metrics["report"]["frames"], 10);
//! assert!(dir.path().join("report.html").is_file());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod document;
mod eval_report;
mod run_report;
pub mod views;

pub use eval_report::{
    EvalReport, SampleFrame, VOXEL_COLUMNS, VOXEL_LEGEND, voxel_table, write_eval_report,
};
pub use run_report::{RunSummary, write_run_report};

use std::path::{Path, PathBuf};

/// A report file that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct ReportError {
    pub path: PathBuf,
    pub message: String,
}

impl ReportError {
    pub(crate) fn new(path: &Path, e: impl std::fmt::Display) -> Self {
        Self {
            path: path.to_owned(),
            message: e.to_string(),
        }
    }
}

impl From<voxpan_io::IoError> for ReportError {
    fn from(e: voxpan_io::IoError) -> Self {
        Self {
            path: e.path().to_owned(),
            message: e.to_string(),
        }
    }
}

pub type Result<T> = std::result::Result<T, ReportError>;

/// Writes a text file atomically.
fn write_text(path: &Path, text: &str) -> Result<()> {
    Ok(voxpan_io::write_atomically(path, |w| {
        w.write_all(text.as_bytes())
    })?)
}
