//! All integration tests in one binary (faster to build and run than one binary per
//! file). Each module holds the tests of one capability.
mod common;
mod ffz_bad_values;
mod ffz_common;
mod ffz_corrupt;
mod ffz_golden;
mod ffz_kill;
mod ffz_python;
mod ffz_roundtrip;
mod ffz_tools;
mod formfactor;
mod mpi;
mod pipeline;
mod render;
mod run;
mod scene;
mod scene_formats;
mod service;
mod solve;
mod stress_cli;
mod stress_corrupt;
mod stress_faults;
mod stress_fuzz;
mod stress_geom;
mod stress_numeric;
mod stress_props;
mod stress_resume;
