//! voxpan-yolo against ONNX Runtime's goldens and on the real weights (one test binary).
//!
//! Always: post-processing on the committed goldens, and the errors of a build without a
//! backend. With `--features ort` and/or `--features tract`: each backend's raw outputs
//! against the goldens, the letterbox against the goldens' inputs, bad models and libraries,
//! and the chair in flat frame 74 (these need `tools/yolo/fetch_weights.sh`'s models and, for
//! ONNX Runtime, its library: `$ORT_DYLIB_PATH` or the tools venv).

#[cfg(any(feature = "ort", feature = "tract"))]
mod backends;
mod common;
mod errors;
mod postprocess;
#[cfg(any(feature = "ort", feature = "tract"))]
mod segment;
