//! Stage 3 — facets: a target NDF to a tileable heightfield (Section 7.2, Eqs. 17–21).
//!
//! 1. `sampling`: N = W×H facet slopes from the NDF — low-discrepancy importance samples, then Lloyd
//!    iterations toward a CVT (Voronoi cells from `spade`). Slopes steeper than the machinable limit are
//!    dropped from the density (or clamped), and the mass that removed is reported.
//! 2. `arrange`: the facets placed on a W×H cyclic grid by simulated annealing of `E = C + I + V`.
//! 3. `poisson`: facet heights by periodic Poisson integration (FFT), then the facet planes rasterised at
//!    a fine pitch into a periodic [`Heightfield`]; `stl` writes the exact faceted solid.
//!
//! ```
//! use brdfmill::stages::{brdf::Brdf, facets, ndf};
//! let n = ndf::run(&ndf::NdfConfig { res: 64, ..Default::default() },
//!                  &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
//! let cfg = facets::FacetsConfig { facets_x: 8, facets_y: 8, pitch_um: 100.0, ..Default::default() };
//! let tile = facets::run(&cfg, &n.target).unwrap();
//! assert_eq!(tile.heightfield.nx, 80);
//! assert!(tile.heightfield.range().1.abs() < 1e-12); // the top of the tile is the stock top, z = 0
//! ```

pub(crate) mod arrange;
pub mod curved;
pub mod format;
pub(crate) mod poisson;
pub(crate) mod relief;
pub(crate) mod sampling;
pub(crate) mod steps;
pub(crate) mod stl;

pub use arrange::{AnnealConfig, AnnealReport, Arrangement, Energy};
pub use format::TileFile;
pub use poisson::PoissonSolver;

use crate::base::heightfield::Heightfield;
use crate::base::slope::{SlopeGrid, SlopeStats};
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

/// Errors of the facets stage.
#[derive(Debug, thiserror::Error)]
pub enum FacetsError {
    /// A configuration value is out of range.
    #[error("facets config: `{field}` {reason}")]
    Config {
        /// The offending field.
        field: &'static str,
        /// What was expected.
        reason: String,
    },
    /// A limit that several fields reach together: the message names each of them.
    #[error("facets config: {0}")]
    Limit(String),
    /// The NDF cannot be sampled.
    #[error("ndf: {0}")]
    Ndf(String),
}

/// What to do with facet slopes steeper than the machinable limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SteepPolicy {
    /// Drop that part of the distribution and renormalise (no facet is steeper than the limit).
    Truncate,
    /// Sample the whole distribution and clamp steep facets onto the limit (keeps their azimuth).
    Clamp,
}

/// Configuration of the facets stage. Lengths carry their unit in the name.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FacetsConfig {
    /// Facets along x (W).
    pub facets_x: usize,
    /// Facets along y (H).
    pub facets_y: usize,
    /// Side of one square facet, mm.
    pub facet_mm: f64,
    /// Heightfield sample spacing, µm; must divide the facet side.
    pub pitch_um: f64,
    /// Seed of every random choice (sampling baseline, annealing).
    #[serde(deserialize_with = "crate::base::de::seed")]
    pub seed: u64,
    /// Machinable limit: the steepest facet, degrees from the surface normal.
    pub max_slope_deg: f64,
    /// What happens to steeper slopes.
    pub steep: SteepPolicy,
    /// Relief budget: the tile's highest minus lowest point at most this, mm (0: unbounded). The heights are
    /// then the least-squares ones within the budget, with deliberate steps where they had to be held.
    pub max_relief_mm: f64,
    /// Lloyd iterations of the CVT. A light relaxation: at N ≈ 1000 sites a fully converged ρ²-weighted CVT
    /// pulls the tails in (measured on Beckmann α = 0.3: slope variance −3% after 200 iterations, −2.3%
    /// after 10, with the 2D KS distance to the NDF 0.008 either way against 0.054 for i.i.d. samples).
    pub lloyd_iterations: usize,
    /// Supersampling of the NDF grid when integrating Voronoi cells.
    pub cvt_supersample: usize,
    /// Cells are weighted by ρ^exponent (2 makes sites follow ρ asymptotically; see `sampling`).
    pub cvt_weight_exponent: f64,
    /// Permutations of the two-sample test.
    pub test_permutations: usize,
    /// Simulated annealing.
    pub anneal: AnnealConfig,
}

impl Default for FacetsConfig {
    fn default() -> Self {
        Self {
            facets_x: 32,
            facets_y: 32,
            facet_mm: 1.0,
            pitch_um: 10.0,
            seed: 1,
            max_slope_deg: 45.0,
            steep: SteepPolicy::Truncate,
            max_relief_mm: 0.0,
            lloyd_iterations: 10,
            cvt_supersample: 4,
            cvt_weight_exponent: 2.0,
            test_permutations: 199,
            anneal: AnnealConfig::default(),
        }
    }
}

impl FacetsConfig {
    /// Heightfield samples per facet side.
    pub fn samples_per_facet(&self) -> usize {
        (self.facet_mm * 1000.0 / self.pitch_um).round() as usize
    }

    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<(), FacetsError> {
        let bad = |field, reason: String| Err(FacetsError::Config { field, reason });
        // checked: a product that wraps would pass any bound
        let count = self.facets_x.checked_mul(self.facets_y);
        // each axis needs two facets: one column or row has no neighbour to integrate against (and the
        // periodic Poisson solver's FFT needs two samples along x)
        let (fx, fy) = (self.facets_x, self.facets_y);
        if fx < 2 || fy < 2 {
            return Err(FacetsError::Limit(format!(
                "`facets_x` × `facets_y` must be at least 2×2 facets, got {fx}x{fy}"
            )));
        }
        if count.is_none_or(|n| n > 1 << 20) {
            return Err(FacetsError::Limit(format!(
                "`facets_x` × `facets_y` = {fx}x{fy} is more than 2^20 facets"
            )));
        }
        if !(self.facet_mm.is_finite() && self.facet_mm > 0.0) {
            return bad(
                "facet_mm",
                format!("must be a positive length in mm, got {}", self.facet_mm),
            );
        }
        if !(self.pitch_um.is_finite() && self.pitch_um > 0.0) {
            return bad(
                "pitch_um",
                format!("must be a positive length in µm, got {}", self.pitch_um),
            );
        }
        let ratio = self.facet_mm * 1000.0 / self.pitch_um;
        if ratio < 1.0 - 1e-9 {
            return bad(
                "pitch_um",
                format!(
                    "{} µm is larger than a facet ({} mm): the heightfield could not show the facets",
                    self.pitch_um, self.facet_mm
                ),
            );
        }
        if (ratio - ratio.round()).abs() > 1e-6 {
            return bad(
                "pitch_um",
                format!(
                    "{} µm must divide the facet side {} mm into whole samples ({ratio:.4} per facet)",
                    self.pitch_um, self.facet_mm
                ),
            );
        }
        let samples = (fx * fy) as f64 * ratio.round().powi(2);
        if samples > 4e8 {
            return Err(FacetsError::Limit(format!(
                "{fx}×{fy} facets of {} mm at {} µm pitch (`facets_x` × `facets_y` × (`facet_mm` / `pitch_um`)²) would be a heightfield of {samples:.3e} samples (limit 4e8)",
                self.facet_mm, self.pitch_um
            )));
        }
        if !(self.max_slope_deg > 0.0 && self.max_slope_deg < 89.0) {
            return bad(
                "max_slope_deg",
                format!("must be in (0, 89) degrees, got {}", self.max_slope_deg),
            );
        }
        if !(self.max_relief_mm.is_finite() && self.max_relief_mm >= 0.0) {
            return bad(
                "max_relief_mm",
                format!("must be a length ≥ 0 in mm (0: unbounded), got {}", self.max_relief_mm),
            );
        }
        for (field, v) in [
            ("anneal.step_weight", self.anneal.step_weight),
            ("anneal.relief_weight", self.anneal.relief_weight),
            ("anneal.valley_weight", self.anneal.valley_weight),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("must be a weight ≥ 0, got {v}"));
            }
        }
        if self.lloyd_iterations > 10_000 {
            return bad(
                "lloyd_iterations",
                format!("must be at most 10000, got {}", self.lloyd_iterations),
            );
        }
        // annealing work is sweeps × facets swap proposals
        let work = self.anneal.sweeps as f64 * (self.facets_x * self.facets_y) as f64;
        if work > 1e11 {
            return Err(FacetsError::Limit(format!(
                "{} sweeps of {} facets (`anneal.sweeps` × `facets_x` × `facets_y`) is {work:.2e} swap proposals (limit 1e11, about an hour)",
                self.anneal.sweeps,
                fx * fy
            )));
        }
        if !(self.cvt_weight_exponent > 0.0 && self.cvt_weight_exponent <= 8.0) {
            return bad(
                "cvt_weight_exponent",
                format!("must be in (0, 8], got {}", self.cvt_weight_exponent),
            );
        }
        let t0 = self.anneal.initial_temperature;
        if !(t0.is_finite() && t0 > 0.0) {
            return bad(
                "anneal.initial_temperature",
                format!("must be a positive fraction, got {t0}"),
            );
        }
        let ratio = self.anneal.final_temperature_ratio;
        if !(ratio > 0.0 && ratio <= 1.0) {
            return bad(
                "anneal.final_temperature_ratio",
                format!("must be in (0, 1], got {ratio}"),
            );
        }
        if self.test_permutations > MAX_TEST_PERMUTATIONS {
            return bad(
                "test_permutations",
                format!(
                    "must be at most {MAX_TEST_PERMUTATIONS}, got {}",
                    self.test_permutations
                ),
            );
        }
        if self.anneal.random_baselines > 10_000 {
            return bad(
                "anneal.random_baselines",
                format!("must be at most 10000, got {}", self.anneal.random_baselines),
            );
        }
        if self.cvt_supersample == 0 || self.cvt_supersample > 16 {
            return bad(
                "cvt_supersample",
                format!("must be in 1..=16, got {}", self.cvt_supersample),
            );
        }
        Ok(())
    }
}

/// How well the facet slopes follow the NDF.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplingStats {
    /// Mass of the NDF beyond the machinable limit (dropped or clamped), fraction of 1.
    pub steep_mass: f64,
    /// 2D Kolmogorov–Smirnov distance to the NDF: i.i.d. importance samples.
    pub ks_random: f64,
    /// … Halton importance samples (before Lloyd).
    pub ks_halton: f64,
    /// … after the CVT Lloyd iterations (the facets used).
    pub ks_cvt: f64,
    /// Energy-distance two-sample test of the facets against an i.i.d. sample of the NDF: statistic.
    pub energy_statistic: f64,
    /// … and its permutation p-value (the test passes at the 5% level when p ≥ 0.05).
    pub energy_p_value: f64,
    /// Mean slope subtracted from the samples so the tile has zero mean slope.
    pub mean_removed: [f64; 2],
    /// The Lloyd iterations.
    pub lloyd: sampling::LloydReport,
}

/// Steps between neighbouring facet planes at their shared edges.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeamStats {
    /// Largest step at an interior edge, µm.
    pub max_interior_um: f64,
    /// Largest step at an edge where the tile meets its own copy, µm.
    pub max_seam_um: f64,
    /// RMS step over all edges, µm.
    pub rms_um: f64,
}

/// The facets stage's result.
#[derive(Clone, Debug)]
pub struct Tile {
    /// The configuration used.
    pub config: FacetsConfig,
    /// The arrangement (slopes per position).
    pub arrangement: Arrangement,
    /// Facet-centre heights, mm, row-major (same origin as the heightfield).
    pub z_mm: Vec<f64>,
    /// The rasterised periodic heightfield, top at z = 0.
    pub heightfield: Heightfield,
    /// Slope statistics of the facets.
    pub slope_stats: SlopeStats,
    /// Sampling quality.
    pub sampling: SamplingStats,
    /// Annealing report (energy, random baseline, trace).
    pub anneal: AnnealReport,
    /// Steps at facet edges.
    pub seams: SeamStats,
    /// Set when the design loop refined the tile as a continuous surface (`design.method = "refined"`):
    /// `heightfield` is then that surface, and `arrangement`, `z_mm` and `seams` the facets it started from.
    pub refined: Option<Refinement>,
}

/// How a tile was refined as a continuous surface (`design::refine`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// Iterations run.
    pub iterations: usize,
    /// The iteration kept (1-based; the one whose as-milled model scored best).
    pub chosen: usize,
    /// The grid the refinement ran on, mm (the as-milled model's); the heightfield is that surface resampled
    /// bilinearly onto the tile's own pitch.
    pub model_pitch_mm: f64,
}

/// Samples per side of a refined tile's STL at most (a 12 mm tile at 24 µm: half a million triangles).
pub const REFINED_STL_SIDE: usize = 512;

impl Tile {
    /// The exact faceted solid of one tile as binary STL (mm), its flat bottom 1 mm below the lowest point. A
    /// refined tile's is its surface through at most [`REFINED_STL_SIDE`] sample centres per side.
    pub fn stl(&self) -> Vec<u8> {
        let (lo, _) = self.heightfield.range();
        if self.refined.is_some() {
            let hf = &self.heightfield;
            return crate::base::stl::to_binary_stl(
                &crate::base::stl::heightfield_solid(hf, [0.0, 0.0], REFINED_STL_SIDE, 1.0),
                &format!(
                    "brdfmill refined tile, mm, every {}th sample",
                    hf.nx.max(hf.ny).div_ceil(REFINED_STL_SIDE)
                ),
            );
        }
        crate::base::stl::to_binary_stl(
            &stl::tile_solid(&self.arrangement, &self.z_mm, self.config.facet_mm, lo - 1.0),
            "brdfmill tile, mm",
        )
    }

    /// The tile's shaded relief with a title that gives its facets and relief.
    pub fn relief_png(&self) -> crate::base::plot::Canvas {
        let (lo, _) = self.heightfield.range();
        let c = &self.config;
        let what = if self.refined.is_some() { "refined from" } else { "tile" };
        self.heightfield.relief_png(
            &format!(
                "{what} {}x{} facets of {} mm, relief {:.1} µm",
                c.facets_x,
                c.facets_y,
                c.facet_mm,
                -lo * 1000.0
            ),
            1024,
        )
    }
}

/// Restrict the NDF to the machinable cone: returns the density used for sampling and the mass beyond it.
fn machinable(ndf: &SlopeGrid, cfg: &FacetsConfig) -> Result<(SlopeGrid, f64), FacetsError> {
    ndf.check_invariants().map_err(|e| FacetsError::Ndf(e.0))?;
    let total = ndf.mass();
    if total.is_nan() || total <= 0.0 {
        return Err(FacetsError::Ndf("the density has no mass".into()));
    }
    let mut inside = ndf.cut_to_cone(cfg.max_slope_deg.to_radians().tan());
    let steep = 1.0 - inside.mass() / total;
    match cfg.steep {
        SteepPolicy::Truncate => {
            if inside.normalise() <= 0.0 {
                return Err(FacetsError::Ndf(format!(
                    "all of the density lies beyond the machinable limit of {}°",
                    cfg.max_slope_deg
                )));
            }
            Ok((inside, steep))
        }
        SteepPolicy::Clamp => {
            let mut g = ndf.clone();
            g.normalise();
            Ok((g, steep))
        }
    }
}

/// The most facets of each sample the energy-distance two-sample test compares: its distance matrix holds
/// `(2n)²` values and each permutation sums them all, so beyond this every k-th facet of each sample is
/// tested (32 MB and 4·10⁶ sums a permutation at most, instead of 8.6 GB at 128×128 facets).
pub const ENERGY_TEST_FACETS: usize = 1024;

/// The most permutations of the two-sample test (at [`ENERGY_TEST_FACETS`], about a minute of sums).
pub const MAX_TEST_PERMUTATIONS: usize = 10_000;

/// Run the facets stage on a target NDF (`P22` slope grid).
pub fn run(cfg: &FacetsConfig, ndf: &SlopeGrid) -> Result<Tile, FacetsError> {
    run_from(cfg, &sites(cfg, ndf)?)
}

/// The part of the facets stage that does not depend on the seed: the machinable density and the facet
/// slopes sampled from it (Halton points relaxed toward a CVT). Arrangements of the same facets from several
/// seeds ([`run_from`]) share it.
#[derive(Clone, Debug)]
pub struct Sites {
    /// The configuration it was sampled with (its seed and annealing aside, what [`run_from`] must be given).
    config: FacetsConfig,
    density: SlopeGrid,
    steep_mass: f64,
    sites: Vec<(f64, f64)>,
    ks_halton: f64,
    ks_cvt: f64,
    lloyd: sampling::LloydReport,
    /// Curved facets: each site's dome curvature (`curved::curvature`), 1/mm; empty for flat facets.
    curvature: Vec<[f64; 3]>,
}

impl Sites {
    /// The same sites as curved facets: each a dome whose slopes sweep the site's Voronoi cell of the
    /// density with the cell's own second moment ([`curved`]).
    pub fn curved(mut self) -> Self {
        let moments = curved::cell_moments(&self.density, &self.sites);
        self.curvature = moments
            .into_iter()
            .map(|m| curved::curvature(m, self.config.facet_mm))
            .collect();
        self
    }

    /// The curvature of the facet at each position, `index` giving which site sits there; empty for flat
    /// facets.
    fn curvature_at(&self, index: &[usize]) -> Vec<[f64; 3]> {
        if self.curvature.is_empty() {
            return vec![];
        }
        index.iter().map(|&k| self.curvature[k]).collect()
    }
}

/// Subtract the mean slope from `sites` (a periodic tile's facets must average to no tilt) and return it.
fn centre(sites: &mut [(f64, f64)]) -> (f64, f64) {
    let n = sites.len() as f64;
    let mean = sites.iter().fold((0.0, 0.0), |a, s| (a.0 + s.0 / n, a.1 + s.1 / n));
    sites.iter_mut().for_each(|s| *s = (s.0 - mean.0, s.1 - mean.1));
    mean
}

/// The facets' slopes for `cfg` (its seed and annealing play no part).
pub fn sites(cfg: &FacetsConfig, ndf: &SlopeGrid) -> Result<Sites, FacetsError> {
    cfg.validate()?;
    let (density, steep_mass) = machinable(ndf, cfg)?;
    let n = cfg.facets_x * cfg.facets_y;
    let mut sites = sampling::halton_samples(&density, n);
    let ks_halton = sampling::ks_distance(&density, &sites);
    let lloyd = sampling::lloyd(
        &density,
        &mut sites,
        cfg.lloyd_iterations,
        cfg.cvt_supersample,
        cfg.cvt_weight_exponent,
    );
    if cfg.steep == SteepPolicy::Clamp {
        let limit = cfg.max_slope_deg.to_radians().tan();
        for s in sites.iter_mut() {
            let r = s.0.hypot(s.1);
            if r > limit {
                *s = (s.0 * limit / r, s.1 * limit / r);
            }
        }
    }
    let ks_cvt = sampling::ks_distance(&density, &sites);
    Ok(Sites {
        config: *cfg,
        density,
        steep_mass,
        sites,
        ks_halton,
        ks_cvt,
        lloyd,
        curvature: vec![],
    })
}

/// The facets stage from its sampled slopes: the seed's baselines and test, the arrangement, the
/// integration. `cfg` must be the configuration `sites` was sampled with, up to its seed and annealing.
pub fn run_from(cfg: &FacetsConfig, sites: &Sites) -> Result<Tile, FacetsError> {
    cfg.validate()?;
    let same = FacetsConfig {
        seed: cfg.seed,
        anneal: cfg.anneal,
        ..sites.config
    };
    if same != *cfg {
        return Err(FacetsError::Config {
            field: "facets",
            reason: "differs from the configuration its facets were sampled with (beyond seed and anneal)".into(),
        });
    }
    let density = &sites.density;
    let n = cfg.facets_x * cfg.facets_y;
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(cfg.seed);

    // 1. sampling: the seed's i.i.d. baseline and two-sample test against the shared CVT sites
    let reference = sampling::random_samples(density, n, &mut rng);
    let ks_random = sampling::ks_distance(density, &reference);
    let mut sites_now = sites.sites.clone();
    let independent = sampling::random_samples(density, n, &mut rng);
    // the test's distance matrix is (2n)² values: beyond ENERGY_TEST_FACETS facets, every k-th of each sample
    let stride = n.div_ceil(ENERGY_TEST_FACETS);
    let every = |v: &[(f64, f64)]| v.iter().step_by(stride).copied().collect::<Vec<_>>();
    let (energy_statistic, energy_p_value) = sampling::energy_test(
        &every(&sites_now),
        &every(&independent),
        cfg.test_permutations,
        &mut rng,
    );
    let mean = centre(&mut sites_now);

    // 2. arrangement
    let slope_stats = stats_of(&sites_now);
    let w_v = cfg.anneal.valley_weight * 0.5 * (slope_stats.cov[0][0] + slope_stats.cov[1][1]);
    let mut arrangement = Arrangement::new(cfg.facets_x, cfg.facets_y, &sites_now, w_v);
    let anneal = arrange::anneal(&mut arrangement, &cfg.anneal, &mut rng);
    arrangement.curvature_per_mm = sites.curvature_at(&arrangement.index);

    // 3. integration and rasterisation
    let (z, heightfield, seams) = integrate(&arrangement, cfg);

    Ok(Tile {
        config: *cfg,
        arrangement,
        z_mm: z,
        heightfield,
        slope_stats,
        sampling: SamplingStats {
            steep_mass: sites.steep_mass,
            ks_random,
            ks_halton: sites.ks_halton,
            ks_cvt: sites.ks_cvt,
            energy_statistic,
            energy_p_value,
            mean_removed: [mean.0, mean.1],
            lloyd: sites.lloyd,
        },
        anneal,
        seams,
        refined: None,
    })
}

/// Facet heights by periodic Poisson integration, the rasterised heightfield (top at z = 0) and the steps.
/// Curved facets meet at their edges' midpoints when their centre heights also carry the difference of the
/// two domes' sags there ([`curved::edge_sag_differences`], added to the edge gradients).
fn integrate(arrangement: &Arrangement, cfg: &FacetsConfig) -> (Vec<f64>, Heightfield, SeamStats) {
    let (w, h, a) = (cfg.facets_x, cfg.facets_y, cfg.facet_mm);
    let mut z = vec![0.0; w * h];
    let (mut gx, mut gy) = poisson::edge_gradients(&arrangement.p, &arrangement.q, w, h);
    let (cx, cy) = curved::edge_sag_differences(&arrangement.curvature_per_mm, w, h, a);
    gx.iter_mut().zip(&cx).for_each(|(g, c)| *g += c / a);
    gy.iter_mut().zip(&cy).for_each(|(g, c)| *g += c / a);
    PoissonSolver::new(w, h).integrate_edge_gradients(&gx, &gy, a, &mut z);
    if cfg.max_relief_mm > 0.0 {
        // `None`: one facet alone is taller than the budget; the toolpath's depth check then refuses it
        // (the bound counts the facets' planes: a dome's corners sit lower by its sag, within the check's
        // reading of the heightfield itself)
        let _ = relief::bound(&arrangement.p, &arrangement.q, &mut z, w, h, a, cfg.max_relief_mm);
    }
    // the steps: the signed jump between the planes' edge midpoints, less the sags' difference
    let (sx, sy) = poisson::signed_edge_steps(&arrangement.p, &arrangement.q, &z, w, h, a);
    let sx: Vec<f64> = sx.iter().zip(&cx).map(|(s, c)| (s - c).abs()).collect();
    let sy: Vec<f64> = sy.iter().zip(&cy).map(|(s, c)| (s - c).abs()).collect();
    let seams = seam_stats(&sx, &sy, w, h);
    let mut heightfield = rasterise(arrangement, &z, cfg);
    let top = heightfield.range().1;
    heightfield.z_mm.iter_mut().for_each(|v| *v -= top);
    z.iter_mut().for_each(|v| *v -= top);
    (z, heightfield, seams)
}

/// The same arrangement with every facet's x slope scaled by `scale[0]` and y slope by `scale[1]`,
/// re-integrated: the heights and every step scale with the slopes, the order of the facets is kept. The
/// sampling statistics are those of the unscaled sample.
pub fn rescaled(tile: &Tile, scale: [f64; 2]) -> Tile {
    let mut arrangement = tile.arrangement.clone();
    arrangement.p.iter_mut().for_each(|p| *p *= scale[0]);
    arrangement.q.iter_mut().for_each(|q| *q *= scale[1]);
    let a = tile.config.facet_mm;
    arrangement
        .curvature_per_mm
        .iter_mut()
        .for_each(|h| *h = curved::rescaled(*h, scale, a));
    let sites: Vec<(f64, f64)> = arrangement
        .p
        .iter()
        .copied()
        .zip(arrangement.q.iter().copied())
        .collect();
    reintegrated(tile, arrangement, &sites)
}

/// `tile` with a changed `arrangement` whose facet slopes are `slopes`: integrated again, the sampling and
/// annealing records kept.
fn reintegrated(tile: &Tile, arrangement: Arrangement, slopes: &[(f64, f64)]) -> Tile {
    let (z, heightfield, seams) = integrate(&arrangement, &tile.config);
    Tile {
        config: tile.config,
        slope_stats: stats_of(slopes),
        arrangement,
        z_mm: z,
        heightfield,
        sampling: tile.sampling,
        anneal: tile.anneal.clone(),
        seams,
        refined: None,
    }
}

/// The same arrangement with its facets' slopes (and curvatures) replaced by those of `sites`, facet for
/// facet (the facet at each position is the same index of the sampled set), re-integrated: the design
/// loop's shape correction re-samples the facets from a corrected aim without re-annealing, so the order of
/// the facets, and the steps it leaves, move only as much as the slopes do. `sites` must hold as many
/// facets as the tile.
pub fn resited(tile: &Tile, sites: &Sites) -> Tile {
    assert_eq!(
        sites.sites.len(),
        tile.arrangement.index.len(),
        "as many sites as facets"
    );
    let mut centred = sites.sites.clone();
    centre(&mut centred);
    let mut arrangement = tile.arrangement.clone();
    for (j, &k) in tile.arrangement.index.iter().enumerate() {
        arrangement.p[j] = centred[k].0;
        arrangement.q[j] = centred[k].1;
    }
    arrangement.curvature_per_mm = sites.curvature_at(&tile.arrangement.index);
    reintegrated(tile, arrangement, &centred)
}

fn stats_of(s: &[(f64, f64)]) -> SlopeStats {
    let n = s.len() as f64;
    let (mp, mq) = s.iter().fold((0.0, 0.0), |a, v| (a.0 + v.0 / n, a.1 + v.1 / n));
    let (mut pp, mut pq, mut qq) = (0.0, 0.0, 0.0);
    for v in s {
        pp += (v.0 - mp) * (v.0 - mp) / n;
        pq += (v.0 - mp) * (v.1 - mq) / n;
        qq += (v.1 - mq) * (v.1 - mq) / n;
    }
    SlopeStats {
        mass: 1.0,
        mean: [mp, mq],
        cov: [[pp, pq], [pq, qq]],
    }
}

fn seam_stats(sx: &[f64], sy: &[f64], w: usize, h: usize) -> SeamStats {
    let (mut interior, mut seam, mut ss) = (0.0f64, 0.0f64, 0.0);
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            ss += sx[k] * sx[k] + sy[k] * sy[k];
            if x + 1 == w {
                seam = seam.max(sx[k]);
            } else {
                interior = interior.max(sx[k]);
            }
            if y + 1 == h {
                seam = seam.max(sy[k]);
            } else {
                interior = interior.max(sy[k]);
            }
        }
    }
    SeamStats {
        max_interior_um: interior * 1000.0,
        max_seam_um: seam * 1000.0,
        rms_um: (ss / (2 * w * h) as f64).sqrt() * 1000.0,
    }
}

/// Rasterise the facets: sample `(i, j)` of facet `(fx, fy)` gets `z + p (x − xc) + q (y − yc)`, less a
/// curved facet's sag `½ dᵀ H d` at `d = (x − xc, y − yc)`.
pub fn rasterise(a: &Arrangement, z: &[f64], cfg: &FacetsConfig) -> Heightfield {
    use rayon::prelude::*;
    let m = cfg.samples_per_facet();
    let (nx, ny) = (a.w * m, a.h * m);
    let pitch = cfg.facet_mm / m as f64;
    let mut hf = Heightfield::flat(nx, ny, pitch, true, 0.0);
    hf.z_mm.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        let fy = j / m;
        let dy = ((j % m) as f64 + 0.5) * pitch - 0.5 * cfg.facet_mm;
        for (i, v) in row.iter_mut().enumerate() {
            let fx = i / m;
            let dx = ((i % m) as f64 + 0.5) * pitch - 0.5 * cfg.facet_mm;
            let k = fy * a.w + fx;
            *v = z[k] + a.p[k] * dx + a.q[k] * dy;
            if let Some(h) = a.curvature_per_mm.get(k) {
                *v += curved::sag(h, dx, dy);
            }
        }
    });
    hf
}
