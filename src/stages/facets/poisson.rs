//! Periodic Poisson integration of facet slopes into facet heights (Eqs. 20–21), by FFT.
//!
//! Neighbouring facet planes meet without a step when, across the edge between facets `x` and `x+1` (spacing
//! `h`), `z(x+1) − z(x) = h · ½(p(x) + p(x+1))`. The edge gradient `G(x+½) = ½(p(x) + p(x+1))` is Eq. 21's
//! smoothing read at the edge (Eq. 21's `g(x) = ¼p(x−1) + ½p(x) + ¼p(x+1)` is its average back to the facet
//! centre). The heights that minimise the sum of squared steps over all edges solve the normal equations
//! `L z = h · div G`, the cyclic 5-point discrete Poisson equation (Eq. 20), which diagonalises under the FFT:
//! `ẑ(k) = b̂(k) / λ(k)` with `λ = 2cos(2πkx/W) + 2cos(2πky/H) − 4`. The free constant (λ = 0 at k = 0) is
//! fixed by setting the mean height to zero; callers then shift as they need (the rasteriser puts the top at
//! z = 0). A solver is planned once per grid size and reused ([`PoissonSolver::new`], then `solve`).

use crate::base::fft2::RealFft2;
use std::f64::consts::TAU;

/// A planned periodic Poisson solver for `nx × ny` grids.
pub struct PoissonSolver {
    nx: usize,
    ny: usize,
    fft: RealFft2,
    /// `1/λ(kx, ky)` in the column-major spectrum layout, 0 at the origin.
    inv_lambda: Vec<f64>,
}

impl PoissonSolver {
    /// Plan for an `nx × ny` cyclic grid (both ≥ 2).
    pub fn new(nx: usize, ny: usize) -> Self {
        let fft = RealFft2::new(nx, ny);
        let hx = fft.half_width();
        let mut inv_lambda = vec![0.0; hx * ny];
        for kx in 0..hx {
            let lx = 2.0 * (TAU * kx as f64 / nx as f64).cos() - 2.0;
            for ky in 0..ny {
                let l = lx + 2.0 * (TAU * ky as f64 / ny as f64).cos() - 2.0;
                inv_lambda[kx * ny + ky] = if kx == 0 && ky == 0 { 0.0 } else { 1.0 / l };
            }
        }
        Self {
            nx,
            ny,
            fft,
            inv_lambda,
        }
    }

    /// Solve `L z = rhs` (unit-spacing cyclic 5-point Laplacian) with mean(z) = 0. The mean of `rhs` is
    /// ignored (a periodic divergence has none).
    pub fn solve(&mut self, rhs: &[f64], z: &mut [f64]) {
        let (nx, ny) = (self.nx, self.ny);
        let inv = &self.inv_lambda;
        self.fft.filter(rhs, (nx, ny), z, (nx, ny), |kx, col| {
            col.iter_mut()
                .zip(&inv[kx * ny..(kx + 1) * ny])
                .for_each(|(c, l)| *c *= l);
        });
    }

    /// Heights from edge gradients: `gx[y·nx + x]` is the slope across the edge from `x` to `x+1`,
    /// `gy[y·nx + x]` across the edge from `y` to `y+1` (cyclic), `spacing` the grid step. Least-squares
    /// exact: when the gradients are differences of some periodic `z`, this returns that `z` (mean zero).
    pub fn integrate_edge_gradients(&mut self, gx: &[f64], gy: &[f64], spacing: f64, z: &mut [f64]) {
        let (nx, ny) = (self.nx, self.ny);
        let mut rhs = vec![0.0; nx * ny];
        for y in 0..ny {
            let ym = (y + ny - 1) % ny;
            for x in 0..nx {
                let xm = (x + nx - 1) % nx;
                rhs[y * nx + x] = spacing * (gx[y * nx + x] - gx[y * nx + xm] + gy[y * nx + x] - gy[ym * nx + x]);
            }
        }
        self.solve(&rhs, z);
    }

    /// Facet-centre heights of a cyclic `nx × ny` arrangement of facets of side `facet` with slopes `p`, `q`
    /// (Eqs. 20–21, edge form): the heights that minimise the squared steps at all facet edges.
    pub fn facet_heights(&mut self, p: &[f64], q: &[f64], facet: f64, z: &mut [f64]) {
        let (gx, gy) = edge_gradients(p, q, self.nx, self.ny);
        self.integrate_edge_gradients(&gx, &gy, facet, z);
    }
}

/// Edge gradients of a cyclic facet arrangement: the mean of the two facets' slopes across each edge.
pub fn edge_gradients(p: &[f64], q: &[f64], nx: usize, ny: usize) -> (Vec<f64>, Vec<f64>) {
    let mut gx = vec![0.0; nx * ny];
    let mut gy = vec![0.0; nx * ny];
    for y in 0..ny {
        for x in 0..nx {
            let k = y * nx + x;
            gx[k] = 0.5 * (p[k] + p[y * nx + (x + 1) % nx]);
            gy[k] = 0.5 * (q[k] + q[((y + 1) % ny) * nx + x]);
        }
    }
    (gx, gy)
}

/// Steps at the facet edges of an arrangement with heights `z`: `(x-edges, y-edges)`, each the height jump
/// between the two facet planes at the midpoint of their shared edge (absolute value).
#[cfg(test)]
pub fn edge_steps(p: &[f64], q: &[f64], z: &[f64], nx: usize, ny: usize, facet: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut sx, mut sy) = signed_edge_steps(p, q, z, nx, ny, facet);
    sx.iter_mut().chain(sy.iter_mut()).for_each(|s| *s = s.abs());
    (sx, sy)
}

/// [`edge_steps`] with their signs: the far facet's edge midpoint (right, up) minus the near one's.
pub fn signed_edge_steps(p: &[f64], q: &[f64], z: &[f64], nx: usize, ny: usize, facet: f64) -> (Vec<f64>, Vec<f64>) {
    let mut sx = vec![0.0; nx * ny];
    let mut sy = vec![0.0; nx * ny];
    for y in 0..ny {
        for x in 0..nx {
            let k = y * nx + x;
            let r = y * nx + (x + 1) % nx;
            let u = ((y + 1) % ny) * nx + x;
            sx[k] = (z[r] - 0.5 * facet * p[r]) - (z[k] + 0.5 * facet * p[k]);
            sy[k] = (z[u] - 0.5 * facet * q[u]) - (z[k] + 0.5 * facet * q[k]);
        }
    }
    (sx, sy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_periodic(nx: usize, ny: usize, seed: u64) -> Vec<f64> {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut z: Vec<f64> = (0..nx * ny).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let m = z.iter().sum::<f64>() / z.len() as f64;
        z.iter_mut().for_each(|v| *v -= m);
        z
    }

    fn max_rel(a: &[f64], b: &[f64]) -> f64 {
        let scale = b.iter().map(|v| v.abs()).fold(0.0, f64::max);
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale
    }

    /// Independent slow solver: conjugate gradients on the same normal equations (−L is SPD on zero-mean
    /// fields), no FFT.
    fn cg_solve(rhs: &[f64], nx: usize, ny: usize) -> Vec<f64> {
        let lap = |z: &[f64]| -> Vec<f64> {
            (0..nx * ny)
                .map(|k| {
                    let (x, y) = (k % nx, k / nx);
                    let n = z[y * nx + (x + 1) % nx]
                        + z[y * nx + (x + nx - 1) % nx]
                        + z[((y + 1) % ny) * nx + x]
                        + z[((y + ny - 1) % ny) * nx + x];
                    -(n - 4.0 * z[k])
                })
                .collect()
        };
        let b: Vec<f64> = rhs.iter().map(|v| -v).collect();
        let mut x = vec![0.0; nx * ny];
        let mut r = b.clone();
        let mut p = r.clone();
        let mut rr: f64 = r.iter().map(|v| v * v).sum();
        for _ in 0..20 * nx * ny {
            let ap = lap(&p);
            let alpha = rr / p.iter().zip(&ap).map(|(a, b)| a * b).sum::<f64>();
            x.iter_mut().zip(&p).for_each(|(x, p)| *x += alpha * p);
            r.iter_mut().zip(&ap).for_each(|(r, a)| *r -= alpha * a);
            let rr2: f64 = r.iter().map(|v| v * v).sum();
            if rr2.sqrt() < 1e-14 {
                break;
            }
            p = r.iter().zip(&p).map(|(r, p)| r + rr2 / rr * p).collect();
            rr = rr2;
        }
        let m = x.iter().sum::<f64>() / x.len() as f64;
        x.iter().map(|v| v - m).collect()
    }

    #[test]
    fn exact_gradients_return_the_surface() {
        for (nx, ny) in [(32, 32), (30, 18), (7, 12)] {
            let z = random_periodic(nx, ny, (nx * ny) as u64);
            let h = 0.7;
            let mut gx = vec![0.0; nx * ny];
            let mut gy = vec![0.0; nx * ny];
            for y in 0..ny {
                for x in 0..nx {
                    gx[y * nx + x] = (z[y * nx + (x + 1) % nx] - z[y * nx + x]) / h;
                    gy[y * nx + x] = (z[((y + 1) % ny) * nx + x] - z[y * nx + x]) / h;
                }
            }
            let mut s = PoissonSolver::new(nx, ny);
            let mut out = vec![0.0; nx * ny];
            s.integrate_edge_gradients(&gx, &gy, h, &mut out);
            let e = max_rel(&out, &z);
            assert!(e < 1e-9, "{nx}×{ny}: {e}");
        }
    }

    #[test]
    fn fft_solver_agrees_with_conjugate_gradients() {
        let (nx, ny) = (24, 20);
        let rhs = random_periodic(nx, ny, 11);
        let mut s = PoissonSolver::new(nx, ny);
        let mut z = vec![0.0; nx * ny];
        s.solve(&rhs, &mut z);
        let slow = cg_solve(&rhs, nx, ny);
        let e = max_rel(&z, &slow);
        assert!(e < 1e-9, "{e}");
    }

    #[test]
    fn facet_heights_minimise_the_squared_edge_steps() {
        let (nx, ny, h) = (16, 16, 1.0);
        let z = random_periodic(nx, ny, 5);
        let p: Vec<f64> = z.iter().map(|v| (v * 3.0).sin() * 0.3).collect();
        let q: Vec<f64> = z.iter().map(|v| (v * 5.0).cos() * 0.3).collect();
        let mut s = PoissonSolver::new(nx, ny);
        let mut zz = vec![0.0; nx * ny];
        s.facet_heights(&p, &q, h, &mut zz);
        let cost = |z: &[f64]| {
            let (a, b) = edge_steps(&p, &q, z, nx, ny, h);
            a.iter().chain(&b).map(|v| v * v).sum::<f64>()
        };
        let best = cost(&zz);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(9);
        for _ in 0..20 {
            let k = rng.gen_range(0..nx * ny);
            let mut z2 = zz.clone();
            z2[k] += rng.gen_range(-0.01..0.01);
            assert!(cost(&z2) >= best - 1e-12, "not a minimum of the squared steps");
        }
    }
}
