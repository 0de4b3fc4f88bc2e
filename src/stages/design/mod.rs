//! Stage 3 in a loop — fabrication-aware design: the facets stage (sampling, arrangement, integration) run
//! again and again against a model of what the finishing ball will cut, until the *as-milled* surface, not
//! the design tile, matches the target (DESIGN.md §3.1).
//!
//! Each round: facets from the current aim → the tile's as-milled model (`model`: the ball's opening of
//! the periodic tile, its NDF convolved with the scallop lobe) → its figures against the target's observed
//! distribution (correlation, L1, slope variances within the machinable cone) → a multiplicative
//! correction of the aim (`update`). The loop stops when the model meets the tolerances with a margin, or
//! after `rounds`; the round whose model scores best is the design. Before the first round,
//! `arrangements` candidate arrangements of the same facets (different annealing seeds) are modelled and the
//! best-scoring one is the one the rounds correct. Lucy–Richardson, the CVT and Eqs. 17–21
//! stay the core: this is a loop around them. The final verdict still comes from simulating the G-code.

pub(crate) mod model;
pub(crate) mod refine;
pub(crate) mod update;

use crate::base::distance::correlation;
use crate::base::heightfield::Heightfield;
use crate::base::slope::SlopeGrid;
use crate::base::surface;
use crate::cut::chords::PassChords;
use crate::cut::tool::Shape;
use crate::stages::facets::{self, FacetsConfig, Tile};
use crate::stages::ndf::{Kernel, Ndf};
use serde::{Deserialize, Serialize};

/// Seeds of the candidate arrangements: the job's seed, then the seed plus multiples of this odd constant
/// (the golden-ratio increment), so that the candidates of neighbouring job seeds do not overlap.
const SEED_STRIDE: u64 = 0x9E37_79B9_7F4A_7C15;

/// What the design draws the target with (`design.method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DesignMethod {
    /// Weyrich et al.'s flat facets: `N` facets are `N` normals, each blurred only by the base lobe.
    FlatFacets,
    /// Each facet a dome whose normals sweep its own Voronoi cell of the target (`facets::curved`): the
    /// facets draw a continuous distribution.
    CurvedFacets,
    /// Curved facets, then the tile refined as a continuous heightfield (`refine`): its slopes transported
    /// onto the target, projected back onto integrable, reachable surfaces within the relief budget.
    Refined,
}

/// What the rounds after the first correct (`design.correction`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Correction {
    /// The facet slopes scaled per axis until the as-milled variance meets the target's (two numbers).
    Scale,
    /// The aim reweighted cell by cell by the target over the as-milled model (`update::reweighted`, a
    /// Richardson–Lucy step), the facets re-sampled from it and put in the first round's arrangement, then
    /// scaled per axis as with `Scale` (the reweighting corrects the shape, the scale the variance).
    Shape,
}

/// Slopes per facet and axis over which a curved facet's own distribution is counted (16² = 256 per facet:
/// finer than the NDF grid's cell across the smallest Voronoi cell of the default job).
pub const DESIGN_SLOPES_PER_AXIS: usize = 16;

/// `[design]` of a job.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DesignConfig {
    /// Flat or curved facets.
    pub method: DesignMethod,
    /// What the rounds correct: the per-axis scale or the shape.
    pub correction: Correction,
    /// Rounds at most (1: the facets stage once, no correction).
    pub rounds: usize,
    /// Gain γ of the multiplicative correction (1: a full Richardson–Lucy step).
    pub gain: f64,
    /// Stop early once every figure of the model is within this fraction of its tolerance band (0.5: the
    /// variance ratio within half the band, correlation and L1 within half their margins).
    pub stop_fraction: f64,
    /// Candidate arrangements annealed (in parallel) from as many seeds before the first round; the one
    /// whose as-milled model scores best is corrected. The same facets arranged differently leave different
    /// concave corners to the ball: on the brushed Ward example, seeds 1–8 gave a first-round model x
    /// variance ratio from 1.31 to 1.50, and the corrected designs from 1.03 to 1.25.
    pub arrangements: usize,
    /// With `method = "refined"`: iterations of the refinement (each modelled and scored as a round).
    pub refine_iterations: usize,
    /// With `method = "refined"`: the gain of the Richardson–Lucy reweighting of the refinement's aim after
    /// each iteration (1 overshot: the default job's variance ratios swung ±3% from one iteration to the next).
    pub refine_gain: f64,
}

impl Default for DesignConfig {
    fn default() -> Self {
        Self {
            method: DesignMethod::FlatFacets,
            correction: Correction::Scale,
            rounds: 4,
            gain: 1.0,
            stop_fraction: 0.2,
            arrangements: 4,
            refine_iterations: 12,
            refine_gain: 0.3,
        }
    }
}

impl DesignConfig {
    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<(), DesignError> {
        let bad = |field: &'static str, reason: String| Err(DesignError::Config { field, reason });
        if !(1..=50).contains(&self.rounds) {
            return bad("rounds", format!("must be in 1..=50, got {}", self.rounds));
        }
        if !(1..=64).contains(&self.arrangements) {
            return bad("arrangements", format!("must be in 1..=64, got {}", self.arrangements));
        }
        if !(1..=200).contains(&self.refine_iterations) {
            return bad(
                "refine_iterations",
                format!("must be in 1..=200, got {}", self.refine_iterations),
            );
        }
        if !(self.refine_gain > 0.0 && self.refine_gain <= 1.0) {
            return bad("refine_gain", format!("must be in (0, 1], got {}", self.refine_gain));
        }
        if !(self.gain > 0.0 && self.gain <= 2.0) {
            return bad("gain", format!("must be in (0, 2], got {}", self.gain));
        }
        if !(self.stop_fraction >= 0.0 && self.stop_fraction <= 1.0) {
            return bad(
                "stop_fraction",
                format!("must be in [0, 1], got {}", self.stop_fraction),
            );
        }
        Ok(())
    }
}

/// The design loop failed.
#[derive(Debug, thiserror::Error)]
pub enum DesignError {
    /// A `[design]` setting is out of range.
    #[error("`design.{field}` {reason}")]
    Config {
        /// The field.
        field: &'static str,
        /// What was expected.
        reason: String,
    },
    /// The facets stage failed.
    #[error(transparent)]
    Facets(#[from] facets::FacetsError),
}

/// One round of the loop, as `metrics.json` records it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Round {
    /// 1, 2, …
    pub round: usize,
    /// The seed of the round's arrangement (the facets' `seed`: `brdfmill facets --seed` rebuilds it).
    #[serde(default)]
    pub seed: u64,
    /// The as-milled model's NDF correlation with the target's observed distribution.
    pub ndf_corr: f64,
    /// … relative L1 distance.
    pub ndf_l1: f64,
    /// … slope variance ratio along x and y within the machinable cone.
    pub cov_ratio: [f64; 2],
    /// The design tile alone (its facets, or a refined tile's surface, ⊛ base lobe): variance ratio along x and y.
    pub design_cov_ratio: [f64; 2],
    /// The tile's relief, mm.
    pub relief_mm: f64,
    /// RMS height step between neighbouring facets, µm.
    pub rms_step_um: f64,
    /// Fraction of the tile the ball cannot reach.
    pub unreachable: f64,
    /// The aim's slope scales along x and y (1: the target NDF itself).
    pub scale: [f64; 2],
    /// The round's score: its worst figure as a fraction of its tolerance band (≤ 1 meets them all).
    pub score: f64,
    /// With a drawn highlight target: the correlation of the model's highlight with the image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight_corr: Option<f64>,
    /// An iteration of the refinement (`design.method = "refined"`): the figures are those of a continuous
    /// surface, not of facets (no steps; `scale` is the facets' round it started from).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub refined: bool,
}

/// What the loop needs besides the facets configuration.
pub struct DesignInput<'a> {
    /// The NDF stage's result: `target` is the first aim, `observed` the reference.
    pub ndf: &'a Ndf,
    /// The base lobe the design tile is convolved with (its design figures), if any.
    pub base: Option<&'a Kernel>,
    /// The scallop lobe (with the polish) the as-milled model is convolved with.
    pub scallop: &'a Kernel,
    /// The finishing bit.
    pub tool: Shape,
    /// The finishing raster's stepover, mm, and the angle of its passes from x, degrees: the model's slopes
    /// are measured as the milled surface's are (the mean over one stepover across the passes).
    pub stepover_mm: f64,
    /// See `stepover_mm`.
    pub raster_angle_deg: f64,
    /// The band the slope variance ratios must fall in, `[low, high]` (the verdict's).
    pub cov_band: [f64; 2],
    /// The smallest NDF correlation (the verdict's).
    pub corr_min: f64,
    /// The largest relative L1 distance (the verdict's).
    pub l1_max: f64,
    /// A drawn highlight target: each round's model is also rendered in its configuration and scored by
    /// its correlation with the image, since scaling the slopes to meet the variance also scales the shape.
    pub highlight: Option<&'a crate::stages::brdf::Highlight>,
    /// The smallest highlight correlation (the verdict's).
    pub highlight_corr_min: f64,
    /// The chords the controller cuts arcs as (GRBL's `$12`, along the finishing passes), which the model
    /// cuts too ([`crate::cut::chords`]); `None` for a controller that follows arcs, or passes at an angle
    /// to the grid.
    pub chords: Option<PassChords>,
}

/// The loop's result.
pub struct Design {
    /// The chosen round's tile.
    pub tile: Tile,
    /// Every round, in order.
    pub rounds: Vec<Round>,
    /// Index into `rounds` of the chosen one.
    pub chosen: usize,
    /// The candidate arrangements' first rounds (uncorrected), in seed order; `rounds[0]` is the best of them.
    pub arrangements: Vec<Round>,
    /// The chosen round's aim density (what its facets sampled).
    pub aim: SlopeGrid,
}

/// What the loop reports as it goes.
pub enum Progress<'a> {
    /// A candidate arrangement's first (uncorrected) round.
    Arrangement(&'a Round),
    /// A round of the loop.
    Round(&'a Round),
}

/// Run the loop; `on_progress` is called after each candidate arrangement and each round.
pub fn run(
    cfg: &DesignConfig,
    fcfg: &FacetsConfig,
    input: &DesignInput,
    on_progress: &mut dyn FnMut(Progress),
) -> Result<Design, DesignError> {
    use rayon::prelude::*;
    cfg.validate()?;
    let n = input.ndf;
    let cone_tan = fcfg.max_slope_deg.to_radians().tan();
    let aim = n.target.within_cone(cone_tan);
    // candidate arrangements, each annealed and modelled once; the best is corrected
    let seeds: Vec<u64> = (0..cfg.arrangements as u64)
        .map(|k| fcfg.seed.wrapping_add(k.wrapping_mul(SEED_STRIDE)))
        .collect();
    // the facets' slopes do not depend on the seed: sampled once, arranged from each seed
    let sites_of = |aim: &SlopeGrid| -> Result<facets::Sites, DesignError> {
        Ok(match cfg.method {
            DesignMethod::FlatFacets => facets::sites(fcfg, aim)?,
            DesignMethod::CurvedFacets | DesignMethod::Refined => facets::sites(fcfg, aim)?.curved(),
        })
    };
    let sites = sites_of(&aim)?;
    let candidates: Vec<(Tile, Round, SlopeGrid)> = seeds
        .par_iter()
        .map(|&seed| {
            let tile = facets::run_from(&FacetsConfig { seed, ..*fcfg }, &sites)?;
            let (round, model) = evaluate(1, &tile, input, cone_tan, [1.0, 1.0]);
            Ok((tile, round, model))
        })
        .collect::<Result<_, DesignError>>()?;
    if candidates.len() > 1 {
        candidates
            .iter()
            .for_each(|(_, r, _)| on_progress(Progress::Arrangement(r)));
    }
    let pick = (0..candidates.len())
        .min_by(|&a, &b| candidates[a].1.score.total_cmp(&candidates[b].1.score))
        .expect("at least one arrangement");
    let arrangements: Vec<Round> = candidates.iter().map(|(_, r, _)| r.clone()).collect();
    let (first, _, mut model) = candidates.into_iter().nth(pick).expect("the pick exists");
    let mut shape_aim = aim;

    let mut scale = [1.0, 1.0];
    let mut history: Vec<([f64; 2], [f64; 2])> = vec![];
    let mut rounds: Vec<Round> = vec![];
    let mut best: Option<(Tile, SlopeGrid)> = None;
    let mut chosen = 0;
    for k in 0..cfg.rounds {
        let (tile, round) = if k == 0 {
            (first.clone(), arrangements[pick].clone())
        } else if cfg.correction == Correction::Shape {
            shape_aim = update::reweighted(&shape_aim, &n.observed, &model, input.scallop, cfg.gain, cone_tan);
            // the shape from the reweighted aim, the variance still held by the per-axis scale (the
            // reweighting alone narrowed the vinyl's model to a variance ratio of 0.81 in three rounds)
            let t = facets::rescaled(&facets::resited(&first, &sites_of(&shape_aim)?), scale);
            let (r, m) = evaluate(k + 1, &t, input, cone_tan, scale);
            model = m;
            (t, r)
        } else {
            let t = facets::rescaled(&first, scale);
            let (r, m) = evaluate(k + 1, &t, input, cone_tan, scale);
            model = m;
            (t, r)
        };
        on_progress(Progress::Round(&round));
        let better = rounds.get(chosen).is_none_or(|b| round.score < b.score);
        let done = round.score <= cfg.stop_fraction;
        history.push((scale, round.cov_ratio));
        let next = update::next_scale(&history, cfg.gain);
        rounds.push(round);
        if better {
            chosen = k;
            let aim = match cfg.correction {
                Correction::Shape => update::scaled(&shape_aim, scale, cone_tan),
                Correction::Scale => update::scaled(&n.target, scale, cone_tan),
            };
            best = Some((tile, aim));
        }
        if done {
            break;
        }
        scale = next;
    }
    let (mut tile, aim) = best.expect("at least one round");
    if cfg.method == DesignMethod::Refined {
        refine_tile(
            cfg,
            fcfg,
            input,
            cone_tan,
            &mut tile,
            &mut rounds,
            &mut chosen,
            on_progress,
        );
    }
    Ok(Design {
        tile,
        rounds,
        chosen,
        arrangements,
        aim,
    })
}

/// The refinement (`refine`, DESIGN.md §3.5) from the as-milled model of the chosen round's `tile`: each
/// iteration is modelled and scored as a round (appended to `rounds`), and the aim it transports the slopes
/// onto is reweighted by the model, a Richardson–Lucy step of gain `refine_gain` (`update::reweighted`). When
/// an iteration scores better than `rounds[chosen]`, the best one's surface becomes the tile's heightfield.
#[allow(clippy::too_many_arguments)]
fn refine_tile(
    cfg: &DesignConfig,
    fcfg: &FacetsConfig,
    input: &DesignInput,
    cone_tan: f64,
    tile: &mut Tile,
    rounds: &mut Vec<Round>,
    chosen: &mut usize,
    on_progress: &mut dyn FnMut(Progress),
) {
    let n = input.ndf;
    let pitch = model::model_pitch_mm(tile, &input.tool);
    let mut h = model::as_milled(tile, &input.tool, pitch, None).opened;
    let mut aim = n.target.within_cone(cone_tan);
    let mut solver = facets::poisson::PoissonSolver::new(h.nx, h.ny);
    let mut best: Option<(Heightfield, usize)> = None;
    let scale = rounds[*chosen].scale;
    for it in 0..cfg.refine_iterations {
        let chorded = refine::iterate(
            &mut h,
            &aim,
            &input.tool,
            fcfg.max_relief_mm,
            it,
            &mut solver,
            input.chords,
        );
        let cut = chorded.map(|z_mm| h.with_heights(z_mm));
        let (round, model) = evaluate_surface(rounds.len() + 1, &h, cut.as_ref(), input, cone_tan, scale);
        aim = update::reweighted(&aim, &n.observed, &model, input.scallop, cfg.refine_gain, cone_tan);
        on_progress(Progress::Round(&round));
        if round.score < rounds[*chosen].score {
            *chosen = rounds.len();
            best = Some((h.clone(), it + 1));
        }
        rounds.push(round);
    }
    if let Some((h, it)) = best {
        // the resampling's bilinear chords cut a hair into concave parts: opened again on the tile's grid,
        // as the verification's reach check takes it
        let mut hf = refine::resampled(&h, tile.config.pitch_um * 1e-3);
        hf.z_mm = crate::cut::morphology::opening_periodic(&hf.z_mm, hf.nx, hf.ny, hf.pitch_mm, &input.tool);
        tile.heightfield = hf;
        tile.refined = Some(facets::Refinement {
            iterations: cfg.refine_iterations,
            chosen: it,
            model_pitch_mm: pitch,
        });
    }
}

/// The design tile's NDF on `domain`: its facets' slopes (each facet's area alike; a curved facet's over its
/// area, [`DESIGN_SLOPES_PER_AXIS`]² per facet; a refined tile's its heightfield's, sample by sample)
/// convolved with the base lobe, normalised; and the fraction of
/// those slopes beyond the grid. The loop's rounds and the verdict's design column both measure it.
pub fn design_ndf(tile: &Tile, base: Option<&Kernel>, domain: crate::base::slope::SlopeDomain) -> (SlopeGrid, f64) {
    let (raw, outside) = if tile.refined.is_some() {
        surface_ndf(&tile.heightfield, domain)
    } else {
        let facet_slopes =
            facets::curved::facet_slopes(&tile.arrangement, tile.config.facet_mm, DESIGN_SLOPES_PER_AXIS);
        surface::ndf_of_slopes(&facet_slopes, domain)
    };
    (with_base(raw, base), outside)
}

/// A refined surface's figures as a round. The surface is an opening (`refine::iterate` ends with one), so
/// it is its own as-milled surface: nothing of it is out of the ball's reach, and it has no facet steps. The
/// model measures `cut`, the controller's chords' cut of it, where there is one.
fn evaluate_surface(
    round: usize,
    surface: &Heightfield,
    cut: Option<&Heightfield>,
    input: &DesignInput,
    cone_tan: f64,
    scale: [f64; 2],
) -> (Round, SlopeGrid) {
    let design = with_base(surface_ndf(surface, input.ndf.config.domain()).0, input.base);
    let (lo, hi) = surface.range();
    let model_surface = cut.unwrap_or(surface);
    let (mut r, model) = figures(
        round,
        model_surface,
        &design,
        input,
        cone_tan,
        scale,
        [hi - lo, 0.0, 0.0],
        0,
    );
    r.refined = true;
    (r, model)
}

/// A surface's NDF by central differences, each sample alike, and the fraction of its slopes beyond the grid.
fn surface_ndf(hf: &Heightfield, domain: crate::base::slope::SlopeDomain) -> (SlopeGrid, f64) {
    surface::ndf_of_slopes(&surface::slopes(hf, 0.0, 0), domain)
}

/// `g` convolved with the base lobe, if any, normalised.
fn with_base(g: SlopeGrid, base: Option<&Kernel>) -> SlopeGrid {
    match base {
        Some(k) => {
            let mut c = k.convolve(&g);
            c.normalise();
            c
        }
        None => g,
    }
}

/// One round's figures, and its as-milled model's NDF.
fn evaluate(round: usize, tile: &Tile, input: &DesignInput, cone_tan: f64, scale: [f64; 2]) -> (Round, SlopeGrid) {
    let domain = input.ndf.config.domain();
    let pitch = model::model_pitch_mm(tile, &input.tool);
    let milled = model::as_milled(tile, &input.tool, pitch, input.chords);
    let (design, _) = design_ndf(tile, input.base, domain);
    let (lo, hi) = tile.heightfield.range();
    let unreachable = model::unreachable_fraction(&milled);
    figures(
        round,
        milled.cut(),
        &design,
        input,
        cone_tan,
        scale,
        [hi - lo, tile.seams.rms_um, unreachable],
        tile.config.seed,
    )
}

/// The figures of an as-milled surface `cut` (the opening, or its cut along the controller's chords)
/// against the target; `design` is the design's NDF and `[relief_mm, rms_step_um, unreachable]` its shape
/// figures.
#[allow(clippy::too_many_arguments)]
fn figures(
    round: usize,
    cut: &Heightfield,
    design: &SlopeGrid,
    input: &DesignInput,
    cone_tan: f64,
    scale: [f64; 2],
    shape: [f64; 3],
    seed: u64,
) -> (Round, SlopeGrid) {
    let n = input.ndf;
    let domain = n.config.domain();
    let slopes = surface::stepover_slopes(cut, [0, 0, cut.nx, cut.ny], input.raster_angle_deg, input.stepover_mm);
    let (raw, _) = surface::ndf_of_slopes(&slopes, domain);
    let mut milled = input.scallop.convolve(&raw);
    milled.normalise();
    let obs = n.observed.within_cone(cone_tan).stats();
    let ratio = |g: &SlopeGrid| {
        let s = g.within_cone(cone_tan).stats();
        [s.cov[0][0] / obs.cov[0][0], s.cov[1][1] / obs.cov[1][1]]
    };
    let cov_ratio = ratio(&milled);
    let ndf_corr = correlation(&milled.density, &n.observed.density);
    let ndf_l1 = milled.relative_l1(&n.observed);
    let band = |v: f64| {
        let [lo, hi] = input.cov_band;
        if v >= 1.0 {
            (v - 1.0) / (hi - 1.0).max(1e-9)
        } else {
            (1.0 - v) / (1.0 - lo).max(1e-9)
        }
    };
    let highlight_corr = input.highlight.map(|h| h.correlation(&milled, (n.tilt.p, n.tilt.q)));
    let score = [
        band(cov_ratio[0]),
        band(cov_ratio[1]),
        (1.0 - ndf_corr) / (1.0 - input.corr_min).max(1e-9),
        ndf_l1 / input.l1_max.max(1e-9),
        highlight_corr.map_or(0.0, |c| (1.0 - c) / (1.0 - input.highlight_corr_min).max(1e-9)),
    ]
    .into_iter()
    .fold(0.0, f64::max);
    let [relief_mm, rms_step_um, unreachable] = shape;
    let r = Round {
        round,
        seed,
        ndf_corr,
        ndf_l1,
        cov_ratio,
        design_cov_ratio: ratio(design),
        relief_mm,
        rms_step_um,
        unreachable,
        scale,
        score,
        highlight_corr,
        refined: false,
    };
    (r, milled)
}
