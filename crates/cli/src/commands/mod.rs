pub mod eval;
pub mod frames;
pub mod refine;
pub mod synth;
