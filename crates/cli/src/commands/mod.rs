pub mod refine;
pub mod synth;
