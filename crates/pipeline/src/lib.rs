//! The whole data flow: a [`FrameStream`](voxpan_core::FrameStream) (a dataset, a bag, a
//! subscriber) → perception (segment, refine on measured depth, fill; on a worker thread one
//! frame ahead) → the [`PanopticMap`](voxpan_map::PanopticMap) (associate, integrate) →
//! meshes and the map file. [`Config`] is the nested configuration file every stage reads.
//!
//! ```
//! use std::sync::{atomic::AtomicBool, Arc};
//! use voxpan_dataset::{open_dataset, stream, FrameSource};
//! use voxpan_map::PanopticMap;
//! use voxpan_perception::{DatasetMasks, Perception};
//! use voxpan_pipeline::{build, Config};
//!
//! // A small synthetic dataset stands in for a recording.
//! let dir = tempfile::tempdir()?;
//! let synth = voxpan_sim::SynthConfig { frames: 10, ..voxpan_sim::SynthConfig::tiny() };
//! voxpan_sim::generate(dir.path(), &synth, |_| {})?;
//!
//! let config = Config::default();
//! let dataset: Arc<dyn FrameSource> = Arc::from(open_dataset(dir.path())?);
//! let frames = stream(dataset.clone(), (0..dataset.len()).collect());
//! let perception = Perception::new(config.perception(), Box::new(DatasetMasks))?;
//! let mapped = build(frames, perception, PanopticMap::new(config.map())?,
//!                    &AtomicBool::new(false), |_| Ok(()))?;
//! assert_eq!(mapped.report.frames, 10);
//! // Floor, walls, and the objects seen in two frames or more.
//! assert!(mapped.map.instance_count() >= 4);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod config;
mod folder;
mod outputs;
pub mod protocols;
mod run;

pub use config::{
    Config, ConfigFileError, OutputConfig, ResourceConfig, SegmentConfig, SegmentSource,
    SourceConfig,
};
pub use folder::{MANIFEST, Manifest, RunFolder};
pub use outputs::{
    OutputError, OutputStep, Outputs, instance_file_name, write_config, write_costmap,
    write_outputs, write_refined,
};
pub use run::{
    Association, Ending, FrameEvent, FrameRecord, Mapped, ONCE_PER_RUN, RunError, RunReport,
    STAGES, SkippedFrame, build, build_with, median,
};

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use voxpan_core::ClassTable;
use voxpan_dataset::{FrameSource, paced, stream_with};
use voxpan_map::{MapError, PanopticMap};
use voxpan_perception::{
    DatasetMasks, GroundTruthMasks, Perceived, Perception, PerceptionError, Segmenter,
};

/// The segmenter a configuration asks for, over a dataset: its stored masks or its ground
/// truth (with the ground truth's label table).
pub fn dataset_segmenter(config: &Config, source: &Arc<dyn FrameSource>) -> Box<dyn Segmenter> {
    match config.segment.source {
        SegmentSource::Predicted => Box::new(DatasetMasks),
        SegmentSource::Gt => Box::new(GroundTruthMasks::new(
            source.ground_truth_classes().cloned(),
        )),
    }
}

/// The names of the class ids the configured segments carry: the network's label table for
/// predicted masks, the ground truth's class names for ground truth.
pub fn segment_class_names(
    config: &Config,
    source: &Arc<dyn FrameSource>,
) -> std::collections::BTreeMap<u32, String> {
    match config.segment.source {
        SegmentSource::Predicted => source
            .network_classes()
            .map(ClassTable::names)
            .unwrap_or_default(),
        SegmentSource::Gt => source
            .ground_truth_class_names()
            .cloned()
            .unwrap_or_default(),
    }
}

/// What a dataset run is doing, for progress displays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunProgress {
    /// Frames done so far, mapped or skipped.
    Frames(usize),
    /// Mapping has ended; the outputs are being written.
    Output(OutputStep),
}

/// Why a dataset run failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Run(#[from] RunError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(transparent)]
    Map(#[from] MapError),
    #[error(transparent)]
    Perception(#[from] PerceptionError),
}

/// `voxpan run` on a dataset: maps frames `indices` of `source` as `config` says and writes the
/// map, its meshes, `config.toml` and (if configured) the refined masks into the run folder
/// (committed by the caller, after its own files). `progress` hears after every frame, mapped
/// or skipped, how many are done, and then which output is being written.
pub fn run_dataset(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    config: &Config,
    folder: &mut RunFolder,
    stop: &AtomicBool,
    progress: impl FnMut(RunProgress),
) -> Result<(Mapped, Outputs), PipelineError> {
    let segmenter = dataset_segmenter(config, &source);
    run_dataset_with(source, indices, config, segmenter, folder, stop, progress)
}

/// [`run_dataset`] with the frames segmented by `segmenter` (a network) instead of the source
/// the configuration names; its own label table, if it has one, names the map's classes.
pub fn run_dataset_with(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    config: &Config,
    segmenter: Box<dyn Segmenter>,
    folder: &mut RunFolder,
    stop: &AtomicBool,
    progress: impl FnMut(RunProgress),
) -> Result<(Mapped, Outputs), PipelineError> {
    run_dataset_observed(
        source,
        indices,
        config,
        segmenter,
        folder,
        stop,
        progress,
        |_, _| Ok(()),
    )
}

/// [`run_dataset_with`] with `observe` shown each mapped frame as integrated (hole-filled
/// depth, refined segments) and the map with it, e.g. a live view; its error aborts the run.
#[allow(clippy::too_many_arguments)] // the run's inputs plus its two listeners
pub fn run_dataset_observed(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    config: &Config,
    segmenter: Box<dyn Segmenter>,
    folder: &mut RunFolder,
    stop: &AtomicBool,
    mut progress: impl FnMut(RunProgress),
    mut observe: impl FnMut(
        &Perceived,
        &mut PanopticMap,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>>,
) -> Result<(Mapped, Outputs), PipelineError> {
    let class_names = match segmenter.classes() {
        Some(table) => table.names(),
        None => segment_class_names(config, &source),
    };
    // Only what the segmenter reads is decoded (a flat frame's ground truth is a second
    // label PNG per frame).
    let wanted = segmenter.reads();
    let perception = Perception::new(config.perception(), segmenter)?;
    let mut map = PanopticMap::new(config.map())?;
    map.set_class_names(class_names);
    map.set_memory_limit(config.resources.max_memory_bytes());
    map.keep_dropped_blocks(config.output.dropped_blocks);
    write_config(folder, config)?;
    let mut done = 0;
    let mut frames = stream_with(source.clone(), indices, wanted);
    if config.source.rate > 0.0 {
        frames = paced(frames, config.source.rate);
    }
    let mut mapped = build(frames, perception, map, stop, |event| {
        done += 1;
        progress(RunProgress::Frames(done));
        if let FrameEvent::Mapped { perceived, map, .. } = event {
            if config.output.save_refined {
                write_refined(folder, perceived)?;
            }
            if config.output.dropped_blocks {
                outputs::write_dropped_blocks(folder, map, outputs::DROPPED_BLOCKS_PER_FILE)?;
            }
            observe(perceived, map)?;
        }
        Ok(())
    })?;
    let mut skipped: Vec<SkippedFrame> = source
        .skipped()
        .iter()
        .map(|(frame, reason)| SkippedFrame {
            frame: frame.clone(),
            reason: reason.clone(),
        })
        .collect();
    skipped.append(&mut mapped.report.skipped);
    mapped.report.skipped = skipped;
    let mut warnings = source.warnings().to_vec();
    warnings.append(&mut mapped.report.warnings);
    mapped.report.warnings = warnings;
    let outputs = write_outputs(folder, &mut mapped, config, |step| {
        progress(RunProgress::Output(step))
    })?;
    Ok((mapped, outputs))
}
