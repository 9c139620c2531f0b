//! Refinement rules on constructed and real frames (one test binary).

mod flat_frames;
mod planes;
mod release_comb;
mod rules;
