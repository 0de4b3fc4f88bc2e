//! Stage 2 — BRDF → target NDF (Section 7.1, DESIGN.md §2).
//!
//! 1. The BRDF's half-angle distribution on a slope grid ([`halfangle`]): the *observed* distribution `O`.
//! 2. Lucy–Richardson deconvolution of the base material's own lobe `K` (`deconvolve`): the facet
//!    distribution that, blurred by the material, shows `O`.
//! 3. The mean slope removed (Section 7.2: a tileable surface has zero mean slope), and reported.
//!
//! The result is an [`Ndf`], saved as `ndf.json` ([`format`](mod@format)) and drawn as a PNG.
//!
//! ```
//! use brdfmill::stages::{brdf::Brdf, ndf};
//! let cfg = ndf::NdfConfig { res: 64, ..Default::default() };
//! let out = ndf::run(&cfg, &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
//! let var = out.stats.cov[0][0];
//! assert!((var - 0.045).abs() < 0.002, "{var}");
//! ```

pub(crate) mod deconvolve;
pub mod format;
pub mod halfangle;
pub(crate) mod lobes;

pub use deconvolve::{LrReport, LucyRichardson, StoppedBy};
pub use format::NdfFile;
pub use halfangle::{HalfAngleConfig, Source};
pub use lobes::Kernel;

use crate::base::slope::{SlopeDomain, SlopeGrid, SlopeStats};
use crate::stages::brdf::{Brdf, ConductorIor};
use serde::{Deserialize, Serialize};

/// Errors of the NDF stage.
#[derive(Debug, thiserror::Error)]
pub enum NdfError {
    /// A configuration value is out of range.
    #[error("ndf config: `{field}` {reason}")]
    Config {
        /// The offending field.
        field: &'static str,
        /// What was expected.
        reason: String,
    },
    /// The BRDF gives no usable distribution on the grid.
    #[error("{what}: the half-angle distribution has no mass on the slope grid (|p|, |q| ≤ {max_slope:.3}); is the BRDF zero or all below the horizon?")]
    Empty {
        /// Which distribution.
        what: String,
        /// Half-width of the slope grid.
        max_slope: f64,
    },
}

/// Configuration of the NDF stage. Angles in degrees at this interface.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NdfConfig {
    /// Grid resolution per axis (cells).
    pub res: usize,
    /// Half-width of the slope grid as a polar angle in degrees: `|p|, |q| ≤ tan(max_angle_deg)`.
    pub max_angle_deg: f64,
    /// Lucy–Richardson iteration limit.
    pub iterations: usize,
    /// Stop earlier when an iteration changes the estimate by less than this (relative L1); 0 disables.
    pub tolerance: f64,
    /// How the half-angle distribution is read off the BRDF.
    pub half_angle: HalfAngleConfig,
}

impl Default for NdfConfig {
    fn default() -> Self {
        Self {
            res: 256,
            max_angle_deg: 60.0,
            iterations: 200,
            tolerance: 1e-5,
            half_angle: HalfAngleConfig::default(),
        }
    }
}

impl NdfConfig {
    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<(), NdfError> {
        let bad = |field, reason: &str| {
            Err(NdfError::Config {
                field,
                reason: reason.into(),
            })
        };
        if !(8..=4096).contains(&self.res) {
            return bad("res", &format!("must be in 8..=4096, got {}", self.res));
        }
        if !(self.max_angle_deg > 1.0 && self.max_angle_deg < 89.0) {
            return bad(
                "max_angle_deg",
                &format!("must be in (1, 89) degrees, got {}", self.max_angle_deg),
            );
        }
        if !(self.tolerance >= 0.0 && self.tolerance.is_finite()) {
            return bad(
                "tolerance",
                &format!("must be a finite number ≥ 0, got {}", self.tolerance),
            );
        }
        let td = self.half_angle.theta_d_deg;
        if !(0.0..45.0).contains(&td) {
            return bad(
                "half_angle.theta_d_deg",
                &format!("must be in [0, 45) degrees, got {td}"),
            );
        }
        if !(1..=4096).contains(&self.half_angle.phi_d_samples) {
            return bad("half_angle.phi_d_samples", "must be in 1..=4096");
        }
        if self.iterations > 100_000 {
            return bad(
                "iterations",
                &format!(
                    "must be at most 100000 (each is a pair of FFT convolutions), got {}",
                    self.iterations
                ),
            );
        }
        Ok(())
    }

    /// The slope domain of this configuration.
    pub fn domain(&self) -> SlopeDomain {
        SlopeDomain::square(self.res, self.max_angle_deg.to_radians().tan())
    }
}

/// The tilt removed from a distribution so that its mean slope is zero.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tilt {
    /// Mean x slope removed.
    pub p: f64,
    /// Mean y slope removed.
    pub q: f64,
    /// The same as the angle between the mean normal and z, in degrees.
    pub deg: f64,
}

/// The output of the NDF stage.
#[derive(Clone, Debug)]
pub struct Ndf {
    /// The target facet distribution `P22` (deconvolved, zero-mean, unit mass).
    pub target: SlopeGrid,
    /// The observed half-angle distribution `O` (tilt removed likewise, unit mass): the reference that
    /// verification compares fabricated surfaces with.
    pub observed: SlopeGrid,
    /// Statistics of `target`.
    pub stats: SlopeStats,
    /// Statistics of `observed`.
    pub observed_stats: SlopeStats,
    /// The tilt removed.
    pub tilt: Tilt,
    /// What the deconvolution did.
    pub deconvolution: LrReport,
    /// Where the half-angle distribution came from.
    pub source: Source,
    /// The spec of the target BRDF.
    pub brdf_spec: String,
    /// The spec of the base lobe, if any.
    pub base_spec: Option<String>,
    /// The fabrication material, when the spec named one.
    pub material: Option<ConductorIor>,
    /// The configuration used.
    pub config: NdfConfig,
    /// Fraction of the target's half-angle mass over the hemisphere that lies outside the slope grid, which
    /// the normalised distributions leave out ([`halfangle::mass_beyond_grid`]).
    pub mass_beyond_grid: f64,
}

/// The base lobe `K` as an odd-sized kernel on the grid spacing of `domain`, centred at slope 0 and cropped
/// to where it exceeds `1e-7` of its peak. Returns `(values, width, height)`.
pub fn base_kernel(base: &Brdf, domain: &SlopeDomain, cfg: &NdfConfig) -> Result<(Vec<f64>, usize, usize), NdfError> {
    let k = Kernel::from_brdf(base, domain, cfg)?;
    Ok((k.values, k.w, k.h))
}

fn remove_tilt(g: &SlopeGrid, p0: f64, q0: f64) -> SlopeGrid {
    if p0 == 0.0 && q0 == 0.0 {
        return g.clone();
    }
    let mut s = g.shifted(p0, q0);
    s.normalise();
    s
}

/// Run the NDF stage: the target BRDF's observed half-angle distribution, deconvolved by the base lobe's
/// (when `base` is given), with its mean tilt removed.
pub fn run(cfg: &NdfConfig, brdf: &Brdf, base: Option<&Brdf>) -> Result<Ndf, NdfError> {
    cfg.validate()?;
    let kernel = match base {
        Some(b) => Some(Kernel::from_brdf(b, &cfg.domain(), cfg)?),
        None => None,
    };
    run_with_kernel(cfg, brdf, kernel.as_ref())
}

/// [`run`] with the base lobe given as a kernel on the grid's spacing (see [`Kernel`]), e.g. the scallop
/// lobe of a raster finish.
pub fn run_with_kernel(cfg: &NdfConfig, brdf: &Brdf, base: Option<&Kernel>) -> Result<Ndf, NdfError> {
    cfg.validate()?;
    let domain = cfg.domain();
    let (observed, source) = halfangle::half_angle_density(brdf, domain, &cfg.half_angle);
    if observed.mass().is_nan() || observed.mass() <= 0.0 {
        return Err(NdfError::Empty {
            what: format!("BRDF `{}`", brdf.spec),
            max_slope: domain.p_max,
        });
    }
    let mass_beyond_grid = halfangle::mass_beyond_grid(brdf, domain, &cfg.half_angle);
    let mut target = observed.clone();
    let deconvolution = match base {
        None => LrReport::none(),
        Some(k) => {
            let mut lr = LucyRichardson::new(domain.nx, domain.ny, &k.values, k.w, k.h);
            lr.run(&observed.density, &mut target.density, cfg.iterations, cfg.tolerance)
        }
    };
    target.normalise();
    let m = target.stats().mean;
    let tilt = Tilt {
        p: m[0],
        q: m[1],
        deg: (m[0] * m[0] + m[1] * m[1]).sqrt().atan().to_degrees(),
    };
    // Shift both distributions by the same slope so they stay comparable.
    let target = remove_tilt(&target, m[0], m[1]);
    let observed = remove_tilt(&observed, m[0], m[1]);
    Ok(Ndf {
        stats: target.stats(),
        observed_stats: observed.stats(),
        target,
        observed,
        tilt,
        deconvolution,
        source,
        brdf_spec: brdf.spec.clone(),
        base_spec: base.map(|k| k.label.clone()),
        material: brdf.material,
        config: *cfg,
        mass_beyond_grid,
    })
}

/// Above this fraction of the target's mass beyond the slope grid, the run says so.
pub const GRID_ESCAPE_WARNING: f64 = 0.01;

/// A warning when more than [`GRID_ESCAPE_WARNING`] of the target's half-angle mass lies beyond the slope
/// grid: both the design and the verdict see only the part on the grid, renormalised.
pub fn grid_warning(n: &Ndf) -> Option<String> {
    (n.mass_beyond_grid > GRID_ESCAPE_WARNING).then(|| {
        format!(
            "{:.1}% of the target's half-angle mass lies beyond the NDF grid (|p|, |q| ≤ {:.3}, `ndf.max_angle_deg` = {}°): the design and the verdict see only the rest, renormalised, so the target is wider than anything designed or measured here",
            n.mass_beyond_grid * 100.0,
            n.config.domain().p_max,
            n.config.max_angle_deg
        )
    })
}

/// The stage's figure: the observed half-angle distribution and the deconvolved target side by side.
pub fn render_pair_png(n: &Ndf) -> crate::base::plot::Canvas {
    crate::base::plot::Canvas::hstack(&[
        render_png(&n.observed, "observed half-angle distribution O"),
        render_png(&n.target, "target NDF (deconvolved)"),
    ])
}

/// Draw a slope density as a false-colour PNG figure (log scale over 4 decades, axes in slope units).
pub fn render_png(grid: &SlopeGrid, title: &str) -> crate::base::plot::Canvas {
    let d = &grid.domain;
    crate::base::plot::Heatmap {
        values: &grid.density,
        nx: d.nx,
        ny: d.ny,
        x_range: (d.p_min, d.p_max),
        y_range: (d.q_min, d.q_max),
        title: title.to_string(),
        x_label: "p = dz/dx (slope)".into(),
        y_label: "q = dz/dy".into(),
        value_label: "P22 (log)".into(),
        scale: crate::base::plot::Scale::Log { decades: 4.0 },
        value_max: None,
        value_min: None,
        plot_px: 384,
        rgb: None,
    }
    .render()
}
