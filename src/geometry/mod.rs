//! (being written)

pub mod subdivide;
