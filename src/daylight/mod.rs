//! Daylight (issue 22, "light across the year"): where the sun is at a place and an
//! hour, and the hourly weather files that drive the sky. The first pieces of
//! `ffstream annual`; the sky model and the command itself are not written yet
//! (docs/daylight.md says what is there).

pub mod sun;
pub mod weather;

pub use sun::{LocalTime, Site, SunError, SunPosition};
pub use weather::{Hour, Weather, WeatherError};
