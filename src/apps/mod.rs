//! Applications beside the pipeline: streaming a program to a GRBL controller (needs only the foundation
//! and the G-code model) and analysing a measured or simulated surface.

pub mod analyze;
pub mod stream;
