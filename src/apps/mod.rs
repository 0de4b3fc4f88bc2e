//! Applications beside the pipeline: streaming a program to a GRBL controller (needs only the foundation
//! and the G-code model) and analysing a measured or simulated surface.

pub mod analyze;
/// A coupon program and sheet that measure a machine profile's `[accuracy]` (backlash, runout, steps/mm).
pub mod calibrate;
pub mod stream;
