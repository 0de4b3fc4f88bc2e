//! RGL material database `.bsdf` files (Dupuy & Jakob 2018, "An Adaptive Parameterization for Efficient
//! Material Acquisition and Rendering"), stored in the `tensor_file` container.
//!
//! **Container**: [`TensorFile`] (`tensor.rs`).
//!
//! **Parameterisation.** Angles map to the unit square by `u = √(θ / (π/2))` and `v = (φ + π) / 2π`. A grid
//! of `n` vertices spans `[0, 1]` inclusive (vertex `j` at `j/(n−1)`) and is interpolated bilinearly.
//! - `ndf[φ, θ]`: the measured NDF `D(wm)`, normalised by projected area (to about 1%).
//! - `sigma[φ, θ]`: the projected area `σ(wi) = ∫ D(m) ⟨m, wi⟩⁺ dm = cosθi / G1(wi)`.
//! - `vndf[φi, θi, y, x]`: per incident direction, the visible NDF over `(u_θm, v_φm)`; its inverse
//!   cumulative distribution maps a half vector to the 2D `sample` coordinate of the reflectance grid.
//! - `rgb[φi, θi, channel, y, x]`: reflectance over `sample`, with `f·cosθo = rgb · D(wm) / (4 σ(wi))`
//!   when `jacobian` is set.
//!
//! Parameter grids (`theta_i`, `phi_i`) are interpolated linearly; with a single `phi_i` (or two) the
//! material is isotropic and azimuths are taken relative to `φi`.

pub use super::tensor::{Field, TensorFile};
use super::{BrdfError, Rgb};
use crate::base::geometry::{cos_sin_phi, Vec3};
use crate::base::Invalid;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::path::Path;

/// A bilinear grid over `[0, 1]²` with `nx × ny` vertices (x the fast axis).
#[derive(Clone, Debug)]
pub(super) struct Grid2 {
    pub(super) nx: usize,
    pub(super) ny: usize,
    pub(super) v: Vec<f64>,
}

/// Cell index and fraction of a coordinate in `[0, 1]` on `n` vertices.
#[inline]
fn cell(u: f64, n: usize) -> (usize, f64) {
    let x = u.clamp(0.0, 1.0) * (n - 1) as f64;
    let i = (x.floor() as usize).min(n - 2);
    (i, x - i as f64)
}

impl Grid2 {
    /// The value at a direction's grid coordinate, `(θ, φ)` parameterised as [`uv`] does (an `ndf` or
    /// `sigma` grid, `[φ, θ]` in the file).
    pub(super) fn at(&self, w: &Vec3) -> f64 {
        let (u, v) = uv(w);
        self.eval(u, v)
    }

    fn eval(&self, x: f64, y: f64) -> f64 {
        let (i, fx) = cell(x, self.nx);
        let (j, fy) = cell(y, self.ny);
        let at = |a: usize, b: usize| self.v[b * self.nx + a];
        (1.0 - fy) * ((1.0 - fx) * at(i, j) + fx * at(i + 1, j))
            + fy * ((1.0 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1))
    }
}

/// The inverse-CDF warp of one `vndf` slice: density and its cumulative sums (normalised).
#[derive(Clone, Debug)]
pub(super) struct Warp {
    d: Vec<f64>,
    /// Row-wise cumulative trapezoid sums, `cc[y·nx + x]`.
    cc: Vec<f64>,
    /// Marginal cumulative sums over rows.
    mc: Vec<f64>,
}

impl Warp {
    /// The warp of the density `d` on `nx × ny` vertices (normalised here).
    pub(super) fn new(d: &[f64], nx: usize, ny: usize) -> Self {
        let mut cc = vec![0.0; nx * ny];
        for y in 0..ny {
            for x in 1..nx {
                cc[y * nx + x] = cc[y * nx + x - 1] + 0.5 * (d[y * nx + x - 1] + d[y * nx + x]);
            }
        }
        let mut mc = vec![0.0; ny];
        for y in 1..ny {
            mc[y] = mc[y - 1] + 0.5 * (cc[(y - 1) * nx + nx - 1] + cc[y * nx + nx - 1]);
        }
        let total = mc[ny - 1];
        let norm = if total > 0.0 { 1.0 / total } else { 0.0 };
        Self {
            d: d.iter().map(|v| v * norm).collect(),
            cc: cc.iter().map(|v| v * norm).collect(),
            mc: mc.iter().map(|v| v * norm).collect(),
        }
    }
}

/// A measured RGL BSDF.
#[derive(Clone, Debug)]
pub struct RglBsdf {
    /// The file's own description.
    pub description: String,
    /// Incident polar angles of the measurement (radians).
    pub theta_i: Vec<f64>,
    /// Incident azimuths (radians).
    pub phi_i: Vec<f64>,
    ndf: Grid2,
    sigma: Grid2,
    /// vndf warps per `(φi, θi)` slice.
    vndf: Vec<Warp>,
    vndf_n: (usize, usize),
    /// rgb grids per `(φi, θi, channel)`.
    rgb: Vec<Grid2>,
    jacobian: bool,
    isotropic: bool,
}

#[inline]
fn theta2u(theta: f64) -> f64 {
    (theta.max(0.0) / FRAC_PI_2).sqrt()
}

#[inline]
fn phi2u(phi: f64) -> f64 {
    (phi + PI) / TAU
}

/// A direction's grid coordinate `(√(θ / (π/2)), (φ + π) / 2π)`, `φ` in `[−π, π]`.
pub(super) fn uv(w: &Vec3) -> (f64, f64) {
    let (t, p) = RglBsdf::angles(w);
    (theta2u(t), phi2u(p))
}

/// Linear interpolation weights over a sorted parameter list.
fn param_weights(v: &[f64], x: f64) -> [(usize, f64); 2] {
    if v.len() < 2 {
        return [(0, 1.0), (0, 0.0)];
    }
    let i = v.iter().rposition(|a| *a <= x).unwrap_or(0).min(v.len() - 2);
    let w = ((x - v[i]) / (v[i + 1] - v[i])).clamp(0.0, 1.0);
    [(i, 1.0 - w), (i + 1, w)]
}

impl RglBsdf {
    /// Read and validate an RGL `.bsdf` file.
    pub fn read(path: &Path) -> Result<Self, BrdfError> {
        let bytes = crate::base::io::read(path)?;
        Self::from_bytes(&bytes).map_err(|reason| BrdfError::Format {
            path: path.to_path_buf(),
            reason: reason.to_string(),
        })
    }

    /// Parse from the bytes of a `.bsdf` file.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, Invalid> {
        let tf = TensorFile::parse(bytes)?;
        let description = tf
            .fields
            .get("description")
            .map(|f| f.data.iter().map(|b| *b as u8 as char).collect())
            .unwrap_or_default();
        let theta_i = tf.field("theta_i", 1)?.data.clone();
        let phi_i = tf.field("phi_i", 1)?.data.clone();
        let (nt, np) = (theta_i.len(), phi_i.len());
        if nt == 0 || np == 0 {
            return Err(Invalid("theta_i and phi_i must not be empty".into()));
        }
        // radians; f32 in the file, so π/2 may come out a few ulps above
        // azimuths: a reader takes φ = atan2(y, x) in [−π, π]; published isotropic files hold one at 0
        for (name, axis, lo, hi) in [("theta_i", &theta_i, 0.0, FRAC_PI_2), ("phi_i", &phi_i, -PI, TAU)] {
            if axis
                .iter()
                .any(|v| !(v.is_finite() && (lo - 1e-6..=hi + 1e-6).contains(v)))
            {
                return Err(Invalid(format!(
                    "`{name}` must hold angles in [{lo:.6}, {hi:.6}] rad, got {axis:?}"
                )));
            }
            if axis.windows(2).any(|w| w[1] <= w[0]) {
                return Err(Invalid(format!("`{name}` must be strictly increasing, got {axis:?}")));
            }
        }
        // An anisotropic file whose azimuths cover part of the circle relies on the reader folding incident
        // directions by its symmetry (Mitsuba's `reduction`); this reader does not fold, so it refuses them.
        if np > 2 && phi_i[np - 1] - phi_i[0] < TAU - 1e-3 {
            return Err(Invalid(format!(
                "`phi_i` spans {:.4} rad of azimuth: anisotropic files reduced by symmetry are not read (whole-circle [−π, π] files are)",
                phi_i[np - 1] - phi_i[0]
            )));
        }
        let grid2 = |name: &str| -> Result<Grid2, Invalid> {
            let f = tf.field(name, 2)?;
            let (ny, nx) = (f.shape[0], f.shape[1]);
            if nx < 2 || ny < 2 {
                return Err(Invalid(format!(
                    "field `{name}` shape {:?}: need at least 2×2",
                    f.shape
                )));
            }
            // RGL stores [φ, θ]: θ is the long axis (128 in the published files), φ has 2 rows when isotropic
            if nx < 8 || ny > nx {
                return Err(Invalid(format!(
                    "field `{name}` shape {:?}: expected [φ, θ] with at least 8 θ samples and no more φ than θ (are the axes swapped?)",
                    f.shape
                )));
            }
            if let Some(v) = f.data.iter().find(|v| !(v.is_finite() && v.abs() <= 1e12)) {
                return Err(Invalid(format!(
                    "field `{name}` holds {v}: not a finite density of at most 1e12"
                )));
            }
            Ok(Grid2 {
                nx,
                ny,
                v: f.data.clone(),
            })
        };
        let ndf = grid2("ndf")?;
        let sigma = grid2("sigma")?;
        if ndf.v.iter().chain(&sigma.v).any(|v| *v < 0.0) {
            return Err(Invalid("`ndf` and `sigma` must be non-negative".into()));
        }
        let vf = tf.field("vndf", 4)?;
        if vf.shape[0] != np || vf.shape[1] != nt || vf.shape[2] < 2 || vf.shape[3] < 2 {
            return Err(Invalid(format!(
                "field `vndf` shape {:?}, expected [{np}, {nt}, ≥2, ≥2]",
                vf.shape
            )));
        }
        let (vy, vx) = (vf.shape[2], vf.shape[3]);
        let vndf = vf.data.chunks_exact(vx * vy).map(|s| Warp::new(s, vx, vy)).collect();
        let rf = tf.field("rgb", 5)?;
        if rf.shape[0] != np || rf.shape[1] != nt || rf.shape[2] != 3 || rf.shape[3] < 2 || rf.shape[4] < 2 {
            return Err(Invalid(format!(
                "field `rgb` shape {:?}, expected [{np}, {nt}, 3, ≥2, ≥2]",
                rf.shape
            )));
        }
        let (ry, rx) = (rf.shape[3], rf.shape[4]);
        let rgb = rf
            .data
            .chunks_exact(rx * ry)
            .map(|s| Grid2 {
                nx: rx,
                ny: ry,
                v: s.to_vec(),
            })
            .collect();
        let jacobian = tf
            .fields
            .get("jacobian")
            .map(|f| f.data.first() == Some(&1.0))
            .unwrap_or(true);
        Ok(Self {
            description,
            theta_i,
            isotropic: np <= 2,
            phi_i,
            ndf,
            sigma,
            vndf,
            vndf_n: (vx, vy),
            rgb,
            jacobian,
        })
    }

    fn angles(w: &Vec3) -> (f64, f64) {
        let (c, s) = cos_sin_phi(w);
        (w.z.clamp(-1.0, 1.0).acos(), s.atan2(c))
    }

    /// The measured NDF `D(wm)` as stored (projected-area normalised to about 1%).
    pub fn ndf(&self, wm: &Vec3) -> f64 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        self.ndf.at(wm).max(0.0)
    }

    /// The stored projected area `σ(w) = cosθ / G1(w)`.
    pub fn sigma(&self, w: &Vec3) -> f64 {
        self.sigma.at(w)
    }

    /// `f(wi, wo)` in RGB (without the cosine), negatives clipped.
    pub fn eval(&self, wi: &Vec3, wo: &Vec3) -> Rgb {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return [0.0; 3];
        }
        let Some(wm) = crate::base::geometry::half_vector(wi, wo) else {
            return [0.0; 3];
        };
        let (ti, pi) = Self::angles(wi);
        let (tm, pm) = Self::angles(&wm);
        let um = (
            theta2u(tm),
            if self.isotropic {
                let v = phi2u(pm - pi);
                v - v.floor()
            } else {
                phi2u(pm)
            },
        );
        // Slice weights over (φi, θi).
        let wt = param_weights(&self.theta_i, ti);
        let wp = if self.isotropic {
            [(0, 1.0), (0, 0.0)]
        } else {
            param_weights(&self.phi_i, pi)
        };
        let nt = self.theta_i.len();
        let mut slices = [(0usize, 0.0f64); 4];
        for (a, (ip, fp)) in wp.iter().enumerate() {
            for (b, (it, ft)) in wt.iter().enumerate() {
                slices[a * 2 + b] = (ip * nt + it, fp * ft);
            }
        }
        let sample = self.invert_vndf(&slices, um);
        let jac = if self.jacobian {
            let s = self.sigma(wi);
            if s <= 0.0 {
                return [0.0; 3];
            }
            self.ndf(&wm) / (4.0 * s)
        } else {
            1.0
        };
        std::array::from_fn(|c| {
            let v: f64 = slices
                .iter()
                .filter(|(_, w)| *w > 0.0)
                .map(|(s, w)| w * self.rgb[s * 3 + c].eval(sample.0, sample.1))
                .sum();
            v.max(0.0) * jac / wo.z
        })
    }

    /// Map a half-vector coordinate to the reflectance grid's `sample` coordinate by the inverse cumulative
    /// distribution of the (slice-interpolated) vndf: continuous in both axes, bilinear density.
    fn invert_vndf(&self, slices: &[(usize, f64); 4], u: (f64, f64)) -> (f64, f64) {
        invert_blend(self.vndf_n, u, &|f| {
            slices
                .iter()
                .filter(|(_, w)| *w > 0.0)
                .map(|(s, w)| w * f(&self.vndf[*s]))
                .sum()
        })
    }
}

impl Warp {
    /// The inverse cumulative distribution of this one slice at `u` (what a reader does at a measured
    /// incident direction).
    pub(super) fn invert(&self, n: (usize, usize), u: (f64, f64)) -> (f64, f64) {
        invert_blend(n, u, &|f| f(self))
    }

    /// The forward warp: the `u` whose [`Warp::invert`] is `s`, by bisection on each axis (the marginal's
    /// coordinate depends on `u.1` alone and rises with it; the conditional's rises with `u.0`), to 2⁻⁵⁰.
    pub(super) fn sample(&self, n: (usize, usize), s: (f64, f64)) -> (f64, f64) {
        let solve = |target: f64, f: &dyn Fn(f64) -> f64| -> f64 {
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            for _ in 0..50 {
                let mid = 0.5 * (lo + hi);
                if f(mid) < target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        };
        let y = solve(s.1, &|v| self.invert(n, (0.5, v)).1);
        let x = solve(s.0, &|v| self.invert(n, (v, y)).0);
        (x, y)
    }
}

/// Reads a value of a warp (a closure over one [`Warp`]) blended over the slices that hold the direction.
type Blend<'a> = dyn Fn(&dyn Fn(&Warp) -> f64) -> f64 + 'a;

/// The inverse CDF of a bilinear density on `n = (nx, ny)` vertices over `[0, 1]²` (Mitsuba's continuous
/// `Marginal2D::invert`): the marginal over rows first, then the conditional along the row. `lerp` reads a
/// value of the warp, blended over the interpolated slices.
fn invert_blend(n: (usize, usize), u: (f64, f64), lerp: &Blend) -> (f64, f64) {
    let (nx, ny) = n;
    let (px, sx) = cell(u.0, nx);
    let (py, sy) = cell(u.1, ny);
    let v00 = lerp(&|w| w.d[py * nx + px]);
    let v10 = lerp(&|w| w.d[py * nx + px + 1]);
    let v01 = lerp(&|w| w.d[(py + 1) * nx + px]);
    let v11 = lerp(&|w| w.d[(py + 1) * nx + px + 1]);
    let c0 = (1.0 - sy) * v00 + sy * v01;
    let c1 = (1.0 - sy) * v10 + sy * v11;
    let r0 = lerp(&|w| w.cc[py * nx + nx - 1]);
    let r1 = lerp(&|w| w.cc[(py + 1) * nx + nx - 1]);
    let cc0 = lerp(&|w| w.cc[py * nx + px]);
    let cc1 = lerp(&|w| w.cc[(py + 1) * nx + px]);
    let mc = lerp(&|w| w.mc[py]);
    let row = (1.0 - sy) * r0 + sy * r1;
    let x = if row > 0.0 {
        (sx * (c0 + 0.5 * sx * (c1 - c0)) + (1.0 - sy) * cc0 + sy * cc1) / row
    } else {
        u.0
    };
    let y = sy * (r0 + 0.5 * sy * (r1 - r0)) + mc;
    (x.clamp(0.0, 1.0), y.clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::geometry::spherical;

    fn shared(name: &str) -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/rgl")
            .join(name)
    }

    #[test]
    fn anisotropic_files_reduced_by_symmetry_are_refused() {
        use crate::stages::brdf::tensor::{encode, Values};
        let angles = |v: &[f32]| Values::F32(v.to_vec());
        let file = |phi: &[f32]| {
            encode(&[
                ("theta_i", vec![2], angles(&[0.0, 1.0])),
                ("phi_i", vec![phi.len()], angles(phi)),
            ])
        };
        let e = RglBsdf::from_bytes(&file(&[-std::f32::consts::PI, -2.0, -std::f32::consts::FRAC_PI_2])).unwrap_err();
        assert!(e.contains("reduced by symmetry"), "{e}");
        // a whole-circle file gets past the azimuths (and stops at its missing grids)
        let e = RglBsdf::from_bytes(&file(&[-std::f32::consts::PI, 0.0, std::f32::consts::PI])).unwrap_err();
        assert!(e.contains("missing field `ndf`"), "{e}");
    }

    #[test]
    fn real_files_have_consistent_ndf_and_projected_area() {
        for name in ["paper_white_rgb.bsdf", "vch_golden_yellow_rgb.bsdf"] {
            let r = RglBsdf::read(&shared(name)).unwrap();
            assert!(!r.description.is_empty());
            // ∫ D cosθ dω ≈ 1 and σ(w) = ∫ D ⟨m, w⟩⁺ dω, both by quadrature in u-space (dense near θ = 0).
            let (nu, nphi) = (2000, 64);
            let wis = [spherical(0.0, 0.0), spherical(0.8, 0.0), spherical(1.3, 0.0)];
            let mut mass = 0.0;
            let mut proj = [0.0; 3];
            for iu in 0..nu {
                let u = (iu as f64 + 0.5) / nu as f64;
                let th = u * u * FRAC_PI_2;
                let jac = 2.0 * u * FRAC_PI_2 * th.sin() / nu as f64 * TAU / nphi as f64;
                for ip in 0..nphi {
                    let m = spherical(th, (ip as f64 + 0.5) / nphi as f64 * TAU);
                    let d = r.ndf(&m) * jac;
                    mass += d * m.z;
                    for (k, wi) in wis.iter().enumerate() {
                        proj[k] += d * m.dot(wi).max(0.0);
                    }
                }
            }
            assert!((mass - 1.0).abs() < 0.02, "{name}: ∫D cos = {mass}");
            for (k, wi) in wis.iter().enumerate() {
                let rel = proj[k] / r.sigma(wi) - 1.0;
                assert!(rel.abs() < 0.02, "{name}: σ mismatch {rel} at θi={}", wi.z.acos());
            }
        }
    }

    #[test]
    fn real_files_evaluate_to_plausible_albedo() {
        for name in ["paper_white_rgb.bsdf", "vch_golden_yellow_rgb.bsdf"] {
            let r = RglBsdf::read(&shared(name)).unwrap();
            for ti in [0.0f64, 0.6] {
                let wi = spherical(ti, 0.0);
                let (nu, nphi) = (400, 128);
                let mut a = [0.0; 3];
                for iu in 0..nu {
                    let u = (iu as f64 + 0.5) / nu as f64;
                    let th = u * u * FRAC_PI_2;
                    let jac = 2.0 * u * FRAC_PI_2 * th.sin() / nu as f64 * TAU / nphi as f64;
                    for ip in 0..nphi {
                        let wo = spherical(th, (ip as f64 + 0.5) / nphi as f64 * TAU);
                        let f = r.eval(&wi, &wo);
                        for c in 0..3 {
                            a[c] += f[c] * wo.z * jac;
                        }
                    }
                }
                assert!(a.iter().all(|v| *v > 0.01 && *v < 1.05), "{name} θi={ti}: albedo {a:?}");
            }
        }
    }
}
