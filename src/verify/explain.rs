//! Plain-word explanations of where the milled surface falls short and why, from the measured figures.
//!
//! Every failing check gets a line. Where a cause has been measured (a split of the simulated cut against
//! the design, cell by cell, on the default job: the excess slope variance sits in the concave corners the
//! ball cannot enter, not on convex edges), the line says so with this run's own numbers.

use super::metrics::{SurfaceMetrics, Tolerances};
use crate::simulate::Deviation;

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
    if milled.ndf_js > tol.ndf_js_max {
        notes.push(format!(
            "Milled NDF Jensen–Shannon divergence {:.4} bits is above {}.",
            milled.ndf_js, tol.ndf_js_max
        ));
    }
    let r = f.tool_radius_mm;
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
    if milled.peak_offset_deg > tol.peak_offset_deg_max {
        notes.push(format!(
            "The milled NDF's peak is {:.2}° from the target's (at most {}°): the relief tilts or a lobe is skewed.",
            milled.peak_offset_deg, tol.peak_offset_deg_max
        ));
    }
    for a in &milled.albedo {
        let rel = if a.target > 0.0 {
            a.surface / a.target - 1.0
        } else {
            0.0
        };
        if rel.abs() > tol.albedo_rel_max {
            notes.push(format!(
                "Directional albedo at θi = {}° is {:+.1}% off the target's ({:.3} against {:.3}; at most ±{}%): {}",
                a.theta_i_deg,
                rel * 100.0,
                a.surface,
                a.target,
                tol.albedo_rel_max * 100.0,
                if rel > 0.0 {
                    "the fabricated surface is a conductor mirror per facet, while the target loses energy (a diffuse or absorbing part, or masking the facets do not have)"
                } else {
                    "the fabricated surface sends light outside the hemisphere's measured part (steep slopes, masking)"
                }
            ));
        }
    }
    if f.deviation.unreachable_fraction > 0.001 {
        notes.push(format!(
            "{:.2}% of the surface is unreachable for the {} mm ball (concave corners narrower than the bit); there the milled slopes are the bit's, not the design's.",
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
