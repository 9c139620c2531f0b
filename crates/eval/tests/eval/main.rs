//! voxpan-eval against independent implementations and on whole runs (one test binary).

mod surface_golden;
mod synthetic_run;
