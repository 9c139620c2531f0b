pub mod bag;
pub mod bench;
pub mod eval;
pub mod frames;
pub mod mesh;
pub mod refine;
pub mod run;
pub mod synth;
