//! Stage 1 — BRDFs: analytic models and measured data behind one type.
//!
//! A [`Brdf`] is a closed set of models ([`Model`]) plus the conductor the part will be milled from
//! ([`ConductorIor`], optional). Analytic models use that conductor's Fresnel term; measured data already
//! carries its own reflectance and keeps the material only as the fabrication material for later stages.
//!
//! Every model evaluates `f(wi, wo)` in RGB, per steradian, **without** the cosine factor. The microfacet
//! form is Eq. 5 of the paper: `f = D(wh) F(wi·wh) G(wi, wo, wh) / (4 |wi·n| |wo·n|)`.
//!
//! ```
//! use brdfmill::stages::brdf::Brdf;
//! use brdfmill::base::geometry::spherical;
//! let brdf = Brdf::parse("ggx:alpha=0.2,material=aluminium").unwrap();
//! let f = brdf.eval(&spherical(0.3, 0.0), &spherical(0.3, std::f64::consts::PI));
//! assert!(f.iter().all(|v| *v > 0.0));
//! ```

pub mod fresnel;
pub mod highlight;
pub mod merl;
pub(crate) mod microfacet;
pub mod rgl;
pub mod rgl_write;
mod spec;
pub mod surface;
pub(crate) mod tabulated;
pub mod tensor;

pub use fresnel::{ConductorIor, PRESETS};
pub use highlight::Highlight;
pub use merl::Merl;
pub use microfacet::{BlinnPhong, Family, Microfacet};
pub use rgl::RglBsdf;
pub use surface::SurfaceNdf;
pub use tabulated::TabulatedNdf;

use crate::base::geometry::{cos_sin_phi, half_vector, tan2_theta, Vec3};
use std::f64::consts::PI;
use std::path::PathBuf;

/// An RGB triple (linear, channels R, G, B).
pub type Rgb = [f64; 3];

/// Everything that can go wrong while naming, reading or building a BRDF.
#[derive(Debug, thiserror::Error)]
pub enum BrdfError {
    /// The spec string is malformed or names an unknown model, key or material.
    #[error("BRDF spec `{spec}`: {reason}")]
    Spec {
        /// The spec as given.
        spec: String,
        /// What was wrong and what was expected.
        reason: String,
    },
    /// A file could not be opened or read.
    #[error(transparent)]
    Io(#[from] crate::base::io::ReadError),
    /// A scanned surface could not be read (the error names the file).
    #[error(transparent)]
    Scan(#[from] crate::base::scan::ScanError),
    /// A data file is not in the expected format.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What was wrong, with the byte offset, field or line where it applies.
        reason: String,
    },
}

/// Luminance weights of linear sRGB/Rec. 709 primaries (used to reduce RGB to one channel).
pub const LUMINANCE: Rgb = [0.2126, 0.7152, 0.0722];

/// The anisotropic Ward model (Ward 1992, with the normalisation of Walter 2005):
/// `f = F / (4π αx αy √(cosθi cosθo)) · exp(−tan²θh (cos²φh/αx² + sin²φh/αy²))`.
///
/// Its half-vector exponent is the Beckmann distribution's; it has no Smith masking term of its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ward {
    /// Roughness along x.
    pub alpha_x: f64,
    /// Roughness along y.
    pub alpha_y: f64,
}

/// The closed set of reflectance models.
#[derive(Clone, Debug)]
pub enum Model {
    /// Beckmann or GGX microfacet model (isotropic or anisotropic), Eq. 5.
    Microfacet(Microfacet),
    /// Normalised Blinn–Phong NDF in the microfacet model, masking from its Beckmann equivalent.
    BlinnPhong(BlinnPhong),
    /// Anisotropic Ward.
    Ward(Ward),
    /// A MERL `.binary` measurement.
    Merl(Box<Merl>),
    /// An RGL `.bsdf` measurement (Dupuy & Jakob 2018).
    Rgl(Box<RglBsdf>),
    /// A tabulated half-angle distribution (CSV), used as the NDF of a microfacet model.
    Tabulated(Box<TabulatedNdf>),
    /// A drawn highlight (PNG) mapped to slope space, used as the NDF of a microfacet model.
    Highlight(Box<Highlight>),
    /// A measured surface (X3P or `.npy` scan), its NDF used as the NDF of a microfacet model.
    Surface(Box<SurfaceNdf>),
}

/// A BRDF: a model and, optionally, the conductor the part is made of.
#[derive(Clone, Debug)]
pub struct Brdf {
    /// The reflectance model.
    pub model: Model,
    /// Complex IOR of the material; `None` means a white, perfectly reflecting facet (F = 1).
    pub material: Option<ConductorIor>,
    /// The spec string this BRDF was built from (for reports and provenance).
    pub spec: String,
}

impl Brdf {
    /// Build a BRDF from a spec string such as `ggx:ax=0.1,ay=0.3,material=gold` or `merl:PATH`.
    ///
    /// Forms: `beckmann:alpha=A`, `ggx:alpha=A`, `ggx:ax=A,ay=B` (also `beckmann:ax=..,ay=..`),
    /// `ward:ax=A,ay=B`, `blinn:n=N`, `merl:PATH`, `rgl:PATH`, `csv:PATH`, `highlight:PNG` (optionally `,extent_deg=E`, default 30: [`highlight`]), `surface:SCAN` (an X3P or
    /// `.npy` scan; optionally `,filter_um=F`, the pre-filter's σ, default 0, and `,pitch_um=P` for a `.npy`:
    /// [`surface`]), each optionally followed by
    /// `,material=NAME` (see [`PRESETS`]) or `,eta=E,k=K`. Paths must not contain commas.
    pub fn parse(spec: &str) -> Result<Self, BrdfError> {
        spec::parse(spec)
    }

    /// Fresnel reflectance per channel at `cos θ` between the light and the facet normal.
    pub fn fresnel(&self, cos_theta: f64) -> Rgb {
        match &self.material {
            Some(ior) => ior.reflectance(cos_theta),
            None => [1.0; 3],
        }
    }

    /// `f(wi, wo)` in RGB per steradian, without the cosine; zero when either direction is below the horizon.
    pub fn eval(&self, wi: &Vec3, wo: &Vec3) -> Rgb {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return [0.0; 3];
        }
        let Some(wh) = half_vector(wi, wo) else {
            return [0.0; 3];
        };
        let microfacet = |d: f64, g: f64| -> Rgb {
            let s = d * g / (4.0 * wi.z * wo.z);
            self.fresnel(wi.dot(&wh)).map(|f| f * s)
        };
        match &self.model {
            Model::Microfacet(m) => microfacet(m.d(&wh), m.g(wi, wo, &wh)),
            Model::BlinnPhong(b) => microfacet(b.d(&wh), b.smith_proxy().g(wi, wo, &wh)),
            Model::Ward(w) => {
                let (c, s) = cos_sin_phi(&wh);
                let e = tan2_theta(&wh) * (c * c / (w.alpha_x * w.alpha_x) + s * s / (w.alpha_y * w.alpha_y));
                let v = (-e).exp() / (4.0 * PI * w.alpha_x * w.alpha_y * (wi.z * wo.z).sqrt());
                self.fresnel(wi.dot(&wh)).map(|f| f * v)
            }
            Model::Merl(m) => m.eval(wi, wo),
            Model::Rgl(r) => r.eval(wi, wo),
            Model::Tabulated(t) => microfacet(t.d(&wh), t.g(wi, wo, &wh)),
            Model::Highlight(h) => microfacet(h.d(&wh), h.g(wi, wo, &wh)),
            Model::Surface(s) => microfacet(s.d(&wh), s.g(wi, wo, &wh)),
        }
    }

    /// The measured NDF `D(wm)` where the data carries one directly (RGL files, half-angle CSV tables);
    /// `None` for models whose NDF is only reachable through their reflectance.
    pub fn measured_ndf(&self, wm: &Vec3) -> Option<f64> {
        match &self.model {
            Model::Rgl(r) => Some(r.ndf(wm)),
            Model::Tabulated(t) => Some(t.d(wm)),
            Model::Highlight(h) => Some(h.d(wm)),
            Model::Surface(s) => Some(s.d(wm)),
            _ => None,
        }
    }

    /// The NDF `D(wm)` (normalised so that `∫ D cosθm dω = 1` for the analytic models) where it is known
    /// without reading the reflectance: the analytic models' own (Ward's half-vector exponent is Beckmann's)
    /// and the measured NDF of [`Brdf::measured_ndf`]; `None` for reflectance-only data (MERL).
    pub fn known_ndf(&self, wm: &Vec3) -> Option<f64> {
        match &self.model {
            Model::Microfacet(m) => Some(m.d(wm)),
            Model::BlinnPhong(b) => Some(b.d(wm)),
            Model::Ward(w) => Microfacet::new(Family::Beckmann, w.alpha_x, w.alpha_y).map(|m| m.d(wm)),
            Model::Merl(_) => None,
            Model::Rgl(_) | Model::Tabulated(_) | Model::Highlight(_) | Model::Surface(_) => self.measured_ndf(wm),
        }
    }

    /// The share of the data's distribution of normals its NDF leaves out (a scan's slopes beyond the grid
    /// it is binned on, or that its wave estimate cannot hold); 0 for every other model.
    pub fn ndf_mass_left_out(&self) -> f64 {
        match &self.model {
            Model::Surface(s) => s.outside,
            _ => 0.0,
        }
    }

    /// The drawn highlight this BRDF was made from, if it is one.
    pub fn highlight(&self) -> Option<&Highlight> {
        match &self.model {
            Model::Highlight(h) => Some(h),
            _ => None,
        }
    }

    /// True when [`Brdf::measured_ndf`] answers.
    pub fn has_measured_ndf(&self) -> bool {
        matches!(
            self.model,
            Model::Rgl(_) | Model::Tabulated(_) | Model::Highlight(_) | Model::Surface(_)
        )
    }
}

/// Reduce an RGB value to luminance with [`LUMINANCE`] weights.
#[inline]
pub fn luminance(c: &Rgb) -> f64 {
    c[0] * LUMINANCE[0] + c[1] * LUMINANCE[1] + c[2] * LUMINANCE[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::geometry::spherical;
    use proptest::prelude::*;

    const SPECS: &[&str] = &[
        "beckmann:alpha=0.3",
        "ggx:alpha=0.2,material=copper",
        "ggx:ax=0.1,ay=0.3",
        "ward:ax=0.1,ay=0.3,eta=1.35,k=7.47",
        "blinn:n=200,material=gold",
    ];

    proptest! {
        #[test]
        fn analytic_models_are_reciprocal_and_non_negative(
            ti in 0.01..1.5f64, pi in -3.1..3.1f64, to in 0.01..1.5f64, po in -3.1..3.1f64
        ) {
            let (wi, wo) = (spherical(ti, pi), spherical(to, po));
            for s in SPECS {
                let b = Brdf::parse(s).unwrap();
                let a = b.eval(&wi, &wo);
                let r = b.eval(&wo, &wi);
                for c in 0..3 {
                    prop_assert!(a[c] >= 0.0 && a[c].is_finite(), "{s}: {a:?}");
                    prop_assert!((a[c] - r[c]).abs() <= 1e-9 * a[c].max(1e-12), "{s}: {a:?} vs {r:?}");
                }
            }
        }
    }

    #[test]
    fn white_furnace_energy_is_at_most_one() {
        // With F = 1, ∫ f cosθo dωo ≤ 1 for any incident direction (Smith masking loses energy, never adds).
        for s in ["beckmann:alpha=0.3", "ggx:ax=0.1,ay=0.3", "blinn:n=50"] {
            let b = Brdf::parse(s).unwrap();
            for ti in [0.0f64, 0.7, 1.2] {
                let wi = spherical(ti, 0.4);
                let (nt, np) = (400, 200);
                let mut acc = 0.0;
                for it in 0..nt {
                    let th = (it as f64 + 0.5) / nt as f64 * PI / 2.0;
                    for ip in 0..np {
                        let ph = (ip as f64 + 0.5) / np as f64 * 2.0 * PI;
                        let wo = spherical(th, ph);
                        acc += luminance(&b.eval(&wi, &wo)) * th.cos() * th.sin();
                    }
                }
                let albedo = acc * (PI / 2.0 / nt as f64) * (2.0 * PI / np as f64);
                assert!(albedo <= 1.0 + 2e-3, "{s} θi={ti}: albedo {albedo}");
                assert!(albedo > 0.6, "{s} θi={ti}: albedo {albedo} implausibly low");
            }
        }
    }
}
