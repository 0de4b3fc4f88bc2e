//! `tile.json`: the versioned description of a facet tile. The heights themselves are in `tile.npy`
//! beside it (shape `(ny, nx)`, mm, row 0 at y = 0).
//!
//! ```text
//! {
//!   "format": "brdfmill-tile", "version": 1,
//!   "source": {"ndf": "PATH", "brdf": "SPEC", "base": "SPEC" | null},
//!   "config": {...FacetsConfig...},
//!   "facets": {"w", "h", "facet_mm", "p": [w·h], "q": [w·h], "z_mm": [w·h], "index": [w·h]},
//!            slopes and centre heights per position, row-major (row y, column x), z relative to the top
//!   "heightfield": {"file": "tile.npy", "nx", "ny", "pitch_mm", "periodic": true, "min_mm", "max_mm"},
//!   "stats": {"mean": [p, q], "cov": [[pp, pq], [pq, qq]], "relief_mm",
//!             "energy": {"C", "I", "V", "valleys", "S", "steps_sq", "R", "heights_sq"},
//!             "energy_random": {same keys},   C + I + V + S + R is what the annealing lowers: S is
//!             the step term (step_weight × Σ step²/a² = steps_sq), R the relief term (relief_weight ×
//!             Σ z²/a² = heights_sq); S, steps_sq, R, heights_sq read as 0 from files that lack them
//!             "sampling": {"steep_mass", "ks_random", "ks_halton", "ks_cvt", "energy_statistic",
//!                          "energy_p_value", "mean_removed", "lloyd"},
//!             "seams": {"max_interior_um", "max_seam_um", "rms_um"},
//!             "anneal": {"trace", "trace_every", "proposals", "accepted", "w_v"}},
//!   "refined": {"iterations", "chosen", "model_pitch_mm"}   only for a tile refined as a continuous
//!             surface (`design.method = "refined"`): the heightfield is that surface, "facets" and
//!             "seams" the facets it started from
//! }
//! ```

use super::{AnnealReport, Energy, FacetsConfig, SamplingStats, SeamStats, Tile};
use crate::base::heightfield::Heightfield;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The format tag.
pub const FORMAT: &str = "brdfmill-tile";
/// The current version.
pub const VERSION: u32 = 1;

/// Where the tile came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Source {
    /// The ndf.json it was made from.
    pub ndf: String,
    /// The target BRDF spec.
    pub brdf: String,
    /// The base lobe spec.
    pub base: Option<String>,
}

/// Facet slopes and heights per position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FacetsRecord {
    /// Columns.
    pub w: usize,
    /// Rows.
    pub h: usize,
    /// Facet side, mm.
    pub facet_mm: f64,
    /// x slopes.
    pub p: Vec<f64>,
    /// y slopes.
    pub q: Vec<f64>,
    /// Centre heights, mm.
    pub z_mm: Vec<f64>,
    /// Index of each facet in the sampled set.
    pub index: Vec<usize>,
    /// Curved facets (`design.method = "curved-facets"`): each facet's curvature `[Hxx, Hxy, Hyy]`, 1/mm,
    /// its slope at an offset `d` from the centre being `(p, q) − H d`; absent for flat facets.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub curvature_per_mm: Vec<[f64; 3]>,
}

/// The heightfield's description (its data is the `.npy` file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeightfieldRecord {
    /// File name of the heights, relative to tile.json.
    pub file: String,
    /// Samples along x.
    pub nx: usize,
    /// Samples along y.
    pub ny: usize,
    /// Sample spacing, mm.
    pub pitch_mm: f64,
    /// Tileable.
    pub periodic: bool,
    /// Lowest height, mm.
    pub min_mm: f64,
    /// Highest height, mm (0: the stock top).
    pub max_mm: f64,
}

/// Annealing details kept in the stats.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnnealRecord {
    /// Total energy every `trace_every` sweeps.
    pub trace: Vec<f64>,
    /// Sweeps between trace entries.
    pub trace_every: usize,
    /// Proposed swaps.
    pub proposals: u64,
    /// Accepted swaps.
    pub accepted: u64,
    /// Valley penalty used.
    pub w_v: f64,
}

/// Tile statistics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileStats {
    /// Mean facet slope (zero by construction).
    pub mean: [f64; 2],
    /// Facet slope covariance.
    pub cov: [[f64; 2]; 2],
    /// Height range of the heightfield, mm.
    pub relief_mm: f64,
    /// Final arrangement energy.
    pub energy: Energy,
    /// Mean energy of random arrangements.
    pub energy_random: Energy,
    /// Sampling quality.
    pub sampling: SamplingStats,
    /// Steps at facet edges.
    pub seams: SeamStats,
    /// Annealing details.
    pub anneal: AnnealRecord,
}

/// The on-disk form of a [`Tile`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileFile {
    /// [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// Provenance.
    pub source: Source,
    /// The configuration used.
    pub config: FacetsConfig,
    /// Facets.
    pub facets: FacetsRecord,
    /// The heightfield.
    pub heightfield: HeightfieldRecord,
    /// Statistics.
    pub stats: TileStats,
    /// A tile refined as a continuous surface: how (absent for facets; the heightfield is then the surface,
    /// the facets what it started from).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refined: Option<super::Refinement>,
}

/// A `tile.json` (or the heightfield it names) that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum TileFileError {
    /// The file could not be read.
    #[error(transparent)]
    Read(#[from] crate::base::io::ReadError),
    /// The heightfield file is not a 2D float64 array.
    #[error(transparent)]
    Npy(#[from] crate::base::npy::NpyError),
    /// The content is wrong.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the key.
        reason: String,
    },
}

impl TileFile {
    /// Describe a tile whose heights are written to `npy_name` beside the JSON.
    pub fn new(tile: &Tile, source: Source, npy_name: &str) -> Self {
        let a = &tile.arrangement;
        let hf = &tile.heightfield;
        let (lo, hi) = hf.range();
        let AnnealReport {
            energy,
            energy_random,
            trace,
            trace_every,
            proposals,
            accepted,
            w_v,
        } = tile.anneal.clone();
        Self {
            format: FORMAT.into(),
            version: VERSION,
            source,
            config: tile.config,
            facets: FacetsRecord {
                w: a.w,
                h: a.h,
                facet_mm: tile.config.facet_mm,
                p: a.p.clone(),
                q: a.q.clone(),
                z_mm: tile.z_mm.clone(),
                index: a.index.clone(),
                curvature_per_mm: a.curvature_per_mm.clone(),
            },
            heightfield: HeightfieldRecord {
                file: npy_name.into(),
                nx: hf.nx,
                ny: hf.ny,
                pitch_mm: hf.pitch_mm,
                periodic: hf.periodic,
                min_mm: lo,
                max_mm: hi,
            },
            stats: TileStats {
                mean: tile.slope_stats.mean,
                cov: tile.slope_stats.cov,
                relief_mm: hi - lo,
                energy,
                energy_random,
                sampling: tile.sampling,
                seams: tile.seams,
                anneal: AnnealRecord {
                    trace,
                    trace_every,
                    proposals,
                    accepted,
                    w_v,
                },
            },
            refined: tile.refined,
        }
    }

    /// Serialise to JSON text (pretty, it is read by people too).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("TileFile serialises")
    }

    /// Read and validate `tile.json`.
    pub fn read(path: &Path) -> Result<Self, TileFileError> {
        let text = crate::base::io::read_to_string(path)?;
        let invalid = |reason: String| TileFileError::Invalid {
            path: path.to_path_buf(),
            reason,
        };
        let f: TileFile = serde_json::from_str(&text).map_err(|e| invalid(format!("not a valid tile.json: {e}")))?;
        if f.format != FORMAT || f.version != VERSION {
            return Err(invalid(format!(
                "format {} version {}, expected {FORMAT} version {VERSION}",
                f.format, f.version
            )));
        }
        let n = f
            .facets
            .w
            .checked_mul(f.facets.h)
            .ok_or_else(|| invalid(format!("\"facets\" is {}×{}: too many", f.facets.w, f.facets.h)))?;
        for (key, len) in [
            ("p", f.facets.p.len()),
            ("q", f.facets.q.len()),
            ("z_mm", f.facets.z_mm.len()),
        ] {
            if len != n {
                return Err(invalid(format!(
                    "\"facets.{key}\" has {len} values, expected w·h = {n}"
                )));
            }
        }
        Ok(f)
    }

    /// The path of the heightfield file of a tile.json at `json_path`.
    pub fn npy_path(&self, json_path: &Path) -> PathBuf {
        json_path
            .parent()
            .unwrap_or(Path::new("."))
            .join(&self.heightfield.file)
    }

    /// Load the heightfield the tile describes, checking it matches the description.
    pub fn load_heightfield(&self, json_path: &Path) -> Result<Heightfield, TileFileError> {
        let p = self.npy_path(json_path);
        let (rows, cols, z) = crate::base::npy::read_f64_2d(&p)?;
        let invalid = |reason: String| TileFileError::Invalid {
            path: p.clone(),
            reason,
        };
        if rows != self.heightfield.ny || cols != self.heightfield.nx {
            return Err(invalid(format!(
                "shape ({rows}, {cols}) but tile.json says ({}, {})",
                self.heightfield.ny, self.heightfield.nx
            )));
        }
        let hf = Heightfield {
            nx: cols,
            ny: rows,
            pitch_mm: self.heightfield.pitch_mm,
            periodic: self.heightfield.periodic,
            z_mm: z,
        };
        hf.check_invariants().map_err(|e| invalid(e.0))?;
        Ok(hf)
    }
}
