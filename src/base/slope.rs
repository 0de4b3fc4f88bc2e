//! Slope-space densities: the working domain of the `ndf` and `facets` stages.
//!
//! A microfacet normal `wm` is the slope `(p, q) = (-mx/mz, -my/mz)`. The slope density `P22(p, q)`
//! integrates to 1 over the slope plane and relates to the NDF by `D(wm) = P22(p, q) / cos⁴θm`
//! (Heitz 2014, "Understanding the Masking-Shadowing Function", Eq. 2.13 of the microfacet literature).
//! A [`SlopeGrid`] samples `P22` at the centres of a regular grid of cells; it is **not** periodic.

use crate::base::geometry::{cos_sin_phi, Vec3};
use crate::base::Invalid;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The extent and resolution of a slope grid. Cell `(i, j)` covers
/// `[p_min + i·dp, p_min + (i+1)·dp] × [q_min + j·dq, q_min + (j+1)·dq]`; values sit at cell centres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SlopeDomain {
    /// Cells along p (x slope).
    pub nx: usize,
    /// Cells along q (y slope).
    pub ny: usize,
    /// Lower edge of the p range.
    pub p_min: f64,
    /// Upper edge of the p range.
    pub p_max: f64,
    /// Lower edge of the q range.
    pub q_min: f64,
    /// Upper edge of the q range.
    pub q_max: f64,
}

impl SlopeDomain {
    /// A square domain `|p|, |q| ≤ max_slope` with `n × n` cells.
    pub fn square(n: usize, max_slope: f64) -> Self {
        Self {
            nx: n,
            ny: n,
            p_min: -max_slope,
            p_max: max_slope,
            q_min: -max_slope,
            q_max: max_slope,
        }
    }

    /// The default domain of the `ndf` stage: 256 × 256 cells over `|p|, |q| ≤ tan 60°`.
    pub fn default_ndf() -> Self {
        Self::square(256, 60f64.to_radians().tan())
    }

    /// Cell width along p.
    #[inline]
    pub fn dp(&self) -> f64 {
        (self.p_max - self.p_min) / self.nx as f64
    }

    /// Cell width along q.
    #[inline]
    pub fn dq(&self) -> f64 {
        (self.q_max - self.q_min) / self.ny as f64
    }

    /// Cell area `dp·dq`.
    #[inline]
    pub fn cell_area(&self) -> f64 {
        self.dp() * self.dq()
    }

    /// Slope p at the centre of column `i`.
    #[inline]
    pub fn p_at(&self, i: usize) -> f64 {
        self.p_min + (i as f64 + 0.5) * self.dp()
    }

    /// Slope q at the centre of row `j`.
    #[inline]
    pub fn q_at(&self, j: usize) -> f64 {
        self.q_min + (j as f64 + 0.5) * self.dq()
    }

    /// Number of cells.
    #[inline]
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// True when the domain has no cells.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Check that the domain is usable: at least 2 × 2 cells, finite and increasing bounds.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.nx < 2 || self.ny < 2 {
            return Err(Invalid(format!(
                "grid must have at least 2×2 cells, got {}×{}",
                self.nx, self.ny
            )));
        }
        let finite = [self.p_min, self.p_max, self.q_min, self.q_max]
            .iter()
            .all(|v| v.is_finite());
        if !finite || self.p_max <= self.p_min || self.q_max <= self.q_min {
            return Err(Invalid(format!(
                "slope bounds must be finite with min < max, got p [{}, {}], q [{}, {}]",
                self.p_min, self.p_max, self.q_min, self.q_max
            )));
        }
        Ok(())
    }
}

/// Mass, mean and covariance of a slope density.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SlopeStats {
    /// `∑ P22 · dp·dq`: 1 for a normalised density.
    pub mass: f64,
    /// Mean slope `[p̄, q̄]`.
    pub mean: [f64; 2],
    /// Slope covariance `[[pp, pq], [pq, qq]]` about the mean.
    pub cov: [[f64; 2]; 2],
}

/// A slope density `P22(p, q)` sampled at cell centres, row-major with rows along q
/// (`density[j·nx + i]` is at `(p_at(i), q_at(j))`).
#[derive(Clone, Debug, PartialEq)]
pub struct SlopeGrid {
    /// Extent and resolution.
    pub domain: SlopeDomain,
    /// `P22` values, row-major, rows along q.
    pub density: Vec<f64>,
}

impl SlopeGrid {
    /// Sample `f(p, q)` at every cell centre (in parallel).
    pub fn from_fn<F>(domain: SlopeDomain, f: F) -> Self
    where
        F: Fn(f64, f64) -> f64 + Sync,
    {
        let mut density = vec![0.0; domain.len()];
        density.par_chunks_mut(domain.nx).enumerate().for_each(|(j, row)| {
            let q = domain.q_at(j);
            for (i, v) in row.iter_mut().enumerate() {
                *v = f(domain.p_at(i), q);
            }
        });
        Self { domain, density }
    }

    /// The value of cell `(i, j)`.
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.density[j * self.domain.nx + i]
    }

    /// Check the invariants every stage relies on: the right length, finite and non-negative values.
    pub fn check_invariants(&self) -> Result<(), Invalid> {
        self.domain.validate()?;
        if self.density.len() != self.domain.len() {
            return Err(Invalid(format!(
                "density has {} values, expected nx·ny = {}",
                self.density.len(),
                self.domain.len()
            )));
        }
        if let Some(k) = self.density.iter().position(|v| !v.is_finite() || *v < 0.0) {
            return Err(Invalid(format!(
                "density[{k}] = {} (cell p index {}, q index {}) is not a finite non-negative number",
                self.density[k],
                k % self.domain.nx,
                k / self.domain.nx
            )));
        }
        Ok(())
    }

    /// `∑ P22 · dp·dq`.
    pub fn mass(&self) -> f64 {
        self.density.iter().sum::<f64>() * self.domain.cell_area()
    }

    /// Scale to unit mass; returns the mass before scaling (unchanged when the mass is not positive).
    pub fn normalise(&mut self) -> f64 {
        let m = self.mass();
        if m > 0.0 && m.is_finite() {
            self.density.iter_mut().for_each(|v| *v /= m);
        }
        m
    }

    /// Mass, mean slope and slope covariance (midpoint rule over cells).
    pub fn stats(&self) -> SlopeStats {
        let d = &self.domain;
        let (mut s0, mut sp, mut sq) = (0.0, 0.0, 0.0);
        for j in 0..d.ny {
            let q = d.q_at(j);
            for i in 0..d.nx {
                let w = self.at(i, j);
                s0 += w;
                sp += w * d.p_at(i);
                sq += w * q;
            }
        }
        let mass = s0 * d.cell_area();
        if s0 <= 0.0 {
            return SlopeStats {
                mass,
                mean: [0.0; 2],
                cov: [[0.0; 2]; 2],
            };
        }
        let (mp, mq) = (sp / s0, sq / s0);
        let (mut cpp, mut cpq, mut cqq) = (0.0, 0.0, 0.0);
        for j in 0..d.ny {
            let dq = d.q_at(j) - mq;
            for i in 0..d.nx {
                let w = self.at(i, j);
                let dp = d.p_at(i) - mp;
                cpp += w * dp * dp;
                cpq += w * dp * dq;
                cqq += w * dq * dq;
            }
        }
        SlopeStats {
            mass,
            mean: [mp, mq],
            cov: [[cpp / s0, cpq / s0], [cpq / s0, cqq / s0]],
        }
    }

    /// Bilinear interpolation between cell centres; 0 outside the grid (the density is not periodic).
    pub fn sample(&self, p: f64, q: f64) -> f64 {
        let d = &self.domain;
        let x = (p - d.p_min) / d.dp() - 0.5;
        let y = (q - d.q_min) / d.dq() - 0.5;
        if !(x > -1.0 && y > -1.0 && x < d.nx as f64 && y < d.ny as f64) {
            return 0.0;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let get = |i: isize, j: isize| -> f64 {
            if i < 0 || j < 0 || i >= d.nx as isize || j >= d.ny as isize {
                0.0
            } else {
                self.at(i as usize, j as usize)
            }
        };
        let (i0, j0) = (x0 as isize, y0 as isize);
        (1.0 - fy) * ((1.0 - fx) * get(i0, j0) + fx * get(i0 + 1, j0))
            + fy * ((1.0 - fx) * get(i0, j0 + 1) + fx * get(i0 + 1, j0 + 1))
    }

    /// The density shifted by `-(p0, q0)` in slope space: `P'(p, q) = P(p + p0, q + q0)`.
    ///
    /// Adding the plane `z = -p0·x - q0·y` to a surface subtracts `(p0, q0)` from every slope, so this is the
    /// tilt that makes a distribution of mean `(p0, q0)` zero-mean (Section 7.2: the mean normal must be z).
    pub fn shifted(&self, p0: f64, q0: f64) -> SlopeGrid {
        SlopeGrid::from_fn(self.domain, |p, q| self.sample(p + p0, q + q0))
    }

    /// This density restricted to slopes no steeper than `cone_tan` (`|∇z| ≤ tan θ`), renormalised: the
    /// part a tool whose steepest facet is `θ` can make.
    pub fn within_cone(&self, cone_tan: f64) -> SlopeGrid {
        let mut out = self.cut_to_cone(cone_tan);
        out.normalise();
        out
    }

    /// This density with every cell steeper than `cone_tan` set to zero, not renormalised (its mass is the
    /// part within the cone).
    pub fn cut_to_cone(&self, cone_tan: f64) -> SlopeGrid {
        let d = self.domain;
        let mut out = self.clone();
        for j in 0..d.ny {
            for i in 0..d.nx {
                if d.p_at(i).hypot(d.q_at(j)) > cone_tan {
                    out.density[j * d.nx + i] = 0.0;
                }
            }
        }
        out
    }

    /// Relative L1 distance `∑|a − b| / ∑|b|` to a density on the same domain.
    pub fn relative_l1(&self, reference: &SlopeGrid) -> f64 {
        assert_eq!(self.domain, reference.domain, "relative_l1 needs equal domains");
        crate::base::distance::relative_l1(&self.density, &reference.density)
    }

    /// Smith's `Λ(w)` of this density, by quadrature over the grid:
    /// `Λ(w) = ∫ P22(p, q) · max(0, p·wx + q·wy − wz) dp dq / wz`.
    ///
    /// It follows from the projected-area identity `∫ ⟨w, m⟩⁺ D(m) dm = cosθ (1 + Λ)` with
    /// `D dm = P22 dp dq / cosθm` and `⟨w, m⟩ = (wz − p·wx − q·wy) cosθm`. The density should be normalised.
    /// This is the definition, cell by cell; [`SmithTable`] takes its directions with
    /// [`SlopeGrid::smith_lambdas`], which gives the same bits faster.
    pub fn smith_lambda(&self, w: &Vec3) -> f64 {
        if w.z <= 0.0 {
            return f64::INFINITY;
        }
        let d = &self.domain;
        let mut acc = 0.0;
        for j in 0..d.ny {
            let qy = d.q_at(j) * w.y - w.z;
            let row = &self.density[j * d.nx..(j + 1) * d.nx];
            for (i, v) in row.iter().enumerate() {
                let t = d.p_at(i) * w.x + qy;
                if t > 0.0 {
                    acc += v * t;
                }
            }
        }
        acc * d.cell_area() / w.z
    }

    /// [`SlopeGrid::smith_lambda`] of several directions, eight at a time in one pass over the grid: each
    /// direction keeps its own sum, taken over the same cells in the same order (a cell it does not count
    /// adds `+0`), so every value is bit for bit the one-direction result, at a fraction of the cost (the
    /// one-direction sum waits on its own additions; eight independent ones fill the vector lanes), and only
    /// over each row's run of cells some direction counts (`counted_run`). Directions close together
    /// share most of their runs: pass them in order of angle.
    pub fn smith_lambdas(&self, ws: &[Vec3]) -> Vec<f64> {
        ws.chunks(LAMBDA_LANES)
            .flat_map(|c| pulp::Arch::new().dispatch(LambdaLanes { grid: self, ws: c }))
            .take(ws.len())
            .collect()
    }
}

/// The cells `lo..hi` of a row where `t = p·wx + qy > 0`, `ps` the row's increasing slopes: `t` is monotone
/// along the row, so they are one run (a suffix for `wx > 0`, a prefix for `wx < 0`, all or none for
/// `wx = 0`), found by bisection.
fn counted_run(ps: &[f64], wx: f64, qy: f64) -> (usize, usize) {
    if wx > 0.0 {
        (ps.partition_point(|p| p * wx + qy <= 0.0), ps.len())
    } else if wx < 0.0 {
        (0, ps.partition_point(|p| p * wx + qy > 0.0))
    } else if qy > 0.0 {
        (0, ps.len())
    } else {
        (0, 0)
    }
}

/// Directions summed together by [`SlopeGrid::smith_lambdas`].
const LAMBDA_LANES: usize = 8;

/// Up to [`LAMBDA_LANES`] directions' `Λ`, run by `pulp` with the CPU's widest vectors.
struct LambdaLanes<'a> {
    grid: &'a SlopeGrid,
    ws: &'a [Vec3],
}

impl pulp::WithSimd for LambdaLanes<'_> {
    type Output = [f64; LAMBDA_LANES];
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
        const L: usize = LAMBDA_LANES;
        let d = &self.grid.domain;
        // lanes beyond the directions given, or below the horizon, look straight up: t = −1 never counts
        let up = Vec3::new(0.0, 0.0, 1.0);
        let lane: [Vec3; L] = std::array::from_fn(|l| match self.ws.get(l) {
            Some(w) if w.z > 0.0 => *w,
            _ => up,
        });
        let (wx, wy, wz) = (lane.map(|w| w.x), lane.map(|w| w.y), lane.map(|w| w.z));
        let ps: Vec<f64> = (0..d.nx).map(|i| d.p_at(i)).collect();
        let mut acc = [0.0f64; L];
        for j in 0..d.ny {
            let qj = d.q_at(j);
            let qy: [f64; L] = std::array::from_fn(|l| qj * wy[l] - wz[l]);
            // the union of the lanes' runs
            let (mut lo, mut hi) = (d.nx, 0);
            for l in 0..L {
                let (a, b) = counted_run(&ps, wx[l], qy[l]);
                if a < b {
                    lo = lo.min(a);
                    hi = hi.max(b);
                }
            }
            if lo >= hi {
                continue;
            }
            let row = &self.grid.density[j * d.nx..(j + 1) * d.nx];
            for (p, v) in ps[lo..hi].iter().zip(&row[lo..hi]) {
                for l in 0..L {
                    // a select, not a branch, so the lanes vectorise; v·0 = +0 leaves the sum as it is
                    let t = p * wx[l] + qy[l];
                    let t = if t > 0.0 { t } else { 0.0 };
                    acc[l] += v * t;
                }
            }
        }
        std::array::from_fn(|l| match self.ws.get(l) {
            Some(w) if w.z > 0.0 => acc[l] * d.cell_area() / w.z,
            _ => f64::INFINITY,
        })
    }
}

/// Add `w` at `(p, q)` spread bilinearly over the four nearest cell centres (the transpose of
/// [`SlopeGrid::sample`]); the parts that fall on cells outside the grid are dropped.
pub fn splat(g: &mut SlopeGrid, p: f64, q: f64, w: f64) {
    let d = g.domain;
    let x = (p - d.p_min) / d.dp() - 0.5;
    let y = (q - d.q_min) / d.dq() - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    for (dx, dy, ww) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let (i, j) = (x0 as isize + dx, y0 as isize + dy);
        if i >= 0 && j >= 0 && (i as usize) < d.nx && (j as usize) < d.ny {
            g.density[j as usize * d.nx + i as usize] += w * ww;
        }
    }
}

/// Smith's `Λ` of a slope density tabulated over the hemisphere of directions, for fast lookup.
///
/// `Λ` is smooth in direction, so a table of `nt × nphi` directions with bilinear interpolation in
/// `(θ, φ)` is accurate to well below the quadrature error of the grid itself.
#[derive(Clone, Debug)]
pub struct SmithTable {
    nt: usize,
    nphi: usize,
    theta_max: f64,
    lambda: Vec<f64>,
}

impl SmithTable {
    /// Tabulate `Λ` of `grid` at `nt` polar angles in `[0, θmax]` and `nphi` azimuths (parallel).
    pub fn new(grid: &SlopeGrid, nt: usize, nphi: usize) -> Self {
        let theta_max = 89.5f64.to_radians();
        // one azimuth's polar angles together: their half-planes nest, so their runs of cells do too
        let columns: Vec<Vec<f64>> = (0..nphi)
            .into_par_iter()
            .map(|ip| {
                let phi = std::f64::consts::TAU * ip as f64 / nphi as f64;
                let ws: Vec<Vec3> = (0..nt)
                    .map(|it| {
                        let theta = theta_max * it as f64 / (nt - 1) as f64;
                        crate::base::geometry::spherical(theta, phi)
                    })
                    .collect();
                grid.smith_lambdas(&ws)
            })
            .collect();
        let lambda: Vec<f64> = (0..nt * nphi).map(|k| columns[k % nphi][k / nphi]).collect();
        Self {
            nt,
            nphi,
            theta_max,
            lambda,
        }
    }

    /// `Λ(w)` by bilinear interpolation in `(θ, φ)`; beyond the table's last polar angle (89.5°) carried on
    /// by `tanθ` as Λ's limit at the horizon requires ([`SmithTable::lambda_at`]); infinite below the horizon.
    pub fn lambda(&self, w: &Vec3) -> f64 {
        if w.z <= 0.0 {
            return f64::INFINITY;
        }
        self.lambda_at(TableDirection::of(w))
    }

    /// `Λ` at a direction above the horizon whose angles were worked out once ([`TableDirection::of`]), for
    /// callers that look the same directions up in several tables.
    pub fn lambda_at(&self, dir: TableDirection) -> f64 {
        if dir.theta > self.theta_max {
            // toward the horizon (μ = cotθ → 0) Λ = (1/μ) ∫ (q − μ)⁺ P(q) dq → E[q⁺]/μ − P(q > 0), q the slope
            // along φ: the table's last value carried on by tanθ, with P(q > 0) taken as ½ (a distribution
            // centred on the normal); G1 → 0 at grazing, as masking requires
            let edge = TableDirection {
                theta: self.theta_max,
                ..dir
            };
            return (self.lambda_at(edge) + 0.5) * dir.theta.tan().abs() / self.theta_max.tan() - 0.5;
        }
        let theta = dir.theta;
        let t = theta / self.theta_max * (self.nt - 1) as f64;
        let f = dir.phi / std::f64::consts::TAU * self.nphi as f64;
        let (t0, f0) = (t.floor() as usize, f.floor() as usize);
        let (t1, ft) = ((t0 + 1).min(self.nt - 1), t - t0 as f64);
        let t0 = t0.min(self.nt - 1);
        let (p0, p1, fp) = (f0 % self.nphi, (f0 + 1) % self.nphi, f - f0 as f64);
        let at = |a: usize, b: usize| self.lambda[a * self.nphi + b];
        (1.0 - ft) * ((1.0 - fp) * at(t0, p0) + fp * at(t0, p1)) + ft * ((1.0 - fp) * at(t1, p0) + fp * at(t1, p1))
    }

    /// Smith's monodirectional masking `G1(w) = 1 / (1 + Λ(w))`.
    pub fn g1(&self, w: &Vec3) -> f64 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Separable Smith masking–shadowing `G = G1(wi) G1(wo)` of a facet of normal `wm`, 0 when the facet
    /// faces away from either direction or is vertical.
    pub fn g2(&self, wi: &Vec3, wo: &Vec3, wm: &Vec3) -> f64 {
        if wi.dot(wm) <= 0.0 || wo.dot(wm) <= 0.0 || crate::base::geometry::normal_to_slope(wm).is_none() {
            return 0.0;
        }
        self.g1(wi) * self.g1(wo)
    }

    /// [`SmithTable::g1`] at a direction above the horizon given by its angles.
    pub fn g1_at(&self, dir: TableDirection) -> f64 {
        1.0 / (1.0 + self.lambda_at(dir))
    }
}

/// A direction above the horizon as a [`SmithTable`] looks it up: polar angle `θ` and azimuth `φ ∈ [0, 2π)`,
/// radians. Working them out (an `acos` and an `atan2`) costs more than the look-up itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableDirection {
    theta: f64,
    phi: f64,
}

impl TableDirection {
    /// The angles of `w` (`w.z > 0`).
    pub fn of(w: &Vec3) -> Self {
        let (c, s) = cos_sin_phi(w);
        Self {
            theta: w.z.min(1.0).acos(),
            phi: s.atan2(c).rem_euclid(std::f64::consts::TAU),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gaussian(sigma: f64, mp: f64, mq: f64) -> impl Fn(f64, f64) -> f64 {
        move |p, q| {
            let r2 = (p - mp).powi(2) + (q - mq).powi(2);
            (-r2 / (2.0 * sigma * sigma)).exp() / (2.0 * std::f64::consts::PI * sigma * sigma)
        }
    }

    #[test]
    fn gaussian_stats_match_closed_form() {
        let g = SlopeGrid::from_fn(SlopeDomain::square(200, 2.0), gaussian(0.2, 0.1, -0.05));
        let s = g.stats();
        assert!((s.mass - 1.0).abs() < 1e-6, "mass {}", s.mass);
        assert!((s.mean[0] - 0.1).abs() < 1e-9 && (s.mean[1] + 0.05).abs() < 1e-9);
        assert!((s.cov[0][0] - 0.04).abs() < 1e-4, "{:?}", s.cov);
        assert!(s.cov[0][1].abs() < 1e-9);
    }

    #[test]
    fn shift_moves_the_mean() {
        let d = SlopeDomain::square(128, 2.0);
        let g = SlopeGrid::from_fn(d, gaussian(0.2, 0.13, -0.07));
        let s = g.shifted(0.13, -0.07).stats();
        assert!(s.mean[0].abs() < 1e-3 && s.mean[1].abs() < 1e-3, "{:?}", s.mean);
    }

    /// Eight directions at a time give each direction's one-at-a-time sum bit for bit, below the horizon
    /// too, and for a count that is not a multiple of eight.
    #[test]
    fn smith_lambdas_equal_smith_lambda_bit_for_bit() {
        let g = SlopeGrid::from_fn(SlopeDomain::square(96, 1.5), gaussian(0.3, 0.05, -0.1));
        let ws: Vec<Vec3> = (0..21)
            .map(|k| {
                let theta = (k as f64 * 4.7).to_radians();
                crate::base::geometry::spherical(theta, k as f64 * 0.9)
            })
            .chain([
                Vec3::new(0.3, 0.1, -0.2),
                Vec3::new(0.0, 0.6, 0.8),
                Vec3::new(0.6, 0.0, 0.8),
            ])
            .collect();
        let many = g.smith_lambdas(&ws);
        assert_eq!(many.len(), ws.len());
        for (w, got) in ws.iter().zip(&many) {
            assert_eq!(got.to_bits(), g.smith_lambda(w).to_bits(), "{w:?}");
        }
    }

    /// Beckmann's Smith Λ in closed form, `a = 1/(α tanθ)`: `(erf a − 1)/2 + exp(−a²)/(2a√π)`.
    fn beckmann_lambda(alpha: f64, theta: f64) -> f64 {
        let a = 1.0 / (alpha * theta.tan());
        (libm::erf(a) - 1.0) / 2.0 + (-a * a).exp() / (2.0 * a * std::f64::consts::PI.sqrt())
    }

    #[test]
    fn smith_lambda_matches_beckmann_closed_form() {
        // An isotropic Gaussian of slope variance α²/2 is the Beckmann distribution; its Λ has a closed form.
        let alpha: f64 = 0.4;
        let g = SlopeGrid::from_fn(SlopeDomain::square(400, 3.0), gaussian(alpha / 2f64.sqrt(), 0.0, 0.0));
        for theta_deg in [30.0f64, 60.0, 75.0] {
            let w = crate::base::geometry::spherical(theta_deg.to_radians(), 0.7);
            let exact = beckmann_lambda(alpha, theta_deg.to_radians());
            let num = g.smith_lambda(&w);
            assert!(
                (num - exact).abs() < 1e-3 * exact.max(1e-2),
                "θ={theta_deg}: {num} vs {exact}"
            );
        }
    }

    #[test]
    fn smith_table_carries_lambda_to_the_horizon() {
        // beyond the table's 89.5° its Λ follows tanθ, as Beckmann's closed form does there
        // (Λ → α tanθ / (2√π) − ½ as θ → 90°), so that G1 → 0 at grazing
        let alpha: f64 = 0.4;
        let g = SlopeGrid::from_fn(SlopeDomain::square(200, 3.0), gaussian(alpha / 2f64.sqrt(), 0.0, 0.0));
        let table = SmithTable::new(&g, 64, 32);
        for theta_deg in [89.7f64, 89.9, 89.99] {
            let w = crate::base::geometry::spherical(theta_deg.to_radians(), 0.7);
            let exact = beckmann_lambda(alpha, theta_deg.to_radians());
            let table_l = table.lambda(&w);
            assert!(
                (table_l / exact - 1.0).abs() < 0.01,
                "θ={theta_deg}: {table_l} vs {exact}"
            );
        }
        let grazing = crate::base::geometry::spherical(std::f64::consts::FRAC_PI_2, 0.7);
        assert!(table.g1(&grazing) < 1e-12, "G1 at grazing {}", table.g1(&grazing));
    }
}
