//! Daylight (issue 22, "light across the year"): where the sun is at a place and an
//! hour, the hourly weather files that drive the sky, the sky of each hour (Perez's
//! models) and the sky divided into patches. The first pieces of `ffstream annual`;
//! the scene's part and the command itself are not written yet (docs/daylight.md says
//! what is there).

pub mod annual;
pub mod dome;
pub mod heatmap;
pub mod perez;
pub mod report;
pub mod scene;
pub mod sun;
pub mod weather;

pub use dome::{SkyDome, SkyVector};
pub use perez::PerezSky;
pub use sun::{LocalTime, Site, SunError, SunPosition};
pub use weather::{Hour, Weather, WeatherError};
