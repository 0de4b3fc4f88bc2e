//! A measured surface: an X3P scan (ISO 25178-72) or a `.npy` heightfield in mm with its pitch, its missing
//! points, the levelling every use of it starts with, and its slopes.
//!
//! Shared by `analyze` (a scan's NDF and BRDF) and the BRDF stage (a scan as a job's target). Missing points
//! are kept as a mask: the heightfield has them filled by iterated averaging of valid neighbours
//! ([`crate::base::x3p::X3p::heightfield`]), so filters and FFTs see a whole grid, and every slope that
//! touches a missing point is left out.

use crate::base::heightfield::Heightfield;
use std::path::{Path, PathBuf};

/// Pitches a `.npy` heightfield may be given, µm: from an atomic-force scan's nanometres to a coarse
/// profilometer's tenth of a metre.
pub const PITCH_UM: (f64, f64) = (1e-3, 1e5);

/// A scan could not be read or used.
#[derive(Debug, thiserror::Error)]
pub enum ScanError {
    /// The X3P file could not be read.
    #[error(transparent)]
    X3p(#[from] crate::base::x3p::X3pError),
    /// The `.npy` file could not be read (the error names it).
    #[error(transparent)]
    Npy(#[from] crate::base::npy::NpyError),
    /// The input is unusable (named file, reason).
    #[error("{path}: {message}")]
    Input {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// A measured surface with its missing points.
#[derive(Clone, Debug)]
pub struct Scan {
    /// The file it was read from.
    pub path: PathBuf,
    /// Heights in mm (not periodic), missing points filled from their neighbours.
    pub hf: Heightfield,
    /// `valid[k]`: point `k` was measured.
    pub valid: Vec<bool>,
    /// Number of missing points.
    pub missing: usize,
    /// What the reader noticed but read anyway.
    pub warnings: Vec<String>,
}

impl Scan {
    /// Read an X3P file, or a `.npy` heightfield in mm (NaN = missing) with its pitch in µm.
    pub fn read(path: &Path, pitch_um: Option<f64>) -> Result<Self, ScanError> {
        let input = |message: String| ScanError::Input {
            path: path.to_path_buf(),
            message,
        };
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let x3p = match ext.as_str() {
            "x3p" if pitch_um.is_some() => {
                return Err(input(
                    "an X3P file carries its own pitch: give a pitch only for a .npy".into(),
                ))
            }
            "x3p" => crate::base::x3p::read(path)?,
            "npy" => {
                let pitch = pitch_um.ok_or_else(|| input("a .npy heightfield needs its pitch in µm".into()))?;
                if !(PITCH_UM.0..=PITCH_UM.1).contains(&pitch) {
                    return Err(input(format!(
                        "the pitch must be in [{}, {}] µm, got {pitch:e}",
                        PITCH_UM.0, PITCH_UM.1
                    )));
                }
                let (ny, nx, z) = crate::base::npy::read_f64_2d(path)?;
                if nx.checked_mul(ny).is_none_or(|n| n > crate::base::x3p::MAX_POINTS) {
                    return Err(input(format!(
                        "{nx}×{ny} points: at most {} (as for an X3P file)",
                        crate::base::x3p::MAX_POINTS
                    )));
                }
                let valid: Vec<bool> = z.iter().map(|v| v.is_finite()).collect();
                crate::base::x3p::X3p::from_grid(nx, ny, pitch * 1e-3, z, valid)
            }
            _ => return Err(input("expected a .x3p or .npy file".into())),
        };
        let missing = x3p.invalid_count();
        let hf = x3p.heightfield().map_err(|e| input(e.to_string()))?;
        if hf.nx < 3 || hf.ny < 3 {
            return Err(input(format!(
                "{}×{} points: a slope needs at least 3×3 points",
                hf.nx, hf.ny
            )));
        }
        Ok(Self {
            path: path.to_path_buf(),
            hf,
            valid: x3p.valid,
            missing,
            warnings: x3p.warnings,
        })
    }

    /// A scan of a heightfield with every point measured (a simulated cut, a test surface).
    pub fn whole(path: &Path, hf: Heightfield) -> Self {
        let n = hf.z_mm.len();
        Self {
            path: path.to_path_buf(),
            hf,
            valid: vec![true; n],
            missing: 0,
            warnings: Vec::new(),
        }
    }

    /// Remove the least-squares plane through the measured points (the filled ones follow it); returns the
    /// plane's slopes `(∂z/∂x, ∂z/∂y)`.
    pub fn level(&mut self) -> [f64; 2] {
        remove_plane(&mut self.hf.z_mm, &self.valid, self.hf.nx, self.hf.pitch_mm)
    }

    /// RMS height of the measured points, µm.
    pub fn rms_height_um(&self) -> f64 {
        let (s, n) = self
            .hf
            .z_mm
            .iter()
            .zip(&self.valid)
            .filter(|(_, v)| **v)
            .fold((0.0, 0usize), |(s, n), (z, _)| (s + z * z, n + 1));
        (s / n.max(1) as f64).sqrt() * 1e3
    }

    /// Central-difference slopes `(∂z/∂x, ∂z/∂y)` after an optional Gaussian pre-filter of σ = `filter_um`
    /// (seed §5: detail below the scale the light resolves has little influence on the BRDF), at every point
    /// whose four neighbours and itself were measured; the outermost row and column are left out.
    ///
    /// The filter runs over the filled heightfield, so a filtered height near a missing point leans on the
    /// neighbours' average there; the slopes of the missing points themselves are always left out.
    pub fn slopes(&self, filter_um: f64) -> Vec<(f64, f64)> {
        let filtered;
        let hf = if filter_um > 0.0 {
            filtered = crate::base::surface::gaussian(&self.hf, filter_um * 1e-3);
            &filtered
        } else {
            &self.hf
        };
        crate::base::x3p::masked_slopes(&hf.z_mm, &self.valid, hf.nx, [hf.pitch_mm; 2], 1)
    }
}

/// Remove the least-squares plane `z = a + b x + c y` through the points with `valid` set from every point;
/// returns `[b, c]`.
pub fn remove_plane(z: &mut [f64], valid: &[bool], nx: usize, pitch_mm: f64) -> [f64; 2] {
    let Some([a, b, c]) = fit_plane(z, valid, nx, pitch_mm) else {
        return [0.0, 0.0];
    };
    for (k, v) in z.iter_mut().enumerate() {
        let (x, y) = ((k % nx) as f64 * pitch_mm, (k / nx) as f64 * pitch_mm);
        *v -= a + b * x + c * y;
    }
    [b, c]
}

/// The least-squares plane `z = a + b x + c y` through the points with `valid` set, `x = i·pitch`,
/// `y = j·pitch` from point 0; `[a, b, c]`, or `None` when the points do not fix a plane.
#[allow(clippy::needless_range_loop)] // Gauss–Jordan on a 3×4 matrix reads best with indices
pub fn fit_plane(z: &[f64], valid: &[bool], nx: usize, pitch_mm: f64) -> Option<[f64; 3]> {
    let mut s = [[0.0f64; 4]; 3];
    for (k, v) in z.iter().enumerate() {
        if !valid[k] {
            continue;
        }
        let (x, y) = ((k % nx) as f64 * pitch_mm, (k / nx) as f64 * pitch_mm);
        let r = [1.0, x, y];
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += r[i] * r[j];
            }
            s[i][3] += r[i] * v;
        }
    }
    for c in 0..3 {
        let p = s[c][c];
        if p.abs() < 1e-300 {
            return None;
        }
        for r in 0..3 {
            if r != c {
                let f = s[r][c] / p;
                for k in 0..4 {
                    s[r][k] -= f * s[c][k];
                }
            }
        }
    }
    Some([s[0][3] / s[0][0], s[1][3] / s[1][1], s[2][3] / s[2][2]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(nx: usize, ny: usize, pitch_mm: f64, f: impl Fn(f64, f64) -> f64) -> Heightfield {
        let z_mm = (0..nx * ny)
            .map(|k| f((k % nx) as f64 * pitch_mm, (k / nx) as f64 * pitch_mm))
            .collect();
        Heightfield {
            nx,
            ny,
            pitch_mm,
            periodic: false,
            z_mm,
        }
    }

    #[test]
    fn levelling_removes_a_plane_exactly_and_reports_its_slopes() {
        let hf = field(40, 30, 0.01, |x, y| 0.3 + 0.02 * x - 0.05 * y);
        let mut s = Scan::whole(Path::new("plane"), hf);
        s.valid[7] = false; // a missing point does not move the fit of an exact plane
        let t = s.level();
        assert!((t[0] - 0.02).abs() < 1e-12 && (t[1] + 0.05).abs() < 1e-12, "{t:?}");
        assert!(s.hf.z_mm.iter().all(|z| z.abs() < 1e-12));
    }

    #[test]
    fn the_prefilter_scales_a_sinusoids_slopes_by_its_gaussian_transfer() {
        // z = a sin(2πx/L): slope variance (2πa/L)²/2; a Gaussian of σ multiplies the amplitude by
        // exp(−(2πσ/L)²/2), so the variance by exp(−(2πσ/L)²). Central differences at pitch h see
        // sin(kh)/(kh) of the slope.
        let (l_mm, a_mm, h_mm) = (0.2, 0.002, 0.002);
        let hf = field(400, 8, h_mm, |x, _| a_mm * (std::f64::consts::TAU * x / l_mm).sin());
        let s = Scan::whole(Path::new("sine"), hf);
        let k = std::f64::consts::TAU / l_mm;
        let cd = ((k * h_mm).sin() / (k * h_mm)).powi(2);
        for sigma_um in [0.0, 10.0, 20.0] {
            // the clamped border distorts the filtered edge: measure three whole periods away from it
            let sl = s.slopes(sigma_um);
            let inner: Vec<f64> = sl
                .chunks(398)
                .flat_map(|row| row[49..349].iter().map(|p| p.0))
                .collect();
            let var = inner.iter().map(|p| p * p).sum::<f64>() / inner.len() as f64;
            let want = (k * a_mm).powi(2) / 2.0 * cd * (-(k * sigma_um * 1e-3).powi(2)).exp();
            assert!((var / want - 1.0).abs() < 0.01, "σ {sigma_um} µm: {var} vs {want}");
        }
    }

    #[test]
    fn slopes_touching_a_missing_point_are_left_out() {
        let hf = field(10, 10, 0.01, |x, y| x + 2.0 * y);
        let mut s = Scan::whole(Path::new("ramp"), hf);
        assert_eq!(s.slopes(0.0).len(), 64);
        s.valid[5 * 10 + 5] = false;
        s.missing = 1;
        // the point itself and its four neighbours lose their slope
        assert_eq!(s.slopes(0.0).len(), 59);
        assert!(s
            .slopes(0.0)
            .iter()
            .all(|(p, q)| (p - 1.0).abs() < 1e-9 && (q - 2.0).abs() < 1e-9));
    }
}
