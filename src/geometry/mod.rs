//! Geometry: subdivision of scene faces into patches ([`subdivide`]), the occluders
//! that answer the visibility questions ([`occluders`]) and the eight-wide tree they
//! walk (`bvh8`).

mod bvh8;
pub mod occluders;
pub mod subdivide;
mod triangle;
