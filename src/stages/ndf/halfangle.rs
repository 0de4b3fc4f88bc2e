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
//! Data that carries its NDF directly (RGL files, half-angle CSV tables) is sampled as is; a drawn highlight
//! is averaged over each cell ([`crate::stages::brdf::Highlight::slope_grid`]), since its pixels are finer than the
//! grid.

use crate::base::geometry::{from_half_diff, slope_to_normal, Vec3};
use crate::base::slope::{SlopeDomain, SlopeGrid, SmithTable, TableDirection};
use crate::stages::brdf::{luminance, Brdf};
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
    if let Some(h) = brdf.highlight() {
        return (h.slope_grid(domain), Source::MeasuredNdf);
    }
    if brdf.has_measured_ndf() {
        let mut g = SlopeGrid::from_fn(domain, |p, q| {
            let wm = slope_to_normal(p, q);
            brdf.measured_ndf(&wm).unwrap_or(0.0).max(0.0) * wm.z.powi(4)
        });
        g.normalise();
        return (g, Source::MeasuredNdf);
    }
    let samples = RetroSamples::new(brdf, domain, cfg);
    let mut g = samples.estimate(None);
    for _ in 0..cfg.masking_iterations {
        let table = SmithTable::new(&g, 64, 32);
        g = samples.estimate(Some(&table));
    }
    (g, Source::Reflectance)
}

/// Calls `visit(f·4·cosθi·cosθo, wi, wo)` for each near-retro sample of the half vector `wm` (module
/// documentation) whose `wi` and `wo` are above the horizon: the reflectance with the masking left out.
fn for_each_retro_sample(brdf: &Brdf, wm: &Vec3, cfg: &HalfAngleConfig, mut visit: impl FnMut(f64, &Vec3, &Vec3)) {
    let theta_d = cfg.theta_d_deg.to_radians();
    let k = cfg.phi_d_samples.max(1);
    let theta_h = wm.z.min(1.0).acos();
    let phi_h = wm.y.atan2(wm.x);
    for s in 0..k {
        let phi_d = (s as f64 + 0.5) / k as f64 * std::f64::consts::TAU;
        let (wi, wo) = from_half_diff(theta_h, phi_h, theta_d, phi_d);
        if wi.z <= 0.0 || wo.z <= 0.0 {
            continue;
        }
        visit(luminance(&brdf.eval(&wi, &wo)) * 4.0 * wi.z * wo.z, &wi, &wo);
    }
}

/// The mean of `values` divided by their masking (samples whose masking is 0 left out), floored at 0.
fn masked_mean(values: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut acc, mut n) = (0.0, 0usize);
    for (f, g) in values {
        if g > 0.0 {
            acc += f / g;
            n += 1;
        }
    }
    floored_mean(acc, n)
}

/// `acc / n` floored at 0, and 0 for no samples.
fn floored_mean(acc: f64, n: usize) -> f64 {
    if n > 0 {
        (acc / n as f64).max(0.0)
    } else {
        0.0
    }
}

/// The unnormalised `D̃(wm)` read off the reflectance in the near-retro configuration (module
/// documentation), without the masking correction.
fn reflectance_d(brdf: &Brdf, wm: &Vec3, cfg: &HalfAngleConfig) -> f64 {
    let (mut acc, mut n) = (0.0, 0usize);
    for_each_retro_sample(brdf, wm, cfg, |f, _, _| {
        acc += f;
        n += 1;
    });
    floored_mean(acc, n)
}

/// One near-retro sample, kept across the masking fixed point: the reflectance does not change from one
/// round to the next, only the masking it is divided by, so the BRDF is evaluated once per sample.
#[derive(Clone, Copy)]
struct RetroSample {
    /// `f·4·cosθi·cosθo`.
    value: f64,
    wi: TableDirection,
    wo: TableDirection,
}

/// Every cell's near-retro samples (row-major, `start[c]..start[c + 1]` for cell `c`) and `cos⁴θm`.
struct RetroSamples {
    domain: SlopeDomain,
    samples: Vec<RetroSample>,
    start: Vec<usize>,
    cos4: Vec<f64>,
}

impl RetroSamples {
    fn new(brdf: &Brdf, domain: SlopeDomain, cfg: &HalfAngleConfig) -> Self {
        use rayon::prelude::*;
        let rows: Vec<(Vec<RetroSample>, Vec<usize>, Vec<f64>)> = (0..domain.ny)
            .into_par_iter()
            .map(|j| {
                let q = domain.q_at(j);
                let (mut samples, mut counts, mut cos4) = (vec![], vec![], vec![]);
                for i in 0..domain.nx {
                    let wm = slope_to_normal(domain.p_at(i), q);
                    let before = samples.len();
                    for_each_retro_sample(brdf, &wm, cfg, |value, wi, wo| {
                        samples.push(RetroSample {
                            value,
                            wi: TableDirection::of(wi),
                            wo: TableDirection::of(wo),
                        })
                    });
                    counts.push(samples.len() - before);
                    cos4.push(wm.z.powi(4));
                }
                (samples, counts, cos4)
            })
            .collect();
        let mut out = Self {
            domain,
            samples: vec![],
            start: vec![0],
            cos4: vec![],
        };
        for (samples, counts, cos4) in rows {
            out.samples.extend(samples);
            for c in counts {
                out.start.push(out.start.last().copied().unwrap_or(0) + c);
            }
            out.cos4.extend(cos4);
        }
        out
    }

    /// The distribution divided by the masking of `smith` (none: 1), normalised.
    fn estimate(&self, smith: Option<&SmithTable>) -> SlopeGrid {
        use rayon::prelude::*;
        let mut g = SlopeGrid {
            domain: self.domain,
            density: vec![0.0; self.domain.len()],
        };
        g.density.par_iter_mut().enumerate().for_each(|(c, v)| {
            let cell = &self.samples[self.start[c]..self.start[c + 1]];
            let d = masked_mean(
                cell.iter()
                    .map(|s| (s.value, smith.map_or(1.0, |t| t.g1_at(s.wi) * t.g1_at(s.wo)))),
            );
            *v = d * self.cos4[c];
        });
        g.normalise();
        g
    }
}

/// Polar cells of [`mass_beyond_grid`]'s quadrature over the hemisphere: θ in steps of 0.1°, φ of 1°.
const HEMISPHERE_CELLS: (usize, usize) = (900, 360);

/// The fraction of the half-angle distribution's mass `∫ D(wm) cosθm dωm` over the whole hemisphere that
/// lies outside the slope grid `|p| ≤ p_max, |q| ≤ q_max` (mass the grid, and so the design, cannot hold),
/// by the midpoint rule on a polar grid (`dω = sinθ dθ dφ`). Where the NDF is known ([`Brdf::known_ndf`]:
/// the analytic models, data that carries its NDF), that NDF; for reflectance-only data, the estimate
/// without the masking correction (masking only lowers `f` near grazing, so this understates what
/// escapes). A measured surface adds the share of its slopes beyond its own grid.
pub fn mass_beyond_grid(brdf: &Brdf, domain: SlopeDomain, cfg: &HalfAngleConfig) -> f64 {
    // mass the data has but its NDF leaves out (a scan's slopes beyond its own grid) is beyond this one too
    let lost = brdf.ndf_mass_left_out();
    let beyond = if brdf.known_ndf(&Vec3::new(0.0, 0.0, 1.0)).is_some() {
        mass_outside(domain, |wm| brdf.known_ndf(wm).unwrap_or(0.0).max(0.0))
    } else {
        mass_outside(domain, |wm| reflectance_d(brdf, wm, cfg))
    };
    lost + (1.0 - lost) * beyond
}

/// `1 − ∫_grid D cosθ dω / ∫_hemisphere D cosθ dω` for a distribution `d(wm)` (see [`mass_beyond_grid`]).
fn mass_outside(domain: SlopeDomain, d: impl Fn(&Vec3) -> f64 + Sync) -> f64 {
    use rayon::prelude::*;
    let (nt, np) = HEMISPHERE_CELLS;
    let (dt, dp) = (
        std::f64::consts::FRAC_PI_2 / nt as f64,
        std::f64::consts::TAU / np as f64,
    );
    let (inside, total) = (0..nt)
        .into_par_iter()
        .map(|i| {
            let t = (i as f64 + 0.5) * dt;
            let (st, ct) = t.sin_cos();
            let (mut inside, mut total) = (0.0, 0.0);
            for j in 0..np {
                let ph = (j as f64 + 0.5) * dp;
                let (sp, cp) = ph.sin_cos();
                let wm = Vec3::new(st * cp, st * sp, ct);
                let m = d(&wm) * ct * st * dt * dp;
                total += m;
                let (p, q) = (-wm.x / ct, -wm.y / ct);
                if p >= domain.p_min && p <= domain.p_max && q >= domain.q_min && q <= domain.q_max {
                    inside += m;
                }
            }
            (inside, total)
        })
        // added in θ order, not as rayon's `reduce` pairs them (which follows the work stealing)
        .collect::<Vec<_>>()
        .into_iter()
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    if total > 0.0 {
        (1.0 - inside / total).max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::brdf::microfacet::{Family, Microfacet};

    fn square(t: f64) -> SlopeDomain {
        SlopeDomain {
            nx: 64,
            ny: 64,
            p_min: -t,
            p_max: t,
            q_min: -t,
            q_max: t,
        }
    }

    /// Beckmann slopes are Gaussian with variance α²/2 per axis, so the square |p|, |q| ≤ t holds
    /// `erf(t/α)²` of the mass.
    #[test]
    fn beckmann_mass_outside_a_square_matches_the_closed_form() {
        for (alpha, deg) in [(0.5, 30.0f64), (0.3, 30.0), (5.0, 60.0)] {
            let t = deg.to_radians().tan();
            let m = Microfacet::new(Family::Beckmann, alpha, alpha).unwrap();
            let exact = 1.0 - libm::erf(t / alpha).powi(2);
            let got = mass_outside(square(t), |wm| m.d(wm));
            assert!((got - exact).abs() < 1e-3, "α {alpha}, {deg}°: {got} against {exact}");
        }
    }

    /// From the reflectance, without the masking correction, the estimate is a lower bound that stays close
    /// where masking is mild.
    #[test]
    fn from_the_reflectance_the_escaped_mass_is_a_close_lower_bound() {
        let t = 30f64.to_radians().tan();
        let exact = 1.0 - libm::erf(t / 0.5).powi(2);
        let brdf = Brdf::parse("beckmann:alpha=0.5").unwrap();
        let cfg = HalfAngleConfig::default();
        let got = mass_outside(square(t), |wm| reflectance_d(&brdf, wm, &cfg));
        assert!(got <= exact + 1e-3 && got > exact - 0.03, "{got} against {exact}");
        // a model whose NDF is known uses it: α = 5 on the default 60° grid escapes erf(√3/5)² of its mass
        let wide = Brdf::parse("beckmann:alpha=5").unwrap();
        let t60 = 60f64.to_radians().tan();
        let exact = 1.0 - libm::erf(t60 / 5.0).powi(2);
        let got = mass_beyond_grid(&wide, square(t60), &cfg);
        assert!((got - exact).abs() < 1e-3, "{got} against {exact}");
    }
}
