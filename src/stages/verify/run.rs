//! The verification stage's entry point: the target against the design tile and the simulated milled
//! surface, the wave optics of a milled patch, the diffraction check, and the figures of the report.
//!
//! `job` calls [`run`] with the products of the stages before it; everything verification decides (which
//! lobes are applied to what, the metrics and their verdict, the explanations, the optical constants of the
//! wave check) lives here, so the job runner only sequences stages and writes files.

use super::metrics::SurfaceMetrics;
use super::milled::{self, Measurement};
use super::report::Figure;
use super::{explain, highlight, metrics, render, Metrics, Tolerances};
use crate::base::geometry::Vec3;
use crate::base::plot::Canvas;
use crate::base::slope::{SlopeDomain, SlopeGrid};
use crate::base::surface;
use crate::stages::brdf::Brdf;
use crate::stages::facets::Tile;
use crate::stages::ndf::{self, Kernel, Ndf, NdfConfig};
use crate::stages::optics::{geometric, wave};
use crate::stages::simulate::{Deviation, Simulation};
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
    /// A region of a spatially varying target cannot be measured.
    #[error("{0}")]
    Region(String),
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
    /// The simulated cut on the declared machine (the verdict's).
    pub sim: &'a Simulation,
    /// The same program cut by a perfect machine, and its tool without runout (`metrics.json`
    /// `milled_ideal`, measured with that tool's scallop lobe); None: the machine declares no error, so `sim`
    /// is that cut.
    pub ideal: Option<(&'a Simulation, crate::cut::tool::Shape)>,
    /// Its deviation from the design.
    pub deviation: &'a Deviation,
    /// The finishing tool as the machine cuts with it (its runout envelope, [`crate::cut::accuracy`]).
    pub tool: crate::cut::tool::Shape,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
    /// Angle of the finishing passes from x, degrees.
    pub raster_angle_deg: f64,
    /// The machinable cone: the steepest facet the design allows, degrees (slope variances are compared
    /// within it).
    pub cone_deg: f64,
    /// The design loop's rounds, for `metrics.json` and the convergence figure.
    pub rounds: &'a [crate::stages::design::Round],
    /// The candidate arrangements' first rounds.
    pub arrangements: &'a [crate::stages::design::Round],
}

/// What verification produced.
pub struct VerifyOutput {
    /// `metrics.json`.
    pub metrics: Metrics,
    /// The design tile's NDF (⊛ the base lobe).
    pub design: SlopeGrid,
    /// The milled surface's NDF (⊛ the polish lobe).
    pub milled: SlopeGrid,
    /// The fraction of the design tile's facet slopes beyond the NDF grid (the milled surface's is
    /// `metrics.measurement.outside_grid`).
    pub design_outside_grid: f64,
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
    let (design, design_outside) = crate::stages::design::design_ndf(input.tile, input.base, domain);
    let (milled, outside, measurement) = milled_ndf(cfg, input)?;
    let cone_tan = input.cone_deg.to_radians().tan();
    let mut design_m = metrics::measure(&n.observed, &design, input.target, &cfg.incident_deg, &tol, cone_tan);
    let mut milled_m = metrics::measure(&n.observed, &milled, input.target, &cfg.incident_deg, &tol, cone_tan);
    let highlight = input
        .target
        .highlight()
        .map(|h| highlight::compare(h, n, input.base, &design, &milled, &mut design_m, &mut milled_m, &tol));
    let milled_ideal = match input.ideal {
        Some((sim, tool)) => {
            let ideal = VerifyInput {
                sim,
                tool,
                base_is_scallop: false,
                ..*input
            };
            measure_cut(cfg, &ideal)?
        }
        None => milled_m.clone(),
    };
    let facets = input.tile.config.facets_x * input.tile.config.facets_y;
    // across the finishing passes, where the scallops spread the slopes
    let across = {
        let a = (input.raster_angle_deg + 90.0).to_radians();
        (a.cos(), a.sin())
    };
    let mut notes = explain::shortfall(&explain::Findings {
        milled: &milled_m,
        design: &design_m,
        deviation: input.deviation,
        tolerances: &tol,
        tool_radius_mm: input.tool.radius_mm(),
        stepover_mm: input.stepover_mm,
        outside_grid: outside,
        facets,
        scale: input
            .rounds
            .iter()
            .min_by(|a, b| a.score.total_cmp(&b.score))
            .map(|r| r.scale)
            .unwrap_or([1.0, 1.0]),
        // a drawn highlight has no single peak to compare the scallops' lobe with (its check is the image's)
        target_peak_halfwidth: if highlight.is_some() {
            0.0
        } else {
            explain::half_max_extent(&n.observed, across)
        },
        polish_halfwidth: input.polish.map_or(0.0, |b| {
            let (lobe, _) =
                crate::stages::ndf::halfangle::half_angle_density(b, n.observed.domain, &input.ndf_config.half_angle);
            explain::half_max_extent(&lobe, across)
        }),
        target_spec: &input.target.spec,
    });
    if let Some(h) = highlight
        .as_ref()
        .map(|h| &h.metrics)
        .filter(|h| h.milled_corr < tol.highlight_corr_min)
    {
        notes.push(highlight::why(h, &tol));
    }
    if let Some(note) = highlight.as_ref().and_then(|h| h.note.clone()) {
        notes.push(note);
    }
    notes.extend(machine_note(input.sim, &milled_m, &milled_ideal));
    if let Some(w) = crate::stages::ndf::grid_warning(input.ndf) {
        notes.push(format!("{w}."));
    }
    if let Some(note) = beyond_cone_note(input, &measurement) {
        notes.push(note);
    }
    if !measurement.window.whole() {
        notes.push(format!(
            "The milled NDF is measured over the whole interior ({:.2} × {:.2} mm), which is not a whole number of tiles: the work area needs to be at least a tile ({} × {} mm) plus {:.2} mm on each side for the window to hold whole tiles, so the facets inside it are not weighted equally.",
            measurement.window.size_mm[0],
            measurement.window.size_mm[1],
            input.tile.config.facets_x as f64 * input.tile.config.facet_mm,
            input.tile.config.facets_y as f64 * input.tile.config.facet_mm,
            measurement.margin_mm
        ));
    }
    let (wave_png, wave_albedo) = wave_patch(cfg, input, measurement.margin_cells)?;
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
        "the observed half-angle distribution O of `{}`; the design is convolved with the base lobe `{}`, the milled surface (slopes averaged over one stepover across the passes) with the scallop lobe `{}`",
        n.brdf_spec,
        n.base_spec.as_deref().unwrap_or("none"),
        measurement.scallops
    );
    // the milled surface's geometric BRDF (its Smith table an integral over the grid), for the glossmeter's
    // figures and the report's, built once
    let milled_brdf = geometric::MicrofacetBrdf::new(milled.clone(), input.target.material);
    let metrics = Metrics {
        version: 1,
        pass: milled_m.pass,
        design: design_m,
        milled: milled_m,
        milled_ideal: Some(milled_ideal),
        accuracy: input.sim.stats.accuracy,
        machine_effects: vec![],
        tolerances: tol,
        reference,
        notes,
        diffraction,
        measurement: Some(measurement),
        rounds: input.rounds.to_vec(),
        arrangements: input.arrangements.to_vec(),
        highlight_corr: highlight.as_ref().map(|h| h.metrics.milled_corr),
        highlight: highlight.as_ref().map(|h| h.metrics.clone()),
        appearance: Some(appearance(input.target, &milled_brdf)),
    };
    let mut figures = figures(
        cfg,
        input,
        &design,
        &milled_brdf,
        &wave_png,
        wave_albedo,
        metrics.diffraction.is_some(),
    );
    if let Some(h) = highlight {
        figures.insert(0, h.figure);
    }
    if !input.rounds.is_empty() {
        figures.insert(0, convergence(input.rounds, input.arrangements, &metrics, &tol));
    }
    Ok(VerifyOutput {
        metrics,
        design,
        milled,
        design_outside_grid: design_outside,
        wave_png,
        figures,
    })
}

/// The figures of the cut `input.sim` against the target, as the verdict measures the milled surface (the
/// highlight's correlation included for a drawn target).
pub fn measure_cut(cfg: &VerifyConfig, input: &VerifyInput) -> Result<SurfaceMetrics, VerifyError> {
    let n = input.ndf;
    let tol = cfg.tolerances;
    let (milled, _, _) = milled_ndf(cfg, input)?;
    let cone_tan = input.cone_deg.to_radians().tan();
    let mut m = metrics::measure(&n.observed, &milled, input.target, &cfg.incident_deg, &tol, cone_tan);
    if let Some(h) = input.target.highlight() {
        highlight::check_cut(h, n, &milled, &mut m, &tol);
    }
    Ok(m)
}

/// The shape of a cut's milled NDF against the target (L1, correlation, variance ratios: the figures
/// [`measure_cut`] gives, without the albedo integrals and checks it adds), for the cuts that only show
/// what each machine error moves.
pub fn measure_shape(cfg: &VerifyConfig, input: &VerifyInput) -> Result<metrics::NdfShape, VerifyError> {
    let (milled, _, _) = milled_ndf(cfg, input)?;
    Ok(metrics::ndf_shape(
        &input.ndf.observed,
        &milled,
        input.cone_deg.to_radians().tan(),
    ))
}

/// What the machine's errors did to the milled figures (none when it declares none).
fn machine_note(sim: &Simulation, milled: &SurfaceMetrics, ideal: &SurfaceMetrics) -> Option<String> {
    let acc = sim.stats.accuracy?;
    let mut s = format!(
        "The milled figures are the cut on the declared machine ({}): slope variance ratios x {:.3}, y {:.3}, \
         NDF L1 {:.3}, correlation {:.3}; a perfect machine would leave x {:.3}, y {:.3}, L1 {:.3}, correlation \
         {:.3} (`milled_ideal`). The design loop designs for the runout's envelope, so it corrects the runout; \
         backlash and the step grid it cannot correct (one-way finishing keeps backlash out of the finish).",
        acc.describe(),
        milled.cov_ratio[0],
        milled.cov_ratio[1],
        milled.ndf_l1,
        milled.ndf_corr,
        ideal.cov_ratio[0],
        ideal.cov_ratio[1],
        ideal.ndf_l1,
        ideal.ndf_corr,
    );
    match (milled.pass, ideal.pass) {
        (false, true) => s.push_str(" The machine's errors alone make the difference between pass and fail."),
        (true, false) => s.push_str(
            " The cut passes on this machine though not on a perfect one (the loop corrected for its runout).",
        ),
        _ => {}
    }
    Some(s)
}

/// What measuring a cut as the verdict does needs of the job: the target, its NDF and grid, the lobes, the
/// finishing raster and the tile. The verdict's milled surface and a scan of the part (`brdfmill compare`)
/// are measured by the same gauge.
pub struct Gauge<'a> {
    /// The target BRDF.
    pub target: &'a Brdf,
    /// The NDF stage's result (its observed distribution is the reference).
    pub ndf: &'a Ndf,
    /// The NDF stage's settings.
    pub ndf_config: &'a NdfConfig,
    /// The base lobe the NDF stage deconvolved, if any.
    pub base: Option<&'a Kernel>,
    /// The base lobe is the finishing raster's scallop lobe.
    pub base_is_scallop: bool,
    /// The material's polish lobe.
    pub polish: Option<&'a Brdf>,
    /// The finishing tool as the machine cuts with it.
    pub tool: crate::cut::tool::Shape,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
    /// Angle of the finishing passes from x, degrees.
    pub raster_angle_deg: f64,
    /// The machinable cone, degrees.
    pub cone_deg: f64,
    /// The tile's period along x and y, mm.
    pub tile_mm: [f64; 2],
    /// The design tile's sample pitch, mm.
    pub tile_pitch_mm: f64,
}

impl VerifyInput<'_> {
    /// The gauge of this job.
    pub fn gauge(&self) -> Gauge<'_> {
        let c = &self.tile.config;
        Gauge {
            target: self.target,
            ndf: self.ndf,
            ndf_config: self.ndf_config,
            base: self.base,
            base_is_scallop: self.base_is_scallop,
            polish: self.polish,
            tool: self.tool,
            stepover_mm: self.stepover_mm,
            raster_angle_deg: self.raster_angle_deg,
            cone_deg: self.cone_deg,
            tile_mm: [c.facets_x as f64 * c.facet_mm, c.facets_y as f64 * c.facet_mm],
            tile_pitch_mm: self.tile.heightfield.pitch_mm,
        }
    }
}

impl Gauge<'_> {
    /// The band of a surface at pitch `pitch_mm` left out of its NDF, cells: one tool radius grazed, one cut
    /// from one side only, a design sample either side, and the half stepover the slope mean reaches.
    pub fn margin(&self, pitch_mm: f64) -> usize {
        let r = self.tool.radius_mm();
        ((2.0 * r + 2.0 * self.tile_pitch_mm) / pitch_mm).ceil() as usize
            + milled::reach_cells(pitch_mm, self.stepover_mm)
    }

    /// The window the verdict measures on a cut `hf`: whole tiles in its interior ([`milled::window`]).
    pub fn window(
        &self,
        cfg: &VerifyConfig,
        hf: &crate::base::heightfield::Heightfield,
    ) -> Result<milled::Window, VerifyError> {
        let margin = self.margin(hf.pitch_mm);
        milled::window(hf, margin, self.tile_mm).ok_or(VerifyError::TooSmall {
            side_mm: cfg.wave_patch_mm,
            margin,
        })
    }

    /// The NDF of the surface `hf` in the window `win`, as `milled` describes: slopes averaged over a
    /// stepover, the scallop lobe (with the polish) convolved back. Returns the NDF, the fraction of slopes
    /// beyond the grid, and how it was measured. The window must lie [`milled::reach_cells`] inside `hf`.
    pub fn measure(
        &self,
        cfg: &VerifyConfig,
        hf: &crate::base::heightfield::Heightfield,
        win: &milled::Window,
    ) -> Result<(SlopeGrid, f64, Measurement), VerifyError> {
        let n = self.ndf;
        let domain = n.config.domain();
        let mut slopes = milled::slopes(hf, win, self.raster_angle_deg, self.stepover_mm);
        if cfg.prefilter_um > 0.0 {
            // the pre-filter is a Gaussian of the heights; the stepover mean already smooths below a stepover
            let f = surface::gaussian(hf, cfg.prefilter_um * 1e-3);
            slopes = milled::slopes(&f, win, self.raster_angle_deg, self.stepover_mm);
        }
        let (raw, outside) = surface::ndf_of_slopes(&slopes, domain);
        let lobe = match self.base {
            Some(k) if self.base_is_scallop => k.clone(),
            _ => Kernel::scallop(
                &domain,
                &self.tool,
                self.stepover_mm,
                self.raster_angle_deg,
                self.polish,
                self.ndf_config,
            )?,
        };
        let milled = normalised(lobe.convolve(&raw));
        let cone_tan = self.cone_deg.to_radians().tan();
        // the target's mass the facets cannot draw: beyond the grid (steeper than any of its cells; the facets
        // sample the grid) or inside it beyond the cone
        let in_grid = 1.0 - n.observed.cut_to_cone(cone_tan).mass() / n.observed.mass().max(1e-300);
        let g = n.mass_beyond_grid.clamp(0.0, 1.0);
        let beyond = g + (1.0 - g) * in_grid.clamp(0.0, 1.0);
        let margin = self.margin(hf.pitch_mm);
        let measurement = Measurement {
            window: *win,
            margin_cells: margin,
            margin_mm: margin as f64 * hf.pitch_mm,
            scallops: lobe.label.clone(),
            cone_deg: self.cone_deg,
            target_mass_beyond_cone: beyond,
            outside_grid: outside,
        };
        Ok((milled, outside, measurement))
    }

    /// The verdict's figures of a measured NDF against the target (without the highlight's, which needs
    /// the design).
    pub fn metrics(&self, cfg: &VerifyConfig, measured: &SlopeGrid) -> SurfaceMetrics {
        let cone_tan = self.cone_deg.to_radians().tan();
        metrics::measure(
            &self.ndf.observed,
            measured,
            self.target,
            &cfg.incident_deg,
            &cfg.tolerances,
            cone_tan,
        )
    }
}

/// The milled surface's NDF as the verdict measures it ([`Gauge::measure`] in [`Gauge::window`]).
fn milled_ndf(cfg: &VerifyConfig, input: &VerifyInput) -> Result<(SlopeGrid, f64, Measurement), VerifyError> {
    let gauge = input.gauge();
    let hf = &input.sim.heightfield;
    let win = gauge.window(cfg, hf)?;
    gauge.measure(cfg, hf, &win)
}

/// The target's mass beyond the machinable cone, when it matters (over 0.01%): the milled lobe lacks that
/// tail. Quotes `measurement.target_mass_beyond_cone`, the figure `metrics.json` and the report's
/// steepest-facet row give. (The facets' own `steep_mass` is no guide in a job: the design loop hands them
/// the NDF already restricted to the cone, so nothing is left for them to drop.)
fn beyond_cone_note(input: &VerifyInput, measurement: &Measurement) -> Option<String> {
    let beyond = measurement.target_mass_beyond_cone;
    if beyond <= 1e-4 {
        return None;
    }
    let mut s = format!(
        "{:.2}% of the target's distribution lies beyond the machinable limit of {:.1}°, where no facet can draw it",
        beyond * 100.0,
        measurement.cone_deg
    );
    if beyond > 0.01 {
        // the limit is the steepest facet the relief budget allows: atan(relief / (√2·facet))
        s += &format!(
            ": the milled lobe lacks that tail. The limit is `facets.max_slope_deg` (unless the job sets it, the steepest {} mm facet the relief budget allows); smaller facets (`facets.facet_mm`) or a taller budget (a tool with longer flutes, or `facets.max_relief_mm`) raise it, up to the NDF grid's edge (`ndf.max_angle_deg`) and what the ball can reach.",
            input.tile.config.facet_mm
        );
    } else {
        s.push('.');
    }
    Some(s)
}

/// The design loop's convergence: each round's as-milled model variance ratios, the tolerance band, and the
/// simulated cut's ratios at the chosen round.
fn convergence(
    rounds: &[crate::stages::design::Round],
    arrangements: &[crate::stages::design::Round],
    metrics: &Metrics,
    tol: &Tolerances,
) -> Figure {
    use crate::base::plot::{LinePlot, Series, PALETTE};
    let n = rounds.len() as f64;
    // percent off the target's variance, so the band and the rounds share a readable scale
    let pct = |v: f64| (v - 1.0) * 100.0;
    let pts = |k: usize| {
        rounds
            .iter()
            .map(|r| (r.round as f64, pct(r.cov_ratio[k])))
            .collect::<Vec<_>>()
    };
    // half a round of room each side, so the chosen round's marks stay short beside the band even when
    // there is one round
    let band = |v: f64| vec![(0.5, pct(v)), (n + 0.5, pct(v))];
    let chosen = rounds
        .iter()
        .min_by(|a, b| a.score.total_cmp(&b.score))
        .map(|r| r.round as f64)
        .unwrap_or(1.0);
    let mark = |v: f64| vec![(chosen - 0.12, pct(v)), (chosen + 0.12, pct(v))];
    let plot = LinePlot {
        title: "design rounds: variance off the target (%)".into(),
        x_label: "round".into(),
        y_label: "%".into(),
        series: vec![
            Series {
                label: "model x".into(),
                points: pts(0),
                color: PALETTE[0],
                dashed: false,
            },
            Series {
                label: "model y".into(),
                points: pts(1),
                color: PALETTE[1],
                dashed: false,
            },
            Series {
                label: "milled x (G-code)".into(),
                points: mark(metrics.milled.cov_ratio[0]),
                color: PALETTE[0],
                dashed: true,
            },
            Series {
                label: "milled y (G-code)".into(),
                points: mark(metrics.milled.cov_ratio[1]),
                color: PALETTE[1],
                dashed: true,
            },
            Series {
                label: "tolerance".into(),
                points: band(tol.cov_ratio[0]),
                color: [120, 120, 120],
                dashed: true,
            },
            Series {
                label: String::new(),
                points: band(tol.cov_ratio[1]),
                color: [120, 120, 120],
                dashed: true,
            },
        ],
        size_px: (460, 260),
        log_y: false,
        whole_x: true,
    };
    let rows: Vec<String> = rounds
        .iter()
        .map(|r| {
            format!(
                "round {}: {}, model corr {:.4}, L1 {:.3}, variance [{:.3}, {:.3}], relief {:.3} mm{}",
                r.round,
                if r.refined {
                    "refined surface".to_string()
                } else {
                    format!("slopes ×[{:.3}, {:.3}]", r.scale[0], r.scale[1])
                },
                r.ndf_corr,
                r.ndf_l1,
                r.cov_ratio[0],
                r.cov_ratio[1],
                r.relief_mm,
                if r.refined {
                    String::new()
                } else {
                    format!(", steps {:.1} µm rms", r.rms_step_um)
                }
            )
        })
        .collect();
    let candidates = if arrangements.len() > 1 {
        let list: Vec<String> = arrangements
            .iter()
            .map(|r| format!("seed {} [{:.3}, {:.3}]", r.seed, r.cov_ratio[0], r.cov_ratio[1]))
            .collect();
        format!(
            " Round 1 is the best of {} arrangements of the same facets, each modelled uncorrected (variance ratios: {}).",
            arrangements.len(),
            list.join(", ")
        )
    } else {
        String::new()
    };
    let refined = rounds.iter().filter(|r| r.refined).count();
    let refined = if refined > 0 {
        format!(
            " The last {refined} rounds are the refinement's iterations (`design.method = \"refined\"`): the tile as a continuous surface, its slopes transported onto the target and projected back onto integrable surfaces the ball reaches (docs/DESIGN.md §3.5)."
        )
    } else {
        String::new()
    };
    Figure::new(
        "Design rounds",
        format!(
            "Each round models what the ball leaves of the tile (its opening of the periodic tile, convolved with the scallop lobe) and scales the facet slopes so the model's variance meets the target's.{candidates}{refined} The short dashed marks are the simulated G-code of the chosen round (round {chosen}), the grey dashed lines the tolerance band. {}.",
            rows.join("; ")
        ),
        &plot.render(),
    )
}

/// What a glossmeter would read off the target and off the milled surface (its geometric BRDF with the
/// part's material), both at once.
fn appearance(target: &crate::stages::brdf::Brdf, milled_brdf: &geometric::MicrofacetBrdf) -> super::AppearanceMetrics {
    use crate::stages::brdf::luminance;
    use crate::stages::optics::gloss;
    let (t, m) = rayon::join(
        || gloss::appearance(&|a: &Vec3, b: &Vec3| luminance(&target.eval(a, b))),
        || gloss::appearance(&|a: &Vec3, b: &Vec3| luminance(&milled_brdf.eval(a, b))),
    );
    super::AppearanceMetrics {
        method: gloss::METHOD.to_string(),
        target: t,
        milled: m,
    }
}

/// The report's figures of the verification stage.
fn figures(
    cfg: &VerifyConfig,
    input: &VerifyInput,
    design: &SlopeGrid,
    milled_brdf: &geometric::MicrofacetBrdf,
    wave_png: &Canvas,
    wave_albedo: f64,
    diffracts: bool,
) -> Vec<Figure> {
    let material = input.target.material;
    let ndf_row = Canvas::hstack(&[
        ndf::render_png(&input.ndf.observed, "target: observed O"),
        ndf::render_png(design, "design tile * base lobe"),
        ndf::render_png(milled_brdf.ndf(), "milled (simulated)"),
    ]);
    let design_brdf = geometric::MicrofacetBrdf::new(design.clone(), material);
    let tf = |a: &Vec3, b: &Vec3| input.target.eval(a, b);
    let df = |a: &Vec3, b: &Vec3| design_brdf.eval(a, b);
    let mf = |a: &Vec3, b: &Vec3| milled_brdf.eval(a, b);
    let items: [(&str, render::BrdfFn); 3] = [("target", &tf), ("design tile", &df), ("milled", &mf)];
    let slices = render::slices(&items, &cfg.incident_deg);
    let spheres = render::sphere_row(&items, 260, 1.0);
    vec![
        Figure::new(
            "NDFs",
            "Slope densities P22 (log scale over four decades) on the target's grid: the target's observed distribution, the design tile's facets convolved with the base lobe, and the simulated milled surface.",
            &ndf_row,
        ),
        Figure::new(
            "BRDF slices",
            "f·cosθo (luminance) in the plane of incidence for each incident angle.",
            &slices,
        ),
        Figure::new(
            "Rendered preview",
            "Spheres of the target material and of the fabricated surfaces' microfacet BRDFs under the same two lights (orthographic view, raster direction horizontal).",
            &spheres,
        ),
        Figure::new(
            "Wave optics of the milled surface",
            format!(
                "Kirchhoff BRDF (FFT, λ = {} µm, Gaussian coherence σ = {} µm, 3×3 windows) of a {} mm patch at the centre of the simulated surface at normal incidence, beside the geometric microfacet BRDF of the same patch, on one colour scale (four decades below the larger peak), within the disc of real outgoing directions (grey beyond). {}Wave albedo {wave_albedo:.3}. Scallop stepover {:.1} µm: {}",
                cfg.wavelength_um,
                cfg.coherence_sigma_um,
                cfg.wave_patch_mm,
                if cfg.wave_patch_mm < 2.0 * input.tile.config.facet_mm {
                    format!(
                        "The patch is smaller than two of the tile's {} mm facets: it shows the lobe of the facets under it and their scallops (what diffraction does), not the tile's BRDF, which the BRDF slices above show. ",
                        input.tile.config.facet_mm
                    )
                } else {
                    String::new()
                },
                input.stepover_mm * 1000.0,
                if diffracts { "its diffraction orders fall inside the lobe (see Why)." } else { "no resolved diffraction orders inside the lobe." }
            ),
            wave_png,
        ),
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
    let mut patch = crate::base::heightfield::Heightfield::flat(side, side, p, false, 0.0);
    for j in 0..side {
        for i in 0..side {
            patch.z_mm[j * side + i] = hf.at(i0 + i, j0 + j);
        }
    }
    let material = input.target.material;
    let max_slope = input.tile.config.max_slope_deg.to_radians().tan();
    let (geo_ndf, _) = surface::ndf(&patch, SlopeDomain::square(129, 1.2 * max_slope), 0.0, 1);
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
        crate::stages::optics::figures::wave_vs_geometric_png(&slice, &geo, &wi, max_slope),
        slice.albedo(),
    ))
}

fn normalised(mut g: SlopeGrid) -> SlopeGrid {
    g.normalise();
    g
}
