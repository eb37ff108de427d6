//! ffstream: radiosity form factors for large triangle meshes, computed in parallel
//! (threads, or MPI ranks with rank 0 as a pure I/O master), streamed into a chunked,
//! zstd-compressed `.ffz` file, solved out of core and rendered.
//!
//! Layers, bottom up (each has its own error type):
//!
//! | module | holds |
//! |---|---|
//! | [`patch`] | [`patch::Patch`] and [`patch::PatchSet`]: the unit of the matrix, shared by every layer |
//! | [`rows`] | [`rows::Row`]: one computed matrix row, as compute produces it and the file stores it |
//! | [`scene`] | OBJ/MTL loading and validation, built-in scenes |
//! | [`geometry`] | subdivision into patches, the BVH used for visibility |
//! | [`formfactor`] | the form-factor kernels (`point`, `mc`, `contour`) and the row engine |
//! | [`ffz`] | the `.ffz` file format: spec types, chunk codec, streaming writer, mmap reader |
//! | [`service`] | the I/O master and its transports (embedded threads, MPI) |
//! | [`solve`] | out-of-core radiosity solvers |
//! | [`render`] | software rasterizer for the lit scene |
//! | [`vtu`] | the patches as a VTK unstructured grid with per-patch values (ParaView, meshio) |
//! | [`daylight`] | the sun's position at a place and hour, EPW/TMY3 weather files, the Perez sky on sky patches (the start of `ffstream annual`) |

pub mod daylight;
pub mod ffz;
pub mod formfactor;
pub mod geometry;
mod input;
pub mod patch;
pub mod render;
pub mod rows;
pub mod scene;
pub mod service;
pub mod solve;
mod table;
pub mod vtu;

pub use input::refuse_special_file;
pub use table::brief_number;
