//! The `voxpan` command line, end to end (one test binary).

mod bag;
mod bench;
mod common;
mod eval;
mod fuzz_corpus;
mod live;
mod network;
mod readme;
mod refine;
mod report;
mod robustness;
mod ros;
mod synth;
