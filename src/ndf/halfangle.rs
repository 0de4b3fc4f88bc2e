//! BRDF → half-angle distribution in slope space (Section 7.1, DESIGN.md §2).
//!
//! Under the microfacet model (Eq. 5) `f(wi, wo) = D(wh) F G / (4 |wi·n| |wo·n|)`, so
//! `D̃(wh) ∝ f(wi, wo) · 4 |wi·n| |wo·n| / (F G)`. We evaluate it over the half vectors of the slope grid in a
//! near-retro configuration: a fixed small difference angle `θd`, averaged over `φd`. At fixed `θd` the Fresnel
//! factor `F(cos θd)` is the same for every half vector and drops out with the normalisation. The masking
//! term G is not known for measured data, so it is derived from the distribution itself: Smith's Λ of the
//! current estimate (by quadrature over the slope grid) gives `G = G1(wi) G1(wo)`, and the estimate is
//! divided by it; a few fixed-point rounds converge because G depends weakly on D.
//!
//! Data that carries its NDF directly (RGL files, half-angle CSV tables) is sampled as is.

use crate::brdf::{luminance, Brdf};
use crate::geometry::{from_half_diff, slope_to_normal};
use crate::slope::{SlopeDomain, SlopeGrid, SmithTable};
use serde::{Deserialize, Serialize};

/// How the half-angle distribution is read off a BRDF.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HalfAngleConfig {
    /// Difference angle θd of the near-retro configuration, in degrees (0.5° is the centre of MERL's first
    /// θd bin).
    pub theta_d_deg: f64,
    /// Azimuths φd averaged over.
    pub phi_d_samples: usize,
    /// Fixed-point rounds of the Smith masking correction (0 = no masking correction).
    pub masking_iterations: usize,
}

impl Default for HalfAngleConfig {
    fn default() -> Self {
        Self {
            theta_d_deg: 0.5,
            phi_d_samples: 8,
            masking_iterations: 3,
        }
    }
}

/// Where a half-angle distribution came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Source {
    /// Read off the reflectance `f(wi, wo)`.
    Reflectance,
    /// Sampled from an NDF the data carries.
    MeasuredNdf,
}

/// The slope density `P22` of a BRDF's half-angle distribution on `domain`, normalised to unit mass.
pub fn half_angle_density(brdf: &Brdf, domain: SlopeDomain, cfg: &HalfAngleConfig) -> (SlopeGrid, Source) {
    if brdf.has_measured_ndf() {
        let mut g = SlopeGrid::from_fn(domain, |p, q| {
            let wm = slope_to_normal(p, q);
            brdf.measured_ndf(&wm).unwrap_or(0.0).max(0.0) * wm.z.powi(4)
        });
        g.normalise();
        return (g, Source::MeasuredNdf);
    }
    let theta_d = cfg.theta_d_deg.to_radians();
    let k = cfg.phi_d_samples.max(1);
    let estimate = |smith: Option<&SmithTable>| -> SlopeGrid {
        let mut g = SlopeGrid::from_fn(domain, |p, q| {
            let wm = slope_to_normal(p, q);
            let theta_h = wm.z.min(1.0).acos();
            let phi_h = (-q).atan2(-p);
            let (mut acc, mut n) = (0.0, 0usize);
            for s in 0..k {
                let phi_d = (s as f64 + 0.5) / k as f64 * std::f64::consts::TAU;
                let (wi, wo) = from_half_diff(theta_h, phi_h, theta_d, phi_d);
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    continue;
                }
                let f = luminance(&brdf.eval(&wi, &wo));
                let g = smith.map_or(1.0, |t| t.g1(&wi) * t.g1(&wo));
                if g > 0.0 {
                    acc += f * 4.0 * wi.z * wo.z / g;
                    n += 1;
                }
            }
            let d = if n > 0 { acc / n as f64 } else { 0.0 };
            d.max(0.0) * wm.z.powi(4)
        });
        g.normalise();
        g
    };
    let mut g = estimate(None);
    for _ in 0..cfg.masking_iterations {
        let table = SmithTable::new(&g, 64, 32);
        g = estimate(Some(&table));
    }
    (g, Source::Reflectance)
}
