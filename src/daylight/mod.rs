//! Daylight: where the sun is at a place and an hour (issue 22, "light across the
//! year"). The first piece of `ffstream annual`; the sky model, the weather files and
//! the command itself are not written yet (docs/daylight.md says what is there).

pub mod sun;

pub use sun::{LocalTime, Site, SunError, SunPosition};
