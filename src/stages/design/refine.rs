//! The tile refined as a continuous heightfield (`design.method = "refined"`, DESIGN.md §3.5): alternating
//! projections from the as-milled model of the facets' design towards a surface whose own slopes follow the
//! target, which integrates, which the ball reaches, and which keeps to the relief budget.
//!
//! Facets draw the target with `N` normals (or `N` domes); the ball then fillets every concave corner.
//! Starting from that as-milled surface `h`, each iteration takes four projections:
//!
//! 1. **Slopes to the target** (sliced optimal transport; Pitié et al. 2007, Rabin et al. 2011): the grid's
//!    edge slopes `g = (∂ₓh, ∂ᵧh)` projected on two orthogonal directions `u`, `v` (turned by the golden
//!    angle each iteration), and each projection moved to the target's quantile of its own rank,
//!    `g·u ← F_T,u⁻¹(F_g,u(g·u))`: the monotone (optimal, in 1D) map of one marginal onto the other.
//! 2. **Integrable**: the periodic heights whose differences are nearest those slopes in least squares, the
//!    Poisson equation `L h = div g` solved by FFT (the facets' own solver, `facets::poisson`).
//! 3. **Relief**: the top at z = 0, nothing below the relief budget.
//! 4. **Reachable**: the ball's opening (`cut::morphology`), the highest surface the bit can leave on `h`.
//!
//! The iterate after step 4 is its own as-milled surface (an opening is idempotent), so the design *is*
//! what the ball can cut. Step 1 moves slopes towards the target; steps 2–4 move them back only as far as a
//! surface and the ball require. The design loop models each iteration as it models a round and keeps the
//! best.

use crate::base::heightfield::Heightfield;
use crate::base::slope::SlopeGrid;
use crate::cut::chords::PassChords;
use crate::cut::tool::Shape;
use crate::stages::facets::poisson::PoissonSolver;
use rayon::prelude::*;

/// Bins of the 1D marginals the transport step matches (the surface's and the target's), over the range
/// of both: 4096 bins put a bin at 5·10⁻⁴ of slope for a 45° cone, a thirtieth of the NDF grid's cell.
const BINS: usize = 4096;

/// The golden angle, radians: successive iterations' directions never repeat and fill the half-turn evenly.
const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;

/// A 1D distribution on `BINS` equal bins over `[lo, hi]`, as its cumulative mass at the bin edges.
struct Marginal {
    lo: f64,
    width: f64,
    /// `cdf[b]`: the mass below edge `b` (`BINS + 1` edges, from 0 to 1).
    cdf: Vec<f64>,
}

impl Marginal {
    /// From bin masses (not normalised).
    fn from_bins(lo: f64, hi: f64, mass: &[f64]) -> Self {
        let total: f64 = mass.iter().sum();
        let mut cdf = Vec::with_capacity(mass.len() + 1);
        let mut acc = 0.0;
        cdf.push(0.0);
        for m in mass {
            acc += m / total;
            cdf.push(acc);
        }
        Self {
            lo,
            width: (hi - lo) / mass.len() as f64,
            cdf,
        }
    }

    /// `F(x)`, linear within a bin (the mass spread evenly across it).
    fn cdf_at(&self, x: f64) -> f64 {
        let t = ((x - self.lo) / self.width).clamp(0.0, BINS as f64);
        let b = (t as usize).min(BINS - 1);
        let f = t - b as f64;
        self.cdf[b] + f * (self.cdf[b + 1] - self.cdf[b])
    }

    /// `F⁻¹(c)`: the smallest x with `F(x) = c`, linear within the bin that holds it.
    fn quantile(&self, c: f64) -> f64 {
        // the first edge whose cumulative mass reaches c
        let b = self.cdf.partition_point(|&v| v < c).clamp(1, BINS);
        let (a, z) = (self.cdf[b - 1], self.cdf[b]);
        let f = if z > a {
            ((c - a) / (z - a)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.lo + (b as f64 - 1.0 + f) * self.width
    }
}

/// The target's marginal along `u`: each slope cell's mass spread evenly over its projection's extent
/// (`(|uₓ| + |uᵧ|)·cell`, the box its square projects to, to first order), so the marginal has no comb of
/// cell centres for the surface's slopes to collapse onto.
fn target_marginal(target: &SlopeGrid, u: (f64, f64), lo: f64, hi: f64) -> Marginal {
    let d = target.domain;
    let width = (hi - lo) / BINS as f64;
    let half = 0.5 * (u.0.abs() * d.dp() + u.1.abs() * d.dq());
    let mut mass = vec![0.0; BINS];
    for j in 0..d.ny {
        for i in 0..d.nx {
            let w = target.at(i, j);
            if w <= 0.0 {
                continue;
            }
            let c = d.p_at(i) * u.0 + d.q_at(j) * u.1;
            let (a, b) = (
                ((c - half - lo) / width).max(0.0),
                ((c + half - lo) / width).min(BINS as f64),
            );
            if b <= a {
                continue;
            }
            let per = w / (b - a);
            let (ba, bb) = (a as usize, (b.ceil() as usize).min(BINS));
            for (k, m) in mass.iter_mut().enumerate().take(bb).skip(ba) {
                let overlap = (b.min(k as f64 + 1.0) - a.max(k as f64)).max(0.0);
                *m += per * overlap;
            }
        }
    }
    Marginal::from_bins(lo, hi, &mass)
}

/// The surface's marginal of `values` (each sample alike).
fn sample_marginal(values: &[f64], lo: f64, hi: f64) -> Marginal {
    let width = (hi - lo) / BINS as f64;
    let mass = values
        .par_chunks(1 << 14)
        .map(|chunk| {
            let mut m = vec![0.0; BINS];
            for v in chunk {
                let b = (((v - lo) / width) as usize).min(BINS - 1);
                m[b] += 1.0;
            }
            m
        })
        .reduce(
            || vec![0.0; BINS],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        );
    Marginal::from_bins(lo, hi, &mass)
}

/// Move the slopes `(gx, gy)` so that their projections on `u` follow the target's (step 1 of the module).
fn match_direction(gx: &mut [f64], gy: &mut [f64], target: &SlopeGrid, u: (f64, f64)) {
    let proj: Vec<f64> = gx
        .par_iter()
        .zip(gy.par_iter())
        .map(|(x, y)| x * u.0 + y * u.1)
        .collect();
    let (smin, smax) = proj
        .par_iter()
        .fold(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |(a, b), v| (a.min(*v), b.max(*v)),
        )
        .reduce(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |x, y| (x.0.min(y.0), x.1.max(y.1)),
        );
    let d = target.domain;
    let reach = d.p_max.abs().max(d.p_min.abs()).max(d.q_max.abs()).max(d.q_min.abs()) * 1.5;
    let (lo, hi) = (smin.min(-reach), smax.max(reach) * (1.0 + 1e-12) + 1e-12);
    let fs = sample_marginal(&proj, lo, hi);
    let ft = target_marginal(target, u, lo, hi);
    gx.par_iter_mut()
        .zip(gy.par_iter_mut())
        .zip(proj.par_iter())
        .for_each(|((x, y), a)| {
            let moved = ft.quantile(fs.cdf_at(*a)) - a;
            *x += moved * u.0;
            *y += moved * u.1;
        });
}

/// One iteration of the module's four projections on the periodic grid `h` (heights, mm, top at 0). With
/// `chords`, it also returns the cut a controller leaves of the new `h` along its passes' chords (from the
/// opening's own dilation: [`crate::cut::morphology::opening_f32_chorded`]), the surface the model measures.
pub fn iterate(
    h: &mut Heightfield,
    target: &SlopeGrid,
    tool: &Shape,
    budget_mm: f64,
    k: usize,
    solver: &mut PoissonSolver,
    chords: Option<PassChords>,
) -> Option<Vec<f64>> {
    let (nx, ny, p) = (h.nx, h.ny, h.pitch_mm);
    let z = &h.z_mm;
    // edge slopes: gx across the edge from x to x+1, gy from y to y+1 (cyclic)
    let mut gx = vec![0.0; nx * ny];
    let mut gy = vec![0.0; nx * ny];
    gx.par_chunks_mut(nx)
        .zip(gy.par_chunks_mut(nx))
        .enumerate()
        .for_each(|(j, (rx, ry))| {
            let up = ((j + 1) % ny) * nx;
            for i in 0..nx {
                let c = z[j * nx + i];
                rx[i] = (z[j * nx + (i + 1) % nx] - c) / p;
                ry[i] = (z[up + i] - c) / p;
            }
        });
    let a = GOLDEN_ANGLE * k as f64;
    let (c, s) = (a.cos(), a.sin());
    match_direction(&mut gx, &mut gy, target, (c, s));
    match_direction(&mut gx, &mut gy, target, (-s, c));
    let mut out = vec![0.0; nx * ny];
    solver.integrate_edge_gradients(&gx, &gy, p, &mut out);
    let top = out.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    out.iter_mut().for_each(|v| {
        *v -= top;
        if budget_mm > 0.0 {
            *v = v.max(-budget_mm);
        }
    });
    let (opened, chorded) = crate::cut::morphology::opening_f32_chorded(&out, nx, ny, p, tool, chords);
    h.z_mm = opened;
    chorded
}

/// `hf` resampled (periodic bilinear) onto a grid of `pitch_mm` over the same period, which it must divide.
pub fn resampled(hf: &Heightfield, pitch_mm: f64) -> Heightfield {
    let (w, hgt) = hf.size_mm();
    let nx = (w / pitch_mm).round() as usize;
    let ny = (hgt / pitch_mm).round() as usize;
    let mut z = vec![0.0; nx * ny];
    z.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        let y = ((j as f64 + 0.5) * pitch_mm / hf.pitch_mm - 0.5).rem_euclid(hf.ny as f64);
        let (j0, fy) = (y.floor() as usize % hf.ny, y - y.floor());
        let j1 = (j0 + 1) % hf.ny;
        for (i, v) in row.iter_mut().enumerate() {
            let x = ((i as f64 + 0.5) * pitch_mm / hf.pitch_mm - 0.5).rem_euclid(hf.nx as f64);
            let (i0, fx) = (x.floor() as usize % hf.nx, x - x.floor());
            let i1 = (i0 + 1) % hf.nx;
            let a = hf.at(i0, j0) * (1.0 - fx) + hf.at(i1, j0) * fx;
            let b = hf.at(i0, j1) * (1.0 - fx) + hf.at(i1, j1) * fx;
            *v = a * (1.0 - fy) + b * fy;
        }
    });
    Heightfield {
        nx,
        ny,
        pitch_mm,
        periodic: true,
        z_mm: z,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::{SlopeDomain, SlopeGrid};

    /// An isotropic Gaussian density of slopes with standard deviation `sigma` per axis, on `n²` cells.
    fn gaussian(sigma: f64, n: usize) -> SlopeGrid {
        let mut g = SlopeGrid::from_fn(SlopeDomain::square(n, 1.0), |p, q| {
            (-(p * p + q * q) / (2.0 * sigma * sigma)).exp()
        });
        g.normalise();
        g
    }

    #[test]
    fn the_marginal_quantile_inverts_its_cdf() {
        // a triangular density on [0, 1]: F(x) = x², F⁻¹(c) = √c (to the bins' linear interpolation)
        let mass: Vec<f64> = (0..BINS).map(|b| (b as f64 + 0.5) / BINS as f64).collect();
        let m = Marginal::from_bins(0.0, 1.0, &mass);
        for x in [0.01, 0.2, 0.5, 0.77, 0.999] {
            assert!((m.cdf_at(x) - x * x).abs() < 1e-6, "F({x}) = {}", m.cdf_at(x));
            assert!((m.quantile(m.cdf_at(x)) - x).abs() < 1e-9);
            assert!((m.quantile(x * x) - x).abs() < 1e-6);
        }
    }

    #[test]
    fn one_direction_transports_the_marginal_onto_the_targets() {
        // 40,000 slopes uniform on a square, every value distinct (x in order, y a permutation); the target a
        // Gaussian of σ 0.15: after matching along x and along y each marginal has the target's variance (the
        // grid's own `stats`, a second computation) and the map is monotone (the order along u is kept)
        let target = gaussian(0.15, 128);
        let want = target.stats().cov;
        let n = 40_000;
        let (mut gx, mut gy): (Vec<f64>, Vec<f64>) = (0..n)
            .map(|k| {
                let y = (k * 7919) % n;
                ((k as f64 + 0.5) / n as f64 - 0.5, (y as f64 + 0.5) / n as f64 - 0.5)
            })
            .unzip();
        match_direction(&mut gx, &mut gy, &target, (1.0, 0.0));
        match_direction(&mut gx, &mut gy, &target, (0.0, 1.0));
        let var = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64
        };
        assert!(
            (var(&gx) / want[0][0] - 1.0).abs() < 0.01,
            "{} vs {}",
            var(&gx),
            want[0][0]
        );
        assert!(
            (var(&gy) / want[1][1] - 1.0).abs() < 0.01,
            "{} vs {}",
            var(&gy),
            want[1][1]
        );
        assert!((1..n).all(|k| gx[k] >= gx[k - 1]), "monotone along x");
    }

    #[test]
    fn an_iteration_leaves_a_reachable_surface_within_the_budget_and_closer_to_the_target() {
        // a 2.4 mm periodic tile of waves, 240² at 10 µm (slope variances 0.14 and 0.31 of the target's),
        // refined towards a Gaussian of σ 0.2 with a 0.5 mm ball; the NDF on 32² cells, so that 57,600 slopes
        // fill its cells without much sampling noise
        let (n, pitch, budget) = (240, 0.01, 0.3);
        let tool = Shape::Ball { diameter_mm: 0.5 };
        let tau = std::f64::consts::TAU;
        let z: Vec<f64> = (0..n * n)
            .map(|k| {
                let (x, y) = ((k % n) as f64 / n as f64, (k / n) as f64 / n as f64);
                0.02 * ((tau * 2.0 * x).sin() + (tau * 3.0 * y).cos())
            })
            .collect();
        let mut h = Heightfield {
            nx: n,
            ny: n,
            pitch_mm: pitch,
            periodic: true,
            z_mm: z,
        };
        let target = gaussian(0.2, 32);
        let ndf = |h: &Heightfield| {
            let (mut g, _) =
                crate::base::surface::ndf_of_slopes(&crate::base::surface::slopes(h, 0.0, 0), target.domain);
            g.normalise();
            g
        };
        let first = ndf(&h).relative_l1(&target);
        let mut solver = PoissonSolver::new(n, n);
        for k in 0..6 {
            iterate(&mut h, &target, &tool, budget, k, &mut solver, None);
        }
        let (lo, hi) = h.range();
        assert!(hi.abs() < 1e-9 && lo >= -budget - 1e-12, "range {lo}..{hi}");
        let opened = crate::cut::morphology::opening(&h.z_mm, n, n, pitch, true, &tool);
        let worst = opened.iter().zip(&h.z_mm).map(|(o, z)| o - z).fold(0.0, f64::max);
        assert!(
            worst < 1e-6,
            "the ball's opening stands {worst} mm above the refined surface"
        );
        let g = ndf(&h);
        let last = g.relative_l1(&target);
        assert!(last < 0.5 * first, "L1 to the target {first:.3} → {last:.3}");
        let (got, want) = (g.stats().cov, target.stats().cov);
        println!(
            "L1 {first:.3} → {last:.3}; variance ratios {:.3}, {:.3}; opening above by {worst:.1e} mm",
            got[0][0] / want[0][0],
            got[1][1] / want[1][1]
        );
        for a in 0..2 {
            let r = got[a][a] / want[a][a];
            assert!((r - 1.0).abs() < 0.1, "axis {a}: variance ratio {r:.3}");
        }
    }

    #[test]
    fn resampling_stays_within_the_bilinear_bound() {
        // f = sin(2πx/L)·cos(2πy/L) on a periodic grid of 40 samples, onto 2.5× finer: bilinear interpolation errs
        // by at most (h²/8)(|f_xx| + |f_yy|) ≤ h²/8 · 2(2π/L)²
        let (n, pitch) = (40, 0.05);
        let l = n as f64 * pitch;
        let w = std::f64::consts::TAU / l;
        let f = |x: f64, y: f64| (w * x).sin() * (w * y).cos();
        let hf = Heightfield {
            nx: n,
            ny: n,
            pitch_mm: pitch,
            periodic: true,
            z_mm: (0..n * n)
                .map(|k| f(((k % n) as f64 + 0.5) * pitch, ((k / n) as f64 + 0.5) * pitch))
                .collect(),
        };
        let fine = resampled(&hf, pitch * 0.4);
        assert_eq!((fine.nx, fine.ny), (100, 100));
        let bound = pitch * pitch / 8.0 * 2.0 * w * w;
        for j in 0..fine.ny {
            for i in 0..fine.nx {
                let (x, y) = ((i as f64 + 0.5) * fine.pitch_mm, (j as f64 + 0.5) * fine.pitch_mm);
                let e = (fine.at(i, j) - f(x, y)).abs();
                assert!(e <= bound, "({i}, {j}): {e} > {bound}");
            }
        }
        let same = resampled(&hf, pitch);
        let worst = same
            .z_mm
            .iter()
            .zip(&hf.z_mm)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "the same pitch is the same grid, to rounding: {worst}");
    }
}
