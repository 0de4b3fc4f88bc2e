//! A measured surface as the target: the NDF of a scan (X3P or `.npy`), used as the NDF of a microfacet
//! model — the heightfield → BRDF half of the seed's loop feeding its BRDF → heightfield half.
//!
//! The scan is levelled (its least-squares plane removed: the part's own normal is the mean of the scan's
//! plane, whatever the tilt it was measured at), optionally smoothed by a Gaussian of σ = `filter_um` (seed
//! §5: detail below the scale the light resolves has little influence on the BRDF), and its central-difference
//! slopes, each standing for one sample's projected area, are binned into the slope density
//! `P22(p, q)` (Eq. 6; [`crate::base::surface`]). `D(m) = P22(p, q) / cos⁴θm` then satisfies
//! `∫ D cos θm dω = 1`. The masking term is Smith's, from the density itself.
//!
//! The geometric estimate is what this module computes. The wave-optics estimate of the same scan (seed §4,
//! §6) needs the optics stage, which comes after this one: the job computes it and hands its density in
//! ([`SurfaceNdf::with_density`]).

use super::BrdfError;
use crate::base::geometry::{normal_to_slope, Vec3};
use crate::base::scan::Scan;
use crate::base::slope::{SlopeDomain, SlopeGrid, SmithTable};
use crate::base::surface::ndf_of_slopes;
use std::path::{Path, PathBuf};

/// The slope grid a scan's NDF is binned on: 512 × 512 cells over `|p|, |q| ≤ tan 80°` — beyond the NDF
/// stage's grid, so that the stage measures how much of the scan lies outside its own, in cells of 0.022
/// (about 1.3° near the normal, the NDF stage's 0.0135 coarsened so that each cell of a typical scan's lobe
/// holds hundreds of slopes).
pub fn domain() -> SlopeDomain {
    SlopeDomain::square(512, 80f64.to_radians().tan())
}

/// The largest pre-filter accepted, µm.
pub const MAX_FILTER_UM: f64 = 1000.0;

/// The widest pre-filter kernel accepted, samples (±3σ): a wider one costs that many multiply-adds per
/// point, twice.
pub const MAX_FILTER_TAPS: usize = 1024;

/// How a scan's NDF was estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Geometric optics: the histogram of the (pre-filtered) slopes.
    Geometric,
    /// Wave optics: the Kirchhoff slice at normal incidence mapped to half vectors (computed by the job).
    Wave,
}

/// The NDF of a measured surface.
#[derive(Clone, Debug)]
pub struct SurfaceNdf {
    /// The scan file.
    pub path: PathBuf,
    /// Samples `(x, y)`.
    pub size: [usize; 2],
    /// Pitch, µm.
    pub pitch_um: f64,
    /// Missing points of the scan.
    pub missing: usize,
    /// The levelling plane's slopes `(∂z/∂x, ∂z/∂y)`.
    pub tilt_removed: [f64; 2],
    /// RMS height after levelling, µm.
    pub rms_height_um: f64,
    /// σ of the Gaussian pre-filter, µm (0: none).
    pub filter_um: f64,
    /// Slopes binned.
    pub slope_count: usize,
    /// Fraction of those slopes steeper than the grid's 80° (left out of the density; counted in the NDF
    /// stage's mass beyond its grid).
    pub outside: f64,
    /// How the density below was estimated.
    pub method: Method,
    /// What the reader noticed but read anyway.
    pub warnings: Vec<String>,
    /// `P22` on [`domain`], unit mass.
    density: SlopeGrid,
    /// Smith Λ of the density.
    smith: SmithTable,
}

impl SurfaceNdf {
    /// Read a scan (a `.npy` needs `pitch_um`) and estimate its NDF geometrically after a Gaussian
    /// pre-filter of σ = `filter_um` µm.
    pub fn read(path: &Path, pitch_um: Option<f64>, filter_um: f64) -> Result<Self, BrdfError> {
        let format = |reason: String| BrdfError::Format {
            path: path.to_path_buf(),
            reason,
        };
        if !(0.0..=MAX_FILTER_UM).contains(&filter_um) {
            return Err(format(format!(
                "`filter_um` must be in [0, {MAX_FILTER_UM}] µm, got {filter_um}"
            )));
        }
        let mut scan = Scan::read(path, pitch_um)?;
        let taps = 6.0 * filter_um / (scan.hf.pitch_mm * 1e3);
        if taps > MAX_FILTER_TAPS as f64 {
            return Err(format(format!(
                "`filter_um` = {filter_um} µm spans {taps:.0} samples of the scan's {:.4} µm pitch (±3σ); at most \
                 {MAX_FILTER_TAPS}: resample the scan coarser first",
                scan.hf.pitch_mm * 1e3
            )));
        }
        let tilt_removed = scan.level();
        let slopes = scan.slopes(filter_um);
        if slopes.is_empty() {
            return Err(format("no slope could be formed from measured points".into()));
        }
        let (density, outside) = ndf_of_slopes(&slopes, domain());
        if density.mass() <= 0.0 {
            return Err(format(
                "every slope of the scan is steeper than 80°: no NDF to aim at".into(),
            ));
        }
        Ok(Self {
            path: path.to_path_buf(),
            size: [scan.hf.nx, scan.hf.ny],
            pitch_um: scan.hf.pitch_mm * 1e3,
            missing: scan.missing,
            tilt_removed,
            rms_height_um: scan.rms_height_um(),
            filter_um,
            slope_count: slopes.len(),
            outside,
            method: Method::Geometric,
            warnings: scan.warnings,
            smith: SmithTable::new(&density, 48, 48),
            density,
        })
    }

    /// The same scan with its density estimated otherwise (the wave-optics estimate the job computes):
    /// resampled onto [`domain`] and normalised, `outside` the share of the scan that estimate cannot
    /// represent (counted beyond the grid). Refused when it has no mass there.
    pub fn with_density(&self, grid: &SlopeGrid, method: Method, outside: f64) -> Result<Self, BrdfError> {
        let mut density = SlopeGrid::from_fn(domain(), |p, q| grid.sample(p, q).max(0.0));
        let mass = density.normalise();
        if mass.is_nan() || mass <= 0.0 {
            return Err(BrdfError::Format {
                path: self.path.clone(),
                reason: format!("the {method:?} estimate of the scan's NDF has no mass within 80°"),
            });
        }
        Ok(Self {
            smith: SmithTable::new(&density, 48, 48),
            density,
            method,
            outside: outside.clamp(0.0, 1.0),
            ..self.clone()
        })
    }

    /// The slope density `P22` (unit mass on [`domain`]).
    pub fn density(&self) -> &SlopeGrid {
        &self.density
    }

    /// The normalised NDF `D(wm) = P22 / cos⁴θm`.
    pub fn d(&self, wm: &Vec3) -> f64 {
        match normal_to_slope(wm) {
            Some((p, q)) => self.density.sample(p, q).max(0.0) / wm.z.powi(4),
            None => 0.0,
        }
    }

    /// Separable Smith masking from the density's own Λ.
    pub fn g(&self, wi: &Vec3, wo: &Vec3, wm: &Vec3) -> f64 {
        self.smith.g2(wi, wo, wm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::SlopeStats;

    fn write_npy(path: &Path, nx: usize, ny: usize, f: impl Fn(usize, usize) -> f64) {
        let z: Vec<f64> = (0..nx * ny).map(|k| f(k % nx, k / nx)).collect();
        crate::base::npy::write_f64_2d(path, ny, nx, &z).unwrap();
    }

    #[test]
    fn a_tilted_roof_scan_aims_at_its_two_facets() {
        // a triangle wave of slopes ±0.3 along x on a 0.1 tilt along y: levelling removes the tilt, and the
        // NDF is two equal spikes at p = ±0.3, q = 0 (closed form: mean 0, var_p 0.09, var_q 0)
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("roof.npy");
        let (period, h) = (40usize, 1e-3);
        write_npy(&path, 400, 200, |i, j| {
            let t = (i % period) as f64;
            let tri = if t < period as f64 / 2.0 { t } else { period as f64 - t };
            0.3 * tri * h + 0.1 * j as f64 * h
        });
        let s = SurfaceNdf::read(&path, Some(1.0), 0.0).unwrap();
        assert!((s.tilt_removed[1] - 0.1).abs() < 1e-9, "{:?}", s.tilt_removed);
        let SlopeStats { mean, cov, .. } = s.density().stats();
        // the crests' central differences read 0: 2 of every 40 columns
        let want = 0.09 * (period - 2) as f64 / period as f64;
        assert!(mean[0].abs() < 1e-3 && mean[1].abs() < 1e-3, "{mean:?}");
        assert!((cov[0][0] / want - 1.0).abs() < 0.02, "{} vs {want}", cov[0][0]);
        // q = 0 lies on a cell edge of the grid: splatting shares it between the two cells beside it, half a
        // cell either way
        let half_cell = domain().dq() / 2.0;
        assert!(cov[1][1] <= half_cell * half_cell * 1.001, "{}", cov[1][1]);
        // D of a facet normal is large, of a normal between the facets small
        let on = crate::base::geometry::slope_to_normal(0.3, 0.0);
        let between = crate::base::geometry::slope_to_normal(0.15, 0.0);
        assert!(s.d(&on) > 100.0 * s.d(&between).max(1e-12));
    }

    #[test]
    fn refuses_a_bad_filter_and_a_npy_without_pitch() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flat.npy");
        write_npy(&path, 8, 8, |i, j| (i * j) as f64 * 1e-4);
        let e = SurfaceNdf::read(&path, None, 0.0).unwrap_err().to_string();
        assert!(e.contains("flat.npy") && e.contains("pitch"), "{e}");
        let e = SurfaceNdf::read(&path, Some(1.0), -1.0).unwrap_err().to_string();
        assert!(e.contains("filter_um"), "{e}");
    }
}
