//! Fresnel reflectance of a conductor from its complex index of refraction `η + iκ`, per RGB channel.

use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// Complex index of refraction per RGB channel, relative to the outside medium (air).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConductorIor {
    /// Real part η for R, G, B.
    pub eta: [f64; 3],
    /// Extinction coefficient κ for R, G, B.
    pub k: [f64; 3],
}

/// A named conductor with the source of its constants.
#[derive(Clone, Copy, Debug)]
pub struct MaterialPreset {
    /// Name used on the command line (`material=NAME`).
    pub name: &'static str,
    /// Complex IOR at the channel wavelengths (R 650 nm, G 550 nm, B 450 nm).
    pub ior: ConductorIor,
    /// Where the numbers come from.
    pub source: &'static str,
}

/// Named conductor presets: point values of the measured optical constants at 650 nm (R), 550 nm (G) and
/// 450 nm (B), linearly interpolated in the published tables named in `source` (as tabulated by the
/// refractiveindex.info database). Point values, not spectral integrals: renderers that integrate spectra
/// against colour-matching functions (Mitsuba's `material=` presets) give somewhat different RGB constants.
pub const PRESETS: &[MaterialPreset] = &[
    MaterialPreset {
        name: "aluminium",
        ior: ConductorIor {
            eta: [1.3456, 0.9652, 0.6172],
            k: [7.4746, 6.3995, 5.3031],
        },
        source: "Rakić 1998, Appl. Opt. 37, 5271 (Brendel–Bormann model), linearly interpolated",
    },
    MaterialPreset {
        name: "copper",
        ior: ConductorIor {
            eta: [0.2378, 1.0066, 1.2404],
            k: [3.6264, 2.5823, 2.3929],
        },
        source: "Johnson & Christy 1972, Phys. Rev. B 6, 4370, linearly interpolated",
    },
    MaterialPreset {
        name: "gold",
        ior: ConductorIor {
            eta: [0.1556, 0.4241, 1.3831],
            k: [3.6024, 2.4721, 1.9155],
        },
        source: "Johnson & Christy 1972, Phys. Rev. B 6, 4370, linearly interpolated",
    },
    MaterialPreset {
        name: "silver",
        ior: ConductorIor {
            eta: [0.0522, 0.0596, 0.0400],
            k: [4.4094, 3.5974, 2.6484],
        },
        source: "Johnson & Christy 1972, Phys. Rev. B 6, 4370, linearly interpolated",
    },
    MaterialPreset {
        name: "iron",
        ior: ConductorIor {
            eta: [2.9114, 2.9497, 2.5845],
            k: [3.0893, 2.9318, 2.7670],
        },
        source: "Johnson & Christy 1974, Phys. Rev. B 9, 5056, linearly interpolated",
    },
    MaterialPreset {
        name: "chromium",
        ior: ConductorIor {
            eta: [3.1071, 3.1812, 2.3230],
            k: [3.3314, 3.3291, 3.1350],
        },
        source: "Johnson & Christy 1974, Phys. Rev. B 9, 5056, linearly interpolated",
    },
];

impl ConductorIor {
    /// The same complex IOR in every channel.
    pub fn grey(eta: f64, k: f64) -> Self {
        Self {
            eta: [eta; 3],
            k: [k; 3],
        }
    }

    /// Look up a preset by name (case-insensitive; `aluminum` is accepted too).
    pub fn preset(name: &str) -> Option<Self> {
        let n = name.to_ascii_lowercase();
        let n = if n == "aluminum" { "aluminium".to_string() } else { n };
        PRESETS.iter().find(|m| m.name == n).map(|m| m.ior)
    }

    /// Reflectance per channel at `cos θi` (cosine between the incident direction and the facet normal).
    pub fn reflectance(&self, cos_theta_i: f64) -> [f64; 3] {
        std::array::from_fn(|c| fresnel_conductor(cos_theta_i, self.eta[c], self.k[c]))
    }
}

/// Unpolarised Fresnel reflectance of a conductor, exact for complex `η + iκ`:
/// `F = (|r_s|² + |r_p|²) / 2` with `r_s = (cosθi − η cosθt)/(cosθi + η cosθt)`,
/// `r_p = (η cosθi − cosθt)/(η cosθi + cosθt)` and `cosθt = sqrt(1 − sin²θi / η²)` (complex).
pub fn fresnel_conductor(cos_theta_i: f64, eta: f64, k: f64) -> f64 {
    let ci = cos_theta_i.clamp(0.0, 1.0);
    let n = Complex64::new(eta, k);
    let sin2 = 1.0 - ci * ci;
    let ct = (Complex64::new(1.0, 0.0) - sin2 / (n * n)).sqrt();
    let rs = (ci - n * ct) / (ci + n * ct);
    let rp = (n * ci - ct) / (n * ci + ct);
    0.5 * (rs.norm_sqr() + rp.norm_sqr())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_matches_closed_form() {
        // At normal incidence F = ((η−1)² + κ²) / ((η+1)² + κ²).
        for (eta, k) in [(1.5, 0.0), (0.2, 3.9), (1.47, 7.64)] {
            let exact = ((eta - 1.0f64).powi(2) + k * k) / ((eta + 1.0f64).powi(2) + k * k);
            assert!((fresnel_conductor(1.0, eta, k) - exact).abs() < 1e-12);
        }
    }

    #[test]
    fn grazing_incidence_reflects_everything() {
        assert!((fresnel_conductor(0.0, 1.47, 7.64) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn dielectric_brewster_angle_kills_p() {
        // For κ = 0 at Brewster's angle r_p = 0, so F = |r_s|²/2.
        let eta: f64 = 1.5;
        let tb = eta.atan();
        let (ci, ct) = (tb.cos(), (1.0 - tb.sin().powi(2) / (eta * eta)).sqrt());
        let rs = (ci - eta * ct) / (ci + eta * ct);
        assert!((fresnel_conductor(ci, eta, 0.0) - 0.5 * rs * rs).abs() < 1e-12);
    }

    #[test]
    fn presets_are_bright_metals() {
        for m in PRESETS {
            let f = m.ior.reflectance(1.0);
            assert!(f.iter().all(|v| (0.3..1.0).contains(v)), "{}: {f:?}", m.name);
        }
        let al = ConductorIor::preset("Aluminum").unwrap().reflectance(1.0);
        assert!(al.iter().all(|v| *v > 0.85), "aluminium is a bright grey: {al:?}");
        let au = ConductorIor::preset("gold").unwrap().reflectance(1.0);
        assert!(au[0] > au[2] + 0.3, "gold reflects red far more than blue: {au:?}");
    }
}
