//! Datasets on disk (one test binary).

mod flat_sample;
mod tum;
