//! Plain-word explanations of where the milled surface falls short and why, from the measured figures.
//!
//! Every failing check gets a line. Where a cause has been measured (a split of the simulated cut against
//! the design, cell by cell, on the default job: the excess slope variance sits in the concave corners the
//! ball cannot enter, not on convex edges), the line says so with this run's own numbers.

use super::metrics::{SurfaceMetrics, Tolerances};
use crate::stages::simulate::Deviation;

/// What the explanations are drawn from.
pub struct Findings<'a> {
    /// The milled surface's figures.
    pub milled: &'a SurfaceMetrics,
    /// The design tile's figures.
    pub design: &'a SurfaceMetrics,
    /// The simulated cut against the design.
    pub deviation: &'a Deviation,
    /// The tolerances.
    pub tolerances: &'a Tolerances,
    /// Finishing tool radius, mm.
    pub tool_radius_mm: f64,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
    /// Fraction of the milled slopes outside the NDF grid.
    pub outside_grid: f64,
    /// Facets in the tile.
    pub facets: usize,
    /// The design loop's slope scales of the chosen tile (`[1, 1]`: uncorrected).
    pub scale: [f64; 2],
    /// How far the target's observed distribution stays above half its peak across the finishing passes
    /// (the mean of both sides), in slope units ([`half_max_extent`]).
    pub target_peak_halfwidth: f64,
    /// The same extent of the job's polish lobe alone (`target.polish`; 0 without one), slope units.
    pub polish_halfwidth: f64,
    /// The target's spec (`beckmann:alpha=0.2,…`): which model's normalisation an albedo note may blame.
    pub target_spec: &'a str,
}

/// How far from its peak a density stays above half the peak along the direction `(dp, dq)` (unit), the
/// mean of both sides, in slope units: walked in steps of a quarter cell on the bilinear density.
#[must_use]
pub fn half_max_extent(g: &crate::base::slope::SlopeGrid, (dp, dq): (f64, f64)) -> f64 {
    let d = &g.domain;
    let (p0, q0) = super::metrics::peak(g);
    let peak = g.sample(p0, q0);
    let step = 0.25 * d.dp().min(d.dq());
    let reach = (d.p_max - d.p_min).max(d.q_max - d.q_min);
    let side = |sign: f64| {
        let mut t = 0.0;
        while t < reach && g.sample(p0 + sign * t * dp, q0 + sign * t * dq) > 0.5 * peak {
            t += step;
        }
        t
    };
    0.5 * (side(1.0) + side(-1.0))
}

/// One line per shortfall, in the order of the checks.
#[must_use]
pub fn shortfall(f: &Findings) -> Vec<String> {
    let (milled, design, tol) = (f.milled, f.design, f.tolerances);
    let mut notes = vec![];
    let corrected = (f.scale[0] - 1.0).abs() > 1e-9 || (f.scale[1] - 1.0).abs() > 1e-9;
    if !design.pass && corrected {
        notes.push(format!(
            "The design tile alone (variance ratio {:.3}/{:.3}) is deliberately not the target: the design loop scaled its facet slopes by ×{:.3}/×{:.3} so that what the ball leaves of it matches; the milled figures are the ones that count.",
            design.cov_ratio[0], design.cov_ratio[1], f.scale[0], f.scale[1]
        ));
    } else if !design.pass {
        notes.push(format!(
            "The design tile itself misses (correlation {:.3}, variance ratio {:.3}/{:.3}): {} facets sample the NDF coarsely; more facets or a wider base lobe smooth it.",
            design.ndf_corr, design.cov_ratio[0], design.cov_ratio[1], f.facets
        ));
    }
    if milled.ndf_corr < tol.ndf_corr_min {
        notes.push(format!(
            "Milled NDF correlation {:.3} is {:.3} short of {}.",
            milled.ndf_corr,
            tol.ndf_corr_min - milled.ndf_corr,
            tol.ndf_corr_min
        ));
    }
    if milled.ndf_l1 > tol.ndf_l1_max {
        notes.push(format!(
            "Milled NDF relative L1 distance {:.3} is above {}.",
            milled.ndf_l1, tol.ndf_l1_max
        ));
    }
    // the scallops' lobe spans t_max = (s/2)/√(r² − s²/4) across the passes (DESIGN.md §2)
    let (r, s) = (f.tool_radius_mm, f.stepover_mm);
    let t_max = 0.5 * s / (r * r - 0.25 * s * s).max(1e-12).sqrt();
    let t_peak = f.target_peak_halfwidth;
    let t_polish = f.polish_halfwidth;
    let shape_short = milled.ndf_corr < tol.ndf_corr_min || milled.ndf_l1 > tol.ndf_l1_max;
    if shape_short && t_peak > 0.0 && t_polish >= t_peak {
        // the polish lobe alone is as wide as the target's peak: no scallop height can help, and the note
        // says so rather than suggest one
        notes.push(format!(
            "The target's peak is sharper than the job's polish lobe: across the passes the target stays above half its maximum within ±{:.1}°, the polish lobe alone (`target.polish`, the finish the cut leaves on each facet) within ±{:.1}°, so the milled lobe cannot be narrower than the polish whatever the scallop (now ±{:.1}°). The dominant cause is the polish: a finer one (a smaller α in `target.polish`, if the stock takes that finish) is the next step, not a smaller scallop.",
            t_peak.atan().to_degrees(),
            t_polish.atan().to_degrees(),
            t_max.atan().to_degrees()
        ));
    } else if shape_short && t_peak > 0.0 && t_max > t_peak {
        // the scallops' share of the peak's width: half-widths add about in quadrature with the polish's
        let t_scallop = (t_peak * t_peak - t_polish * t_polish).sqrt();
        // the scallop height whose lobe spans ±t_scallop: s/2 = r·t/√(1 + t²), h = r − √(r² − s²/4)
        let half_s = r * t_scallop / (1.0 + t_scallop * t_scallop).sqrt();
        let h_um = 1000.0 * (r - (r * r - half_s * half_s).sqrt());
        notes.push(format!(
            "The target's peak is sharper than the scallops' lobe: across the passes it stays above half its maximum within ±{:.1}°, while the scallops (stepover {:.1} µm) spread the milled slopes over ±{:.1}°{}; a scallop height of about {:.2} µm (`toolpath.scallop_um`) would narrow the lobe to the peak (estimated from the lobes' widths, not re-run).",
            t_peak.atan().to_degrees(),
            s * 1e3,
            t_max.atan().to_degrees(),
            if t_polish > 0.0 {
                format!(" and the polish lobe over ±{:.1}°", t_polish.atan().to_degrees())
            } else {
                String::new()
            },
            h_um
        ));
    }
    if milled.ndf_js > tol.ndf_js_max {
        notes.push(format!(
            "Milled NDF Jensen–Shannon divergence {:.4} bits is above {}.",
            milled.ndf_js, tol.ndf_js_max
        ));
    }
    for (k, axis) in ["x", "y"].iter().enumerate() {
        let c = milled.cov_ratio[k];
        if c < tol.cov_ratio[0] || c > tol.cov_ratio[1] {
            let d = design.cov_ratio[k];
            let why = if c > 1.0 {
                format!(
                    "wider than the target (the design tile alone: {d:.3}×): in the {:.1}% of the surface the {} mm ball cannot reach (concave corners, up to {:.1} µm of material left) the cut carries the ball's own spherical slopes instead of the facets', and the scallops (stepover {:.4} mm) add slope across the raster",
                    f.deviation.unreachable_fraction * 100.0,
                    2.0 * r,
                    f.deviation.max_over_um,
                    f.stepover_mm
                )
            } else {
                format!(
                    "narrower than the target (the design tile alone: {d:.3}×): steep facet slopes near valleys are cut shallower where the ball cannot reach, and facets beyond the slope cap were dropped"
                )
            };
            notes.push(format!("Slope variance along {axis} is {c:.3}× the target's, {why}."));
        }
    }
    let peak_checked = milled
        .checks
        .iter()
        .any(|c| c.name == super::metrics::PEAK_CHECK && !c.pass);
    if peak_checked && milled.peak_offset_deg > tol.peak_offset_deg_max {
        notes.push(format!(
            "The milled NDF's peak is {:.2}° from the target's (at most {}°): the relief tilts or a lobe is skewed.",
            milled.peak_offset_deg, tol.peak_offset_deg_max
        ));
    }
    for a in &milled.albedo {
        let rel = a.rel_error();
        if rel.abs() > tol.albedo_rel_max {
            notes.push(format!(
                "Directional albedo at θi = {}° is {:+.1}% off a perfect cut's ({:.3} against {:.3}; at most ±{}%): {}",
                a.theta_i_deg,
                rel * 100.0,
                a.surface,
                a.ideal.unwrap_or(a.target),
                tol.albedo_rel_max * 100.0,
                if rel > 0.0 {
                    "the milled slopes miss the target's steep tail (beyond the machinable cone, or cut off by the ball), whose facets would shadow and mask one another"
                } else {
                    "the milled surface has steeper slopes than the target's, which shadow and mask one another"
                }
            ));
        }
    }
    let beyond: Vec<String> = milled
        .albedo
        .iter()
        .filter_map(|a| {
            let ideal = a.ideal?;
            let rel = a.target / ideal - 1.0;
            (ideal > 0.0 && rel.abs() > tol.albedo_rel_max).then(|| {
                format!(
                    "{:.3} at θi = {}° against {:.3} ({:+.0}%)",
                    a.target,
                    a.theta_i_deg,
                    ideal,
                    rel * 100.0
                )
            })
        })
        .collect();
    if !beyond.is_empty() {
        notes.push(format!(
            "The target's own albedo is not what any surface of its material with its slopes reflects: {} for a perfect cut. No geometry can change that: {}. The albedo checks compare the milled surface with the perfect cut.",
            beyond.join(", "),
            target_albedo_cause(f.target_spec)
        ));
    }
    if f.deviation.unreachable_fraction > 0.001 {
        notes.push(format!(
            "{:.2}% of the surface is unreachable for a bit cutting {} mm across (concave corners narrower than the cut, runout included); there the milled slopes are the bit's, not the design's.",
            f.deviation.unreachable_fraction * 100.0,
            2.0 * r
        ));
    }
    if f.outside_grid > 1e-3 {
        notes.push(format!(
            "{:.2}% of the milled slopes fall outside the NDF grid (walls at facet steps).",
            f.outside_grid * 100.0
        ));
    }
    notes
}

/// Why a target's albedo differs from a perfect cut's, by its model: Ward's normalisation falls as cosθi;
/// a measured target carries its material's diffuse or absorbed part; an analytic microfacet model with
/// Smith masking differs from the facets' own masking at grazing angles.
fn target_albedo_cause(spec: &str) -> &'static str {
    let model = spec.split([':', ',']).next().unwrap_or("").trim();
    match model {
        "ward" => "Ward's normalisation makes its albedo fall as cosθi",
        "merl" | "rgl" => "the measured material reflects a diffuse part and absorbs some light, which facets of one metal do not",
        "beckmann" | "ggx" => "the model's Smith masking of an unbounded slope distribution differs from what facets cut within the machinable cone shadow and mask, most at grazing incidence",
        _ => "the target model's normalisation or a diffuse or absorbing part differs from a surface of facets",
    }
}

#[cfg(test)]
mod tests {
    use super::half_max_extent;

    /// Ward's normalisation is named only for a Ward target (it was blamed on vinyl and GGX targets).
    #[test]
    fn the_albedo_note_names_the_targets_own_model() {
        use super::target_albedo_cause as cause;
        assert!(cause("ward:ax=0.1,ay=0.3,material=aluminium").contains("Ward"));
        for other in [
            "ggx:alpha=0.8",
            "rgl:vinyl.bsdf",
            "merl:gold.binary",
            "beckmann:alpha=0.2",
            "phong:n=10",
        ] {
            assert!(!cause(other).contains("Ward"), "{other}: {}", cause(other));
        }
        assert!(cause("rgl:paper.bsdf").contains("diffuse"));
    }
    use crate::base::slope::{SlopeDomain, SlopeGrid};

    /// A Gaussian `exp(−t²/2σ²)` falls to half its peak at `σ√(2 ln 2)`, along each axis.
    #[test]
    fn half_max_extent_of_a_gaussian_is_its_half_width() {
        let (sx, sy) = (0.05f64, 0.12f64);
        let g = SlopeGrid::from_fn(SlopeDomain::square(256, 1.0), |p, q| {
            (-(p * p) / (2.0 * sx * sx) - (q * q) / (2.0 * sy * sy)).exp()
        });
        let k = (2.0 * 2f64.ln()).sqrt();
        let cell = 2.0 / 256.0;
        for (dir, want) in [((1.0, 0.0), sx * k), ((0.0, 1.0), sy * k)] {
            let got = half_max_extent(&g, dir);
            assert!((got - want).abs() < 0.5 * cell, "{dir:?}: {got} vs {want}");
        }
    }
}
