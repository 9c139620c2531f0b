//! The evaluation protocols `voxpan eval` and `voxpan run` print, callable from code.
//!
//! - [`score_masks`]: a dataset's masks under each refinement rule (or a folder of
//!   predictions) against its ground-truth segmentation, with the 2-D protocol;
//! - [`voxel_rows`]: a map per rule against the map of the ground-truth segmentation (voxel PQ);
//! - [`surface_report`]: a map against a ground-truth mesh (accuracy, completeness, label
//!   agreement);
//! - [`sweep`]: the synthetic over-coverage benchmark of the rules.

mod dataset;
mod maps;
mod sweep;

pub use dataset::{MaskEvaluation, MaskOptions, MaskRow, Predictions, score_masks};
pub use maps::{
    LIVE_ROW, MissedObject, ObjectMatch, ReferenceComparison, SurfaceReport, VoxelRow,
    correctly_associated_map, live_map, panoptic_against_reference, random_id_map, reference_map,
    score_from_maps, surface_report, tracked_map, voxel_rows,
};
pub use sweep::{SWEEP_STRENGTHS, SweepRow, sweep};

/// Why an evaluation could not run.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Dataset(#[from] voxpan_dataset::DatasetError),
    #[error("no frame could be scored (first failure: {0})")]
    NoFrames(String),
    #[error(transparent)]
    Run(#[from] crate::RunError),
    #[error(transparent)]
    Map(#[from] voxpan_map::MapError),
    #[error(transparent)]
    Perception(#[from] voxpan_perception::PerceptionError),
    #[error("{0}")]
    Other(String),
}
