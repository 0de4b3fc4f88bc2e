//! Stage 6 (optics) — reflectance from a surface.
//!
//! - [`geometric`]: slopes of a heightfield → its NDF on a slope grid (Eq. 6, Dong et al. 2015, with an
//!   optional Gaussian pre-filter) → a microfacet BRDF (Eq. 5) with Smith masking from that NDF.

pub mod geometric;
