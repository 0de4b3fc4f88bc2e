//! The foundation every layer above builds on: directions and slopes, slope-space densities, heightfields,
//! distances between distributions, FFTs, file formats (`.npy`, X3P, STL, PNG) and atomic output, figures.
//! Nothing here knows about tools, G-code or the pipeline's stages.

pub mod de;
pub mod distance;
pub(crate) mod fft2;
pub mod geometry;
pub mod heightfield;
pub mod image;
pub mod io;
pub mod npy;
pub mod plot;
pub mod slope;
pub mod stl;
pub mod surface;
pub mod x3p;
