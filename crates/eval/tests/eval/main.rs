//! voxpan-eval against independent implementations (one test binary).

mod surface_golden;
