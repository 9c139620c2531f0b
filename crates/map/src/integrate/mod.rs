//! Integrators: how a frame's depth, colour and instance image are fused into the layer. One
//! file per integrator, as in voxblox; today the projective TSDF integrator.

mod prefetch;
mod tsdf;

pub use tsdf::IntegrationStats;
pub(crate) use tsdf::{Claims, FrameInstances, TsdfIntegrator};
