//! The map (steps 3 and 4 of the pipeline): a panoptic truncated signed distance field on
//! hashed voxel blocks, behind one object, [`PanopticMap`].
//!
//! Inside, each stage is a module, as in nvblox and voxblox:
//! - `layer`: `8³`-voxel blocks in a hash map; per voxel distance, weight and colour
//!   (7 bytes) and two-slot instance evidence (5 bytes); per block, update bits for each
//!   consumer of changes (the mesher, publishers) and its surface voxels counted by instance
//!   (what sizes instances for `tracking.min_voxels`);
//! - `integrate`: projective TSDF integration (allocation in the truncation band, `1/z²`
//!   weights, voxblox's drop-off behind the surface, colour, instances), a block's row of 8
//!   voxels at a time in `lanes` (portable, or AVX2 where the CPU has it: same bits);
//! - `associate`: each frame's segments matched to persistent map instances (the instance
//!   labels of the voxels each pixel's depth lands in: Voxblox++'s voxel votes);
//! - `mesh`: marching cubes (generated 256-case table, block seams, incremental), welded with
//!   smooth normals;
//! - `render`: ray casting of the zero crossing into depth, colour, instance and normal images;
//! - `esdf`: the Euclidean signed distance field, updated from the TSDF blocks that changed
//!   (sites on the surface, vector propagation between blocks), and its 2-D costmap;
//! - `serialize`: a versioned, checksummed, compressed map file, written atomically.
//!
//! See [`PanopticMap`] for an example.
//!
//! ```
//! use voxpan_core::{Frame, Image, Intrinsics, Pose, Segment, Segments};
//! use voxpan_map::{Coloring, MapConfig, PanopticMap};
//!
//! let k = Intrinsics { width: 80, height: 60, fx: 40.0, fy: 40.0, cx: 40.0, cy: 30.0 };
//! // A wall 2 m away with a box 1.2 m away in the middle, and masks for both.
//! let near = |x: usize, y: usize| (30..50).contains(&x) && (20..40).contains(&y);
//! let frame = Frame {
//!     id: "0".into(),
//!     timestamp: 0.0,
//!     color: Image::filled(80, 60, [120, 120, 120]),
//!     depth: Image::from_fn(80, 60, |x, y| if near(x, y) { 1.2 } else { 2.0 }),
//!     pose: Pose::identity(),
//!     intrinsics: k,
//!     segments: None,
//!     ground_truth: None,
//! };
//! let labels = Image::from_fn(80, 60, |x, y| if near(x, y) { 2 } else { 1 });
//! let segments = Segments {
//!     labels,
//!     segments: vec![
//!         Segment { id: 1, class_id: Some(0), is_thing: Some(false), score: None },
//!         Segment { id: 2, class_id: Some(7), is_thing: Some(true), score: None },
//!     ],
//! };
//! let mut map = PanopticMap::new(MapConfig::default())?;
//! let report = map.integrate(frame.view(), Some(&segments))?;
//! assert_eq!(report.association.unwrap().created, 2);
//! // Instances are shown once seen again (one-frame fragments stay hidden).
//! let report = map.integrate(frame.view(), Some(&segments))?;
//! assert_eq!(report.association.unwrap().matched, 2);
//! let instances = map.instances();
//! let the_box = instances.iter().find(|i| i.class_id == Some(7)).unwrap();
//! assert!(the_box.is_thing && the_box.voxels > 100);
//! // One mesh per instance, and the map seen again from the camera.
//! assert_eq!(map.mesh(Coloring::Instance).split_by_instance().len(), 2);
//! let view = map.render(&k, &Pose::identity());
//! assert_eq!(*view.instances.get(40, 30), the_box.id);
//! # Ok::<(), voxpan_map::MapError>(())
//! ```

mod associate;
mod config;
mod esdf;
mod integrate;
mod lanes;
mod layer;
mod mesh;
mod panoptic_map;
mod render;
mod serialize;

pub use associate::AssociationStats;
pub use config::{
    ConfigError, EsdfConfig, MapConfig, TrackingConfig, TsdfConfig, UpAxis, check_range,
};
pub use esdf::{Costmap, CostmapCell, EsdfStats};
pub use integrate::IntegrationStats;
pub use layer::{BLOCK_SIDE, BlockIndex, VoxelIndex};
pub use mesh::{Coloring, id_color};
pub use panoptic_map::{
    BLOCK_BYTES, BLOCK_VOXELS, Bounds, ChangeConsumer, FrameReport, InstanceSummary, MapError,
    ObservedVoxel, PanopticMap, VOXEL_BYTES, human_bytes,
};
pub use render::RenderedView;
pub use serialize::{MapFileError, map_file_version};
