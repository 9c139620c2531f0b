//! What a [`PanopticMap`](crate::PanopticMap) is built with: the `[tsdf]` and `[tracking]`
//! sections of voxpan's configuration file. Every field has a default; unknown keys are
//! rejected; [`MapConfig::validate`] names the key of any value it cannot use.

use serde::{Deserialize, Serialize};

/// Integration: voxel grid and how depth is fused (`[tsdf]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TsdfConfig {
    /// Voxel edge in metres (default 0.02, panoptic_mapping's on flat).
    pub voxel_size: f64,
    /// Truncation distance in voxels (default 3): the band around the surface that is updated.
    pub truncation_voxels: f64,
    /// Depth beyond this (metres) is not integrated (default 5, as panoptic_mapping on flat);
    /// association still reads the instance labels closer frames left where it lands (but
    /// founds no instance from it).
    pub max_range: f64,
    /// Depth below this (metres) is ignored (default 0.1: closer than any RGB-D camera's
    /// minimum range).
    pub min_range: f64,
    /// Fusion weights saturate here, so the map keeps adapting (default 10 000, voxblox's). In
    /// practice a voxel's weight stops growing earlier, at a few hundred frames' worth: it is a
    /// bfloat16 (see the voxel's documentation).
    pub max_weight: f32,
    /// Blocks farther than this from the camera (metres, block centre to camera) are dropped
    /// after each frame, with their meshes and distance field, so that memory stays bounded
    /// while the robot drives on (voxblox's `max_block_distance_from_body`, nvblox's
    /// `map_clearing_radius_m`). Default 0: keep every block.
    pub keep_radius: f64,
}

impl Default for TsdfConfig {
    fn default() -> Self {
        Self {
            voxel_size: 0.02,
            truncation_voxels: 3.0,
            max_range: 5.0,
            min_range: 0.1,
            max_weight: 1e4,
            keep_radius: 0.0,
        }
    }
}

/// Association of frame segments with map instances (`[tracking]`; the rule is described in
/// the `associate` module).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackingConfig {
    /// A segment continues the instance holding at least this share of its mapped samples
    /// (default 0.5: a majority); a thing must also explain this share of the segment or of
    /// the instance's visible part.
    pub min_overlap: f64,
    /// An unmatched segment founds a new instance only with this many pixels with depth
    /// (default 8: a plate or a lamp across a room is a few dozen; specks are kept out by
    /// `min_observations` and `min_voxels`).
    pub min_pixels: usize,
    /// Frames are sampled every `downscale` pixels per axis for association (default 4: the
    /// evidence barely changes, the cost is a sixteenth). Segments smaller than 16 such
    /// samples read every pixel of theirs instead.
    pub downscale: usize,
    /// An instance is shown once segments matched it in this many frames (default 2: seen
    /// again at least once), tracked or identified (a once-seen detection is as doubtful
    /// with a known id).
    pub min_observations: u32,
    /// An instance is shown only while it leads this many surface voxels (default 12, about
    /// a 5 cm square at 2 cm voxels: the surface band is two voxels deep). Smaller ones are
    /// fragments (a mask's rim, a voxel or two out-voted everywhere else); they stay tracked
    /// and show once they grow (cross-validated in docs/design/association.md). Consolidation
    /// passes also hide, until the next pass, an instance none of whose pieces (its surface
    /// voxels linked within the truncation distance) holds this many: a few voxels scattered
    /// where its masks were out-voted. 0 shows every instance.
    pub min_voxels: usize,
    /// Instances merge after this many frames in which one segment covered both (default 2).
    pub merge_votes: u32,
    /// Things match only instances of their class (default true; stuff always does), or a
    /// thing instance of another class whose class is unconfirmed or was once theirs, where
    /// the two cover each other (a network renaming one object between frames).
    pub class_aware_things: bool,
    /// Also consolidate the map (see `PanopticMap::consolidate`: pieces of one object joined,
    /// label holes filled) after every this many frames of tracked or carried masks, so that
    /// a live map's readers (meshes, instance lists, the nodes' topics) see about what a run
    /// ending there would write (default 0: only when asked, as `voxpan run` does after its
    /// last frame; a join made on early evidence is kept, which can cost the final map, see
    /// docs/design/association.md).
    pub consolidate_every: u32,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            min_overlap: 0.5,
            min_pixels: 8,
            downscale: 4,
            min_observations: 2,
            min_voxels: 12,
            merge_votes: 2,
            class_aware_things: true,
            consolidate_every: 0,
        }
    }
}

/// The world axis pointing up (against gravity), for costmap slices.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum UpAxis {
    #[serde(rename = "x")]
    X,
    #[serde(rename = "-x")]
    NegX,
    #[serde(rename = "y")]
    Y,
    #[serde(rename = "-y")]
    NegY,
    #[default]
    #[serde(rename = "z")]
    Z,
    #[serde(rename = "-z")]
    NegZ,
}

impl UpAxis {
    /// The axis (0, 1, 2) and whether up is its negative side.
    pub fn axis(self) -> (usize, bool) {
        match self {
            UpAxis::X => (0, false),
            UpAxis::NegX => (0, true),
            UpAxis::Y => (1, false),
            UpAxis::NegY => (1, true),
            UpAxis::Z => (2, false),
            UpAxis::NegZ => (2, true),
        }
    }
}

/// The Euclidean signed distance field and its 2-D costmap (`[esdf]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EsdfConfig {
    /// Keep the distance field up to date while mapping (default false). It also makes
    /// integration allocate the free space every frame sees (the blocks along each ray, not
    /// only around the surface), which the field needs to tell free space from unknown: more
    /// blocks, more memory, slower integration.
    pub enabled: bool,
    /// Distances are propagated this far from the surface, metres (default 2, voxblox's and
    /// nvblox's order); farther voxels read as this distance.
    pub max_distance: f64,
    /// The world axis pointing up (default `"z"`; `"-y"` for a camera-style world).
    pub up_axis: UpAxis,
    /// The costmap's obstacles are the voxels between these heights, metres along the up
    /// axis in the world frame (defaults 0.1 and 1.5: above a floor at height 0, below a
    /// doorway's top).
    pub slice_min_z: f64,
    pub slice_max_z: f64,
    /// Costmap cells within this distance of a surface are occupied (default 0: only the
    /// surface itself; a robot's radius inflates obstacles by it).
    pub robot_radius: f64,
}

impl Default for EsdfConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            max_distance: 2.0,
            up_axis: UpAxis::Z,
            slice_min_z: 0.1,
            slice_max_z: 1.5,
            robot_radius: 0.0,
        }
    }
}

impl EsdfConfig {
    pub fn validate(&self, voxel_size: f64) -> Result<(), ConfigError> {
        check_range("esdf.max_distance", self.max_distance, 0.0, 1e3)?;
        if self.max_distance / voxel_size > 30_000.0 {
            return Err(ConfigError::new(
                "esdf.max_distance",
                self.max_distance,
                "is more than 30 000 voxels (offsets are 16-bit)",
            ));
        }
        check_range("esdf.slice_min_z", self.slice_min_z, -1e6, 1e6)?;
        check_range("esdf.slice_max_z", self.slice_max_z, -1e6, 1e6)?;
        if self.slice_max_z < self.slice_min_z {
            return Err(ConfigError::new(
                "esdf.slice_max_z",
                self.slice_max_z,
                &format!("must not be below esdf.slice_min_z ({})", self.slice_min_z),
            ));
        }
        check_range("esdf.robot_radius", self.robot_radius, 0.0, 1e3)
    }
}

/// Everything a map needs to know.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MapConfig {
    pub tsdf: TsdfConfig,
    pub tracking: TrackingConfig,
    pub esdf: EsdfConfig,
}

/// A configuration value that cannot be used, named by its key.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{key} = {value}: {why}")]
pub struct ConfigError {
    pub key: String,
    pub value: String,
    pub why: String,
}

impl ConfigError {
    pub fn new(key: &str, value: impl std::fmt::Display, why: &str) -> Self {
        Self {
            key: key.to_owned(),
            value: value.to_string(),
            why: why.to_owned(),
        }
    }
}

/// `Ok` when `value` is finite and within `[low, high]`.
pub fn check_range(key: &str, value: f64, low: f64, high: f64) -> Result<(), ConfigError> {
    if value.is_finite() && (low..=high).contains(&value) {
        Ok(())
    } else {
        Err(ConfigError::new(
            key,
            value,
            &format!("expected a finite number in [{low}, {high}]"),
        ))
    }
}

impl TsdfConfig {
    /// The truncation distance in metres.
    pub fn truncation(&self) -> f64 {
        self.truncation_voxels * self.voxel_size
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        // A millimetre to a metre covers every RGB-D mapping use; outside it the grid is
        // either astronomically large or cannot represent a room.
        check_range("tsdf.voxel_size", self.voxel_size, 1e-3, 1.0)?;
        // Fewer than one voxel leaves holes between rays; beyond 20 every frame rewrites
        // free space metres away from the surface.
        check_range("tsdf.truncation_voxels", self.truncation_voxels, 1.0, 20.0)?;
        check_range("tsdf.min_range", self.min_range, 0.0, 1e3)?;
        check_range("tsdf.max_range", self.max_range, 1e-3, 1e3)?;
        if self.max_range <= self.min_range {
            return Err(ConfigError::new(
                "tsdf.max_range",
                self.max_range,
                &format!("must exceed tsdf.min_range ({})", self.min_range),
            ));
        }
        check_range("tsdf.max_weight", self.max_weight as f64, 1e-6, 1e30)?;
        check_range("tsdf.keep_radius", self.keep_radius, 0.0, 1e6)?;
        if self.keep_radius > 0.0 && self.keep_radius < self.max_range {
            return Err(ConfigError::new(
                "tsdf.keep_radius",
                self.keep_radius,
                &format!(
                    "must be 0 (keep everything) or at least tsdf.max_range ({}): blocks in sight \
                     would be dropped between frames and integrated anew",
                    self.max_range
                ),
            ));
        }
        Ok(())
    }
}

impl TrackingConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_range("tracking.min_overlap", self.min_overlap, 0.0, 1.0)?;
        if !(1..=64).contains(&self.downscale) {
            return Err(ConfigError::new(
                "tracking.downscale",
                self.downscale,
                "expected 1 to 64",
            ));
        }
        if self.merge_votes == 0 {
            return Err(ConfigError::new(
                "tracking.merge_votes",
                self.merge_votes,
                "expected at least 1",
            ));
        }
        Ok(())
    }
}

impl MapConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.tsdf.validate()?;
        self.tracking.validate()?;
        self.esdf.validate(self.tsdf.voxel_size)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        assert!(MapConfig::default().validate().is_ok());
        let mut c = MapConfig::default();
        c.tsdf.voxel_size = f64::INFINITY;
        let e = c.validate().unwrap_err();
        assert_eq!(e.key, "tsdf.voxel_size");
        assert!(e.to_string().starts_with("tsdf.voxel_size = inf"), "{e}");
        let mut c = MapConfig::default();
        c.tsdf.max_range = 0.05;
        assert_eq!(c.validate().unwrap_err().key, "tsdf.max_range");
    }
}
