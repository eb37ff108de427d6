//! Geometry: subdivision of scene faces into patches ([`subdivide`]) and the bounding
//! volume hierarchy used for visibility ([`bvh`]).

pub mod bvh;
mod bvh8;
pub mod subdivide;
