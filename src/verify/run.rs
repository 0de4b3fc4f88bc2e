//! The verification stage's entry point: the target against the design tile and the simulated milled
//! surface, the wave optics of a milled patch, the diffraction check, and the figures of the report.
//!
//! `job` calls [`run`] with the products of the stages before it; everything verification decides (which
//! lobes are applied to what, the metrics and their verdict, the explanations, the optical constants of the
//! wave check) lives here, so the job runner only sequences stages and writes files.

use super::report::Figure;
use super::{explain, metrics, render, Metrics, Tolerances};
use crate::brdf::Brdf;
use crate::facets::Tile;
use crate::geometry::Vec3;
use crate::ndf::{self, Kernel, Ndf, NdfConfig};
use crate::optics::{geometric, wave};
use crate::plot::Canvas;
use crate::simulate::{Deviation, Simulation};
use crate::slope::{SlopeDomain, SlopeGrid};
use serde::{Deserialize, Serialize};

/// `[verify]` of a job: what is measured and the optics of the wave check. Angles in degrees, lengths in
/// the unit their name gives.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VerifyConfig {
    /// Incident angles of the BRDF slices and albedos, degrees, each in [0, 90).
    pub incident_deg: Vec<f64>,
    /// Gaussian pre-filter of the milled heights before their slopes are taken, σ in µm (0: none).
    pub prefilter_um: f64,
    /// Wavelength of the wave-optics check, µm.
    pub wavelength_um: f64,
    /// Standard deviation σ of the Gaussian coherence area of the wave-optics check, µm.
    pub coherence_sigma_um: f64,
    /// Side of the square patch of the milled surface the wave optics evaluate, mm.
    pub wave_patch_mm: f64,
    /// Tolerances of the verdict.
    pub tolerances: Tolerances,
}

impl Default for VerifyConfig {
    fn default() -> Self {
        Self {
            incident_deg: vec![0.0, 30.0, 60.0],
            prefilter_um: 0.0,
            wavelength_um: 0.55,
            coherence_sigma_um: 10.0,
            wave_patch_mm: 0.4,
            tolerances: Tolerances::default(),
        }
    }
}

impl VerifyConfig {
    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<(), VerifyError> {
        let bad = |field: &'static str, message: String| Err(VerifyError::Config { field, message });
        if self.incident_deg.is_empty() || self.incident_deg.iter().any(|t| !(0.0..90.0).contains(t)) {
            return bad("incident_deg", "must list angles in [0, 90)".into());
        }
        if !(self.prefilter_um.is_finite() && self.prefilter_um >= 0.0) {
            return bad("prefilter_um", format!("must be ≥ 0, got {}", self.prefilter_um));
        }
        for (field, v, lo, hi) in [
            ("wavelength_um", self.wavelength_um, 0.1, 20.0),
            ("coherence_sigma_um", self.coherence_sigma_um, 0.5, 200.0),
            ("wave_patch_mm", self.wave_patch_mm, 0.01, 5.0),
        ] {
            if !(v >= lo && v <= hi) {
                return bad(field, format!("must be in [{lo}, {hi}], got {v}"));
            }
        }
        self.tolerances.validate().map_err(|e| VerifyError::Config {
            field: "tolerances",
            message: e.to_string(),
        })
    }
}

/// Verification could not be done.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    /// A `[verify]` setting is out of range.
    #[error("`verify.{field}` {message}")]
    Config {
        /// The field.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A lobe could not be tabulated.
    #[error(transparent)]
    Ndf(#[from] ndf::NdfError),
    /// The wave optics failed.
    #[error(transparent)]
    Wave(#[from] wave::WaveError),
    /// The milled surface is too small to evaluate.
    #[error("the milled surface is too small for a {side_mm} mm wave-optics patch inside its {margin}-cell edge band")]
    TooSmall {
        /// The patch side asked for, mm.
        side_mm: f64,
        /// The edge band, cells.
        margin: usize,
    },
}

/// What verification compares: the products of the stages before it.
pub struct VerifyInput<'a> {
    /// The target BRDF.
    pub target: &'a Brdf,
    /// The NDF stage's result (its observed distribution is the reference).
    pub ndf: &'a Ndf,
    /// The NDF stage's settings (the grid the lobes are tabulated on).
    pub ndf_config: &'a NdfConfig,
    /// The base lobe the NDF stage deconvolved, if any (the design tile is convolved with it).
    pub base: Option<&'a Kernel>,
    /// The material's polish lobe, applied to the milled surface when the base lobe is the scallop lobe
    /// (the simulation models the scallops but not the polish).
    pub polish: Option<&'a Brdf>,
    /// The base lobe is the finishing raster's scallop lobe.
    pub base_is_scallop: bool,
    /// The design tile.
    pub tile: &'a Tile,
    /// The simulated cut.
    pub sim: &'a Simulation,
    /// Its deviation from the design.
    pub deviation: &'a Deviation,
    /// Finishing tool radius, mm.
    pub tool_radius_mm: f64,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
}

/// What verification produced.
pub struct VerifyOutput {
    /// `metrics.json`.
    pub metrics: Metrics,
    /// The design tile's NDF (⊛ the base lobe).
    pub design: SlopeGrid,
    /// The milled surface's NDF (⊛ the polish lobe).
    pub milled: SlopeGrid,
    /// `wave.png`: the wave and geometric BRDF of a milled patch.
    pub wave_png: Canvas,
    /// The report's figures of this stage, in order (NDFs, BRDF slices, rendered preview, wave optics).
    pub figures: Vec<Figure>,
}

/// Verify: measure the design tile and the milled surface against the target's observed distribution,
/// explain any shortfall, check the wave optics of a milled patch, and draw the figures.
pub fn run(cfg: &VerifyConfig, input: &VerifyInput) -> Result<VerifyOutput, VerifyError> {
    cfg.validate()?;
    let n = input.ndf;
    let domain = n.config.domain();
    let tol = cfg.tolerances;
    let facet_slopes: Vec<(f64, f64)> = input
        .tile
        .arrangement
        .p
        .iter()
        .copied()
        .zip(input.tile.arrangement.q.iter().copied())
        .collect();
    let (design_raw, _) = geometric::ndf_of_slopes(&facet_slopes, domain);
    let design = match input.base {
        Some(k) => normalised(k.convolve(&design_raw)),
        None => design_raw,
    };
    // The milled surface away from the stock's edge: the outer r is only grazed by the bit, and the next r is
    // cut by ball positions on one side only (the tool centre stays inside the area).
    let margin = milled_margin(input);
    let (milled_raw, outside) = geometric::ndf(&input.sim.heightfield, domain, cfg.prefilter_um, margin);
    let polish_kernel = match input.polish {
        Some(p) if input.base_is_scallop => Some(Kernel::from_brdf(p, &domain, input.ndf_config)?),
        _ => None,
    };
    let milled = match &polish_kernel {
        Some(k) => normalised(k.convolve(&milled_raw)),
        None => milled_raw,
    };
    let design_m = metrics::measure(&n.observed, &design, input.target, &cfg.incident_deg, &tol);
    let milled_m = metrics::measure(&n.observed, &milled, input.target, &cfg.incident_deg, &tol);
    let facets = input.tile.config.facets_x * input.tile.config.facets_y;
    let mut notes = explain::shortfall(&explain::Findings {
        milled: &milled_m,
        design: &design_m,
        deviation: input.deviation,
        tolerances: &tol,
        tool_radius_mm: input.tool_radius_mm,
        stepover_mm: input.stepover_mm,
        outside_grid: outside,
        facets,
    });
    if input.tile.sampling.steep_mass > 1e-4 {
        notes.push(format!(
            "{:.2}% of the target NDF's mass lies beyond the machinable limit of {}° and was dropped from the facets.",
            input.tile.sampling.steep_mass * 100.0,
            input.tile.config.max_slope_deg
        ));
    }
    let (wave_png, wave_albedo) = wave_patch(cfg, input, margin)?;
    let o_std = n.observed_stats.cov[0][0].max(n.observed_stats.cov[1][1]).sqrt();
    let diffraction = wave::diffraction_warning(
        input.stepover_mm,
        cfg.wavelength_um,
        (2.0 * o_std).atan(),
        cfg.coherence_sigma_um,
    );
    if let Some(w) = &diffraction {
        notes.push(format!("Diffraction: {w}"));
    }
    let reference = format!(
        "the observed half-angle distribution O of `{}`; the design is convolved with the base lobe `{}`, the milled surface with {}",
        n.brdf_spec,
        n.base_spec.as_deref().unwrap_or("none"),
        polish_kernel
            .as_ref()
            .map(|k| format!("the polish lobe `{}`", k.label))
            .unwrap_or_else(|| "nothing (the simulation models the whole base lobe)".into())
    );
    let metrics = Metrics {
        version: 1,
        pass: milled_m.pass,
        design: design_m,
        milled: milled_m,
        tolerances: tol,
        reference,
        notes,
        diffraction,
    };
    let figures = figures(
        cfg,
        input,
        &design,
        &milled,
        &wave_png,
        wave_albedo,
        metrics.diffraction.is_some(),
    );
    Ok(VerifyOutput {
        metrics,
        design,
        milled,
        wave_png,
        figures,
    })
}

/// The band of the simulated stock left out of the milled NDF, cells: one tool radius grazed, one cut from
/// one side only, and a design sample either side.
fn milled_margin(input: &VerifyInput) -> usize {
    let r = input.tool_radius_mm;
    ((2.0 * r + 2.0 * input.tile.heightfield.pitch_mm) / input.sim.heightfield.pitch_mm).ceil() as usize
}

/// The report's figures of the verification stage.
fn figures(
    cfg: &VerifyConfig,
    input: &VerifyInput,
    design: &SlopeGrid,
    milled: &SlopeGrid,
    wave_png: &Canvas,
    wave_albedo: f64,
    diffracts: bool,
) -> Vec<Figure> {
    let material = input.target.material;
    let ndf_row = Canvas::hstack(&[
        ndf::render_png(&input.ndf.observed, "target: observed O"),
        ndf::render_png(design, "design tile * base lobe"),
        ndf::render_png(milled, "milled (simulated)"),
    ]);
    let design_brdf = geometric::MicrofacetBrdf::new(design.clone(), material);
    let milled_brdf = geometric::MicrofacetBrdf::new(milled.clone(), material);
    let tf = |a: &Vec3, b: &Vec3| input.target.eval(a, b);
    let df = |a: &Vec3, b: &Vec3| design_brdf.eval(a, b);
    let mf = |a: &Vec3, b: &Vec3| milled_brdf.eval(a, b);
    let items: [(&str, render::BrdfFn); 3] = [("target", &tf), ("design tile", &df), ("milled", &mf)];
    let slices = render::slices(&items, &cfg.incident_deg);
    let spheres = render::sphere_row(&items, 260, 1.0);
    vec![
        Figure {
            title: "NDFs".into(),
            caption: "Slope densities P22 (log scale over four decades) on the target's grid: the target's observed distribution, the design tile's facets convolved with the base lobe, and the simulated milled surface.".into(),
            png: ndf_row.to_png(),
        },
        Figure {
            title: "BRDF slices".into(),
            caption: "f·cosθo (luminance) in the plane of incidence for each incident angle.".into(),
            png: slices.to_png(),
        },
        Figure {
            title: "Rendered preview".into(),
            caption: "Spheres of the target material and of the fabricated surfaces' microfacet BRDFs under the same two lights (orthographic view, raster direction horizontal).".into(),
            png: spheres.to_png(),
        },
        Figure {
            title: "Wave optics of the milled surface".into(),
            caption: format!(
                "Kirchhoff BRDF (FFT, λ = {} µm, Gaussian coherence σ = {} µm, 3×3 windows) of a {} mm patch of the simulated surface at normal incidence, beside the geometric microfacet BRDF of the same patch. Wave albedo {wave_albedo:.3}. Scallop stepover {:.1} µm: {}",
                cfg.wavelength_um,
                cfg.coherence_sigma_um,
                cfg.wave_patch_mm,
                input.stepover_mm * 1000.0,
                if diffracts { "its diffraction orders fall inside the lobe (see Why)." } else { "no resolved diffraction orders inside the lobe." }
            ),
            png: wave_png.to_png(),
        },
    ]
}

/// The wave and geometric BRDFs of a square patch at the centre of the milled surface's interior; returns
/// the figure and the wave albedo.
fn wave_patch(cfg: &VerifyConfig, input: &VerifyInput, margin: usize) -> Result<(Canvas, f64), VerifyError> {
    let hf = &input.sim.heightfield;
    let p = hf.pitch_mm;
    let side = ((cfg.wave_patch_mm / p).round() as usize)
        .min(hf.nx.saturating_sub(2 * margin))
        .min(hf.ny.saturating_sub(2 * margin));
    if side < 16 {
        return Err(VerifyError::TooSmall {
            side_mm: cfg.wave_patch_mm,
            margin,
        });
    }
    let (i0, j0) = ((hf.nx - side) / 2, (hf.ny - side) / 2);
    let mut patch = crate::heightfield::Heightfield::flat(side, side, p, false, 0.0);
    for j in 0..side {
        for i in 0..side {
            patch.z_mm[j * side + i] = hf.at(i0 + i, j0 + j);
        }
    }
    let material = input.target.material;
    let max_slope = input.tile.config.max_slope_deg.to_radians().tan();
    let (geo_ndf, _) = geometric::ndf(&patch, SlopeDomain::square(129, 1.2 * max_slope), 0.0, 1);
    let geo = geometric::MicrofacetBrdf::new(geo_ndf, material);
    let surf = wave::OpticalSurface::new(&patch)?;
    let wcfg = wave::WaveConfig {
        wavelength_um: cfg.wavelength_um,
        sigma_um: cfg.coherence_sigma_um,
        material,
        ..Default::default()
    };
    let wi = Vec3::z();
    let slice = wave::fft_slice(&surf, &wi, &wcfg)?;
    Ok((
        crate::analyze::wave_vs_geometric_png(&slice, &geo, &wi, max_slope),
        slice.albedo(),
    ))
}

fn normalised(mut g: SlopeGrid) -> SlopeGrid {
    g.normalise();
    g
}
