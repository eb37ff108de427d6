//! Geometry: subdivision of scene faces into patches ([`subdivide`]), the occluders
//! that answer the visibility questions ([`occluders`]), coplanar occluders merged
//! into fewer triangles ([`merge`]) and the eight-wide tree they walk (`bvh8`).

mod bvh8;
pub mod merge;
pub mod occluders;
pub mod subdivide;
mod triangle;
