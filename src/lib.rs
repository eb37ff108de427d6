//! ffstream: radiosity form factors for large triangle meshes, computed in parallel
//! (threads, or MPI ranks with rank 0 as a pure I/O master), streamed into a chunked,
//! zstd-compressed `.ffz` file, solved out of core and rendered.
//!
//! Layers, bottom up (each has its own error type). The file-by-file map of the crate
//! is in docs/architecture.md §6; each module's own documentation says what it holds.
//!
//! | module | holds |
//! |---|---|
//! | [`patch`] | [`patch::Patch`] and [`patch::PatchSet`]: the unit of the matrix, shared by every layer |
//! | [`random`] | the one seeded random-number generator (SplitMix64) that every layer draws from |
//! | [`rows`] | [`rows::Row`]: one computed matrix row, as compute produces it and the file stores it |
//! | [`scene`] | scene files (OBJ/MTL, STL, PLY, glTF) loaded and validated, built-in scenes |
//! | [`geometry`] | subdivision into patches, the occluders and the eight-wide tree that answer the visibility questions |
//! | [`formfactor`] | the form-factor kernels (`point`, `mc`, `contour`), exact visibility, and the row engine (dense, top-k and linked rows) |
//! | [`ffz`] | the `.ffz` file format: spec types, chunk codec, streaming writer, mmap reader, verification |
//! | [`report`] | what is made of a file: `info`, the printed `verify`, the exports, `verify --unoccluded` |
//! | [`service`] | the I/O master and its transports (embedded threads, MPI) |
//! | [`job`] | a compute job's typed settings, the header's run parameters, and the building of the job from them |
//! | [`solve`] | out-of-core radiosity solvers |
//! | [`render`] | software rasterizer for the lit scene |
//! | [`vtu`] | the patches as a VTK unstructured grid with per-patch values (ParaView, meshio) |
//! | [`daylight`] | the library of `ffstream annual`: the sun, weather files, the Perez sky on sky patches, daylight in a scene, the year at each sensor |
//! | `table` (private) | the CSV dialect of every table ffstream reads or writes |
//! | `input` (private) | reading input files: regular files only, compressed input only up to a size |

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
