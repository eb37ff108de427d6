//! ffstream: radiosity form factors for large triangle meshes, computed in parallel
//! (threads, or MPI ranks with rank 0 as a pure I/O master), streamed into a chunked,
//! zstd-compressed `.ffz` file, solved out of core and rendered.
//!
//! The layers, bottom up, each with its own error type: [`patch`], [`random`] and
//! [`rows`] shared by all; [`scene`]; [`geometry`]; [`formfactor`]; [`ffz`] (the file
//! format); [`service`] (the I/O master and its transports); [`job`] (a compute job
//! from its settings); [`report`] (what is made of a file); [`solve`], [`render`],
//! [`vtu`] and [`daylight`] on top. The one module map, file by file, is
//! docs/architecture.md §6; each module's own documentation says what it holds.

pub mod daylight;
pub mod ffz;
pub mod formfactor;
pub mod geometry;
mod input;
pub mod job;
pub mod patch;
pub mod random;
pub mod render;
pub mod report;
pub mod rows;
pub mod scene;
pub mod service;
pub mod solve;
mod table;
pub mod vtu;

pub use input::refuse_special_file;
pub use table::brief_number;
