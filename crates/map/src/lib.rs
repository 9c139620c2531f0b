//! The map (step 3 of the pipeline): a truncated signed distance field on hashed voxel blocks,
//! like voxblox and nvblox.
//!
//! - [`TsdfVoxel`]: distance, weight and colour in 12 bytes; [`LabelVoxel`]: instance
//!   evidence in 8 more.
//! - [`Block`]: `8³` voxels (nvblox's size: small blocks allocate tightly around the surface).
//! - [`Layer`]: the blocks in a hash map keyed by integer block index.
//! - [`TsdfIntegrator`]: projective integration of a depth + colour frame (one file per
//!   integrator, as in voxblox).
//! - [`io`]: a versioned, checksummed map file, written atomically.
//!
//! - [`mesh`]: marching cubes (generated 256-case table, seams handled, incremental).
//!
//! - [`InstanceTracker`]: per-frame segments to persistent map instances by IoU.

mod block;
pub mod io;
mod layer;
pub mod mesh;
mod tracking;
mod tsdf;
mod voxel;

pub use block::{Block, BlockIndex, BLOCK_SIDE, VOXELS_PER_BLOCK};
pub use layer::Layer;
pub use mesh::{id_color, mesh_block, Mesh, MeshLayer};
pub use tracking::{downscaled, render_instances, InstanceInfo, InstanceTracker, TrackingConfig};
pub use tsdf::{IntegrationStats, TsdfConfig, TsdfIntegrator};
pub use voxel::{LabelVoxel, TsdfVoxel};
