//! Distances between the target's observed distribution and a fabricated surface's (DESIGN.md §6).
//!
//! Every metric comes with a stated tolerance and a pass/fail:
//! - `ndf_l1`: relative L1 distance of the densities, `∑|a − b| / ∑|b|` (0 = identical, 2 = disjoint);
//! - `ndf_corr`: Pearson correlation of the densities over the grid;
//! - `ndf_js`: Jensen–Shannon divergence of the cell masses, in bits (0 … 1);
//! - `cov_ratio`: slope variance along x and along y, candidate over reference;
//! - `peak_offset_deg`: angle between the normals at the two densities' peaks;
//! - `albedo`: directional albedo `∫ f cosθo dωo` at a few incident angles, candidate over a perfect cut's.
//!
//! **Albedo against a perfect cut.** A milled surface is facets of one material, so what it can reflect
//! at `θi` with the target's slopes is a perfect cut's albedo: Eq. 5 on the target's own observed
//! distribution with the target's material (`ideal`). A target may differ from that for reasons no geometry
//! can change: Ward's normalisation `1/√(cosθi cosθo)` makes a narrow lobe's albedo ≈ ρs·cosθi (half at
//! 60°), a measured dielectric carries a diffuse part (less than a conductor's facets, or more). The check compares the candidate with the perfect cut, so it
//! measures what the cut got wrong; the target's own albedo is kept beside it (`target`), and the
//! verdict's notes say when the two differ by more than the tolerance.

use crate::base::distance::{correlation, jensen_shannon};
use crate::base::geometry::{slope_to_normal, spherical};
use crate::base::slope::SlopeGrid;
use crate::stages::brdf::{luminance, Brdf};
use crate::stages::optics::geometric::MicrofacetBrdf;
use serde::{Deserialize, Serialize};

/// Tolerances of the verdict.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Tolerances {
    /// Largest relative L1 distance.
    pub ndf_l1_max: f64,
    /// Smallest correlation.
    pub ndf_corr_min: f64,
    /// Largest Jensen–Shannon divergence, bits.
    pub ndf_js_max: f64,
    /// Covariance ratio band `[low, high]`, per axis.
    pub cov_ratio: [f64; 2],
    /// Largest peak offset, degrees.
    pub peak_offset_deg_max: f64,
    /// Largest relative albedo error.
    pub albedo_rel_max: f64,
    /// Smallest correlation of the milled surface's highlight with a `highlight` target's image.
    pub highlight_corr_min: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            ndf_l1_max: 0.3,
            ndf_corr_min: 0.95,
            ndf_js_max: 0.05,
            cov_ratio: [0.9, 1.1],
            peak_offset_deg_max: 2.0,
            albedo_rel_max: 0.05,
            highlight_corr_min: 0.95,
        }
    }
}

/// A tolerance that is not a bound: the field, what it must be, what it is.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("`{field}` must be {expected}, got {value}")]
pub struct ToleranceError {
    /// The field of `[verify.tolerances]`.
    pub field: &'static str,
    /// What it must be.
    pub expected: &'static str,
    /// What it is.
    pub value: String,
}

impl Tolerances {
    /// Check that every bound is a number and the band is ordered; the error names the field.
    pub fn validate(&self) -> Result<(), ToleranceError> {
        let bad =
            |field: &'static str, expected: &'static str, value: String| ToleranceError { field, expected, value };
        let [lo, hi] = self.cov_ratio;
        if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi) {
            return Err(bad(
                "cov_ratio",
                "[low, high] with 0 < low ≤ high",
                format!("[{lo}, {hi}]"),
            ));
        }
        for (field, v) in [
            ("ndf_l1_max", self.ndf_l1_max),
            ("ndf_corr_min", self.ndf_corr_min),
            ("ndf_js_max", self.ndf_js_max),
            ("peak_offset_deg_max", self.peak_offset_deg_max),
            ("albedo_rel_max", self.albedo_rel_max),
            ("highlight_corr_min", self.highlight_corr_min),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(field, "a number ≥ 0", v.to_string()));
            }
        }
        for (field, v) in [
            ("ndf_corr_min", self.ndf_corr_min),
            ("highlight_corr_min", self.highlight_corr_min),
        ] {
            if v > 1.0 {
                return Err(bad(field, "at most 1", v.to_string()));
            }
        }
        Ok(())
    }
}

/// The name of the peak direction check.
pub const PEAK_CHECK: &str = "peak direction offset (°)";

/// One checked figure.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// Which metric.
    pub name: String,
    /// Its value.
    pub value: f64,
    /// The bound, as text (`≥ 0.95`, `in [0.9, 1.1]`).
    pub tolerance: String,
    /// Whether it is met.
    pub pass: bool,
}

impl Check {
    /// Whether the bound applies to this target (a drawn highlight has no single peak direction: its
    /// tolerance reads "not checked: …"); an unchecked row is shown as such, never as passed.
    pub fn is_checked(&self) -> bool {
        !self.tolerance.starts_with("not checked")
    }
}

/// Directional albedo at one incident angle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Albedo {
    /// Incident polar angle, degrees.
    pub theta_i_deg: f64,
    /// The target BRDF's albedo (luminance).
    pub target: f64,
    /// This surface's.
    pub surface: f64,
    /// A perfect cut's: Eq. 5 on the target's observed distribution with the target's material (absent in
    /// files written before it was recorded). The check compares `surface` with it.
    #[serde(default)]
    pub ideal: Option<f64>,
}

impl Albedo {
    /// The check's relative error: this surface against a perfect cut (against the target when `ideal` is
    /// absent).
    #[must_use]
    pub fn rel_error(&self) -> f64 {
        let reference = self.ideal.unwrap_or(self.target);
        if reference > 0.0 {
            self.surface / reference - 1.0
        } else {
            0.0
        }
    }
}

/// A surface measured against the target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceMetrics {
    /// Relative L1 distance.
    pub ndf_l1: f64,
    /// Correlation.
    pub ndf_corr: f64,
    /// Jensen–Shannon divergence, bits.
    pub ndf_js: f64,
    /// Variance ratio along x and y.
    pub cov_ratio: [f64; 2],
    /// Peak offset, degrees.
    pub peak_offset_deg: f64,
    /// Albedo at the incident angles.
    pub albedo: Vec<Albedo>,
    /// Every figure with its tolerance.
    pub checks: Vec<Check>,
    /// All checks pass.
    pub pass: bool,
}

/// The three figures of a distribution's shape against a reference (not a tool's shape, `cut::tool::Shape`): relative L1, correlation, and the
/// slope variance ratios per axis (within the machinable cone when `cone_tan` is finite, as the verdict
/// measures them). [`measure`] computes these and the rest; what only compares shapes (each machine
/// error's cut) needs no more.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NdfShape {
    /// Relative L1 distance.
    pub ndf_l1: f64,
    /// Correlation.
    pub ndf_corr: f64,
    /// Variance ratio along x and y.
    pub cov_ratio: [f64; 2],
}

/// See [`NdfShape`].
pub fn ndf_shape(reference: &SlopeGrid, candidate: &SlopeGrid, cone_tan: f64) -> NdfShape {
    let (sr, sc) = if cone_tan.is_finite() {
        (
            reference.within_cone(cone_tan).stats(),
            candidate.within_cone(cone_tan).stats(),
        )
    } else {
        (reference.stats(), candidate.stats())
    };
    NdfShape {
        ndf_l1: candidate.relative_l1(reference),
        ndf_corr: correlation(&candidate.density, &reference.density),
        cov_ratio: [sc.cov[0][0] / sr.cov[0][0], sc.cov[1][1] / sr.cov[1][1]],
    }
}

/// Slope of a density's peak.
pub fn peak(g: &SlopeGrid) -> (f64, f64) {
    let k = g
        .density
        .iter()
        .enumerate()
        .fold(0, |best, (k, v)| if *v > g.density[best] { k } else { best });
    (g.domain.p_at(k % g.domain.nx), g.domain.q_at(k / g.domain.nx))
}

/// Directional albedo (luminance) of `f` at incident angle `theta_i` (radians), azimuth 0.
pub fn albedo(
    f: impl Fn(&crate::base::geometry::Vec3, &crate::base::geometry::Vec3) -> crate::stages::brdf::Rgb,
    theta_i: f64,
) -> f64 {
    let wi = spherical(theta_i, 0.0);
    let (nt, np) = (96, 96);
    let mut acc = 0.0;
    for it in 0..nt {
        // uniform in cos²θ would be better for peaks; use θ midpoints with sinθ cosθ weight
        let th = (it as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
        for ip in 0..np {
            let ph = (ip as f64 + 0.5) / np as f64 * std::f64::consts::TAU;
            let wo = spherical(th, ph);
            acc += luminance(&f(&wi, &wo)) * th.cos() * th.sin();
        }
    }
    acc * (std::f64::consts::FRAC_PI_2 / nt as f64) * (std::f64::consts::TAU / np as f64)
}

/// Measure `candidate` (already blurred by whatever lobe it still lacks) against `reference` (the target's
/// observed distribution) and the target BRDF. The slope variances are those of both densities restricted to
/// the machinable cone `|∇z| ≤ cone_tan` (`f64::INFINITY`: the whole grid); L1, correlation and
/// Jensen–Shannon are over the whole grid, so the target's mass beyond the cone counts against them.
pub fn measure(
    reference: &SlopeGrid,
    candidate: &SlopeGrid,
    target: &Brdf,
    incident_deg: &[f64],
    tol: &Tolerances,
    cone_tan: f64,
) -> SurfaceMetrics {
    let NdfShape {
        ndf_l1,
        ndf_corr,
        cov_ratio,
    } = ndf_shape(reference, candidate, cone_tan);
    let ndf_js = jensen_shannon(&candidate.density, &reference.density);
    let (pr, pc) = (peak(reference), peak(candidate));
    let (na, nb) = (slope_to_normal(pr.0, pr.1), slope_to_normal(pc.0, pc.1));
    let peak_offset_deg = na.cross(&nb).norm().atan2(na.dot(&nb)).to_degrees();
    let micro = MicrofacetBrdf::new(candidate.clone(), target.material);
    let perfect = MicrofacetBrdf::new(reference.clone(), target.material);
    let albedo: Vec<Albedo> = incident_deg
        .iter()
        .map(|t| Albedo {
            theta_i_deg: *t,
            target: self::albedo(|a, b| target.eval(a, b), t.to_radians()),
            surface: self::albedo(|a, b| micro.eval(a, b), t.to_radians()),
            ideal: Some(self::albedo(|a, b| perfect.eval(a, b), t.to_radians())),
        })
        .collect();
    let mut checks = vec![
        Check {
            name: "NDF relative L1".into(),
            value: ndf_l1,
            tolerance: format!("≤ {}", tol.ndf_l1_max),
            pass: ndf_l1 <= tol.ndf_l1_max,
        },
        Check {
            name: "NDF correlation".into(),
            value: ndf_corr,
            tolerance: format!("≥ {}", tol.ndf_corr_min),
            pass: ndf_corr >= tol.ndf_corr_min,
        },
        Check {
            name: "NDF Jensen–Shannon (bits)".into(),
            value: ndf_js,
            tolerance: format!("≤ {}", tol.ndf_js_max),
            pass: ndf_js <= tol.ndf_js_max,
        },
    ];
    for (k, axis) in ["x", "y"].iter().enumerate() {
        checks.push(Check {
            name: format!("slope variance ratio ({axis})"),
            value: cov_ratio[k],
            tolerance: format!("in [{}, {}]", tol.cov_ratio[0], tol.cov_ratio[1]),
            pass: cov_ratio[k] >= tol.cov_ratio[0] && cov_ratio[k] <= tol.cov_ratio[1],
        });
    }
    checks.push(Check {
        name: PEAK_CHECK.into(),
        value: peak_offset_deg,
        tolerance: format!("≤ {}", tol.peak_offset_deg_max),
        pass: peak_offset_deg <= tol.peak_offset_deg_max,
    });
    for a in &albedo {
        let rel = a.rel_error();
        checks.push(Check {
            name: format!(
                "albedo at θi = {}° against a perfect cut (relative error)",
                a.theta_i_deg
            ),
            value: rel,
            tolerance: format!("|·| ≤ {}", tol.albedo_rel_max),
            pass: rel.abs() <= tol.albedo_rel_max,
        });
    }
    let pass = checks.iter().all(|c| c.pass);
    SurfaceMetrics {
        ndf_l1,
        ndf_corr,
        ndf_js,
        cov_ratio,
        peak_offset_deg,
        albedo,
        checks,
        pass,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::SlopeDomain;

    #[test]
    fn identical_distributions_score_perfectly() {
        let d = SlopeDomain::square(64, 1.5);
        let mut g = SlopeGrid::from_fn(d, |p, q| (-(p * p + q * q) / 0.09).exp());
        g.normalise();
        let brdf = Brdf::parse("beckmann:alpha=0.3").unwrap();
        let m = measure(&g, &g, &brdf, &[0.0, 45.0], &Tolerances::default(), f64::INFINITY);
        assert!(m.ndf_l1 < 1e-12 && (m.ndf_corr - 1.0).abs() < 1e-12 && m.ndf_js < 1e-12);
        assert!((m.cov_ratio[0] - 1.0).abs() < 1e-12 && m.peak_offset_deg < 1e-9);
        // the grid's microfacet BRDF reproduces the analytic Beckmann's albedo
        for a in &m.albedo {
            assert!((a.surface / a.target - 1.0).abs() < 0.03, "{a:?}");
            assert!((a.ideal.unwrap() / a.target - 1.0).abs() < 0.03, "{a:?}");
        }
        assert!(m.pass, "{:?}", m.checks);
    }

    /// Ward's normalisation `1/√(cosθi cosθo)`: near the mirror direction a narrow lobe's albedo is
    /// ρs·cosθi of a microfacet surface's, so a perfect cut of its distribution reflects about 1/cosθi more
    /// than the Ward target itself, and the albedo checks, made against the perfect cut, pass.
    #[test]
    fn albedo_is_checked_against_a_perfect_cut_not_the_targets_normalisation() {
        let d = SlopeDomain::square(96, 0.6);
        let brdf = Brdf::parse("ward:ax=0.06,ay=0.06").unwrap();
        let a2 = 0.06f64 * 0.06;
        let mut g = SlopeGrid::from_fn(d, |p, q| (-(p * p + q * q) / a2).exp());
        g.normalise();
        let m = measure(&g, &g, &brdf, &[0.0, 30.0, 60.0], &Tolerances::default(), f64::INFINITY);
        for a in &m.albedo {
            let ideal = a.ideal.expect("recorded");
            let cos = a.theta_i_deg.to_radians().cos();
            assert!(
                (a.target / ideal / cos - 1.0).abs() < 0.03,
                "{a:?}: {}",
                a.target / ideal
            );
            assert!(a.rel_error().abs() < 1e-12, "{a:?}");
        }
        assert!(m.pass, "{:?}", m.checks);
    }

    #[test]
    fn a_wider_distribution_fails_the_covariance_check() {
        let d = SlopeDomain::square(64, 1.5);
        let mut a = SlopeGrid::from_fn(d, |p, q| (-(p * p + q * q) / 0.09).exp());
        let mut b = SlopeGrid::from_fn(d, |p, q| (-(p * p + q * q) / 0.12).exp());
        a.normalise();
        b.normalise();
        let brdf = Brdf::parse("beckmann:alpha=0.3").unwrap();
        let m = measure(&a, &b, &brdf, &[0.0], &Tolerances::default(), f64::INFINITY);
        assert!(m.cov_ratio[0] > 1.2 && !m.pass);
        assert!(m.ndf_js > 0.0 && m.ndf_js < 1.0);
    }

    /// Directional albedo against closed forms: a Lambertian BRDF `ρ/π` reflects `ρ` at every incidence
    /// (`∫ (ρ/π) cosθ dω = ρ`), and a lobe that is zero beyond θo = 30° reflects `ρ·sin²30° = ρ/4` of it.
    #[test]
    fn albedo_matches_closed_forms() {
        let rho = 0.7;
        for theta_deg in [0.0f64, 30.0, 75.0] {
            let a = albedo(|_, _| [rho / std::f64::consts::PI; 3], theta_deg.to_radians());
            assert!((a / rho - 1.0).abs() < 1e-4, "θi {theta_deg}°: {a}");
        }
        let cap = albedo(
            |_, wo| {
                if wo.z >= 30f64.to_radians().cos() {
                    [rho / std::f64::consts::PI; 3]
                } else {
                    [0.0; 3]
                }
            },
            0.0,
        );
        assert!((cap / (rho / 4.0) - 1.0).abs() < 0.02, "{cap}");
    }

    /// The peak offset is the angle between the normals of the two densities' peaks: peaks at slopes
    /// (0.3, 0) and (0, 0.4) are `acos(1/√(1.09·1.16))` apart, whatever else the grids hold.
    #[test]
    fn peak_offset_is_the_angle_between_the_peaks_normals() {
        let d = SlopeDomain::square(101, 1.0);
        let bump = |p0: f64, q0: f64| {
            let mut g = SlopeGrid::from_fn(d, |p, q| (-((p - p0).powi(2) + (q - q0).powi(2)) / 0.01).exp());
            g.normalise();
            g
        };
        let (a, b) = (bump(0.3, 0.0), bump(0.0, 0.4));
        let (pa, pb) = (peak(&a), peak(&b));
        let want = (1.0 / (1.09f64 * 1.16).sqrt()).acos().to_degrees();
        let brdf = Brdf::parse("beckmann:alpha=0.3").unwrap();
        let m = measure(&a, &b, &brdf, &[0.0], &Tolerances::default(), f64::INFINITY);
        // the cells' centres are the peaks to within half a cell (0.01 in slope)
        let exact = {
            let (na, nb) = (slope_to_normal(pa.0, pa.1), slope_to_normal(pb.0, pb.1));
            na.dot(&nb).clamp(-1.0, 1.0).acos().to_degrees()
        };
        assert!(
            (m.peak_offset_deg - exact).abs() < 1e-9,
            "{} vs {exact}",
            m.peak_offset_deg
        );
        assert!(
            (m.peak_offset_deg - want).abs() < 0.6,
            "{} vs {want}",
            m.peak_offset_deg
        );
    }

    /// The verdict's JS divergence against closed forms, in bits: 0 for one distribution, 1 for two with
    /// disjoint supports, and for all the mass in one cell against it shared evenly with a second cell
    /// `½·log₂(4/3) + ½·(½·log₂(2/3) + ½·log₂2) = 0.311278…`; symmetric, and blind to the grids' scale.
    #[test]
    fn jensen_shannon_bounds() {
        let d = SlopeDomain::square(32, 1.0);
        let brdf = Brdf::parse("beckmann:alpha=0.3").unwrap();
        let js =
            |a: &SlopeGrid, b: &SlopeGrid| measure(a, b, &brdf, &[0.0], &Tolerances::default(), f64::INFINITY).ndf_js;
        let mut left = SlopeGrid::from_fn(d, |p, _| if p < -0.2 { 1.0 } else { 0.0 });
        let mut right = SlopeGrid::from_fn(d, |p, _| if p > 0.2 { 3.0 } else { 0.0 });
        left.normalise();
        right.normalise();
        assert!(js(&left, &left).abs() < 1e-12);
        assert!(
            (js(&left, &right) - 1.0).abs() < 1e-12,
            "disjoint: {}",
            js(&left, &right)
        );
        let mut one = SlopeGrid::from_fn(d, |_, _| 0.0);
        let mut two = one.clone();
        one.density[100] = 7.0;
        two.density[100] = 1.0;
        two.density[101] = 1.0;
        let want = 0.5 * (4.0f64 / 3.0).log2() + 0.5 * (0.5 * (2.0f64 / 3.0).log2() + 0.5);
        assert!((js(&one, &two) - want).abs() < 1e-12, "{} vs {want}", js(&one, &two));
        assert!((js(&two, &one) - want).abs() < 1e-12, "symmetric");
    }
}
