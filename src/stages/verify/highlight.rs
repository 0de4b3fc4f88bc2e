//! A `highlight` target against the design and the milled surface: each distribution rendered in the image's
//! configuration ([`crate::stages::brdf::highlight`]) and correlated with the image, the verdict's check, and the
//! report's figure.

use super::metrics::{Check, SurfaceMetrics, Tolerances};
use super::report::Figure;
use super::HighlightMetrics;
use crate::base::slope::SlopeGrid;
use crate::stages::brdf::Highlight;

/// What [`compare`] found.
pub struct Compared {
    /// For `metrics.json`.
    pub metrics: HighlightMetrics,
    /// The image beside the milled surface's highlight.
    pub figure: Figure,
    /// What the user should know about the highlight's placement, if anything.
    pub note: Option<String>,
}

/// The check a highlight adds to a surface's verdict.
fn check(corr: f64, tol: &Tolerances) -> Check {
    Check {
        name: "highlight correlation".into(),
        value: corr,
        tolerance: format!("≥ {}", tol.highlight_corr_min),
        pass: corr >= tol.highlight_corr_min,
    }
}

/// Put the highlight check with correlation `corr` into a surface's verdict. A drawn highlight has no single
/// peak: its densest slope is wherever the image is brightest and the Jacobian largest (its rim), so the
/// peak check is replaced by the image's correlation.
fn add_check(m: &mut SurfaceMetrics, corr: f64, tol: &Tolerances) {
    for p in m.checks.iter_mut().filter(|p| p.name == super::metrics::PEAK_CHECK) {
        p.tolerance = "not checked: a drawn highlight has no single peak".into();
        p.pass = true;
    }
    m.checks.push(check(corr, tol));
    m.pass = m.checks.iter().all(|c| c.pass);
}

/// The check [`compare`] adds to the milled surface's verdict, alone: for a further cut of the same design
/// (a perfect machine's), whose target-side figures and figure `compare` already made.
pub fn check_cut(
    h: &Highlight,
    ndf: &crate::stages::ndf::Ndf,
    milled: &SlopeGrid,
    m: &mut SurfaceMetrics,
    tol: &Tolerances,
) {
    add_check(m, h.correlation(milled, (ndf.tilt.p, ndf.tilt.q)), tol);
}

/// Render the target's observed distribution (from `ndf`, with the tilt it removed), the NDF stage's
/// deconvolved target blurred again by the `base` lobe, `design` and `milled` in the image's configuration,
/// add the check to both surfaces' verdicts, and draw the figure.
#[allow(clippy::too_many_arguments)]
pub fn compare(
    h: &Highlight,
    ndf: &crate::stages::ndf::Ndf,
    base: Option<&crate::stages::ndf::Kernel>,
    design: &SlopeGrid,
    milled: &SlopeGrid,
    design_m: &mut SurfaceMetrics,
    milled_m: &mut SurfaceMetrics,
    tol: &Tolerances,
) -> Compared {
    let (tilt, observed) = (&ndf.tilt, &ndf.observed);
    let t = (tilt.p, tilt.q);
    let grid_corr = h.correlation(observed, t);
    // what any slopes drawn under the base lobe can show: the deconvolved target (the aim) blurred by it
    let lobe_corr = match base {
        Some(k) => {
            let mut blurred = k.convolve(&ndf.target);
            blurred.normalise();
            h.correlation(&blurred, t)
        }
        None => grid_corr,
    };
    let design_corr = h.correlation(design, t);
    let (rendered, w, hh) = h.render(milled, t);
    let (image, _, _) = h.compare_image();
    let milled_corr = crate::stages::brdf::highlight::pearson(image, &rendered);
    add_check(design_m, design_corr, tol);
    add_check(milled_m, milled_corr, tol);
    let canvas = h.figure(&rendered, "milled surface's highlight");
    let figure = Figure::new(
        "Highlight",
        format!(
            "Left, the highlight asked for ({}, {} × {} px, compared at {w} × {hh}); right, the light the simulated milled surface reflects in the same configuration: a collimated light along the normal and a screen parallel to the part, seen from above (image right = +x, up = +y), the ends of the image's longer axis at {}° of reflection. One linear colour scale, topped at the image's brightest pixel (brighter rendered pixels drawn at the top). Correlation {milled_corr:.3} (the design tile's {design_corr:.3}; the target blurred by the scallop and polish lobe, the most any slopes under that lobe could reach, {lobe_corr:.3}; the target as the NDF grid holds it, {grid_corr:.3}).",
            h.path.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default(),
            h.w,
            h.h,
            h.extent_deg
        ),
        &canvas,
    );
    Compared {
        metrics: HighlightMetrics {
            image: h.path.display().to_string(),
            size_px: [h.w, h.h],
            extent_deg: h.extent_deg,
            configuration: "collimated light along the normal; screen parallel to the part, seen from above (image right = +x, up = +y); X/L = tan θo cos φo".into(),
            compared_px: [w, hh],
            milled_corr,
            design_corr,
            lobe_corr,
            grid_corr,
        },
        figure,
        note: (tilt.deg > 0.05).then(|| {
            format!(
                "The highlight is drawn off-centre: its mean facet slope ({:.4}, {:.4}), a tilt of {:.2}°, cannot be made by a tileable surface, whose mean slope is zero, so the part is designed level and shows the highlight where it was drawn when it is mounted tilted by {:.2}° (it is compared so); mounted level, the highlight is centred.",
                tilt.p, tilt.q, tilt.deg, tilt.deg
            )
        }),
    }
}

/// Why the milled highlight falls short, from where along the chain the correlation is lost: the NDF grid,
/// the facets and the lobes they are blurred by, or the cut.
pub fn why(h: &HighlightMetrics, tol: &Tolerances) -> String {
    let head = format!(
        "The milled highlight correlates {:.3} with the image (at least {} asked).",
        h.milled_corr, tol.highlight_corr_min
    );
    let cause = if h.grid_corr < tol.highlight_corr_min {
        format!(
            "Already the target as the NDF grid holds it reaches only {:.3}: the grid's cells are coarse for this image (raise `ndf.res` or lower `ndf.max_angle_deg` towards the image's extent).",
            h.grid_corr
        )
    } else if h.lobe_corr < tol.highlight_corr_min {
        format!(
            "The target as the NDF grid holds it reaches {:.3}, but blurred by the scallop and polish lobe every slope carries it reaches only {:.3}, whatever the design (the NDF stage's deconvolved target blurred again): the image's edges are sharper than the lobe draws. A finer polish (the material's), a smaller `toolpath.scallop_um` or an image with softer edges would help; the design tile reaches {:.3}.",
            h.grid_corr, h.lobe_corr, h.design_corr
        )
    } else if h.design_corr < tol.highlight_corr_min {
        format!(
            "The design tile reaches {:.3} (the grid {:.3}): its facets, blurred by the scallop and polish lobe, cannot draw the image's edges; more facets, a smaller `toolpath.scallop_um` or an image with softer edges would help.",
            h.design_corr, h.grid_corr
        )
    } else {
        format!(
            "The design tile reaches {:.3}: the cut loses the rest (the bit's fillets and the deviation figure show where).",
            h.design_corr
        )
    };
    format!("{head} {cause}")
}
