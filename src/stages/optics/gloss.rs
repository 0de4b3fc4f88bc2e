//! Appearance in the units a paint or metal-finishing lab reads off a glossmeter: specular gloss at 20°,
//! 60° and 85° (the ISO 2813 / ASTM D523 geometries), reflection haze and distinctness of image, computed
//! from a BRDF.
//!
//! **Specular gloss.** A glossmeter lights the sample at `θ` and collects the flux reflected into a receptor
//! aperture around the mirror direction; the reading is 100 × that flux over the flux a polished black glass
//! of refractive index 1.567 sends into the same aperture (the primary standard, 100 gloss units at every
//! angle). With a collimated beam of irradiance `E` on the sample, the flux into the aperture `A` is
//! `E ∫_A f(ωi, ωo) cosθo dωo`, and the glass, a mirror, sends all of `E·R(θ)` into it, `R` its unpolarised
//! Fresnel reflectance. So
//!
//! `G(θ) = 100 · ∫_A f cosθo dωo / R_glass(θ)`.
//!
//! The receptor apertures are D523's (angular width in the plane of incidence × perpendicular to it):
//! 1.8° × 3.6° at 20°, 4.4° × 11.7° at 60°, 4.0° × 6.0° at 85°. The source is taken as collimated: D523's
//! source aperture (0.75° in the plane) blurs the mirror image by less than the receptor's margin around it,
//! and a milled lobe is degrees wide. A mirror of reflectance `F` reads `100·F/R_glass`: metals read far
//! above 100 (aluminium about 1800 at 20°).
//!
//! **Haze and distinctness of image** (after ASTM E430's abridged goniophotometry, at 30°): `Rs` the flux into
//! a narrow receptor at the mirror direction, `R0.3` and `R2` into the same receptor 0.3° and 2.0° from it in
//! the plane of incidence (the two sides averaged). Distinctness of image `DOI = 100·(Rs − R0.3)/Rs` (100 for a
//! mirror, falling as the lobe widens past a few tenths of a degree); reflection haze `H = 100·R2/R_glass,s`,
//! the light scattered 2° off the mirror direction against the black glass's specular reflection into the
//! same receptor. The receptor here is 0.2° wide in the plane and 2.0° across it — the standard's own
//! aperture table was not at hand when this was written, so these are this module's choices, stated in
//! `metrics.json`; the ASTM D4039 haze index `G60 − G20`, which needs only D523's apertures, is given beside it.
//!
//! The integral runs over the aperture in two angles, `t` in the plane of incidence and `v` across it,
//! `ωo = (sin t cos v, sin v, cos t cos v)`, `dωo = cos v dt dv`, by the midpoint rule, in parallel. Where the
//! receptor holds the mirror direction the cells grow geometrically from it (1e-4° wide there, each 5% wider
//! than the one before: at most 5% of their distance from it), so a lobe as narrow as a polished mirror's and
//! one degrees wide are both resolved; a receptor off the mirror direction sees only tails, on cells of 0.005°
//! (at most 300 per axis).

use crate::base::geometry::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Refractive index of the black glass gloss standard (ISO 2813, ASTM D523), at the sodium D line.
pub const BLACK_GLASS_N: f64 = 1.567;

/// The cell of the aperture quadrature next to the mirror direction, degrees.
pub const FINEST_DEG: f64 = 1e-4;

/// Each cell of the quadrature is this much wider than the one nearer the mirror direction.
pub const GROWTH: f64 = 1.05;

/// The cell of a receptor that does not hold the mirror direction, degrees (at most [`MAX_CELLS`] per axis).
pub const STEP_DEG: f64 = 0.005;

/// The most cells per axis of a receptor that does not hold the mirror direction.
pub const MAX_CELLS: usize = 300;

/// A receptor aperture at angle `theta_deg` (incidence = mirror angle), centred `offset_deg` from the mirror
/// direction in the plane of incidence (towards grazing when positive).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Receptor {
    /// Angle of incidence (and of the mirror direction) from the normal, degrees.
    pub theta_deg: f64,
    /// Offset of the receptor's centre from the mirror direction, in the plane of incidence, degrees.
    pub offset_deg: f64,
    /// Angular width in the plane of incidence, degrees.
    pub width_deg: f64,
    /// Angular width perpendicular to the plane of incidence, degrees.
    pub height_deg: f64,
}

/// D523's gloss geometries: 20°, 60°, 85°.
pub const D523: [Receptor; 3] = [
    Receptor {
        theta_deg: 20.0,
        offset_deg: 0.0,
        width_deg: 1.8,
        height_deg: 3.6,
    },
    Receptor {
        theta_deg: 60.0,
        offset_deg: 0.0,
        width_deg: 4.4,
        height_deg: 11.7,
    },
    Receptor {
        theta_deg: 85.0,
        offset_deg: 0.0,
        width_deg: 4.0,
        height_deg: 6.0,
    },
];

/// The angle of the haze and DOI readings, degrees.
pub const HAZE_THETA_DEG: f64 = 30.0;
/// The narrow receptor of the haze and DOI readings: width in the plane, degrees.
pub const HAZE_WIDTH_DEG: f64 = 0.2;
/// The narrow receptor of the haze and DOI readings: width across the plane, degrees.
pub const HAZE_HEIGHT_DEG: f64 = 2.0;
/// The DOI receptor's offset from the mirror direction, degrees.
pub const DOI_OFFSET_DEG: f64 = 0.3;
/// The haze receptor's offset from the mirror direction, degrees.
pub const HAZE_OFFSET_DEG: f64 = 2.0;

/// A surface's appearance in a lab's units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Appearance {
    /// Specular gloss at 20°, 60°, 85°, gloss units (GU).
    pub gloss_gu: [f64; 3],
    /// Reflection haze at 30°, 2.0° off the mirror direction (module notes).
    pub haze: f64,
    /// Distinctness of image at 30°, 0–100 (floored at 0).
    pub doi: f64,
    /// ASTM D4039 haze index `G60 − G20`, gloss units.
    pub haze_index_gu: f64,
}

/// How [`appearance`]'s figures are defined, in a sentence (`metrics.json` carries it beside them).
pub const METHOD: &str = "specular gloss after ISO 2813 / ASTM D523 at 20°, 60°, 85° (receptors 1.8° × 3.6°, 4.4° × 11.7°, 4.0° × 6.0° in × across the plane of incidence; collimated source; polished black glass n = 1.567 = 100 GU); haze and distinctness of image after ASTM E430 at 30° (a 0.2° × 2.0° receptor 2.0° and 0.3° from the mirror direction against one on it: this tool's apertures, not the standard's table); haze index G60 − G20 after ASTM D4039. The milled surface's BRDF is read off its NDF grid (cells of 0.0135 in slope, 0.77° of facet tilt, 1.5° of reflection): its haze and DOI resolve lobes no narrower than a few degrees";

/// Unpolarised Fresnel reflectance of a dielectric of index `n` from air at `cos θ`: the conductor's
/// exact Fresnel term with no absorption (`κ = 0`).
pub fn dielectric_reflectance(n: f64, cos_theta: f64) -> f64 {
    crate::stages::brdf::fresnel::fresnel_conductor(cos_theta, n, 0.0)
}

/// `∫_A f(ωi, ωo) cosθo dωo` over the receptor, for the light incident at its angle in the x–z plane
/// (`ωi = (−sin θ, 0, cos θ)`, mirror direction `(sin θ, 0, cos θ)`); `f` is the luminance of the BRDF.
pub fn receptor_flux(f: &(dyn Fn(&Vec3, &Vec3) -> f64 + Sync), r: &Receptor) -> f64 {
    let th = r.theta_deg.to_radians();
    let wi = Vec3::new(-th.sin(), 0.0, th.cos());
    let ts = cells(r.offset_deg - r.width_deg / 2.0, r.offset_deg + r.width_deg / 2.0);
    let vs = cells(-r.height_deg / 2.0, r.height_deg / 2.0);
    let rows: Vec<f64> = vs
        .par_iter()
        .map(|&(v, dv)| {
            let (sv, cv) = v.sin_cos();
            ts.iter()
                .map(|&(t, dt)| {
                    let (st, ct) = (th + t).sin_cos();
                    let wo = Vec3::new(st * cv, sv, ct * cv);
                    if wo.z <= 0.0 {
                        return 0.0;
                    }
                    f(&wi, &wo) * wo.z * cv * dt * dv
                })
                .sum::<f64>()
        })
        .collect();
    // rows added in order: the same total every run
    rows.iter().sum()
}

/// Midpoints and widths (radians) of the quadrature's cells over `[lo, hi]` degrees from the mirror
/// direction: growing from it when it lies inside, uniform otherwise (module notes).
fn cells(lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    if lo < 0.0 && hi > 0.0 {
        for (end, sign) in [(hi, 1.0), (-lo, -1.0)] {
            let (mut x, mut h) = (0.0f64, FINEST_DEG);
            while x < end {
                let step = h.min(end - x);
                out.push(((sign * (x + step / 2.0)).to_radians(), step.to_radians()));
                x += step;
                h *= GROWTH;
            }
        }
    } else {
        let n = ((hi - lo) / STEP_DEG).ceil().clamp(1.0, MAX_CELLS as f64) as usize;
        let d = (hi - lo) / n as f64;
        out.extend((0..n).map(|k| ((lo + (k as f64 + 0.5) * d).to_radians(), d.to_radians())));
    }
    out
}

/// Specular gloss at the receptor's angle, gloss units.
pub fn gloss(f: &(dyn Fn(&Vec3, &Vec3) -> f64 + Sync), r: &Receptor) -> f64 {
    let glass = dielectric_reflectance(BLACK_GLASS_N, r.theta_deg.to_radians().cos());
    100.0 * receptor_flux(f, r) / glass
}

/// Gloss at 20°, 60°, 85°, haze, DOI and the D4039 haze index of a BRDF's luminance `f`.
pub fn appearance(f: &(dyn Fn(&Vec3, &Vec3) -> f64 + Sync)) -> Appearance {
    let gloss_gu = D523.map(|r| gloss(f, &r));
    let narrow = |offset_deg: f64| Receptor {
        theta_deg: HAZE_THETA_DEG,
        offset_deg,
        width_deg: HAZE_WIDTH_DEG,
        height_deg: HAZE_HEIGHT_DEG,
    };
    let rs = receptor_flux(f, &narrow(0.0));
    let side = |o: f64| 0.5 * (receptor_flux(f, &narrow(o)) + receptor_flux(f, &narrow(-o)));
    let (r03, r2) = (side(DOI_OFFSET_DEG), side(HAZE_OFFSET_DEG));
    let glass = dielectric_reflectance(BLACK_GLASS_N, HAZE_THETA_DEG.to_radians().cos());
    Appearance {
        gloss_gu,
        haze: 100.0 * r2 / glass,
        // a lobe flatter than 0.3° (or a measured one's noise) reads no distinctness, not a negative one
        doi: if rs > 0.0 {
            (100.0 * (rs - r03) / rs).max(0.0)
        } else {
            0.0
        },
        haze_index_gu: gloss_gu[1] - gloss_gu[0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::brdf::{luminance, Brdf, ConductorIor};

    fn lum(b: &Brdf) -> impl Fn(&Vec3, &Vec3) -> f64 + Sync + '_ {
        move |wi: &Vec3, wo: &Vec3| luminance(&b.eval(wi, wo))
    }

    /// Fresnel's closed form at normal incidence, ((n − 1)/(n + 1))², and at Brewster's angle, where the p
    /// wave vanishes and the unpolarised reflectance is half the s wave's, sin²(θi − θt)/sin²(θi + θt)/2.
    #[test]
    fn black_glass_reflects_as_fresnel_says() {
        let n = BLACK_GLASS_N;
        let r0 = ((n - 1.0) / (n + 1.0)).powi(2);
        assert!((dielectric_reflectance(n, 1.0) - r0).abs() < 1e-15);
        let tb = n.atan();
        let tt = (tb.sin() / n).asin();
        let want = 0.5 * ((tb - tt).sin() / (tb + tt).sin()).powi(2);
        assert!((dielectric_reflectance(n, tb.cos()) - want).abs() < 1e-12);
    }

    /// A near-mirror of the standard's own glass (η = 1.567, k = 0: the conductor Fresnel term reduces to
    /// the dielectric one) reads 100 GU at every angle, and an aluminium one 100·F(θ)/R_glass(θ): a Beckmann
    /// lobe of α = 0.0005 falls wholly inside every receptor. DOI 100, haze 0.
    #[test]
    fn a_mirror_reads_its_fresnel_ratio() {
        for (material, name) in [
            (ConductorIor::grey(BLACK_GLASS_N, 0.0), "glass"),
            (ConductorIor::preset("aluminium").unwrap(), "aluminium"),
        ] {
            let b = Brdf {
                material: Some(material),
                ..Brdf::parse("beckmann:alpha=0.0005").unwrap()
            };
            let a = appearance(&lum(&b));
            for (k, r) in D523.iter().enumerate() {
                let c = r.theta_deg.to_radians().cos();
                let want = 100.0 * luminance(&material.reflectance(c)) / dielectric_reflectance(BLACK_GLASS_N, c);
                assert!(
                    (a.gloss_gu[k] / want - 1.0).abs() < 2e-3,
                    "{name} at {}°: {} vs {want}",
                    r.theta_deg,
                    a.gloss_gu[k]
                );
            }
            println!("{name} mirror: {:?}", a);
            assert!(a.doi > 99.9 && a.haze < 1e-6, "{name}: DOI {} haze {}", a.doi, a.haze);
        }
    }

    /// A narrow Beckmann lobe of slope σ² = α²/2 per axis: a facet tilted by ε in the plane of incidence
    /// turns the reflection by 2ε, one tilted by δ across it by 2δ·cosθ, so the receptor of widths w × h
    /// collects the facets within ±w/4 and ±h/(4 cosθ), and for small α (facet tilt ≈ slope, masking ≈ 1,
    /// the projection factors ≈ 1) the gloss is `100·F(θ)·erf(w/(4α))·erf(h/(4α cosθ))/R_glass(θ)`.
    #[test]
    fn a_narrow_beckmann_lobe_reads_its_closed_form() {
        let b = Brdf::parse("beckmann:alpha=0.01").unwrap(); // F = 1
        for r in &D523 {
            let th = r.theta_deg.to_radians();
            let (a, c) = (
                (r.width_deg / 4.0).to_radians() / 0.01,
                (r.height_deg / 4.0).to_radians() / (0.01 * th.cos()),
            );
            let want = 100.0 * libm::erf(a) * libm::erf(c) / dielectric_reflectance(BLACK_GLASS_N, th.cos());
            let got = gloss(&lum(&b), r);
            println!(
                "Beckmann α 0.01 at {}°: {got:.3} GU, closed form {want:.3}",
                r.theta_deg
            );
            // the small-angle reading is good to O(α²) and the masking to 1 − O(α tan θ): 0.2% is ample
            assert!((got / want - 1.0).abs() < 2e-3, "{}°: {got} vs {want}", r.theta_deg);
        }
    }

    /// Haze and DOI of a Beckmann lobe of α = 0.02 at 30°, in the same small-angle reading: a receptor from
    /// `t1` to `t2` off the mirror direction in the plane collects the facets tilted `t1/2` to `t2/2`, a share
    /// `(erf(t2/2α) − erf(t1/2α))/2` of them, times `erf(h/(4α cosθ))` across the plane. So
    /// `DOI = 100·(1 − [erf((o + w/2)/2α) − erf((o − w/2)/2α)] / (2 erf(w/4α)))` at `o` = 0.3°, and the haze is
    /// `100·½[erf((2° + w/2)/2α) − erf((2° − w/2)/2α)]·erf(h/(4α cos 30°))/R_glass(30°)`.
    #[test]
    fn haze_and_doi_of_a_beckmann_lobe_read_their_closed_forms() {
        let alpha = 0.02;
        let b = Brdf::parse("beckmann:alpha=0.02").unwrap();
        let a = appearance(&lum(&b));
        let (w, h, th) = (
            HAZE_WIDTH_DEG.to_radians(),
            HAZE_HEIGHT_DEG.to_radians(),
            HAZE_THETA_DEG.to_radians(),
        );
        let band = |o: f64| 0.5 * (libm::erf((o + w / 2.0) / (2.0 * alpha)) - libm::erf((o - w / 2.0) / (2.0 * alpha)));
        let across = libm::erf(h / (4.0 * alpha * th.cos()));
        let doi = 100.0 * (1.0 - band(DOI_OFFSET_DEG.to_radians()) / band(0.0));
        let haze =
            100.0 * band(HAZE_OFFSET_DEG.to_radians()) * across / dielectric_reflectance(BLACK_GLASS_N, th.cos());
        println!(
            "Beckmann α 0.02: DOI {:.3} (closed form {doi:.3}), haze {:.3} ({haze:.3})",
            a.doi, a.haze
        );
        assert!((a.doi / doi - 1.0).abs() < 0.02, "DOI {} vs {doi}", a.doi);
        assert!((a.haze / haze - 1.0).abs() < 0.02, "haze {} vs {haze}", a.haze);
    }
}
