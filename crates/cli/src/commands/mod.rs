pub mod refine;
