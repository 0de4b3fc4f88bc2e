//! `ndf.json`: the versioned file format of the NDF stage.
//!
//! ```text
//! {
//!   "format": "brdfmill-ndf", "version": 1,
//!   "nx": 256, "ny": 256, "p_min": -1.732, "p_max": 1.732, "q_min": -1.732, "q_max": 1.732,
//!   "density":  [nx·ny numbers]   target P22, row-major, rows along q (density[j·nx + i] at p_i, q_j),
//!                                 cell centres p_i = p_min + (i + ½)(p_max − p_min)/nx; unit mass
//!   "observed": [nx·ny numbers]   the BRDF's half-angle distribution before deconvolution, same layout
//!   "stats":          {"mass", "mean": [p, q], "cov": [[pp, pq], [pq, qq]]}   of "density"
//!   "observed_stats": {same keys}                                             of "observed"
//!   "tilt_removed":   {"p", "q", "deg"}   mean slope subtracted from both grids (Section 7.2)
//!   "deconvolution":  {"method", "iterations", "max_iterations", "tolerance", "stopped_by", "last_change"}
//!   "source": "reflectance" | "measured-ndf",
//!   "brdf": "SPEC", "base": "SPEC" | null, "material": {"eta": [r,g,b], "k": [r,g,b]} | null,
//!   "config": {...}   the NdfConfig used
//!   "mass_beyond_grid": 0.0   fraction of the target's half-angle mass outside the grid (left out of both
//!                             grids; absent in older files, read as 0)
//!   "density_of": "target"    what "density" holds (absent in older files, read as "target"):
//!                             "target"  the deconvolved P22 the facets sample (ndf.json);
//!                             "design"  the design tile's facet slopes ⊛ the base lobe (ndf-design.json);
//!                             "milled"  the simulated cut's slopes ⊛ the polish lobe (ndf-milled.json)
//!   "density_outside_grid": 0.0   with "design" / "milled": the fraction of the surface's slopes beyond the
//!                             grid (left out of "density"); absent with "target"
//! }
//! ```
//!
//! `ndf-design.json` and `ndf-milled.json` hold exactly the grids the verdict measures: their "density"
//! against their "observed" (the target's observed distribution, the verdict's reference) gives
//! `metrics.json`'s `design` and `milled` figures — relative L1 `∑|d − o| / ∑o`, the Pearson correlation of
//! the cells and the Jensen–Shannon divergence in bits, over the whole grid.
//!
//! Readers check the version, the lengths, that every value is finite and non-negative, and that both
//! grids have unit mass (within 1e-3).

use super::{LrReport, Ndf, NdfConfig, Source, Tilt};
use crate::base::slope::{SlopeDomain, SlopeGrid, SlopeStats};
use crate::base::Invalid;
use crate::stages::brdf::ConductorIor;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The format tag.
pub const FORMAT: &str = "brdfmill-ndf";
/// The current format version.
pub const VERSION: u32 = 1;

/// Deconvolution report as stored (owned strings).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeconvolutionRecord {
    /// `"lucy-richardson"` or `"none"`.
    pub method: String,
    /// Iterations run.
    pub iterations: usize,
    /// Iteration limit.
    pub max_iterations: usize,
    /// Tolerance on the relative change.
    pub tolerance: f64,
    /// `"tolerance"`, `"count"` or `"none"`.
    pub stopped_by: super::StoppedBy,
    /// Relative L1 change of the last iteration.
    pub last_change: f64,
}

impl From<LrReport> for DeconvolutionRecord {
    fn from(r: LrReport) -> Self {
        Self {
            method: r.method.to_string(),
            iterations: r.iterations,
            max_iterations: r.max_iterations,
            tolerance: r.tolerance,
            stopped_by: r.stopped_by,
            last_change: if r.last_change.is_finite() { r.last_change } else { 0.0 },
        }
    }
}

/// The on-disk form of an [`Ndf`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NdfFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// Format version ([`VERSION`]).
    pub version: u32,
    /// The slope grid (`nx`, `ny`, `p_min`, `p_max`, `q_min`, `q_max` at the top level of the JSON).
    #[serde(flatten)]
    pub domain: SlopeDomain,
    /// Target `P22`, row-major, rows along q.
    pub density: Vec<f64>,
    /// Observed half-angle distribution, same layout.
    pub observed: Vec<f64>,
    /// Statistics of `density`.
    pub stats: SlopeStats,
    /// Statistics of `observed`.
    pub observed_stats: SlopeStats,
    /// The tilt removed.
    pub tilt_removed: Tilt,
    /// What the deconvolution did.
    pub deconvolution: DeconvolutionRecord,
    /// Where the half-angle distribution came from.
    pub source: Source,
    /// Target BRDF spec.
    pub brdf: String,
    /// Base lobe spec.
    pub base: Option<String>,
    /// Fabrication material.
    pub material: Option<ConductorIor>,
    /// Configuration used.
    pub config: NdfConfig,
    /// Fraction of the target's half-angle mass outside the slope grid (left out of both distributions).
    #[serde(default)]
    pub mass_beyond_grid: f64,
    /// What `density` holds.
    #[serde(default)]
    pub density_of: DensityOf,
    /// With a surface's density (`design`, `milled`): the fraction of its slopes beyond the grid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density_outside_grid: Option<f64>,
}

/// What an NDF file's `density` holds (`"density_of"`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DensityOf {
    /// The deconvolved target `P22` the facets sample (`ndf.json`).
    #[default]
    Target,
    /// The design tile's facet slopes convolved with the base lobe (`ndf-design.json`).
    Design,
    /// The simulated cut's slopes convolved with the polish lobe (`ndf-milled.json`).
    Milled,
    /// A scan of the milled part measured as the cut is (`ndf-scan.json` of `brdfmill compare`).
    Scan,
}

/// An `ndf.json` that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum NdfFileError {
    /// A file could not be opened or read.
    #[error(transparent)]
    Io(#[from] crate::base::io::ReadError),
    /// Not valid JSON of this format.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong, naming the key.
        reason: String,
    },
}

impl From<&Ndf> for NdfFile {
    fn from(n: &Ndf) -> Self {
        let d = n.target.domain;
        Self {
            format: FORMAT.into(),
            version: VERSION,
            domain: d,
            density: n.target.density.clone(),
            observed: n.observed.density.clone(),
            stats: n.stats,
            observed_stats: n.observed_stats,
            tilt_removed: n.tilt,
            deconvolution: n.deconvolution.into(),
            source: n.source,
            brdf: n.brdf_spec.clone(),
            base: n.base_spec.clone(),
            material: n.material,
            config: n.config,
            mass_beyond_grid: n.mass_beyond_grid,
            density_of: DensityOf::Target,
            density_outside_grid: None,
        }
    }
}

impl NdfFile {
    /// The file of a surface's slope distribution measured against `n`'s target (`ndf-design.json`,
    /// `ndf-milled.json`): `density` is `surface` on `n`'s grid, `observed` the target's observed
    /// distribution the verdict compares it with, the rest as in `n`'s `ndf.json`; `outside_grid` is the
    /// fraction of the surface's slopes beyond the grid.
    pub fn of_surface(n: &Ndf, what: DensityOf, surface: &SlopeGrid, outside_grid: f64) -> Self {
        let mut f = Self::from(n);
        debug_assert_eq!(surface.domain, f.domain, "a surface's NDF on its target's grid");
        f.density = surface.density.clone();
        f.stats = surface.stats();
        f.density_of = what;
        f.density_outside_grid = Some(outside_grid);
        f
    }

    /// The slope domain.
    pub fn domain(&self) -> SlopeDomain {
        self.domain
    }

    /// The target density as a grid.
    pub fn target(&self) -> SlopeGrid {
        SlopeGrid {
            domain: self.domain(),
            density: self.density.clone(),
        }
    }

    /// The observed density as a grid.
    pub fn observed(&self) -> SlopeGrid {
        SlopeGrid {
            domain: self.domain(),
            density: self.observed.clone(),
        }
    }

    /// Check the invariants readers rely on; the message names the key.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.format != FORMAT {
            return Err(Invalid(format!(
                "\"format\" is \"{}\", expected \"{FORMAT}\"",
                self.format
            )));
        }
        if self.version != VERSION {
            return Err(Invalid(format!(
                "\"version\" is {}, this build reads version {VERSION}",
                self.version
            )));
        }
        for (key, values) in [("density", &self.density), ("observed", &self.observed)] {
            let g = SlopeGrid {
                domain: self.domain(),
                density: values.clone(),
            };
            g.check_invariants().map_err(|e| format!("\"{key}\": {e}"))?;
            let m = g.mass();
            if (m - 1.0).abs() > 1e-3 {
                return Err(Invalid(format!(
                    "\"{key}\" has mass {m:.6}, expected 1 (a normalised density)"
                )));
            }
        }
        Ok(())
    }

    /// Serialise to JSON text.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("NdfFile serialises")
    }

    /// Write atomically.
    pub fn write(&self, path: &Path) -> Result<(), crate::base::io::WriteError> {
        crate::base::io::write_atomic(path, self.to_json().as_bytes())
    }

    /// Read and validate.
    pub fn read(path: &Path) -> Result<Self, NdfFileError> {
        let text = crate::base::io::read_to_string(path)?;
        let invalid = |reason: String| NdfFileError::Invalid {
            path: path.to_path_buf(),
            reason,
        };
        let f: NdfFile = serde_json::from_str(&text).map_err(|e| invalid(format!("not a valid ndf.json: {e}")))?;
        f.validate().map_err(|e| invalid(e.0))?;
        Ok(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::brdf::Brdf;

    fn small() -> NdfFile {
        let cfg = NdfConfig {
            res: 32,
            ..Default::default()
        };
        let n = super::super::run(&cfg, &Brdf::parse("ggx:alpha=0.3").unwrap(), None).unwrap();
        NdfFile::from(&n)
    }

    #[test]
    fn round_trip_through_a_file() {
        let f = small();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ndf.json");
        f.write(&p).unwrap();
        let back = NdfFile::read(&p).unwrap();
        assert!(back == f, "ndf.json did not round-trip exactly");
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        for key in [
            "version", "nx", "ny", "p_min", "p_max", "q_min", "q_max", "density", "stats",
        ] {
            assert!(v.get(key).is_some(), "missing key {key}");
        }
        for key in ["mass", "mean", "cov"] {
            assert!(v["stats"].get(key).is_some(), "missing stats.{key}");
        }
    }

    #[test]
    fn invalid_files_are_refused_naming_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ndf.json");
        let mut f = small();
        f.density.iter_mut().for_each(|v| *v *= 2.0);
        f.write(&p).unwrap();
        let e = NdfFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("\"density\" has mass"), "{e}");
        let mut f = small();
        f.observed.pop();
        f.write(&p).unwrap();
        let e = NdfFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("\"observed\"") && e.contains("expected nx·ny"), "{e}");
        std::fs::write(&p, "{\"version\": 1}").unwrap();
        let e = NdfFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("not a valid ndf.json") && e.contains("ndf.json"), "{e}");
    }
}
