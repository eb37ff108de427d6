//! Geometry: subdivision of scene faces into patches (`subdivide`, scene helper) and
//! the bounding volume hierarchy used for visibility ([`bvh`]).

pub mod bvh;
