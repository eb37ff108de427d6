//! Daylight (issue 22, "light across the year"): where the sun is at a place and an
//! hour, the hourly weather files that drive the sky, the sky of each hour (Perez's
//! models) on sky patches, what a scene's patches and sensors receive, the year at each
//! sensor, its metrics and pictures: the library of `ffstream annual`
//! (docs/daylight.md).

pub mod annual;
pub mod clearsky;
pub mod dome;
pub mod glazing;
pub mod heatmap;
pub mod input;
pub mod perez;
pub mod report;
pub mod scene;
pub mod sun;
pub mod weather;

pub use dome::{SkyDome, SkyVector};
pub use input::InputError;
pub use perez::PerezSky;
pub use sun::{LocalTime, Site, SunError, SunPosition};
pub use weather::{Hour, Weather};
