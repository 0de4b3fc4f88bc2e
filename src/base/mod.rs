//! The foundation every layer above builds on: directions and slopes, slope-space densities, heightfields,
//! distances between distributions, FFTs, file formats (`.npy`, X3P, STL, PNG) and atomic output, figures.
//! Nothing here knows about tools, G-code or the pipeline's stages.

pub(crate) mod de;
pub mod distance;
pub(crate) mod fft2;
pub mod geometry;
pub mod heightfield;
pub(crate) mod image;
pub mod io;
pub mod npy;
pub mod plot;
pub mod register;
pub mod scan;
pub mod slope;
pub mod stl;
pub mod surface;
pub mod x3p;

/// A value that breaks its type's invariants, or input that is not what a reader expects, and why (the
/// caller adds the file or field it came from).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Invalid(pub String);

impl From<String> for Invalid {
    fn from(s: String) -> Self {
        Invalid(s)
    }
}

impl From<&str> for Invalid {
    fn from(s: &str) -> Self {
        Invalid(s.to_string())
    }
}

impl std::ops::Deref for Invalid {
    type Target = str;
    /// The reason, as text.
    fn deref(&self) -> &str {
        &self.0
    }
}
