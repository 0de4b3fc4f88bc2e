//! Stage 6 (optics) — reflectance from a surface.
//!
//! - [`geometric`]: slopes of a heightfield → its NDF on a slope grid (Eq. 6, Dong et al. 2015, with an
//!   optional Gaussian pre-filter) → a microfacet BRDF (Eq. 5) with Smith masking from that NDF.
//! - [`wave`]: the Kirchhoff wave BRDF (Table 1, Eqs. 1–4) over a Gaussian coherence area, by FFT over a
//!   whole slice and by Gabor kernels per direction (Eqs. 7–16); the scallop diffraction warning.

pub(crate) mod figures;
pub mod geometric;
pub mod gloss;
pub mod wave;
