//! voxpan's configuration file: nested TOML, one section per stage, every key optional (the
//! defaults are documented on each field), unknown keys rejected with the file and key named.
//!
//! ```toml
//! [tsdf]
//! voxel_size = 0.02
//! truncation_voxels = 3.0
//! max_range = 5.0
//! min_range = 0.1
//! max_weight = 10000.0
//!
//! [tracking]
//! min_overlap = 0.5
//! min_pixels = 8
//! downscale = 4
//! min_observations = 2
//! min_voxels = 12
//! merge_votes = 2
//! class_aware_things = true
//! consolidate_every = 0
//!
//! [esdf]
//! enabled = false
//! max_distance = 2.0
//! up_axis = "z"
//! slice_min_z = 0.1
//! slice_max_z = 1.5
//! robot_radius = 0.0
//!
//! [fill]
//! enabled = true
//! kernel_size = 5
//!
//! [refine]
//! rule = "default"   # none | paper | release | default
//! things_only = false
//! min_pixels = 16
//! far_limit = 100.0
//! trim_stuff_planes = true
//!
//! [source]
//! rate = 0.0             # frames/s a recording is played at (0: as fast as it maps)
//!
//! [segment]
//! source = "predicted"   # predicted | gt
//! every = 1              # segment every Nth frame, or "auto"
//! own_thread = false     # the segmenter on a thread of its own: frames never wait for it
//!
//! [output]
//! save_refined = false
//! instance_meshes = true
//!
//! [resources]
//! max_memory_gb = 8.0   # default: half the machine's memory
//! ```

use std::path::Path;

use serde::{Deserialize, Serialize};
use voxpan_fill::FillConfig;
use voxpan_map::{EsdfConfig, MapConfig, TrackingConfig, TsdfConfig};
use voxpan_perception::{Keyframes, PerceptionConfig};
use voxpan_refine::RefineConfig;

/// Which masks are mapped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentSource {
    /// The masks the dataset ships (a network's predictions), refined.
    Predicted,
    /// The dataset's ground-truth segmentation (a reference map).
    Gt,
}

impl std::str::FromStr for SegmentSource {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "predicted" => Ok(Self::Predicted),
            "gt" => Ok(Self::Gt),
            other => Err(format!(
                "unknown segment source {other:?} (expected predicted or gt)"
            )),
        }
    }
}

/// `[segment]`: where masks come from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentConfig {
    pub source: SegmentSource,
    /// Which frames are segmented (default 1, every one): `N` segments the first frame and
    /// every Nth after it, `"auto"` a frame whose view has moved on from the last keyframe's
    /// (less than nine tenths shared). Frames between keyframes are mapped with the masks the map
    /// renders at their pose, refined on their own depth.
    pub every: Keyframes,
    /// Run the segmenter on a thread of its own (default false): frames never wait for it.
    /// A keyframe is then a frame `every` asks for while the segmenter is free, and it is
    /// mapped when its masks are ready, after the frames that passed it. Which frames are
    /// keyframes then depends on the machine's speed: off, a run is reproducible.
    pub own_thread: bool,
}

impl Default for SegmentConfig {
    fn default() -> Self {
        Self {
            source: SegmentSource::Predicted,
            every: Keyframes::default(),
            own_thread: false,
        }
    }
}

/// `[source]`: how a recording is read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SourceConfig {
    /// Frames per second a recording is played at, as a camera would deliver them (default 0:
    /// as fast as mapping takes them). Frames are not dropped: a pipeline slower than the rate
    /// falls behind it. What a segmenter on its own thread keeps up with depends on it.
    pub rate: f64,
}

/// `[output]`: what a run writes besides the map and its meshes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    /// Write the refined label images as `refined/NNNNNN.png` (default false).
    pub save_refined: bool,
    /// Write one mesh per instance into `instances/` (default true).
    pub instance_meshes: bool,
    /// Write the blocks `tsdf.keep_radius` drops into `dropped/blocks-NNNNNN.voxpan` (map
    /// files of their own, a few thousand blocks each) instead of discarding them (default
    /// false).
    pub dropped_blocks: bool,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            save_refined: false,
            instance_meshes: true,
            dropped_blocks: false,
        }
    }
}

/// `[resources]`: what a run may use of the machine.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ResourceConfig {
    /// Most memory the map's voxel blocks may take, in GB. A configuration whose single frame
    /// could need more is refused before mapping; a frame that would grow the map past it
    /// ends the run with an error naming the frame. Default: half the machine's memory (the
    /// meshes and the saved file need room beside the map).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_memory_gb: Option<f64>,
}

impl ResourceConfig {
    /// The limit in bytes (the machine-derived default when unset; `None` only where the
    /// machine's memory cannot be read).
    pub fn max_memory_bytes(&self) -> Option<u64> {
        match self.max_memory_gb {
            Some(gb) => Some((gb * 1e9) as u64),
            None => physical_memory().map(|b| b / 2),
        }
    }
}

/// The machine's physical memory in bytes.
fn physical_memory() -> Option<u64> {
    #[cfg(unix)]
    {
        // SAFETY: sysconf reads constants and has no memory-safety preconditions.
        let (pages, page) = unsafe {
            (
                libc::sysconf(libc::_SC_PHYS_PAGES),
                libc::sysconf(libc::_SC_PAGESIZE),
            )
        };
        (pages > 0 && page > 0).then(|| pages as u64 * page as u64)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// Everything a run can be told.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub tsdf: TsdfConfig,
    pub tracking: TrackingConfig,
    pub esdf: EsdfConfig,
    pub fill: FillConfig,
    pub refine: RefineConfig,
    pub source: SourceConfig,
    pub segment: SegmentConfig,
    pub output: OutputConfig,
    pub resources: ResourceConfig,
}

/// A configuration file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    #[error("{path}: {source}")]
    Read {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Parse {
        path: std::path::PathBuf,
        #[source]
        source: toml::de::Error,
    },
    #[error("{path}: {message}")]
    Invalid {
        path: std::path::PathBuf,
        message: String,
    },
}

impl Config {
    /// Reads a TOML file; errors name the file and the offending key.
    pub fn from_toml_file(path: &Path) -> Result<Self, ConfigFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigFileError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml_text(&text, path)
    }

    /// Parses `text`, read from the file at `path` (which errors name).
    pub fn from_toml_text(text: &str, path: &Path) -> Result<Self, ConfigFileError> {
        let config: Config = toml::from_str(text).map_err(|source| ConfigFileError::Parse {
            path: path.to_owned(),
            source,
        })?;
        config
            .validate()
            .map_err(|message| ConfigFileError::Invalid {
                path: path.to_owned(),
                message,
            })?;
        Ok(config)
    }

    /// The configuration as TOML (what a run saves as `config.toml`).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("plain data")
    }

    pub fn map(&self) -> MapConfig {
        MapConfig {
            tsdf: self.tsdf,
            tracking: self.tracking,
            esdf: self.esdf,
        }
    }

    pub fn perception(&self) -> PerceptionConfig {
        PerceptionConfig {
            fill: self.fill,
            refine: self.refine,
            keyframes: self.segment.every,
            own_thread: self.segment.own_thread,
        }
    }

    /// Checks every section; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        self.map().validate().map_err(|e| e.to_string())?;
        self.fill.validate()?;
        voxpan_map::check_range("refine.far_limit", self.refine.far_limit, 1e-6, 1e12)
            .map_err(|e| e.to_string())?;
        if self.output.dropped_blocks && self.tsdf.keep_radius == 0.0 {
            return Err(
                "output.dropped_blocks: the map drops no blocks unless tsdf.keep_radius \
                 (--keep-radius) is set"
                    .into(),
            );
        }
        if self.source.rate != 0.0 {
            voxpan_map::check_range("source.rate", self.source.rate, 1e-3, 1e6)
                .map_err(|e| e.to_string())?;
        }
        if let Some(gb) = self.resources.max_memory_gb {
            // Below 10 MB not even one frame of a small camera fits.
            voxpan_map::check_range("resources.max_memory_gb", gb, 0.01, 1e6)
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}
