//! The pipeline's stages, in the order data flows through them; each imports only earlier stages and the
//! layers below (`base`, `gcode`, `cut`).

pub mod brdf;
pub mod design;
pub mod facets;
pub mod ndf;
pub mod optics;
pub mod simulate;
pub mod svbrdf;
pub mod toolpath;
pub mod verify;
