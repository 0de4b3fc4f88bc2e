//! The step energy S and the relief energy R of a facet arrangement, as quadratic forms in the slopes that
//! the annealer ([`super::arrange`]) keeps up to date swap by swap.
//!
//! With the edge gradients `gx(x,y) = ½(p(x,y) + p(x+1,y))`, `gy(x,y) = ½(q(x,y) + q(x,y+1))` (cyclic) of
//! [`super::poisson::edge_gradients`], the Poisson heights `z` minimise the squared steps at the edge midpoints,
//! `step_x = z(x+1,y) − z(x,y) − a·gx(x,y)` and likewise in y (facet side `a`).
//!
//! **S, steps.** By the discrete Hodge decomposition on the torus, the residual of that least-squares fit is
//! the curl part of `g` plus its harmonic (constant) part, which no `z` can remove:
//!
//! `S/a² = Σ step²/a² = cᵀ G c + N (p̄² + q̄²)`,
//!
//! where `c(x,y) = gx(x,y) + gy(x+1,y) − gx(x,y+1) − gy(x,y)` is the curl on the plaquette whose corners are
//! the facet centres `(x,y), (x+1,y), (x+1,y+1), (x,y+1)` (indexed like the facet at its lower-left corner),
//! and `G = (−Δ)⁻¹` the periodic Green's function of the 5-point Laplacian on the W×H plaquette grid with the
//! zero mode removed (`Σc = 0` always). Proof sketch: the residual `r = g − ∇z` is divergence-free, so
//! `r = curlᵀφ + h̄` (`h̄` constant), `curl curlᵀ = −Δ`, hence `φ = G c` and `|r|² = cᵀGc + N|h̄|²`; the mean of
//! `gx` is the mean of `p`. The facets stage removes the mean slope, and swaps keep it, so the last term is a
//! constant (kept so that S equals the integrated steps exactly; the tests check it against the solver).
//!
//! **R, relief.** The heights solve `L z = a·d` with `d(x,y) = gx(x,y) − gx(x−1,y) + gy(x,y) − gy(x,y−1)`, i.e.
//! `d = ½(p(x+1,y) − p(x−1,y)) + ½(q(x,y+1) − q(x,y−1))`, so with mean(z) = 0
//!
//! `Σ z²/a² = dᵀ G² d`, `G² = L⁻²` (zero mode removed).
//!
//! Both Green's functions are translation invariant: one table of N values each, `T(dx, dy)` at index
//! `dy·W + dx`. A change `(δp, δq)` at facet `(x,y)` changes `c` at the four plaquettes around it — `(x,y)` by
//! `½(δp − δq)`, `(x−1,y)` by `½(δp + δq)`, `(x,y−1)` by `−½(δp + δq)`, `(x−1,y−1)` by `½(δq − δp)` — and `d`
//! at its four neighbours (not at itself): `(x±1,y)` by `∓½δp`, `(x,y±1)` by `∓½δq`. With `ψ = G c`
//! maintained, `δS/a² = 2 δcᵀψ + δcᵀ G δc`; since a swap moves `(δp, δq)` into one facet and out of another,
//! the stencils are folded into per-facet tables (`Quadratic`): a proposal costs about 16 look-ups, an
//! accepted swap `ψ += G δc` four shifted table copies, O(4N). `ζ = G² d` the same way.
//!
//! The update of ψ and ζ is deferred: [`StepTerms::swap`] leaves the change pending, and the next swap either
//! undoes it (the same pair again: the annealer's rejection, which then costs nothing) or commits it first.

use super::poisson::{edge_gradients, PoissonSolver};

/// Solve `L z = rhs` on the cyclic `w × h` grid (5-point, unit spacing) with mean(z) = 0. A `1 × h` grid is
/// solved as the `h × 1` grid with the same memory layout (the FFT wants at least two columns).
fn solve_periodic(w: usize, h: usize, rhs: &[f64]) -> Vec<f64> {
    let mut z = vec![0.0; w * h];
    match (w, h) {
        (1, 1) => {}
        (1, _) => PoissonSolver::new(h, 1).solve(rhs, &mut z),
        _ => PoissonSolver::new(w, h).solve(rhs, &mut z),
    }
    z
}

/// The Green's function tables `(G, G²)` of the cyclic `w × h` grid: `G = (−L)⁻¹`, `G² = L⁻²`, both with the
/// zero mode removed, at index `dy·w + dx`.
pub(crate) fn green_tables(w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
    let mut delta = vec![0.0; w * h];
    delta[0] = 1.0;
    let lz = solve_periodic(w, h, &delta);
    let g2 = solve_periodic(w, h, &lz);
    (lz.iter().map(|v| -v).collect(), g2)
}

/// Plaquette curl `c` and facet divergence `d` of the edge gradients of slopes `p`, `q` on a cyclic `w × h` grid.
pub(crate) fn curl_and_divergence(p: &[f64], q: &[f64], w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
    let (gx, gy) = edge_gradients(p, q, w, h);
    let mut c = vec![0.0; w * h];
    let mut d = vec![0.0; w * h];
    for y in 0..h {
        let (yu, yd) = ((y + 1) % h, (y + h - 1) % h);
        for x in 0..w {
            let (xr, xl) = ((x + 1) % w, (x + w - 1) % w);
            let k = y * w + x;
            c[k] = gx[k] + gy[y * w + xr] - gx[yu * w + x] - gy[k];
            d[k] = gx[k] - gx[y * w + xl] + gy[k] - gy[yd * w + x];
        }
    }
    (c, d)
}

/// From scratch: `(Σ step²/a², Σ z²/a²)` of the arrangement (dimensionless), in O(N log N).
pub(crate) fn step_and_height_sq(p: &[f64], q: &[f64], w: usize, h: usize) -> (f64, f64) {
    let n = (w * h) as f64;
    let (c, d) = curl_and_divergence(p, q, w, h);
    // cᵀ(−L)⁻¹c = −cᵀ L⁻¹ c
    let lc = solve_periodic(w, h, &c);
    let curl_part = -c.iter().zip(&lc).map(|(a, b)| a * b).sum::<f64>();
    let (pm, qm) = (p.iter().sum::<f64>() / n, q.iter().sum::<f64>() / n);
    let z = solve_periodic(w, h, &d);
    (curl_part + n * (pm * pm + qm * qm), z.iter().map(|v| v * v).sum())
}

/// Facet-centre heights (mean zero) of an arrangement with facet side `facet`, the heights
/// [`PoissonSolver::facet_heights`] gives (also for a single column).
pub(crate) fn facet_heights(p: &[f64], q: &[f64], w: usize, h: usize, facet: f64) -> Vec<f64> {
    let (_, d) = curl_and_divergence(p, q, w, h);
    let rhs: Vec<f64> = d.iter().map(|v| v * facet).collect();
    solve_periodic(w, h, &rhs)
}

/// Relief of the faceted surface, in the unit of `facet`: max − min over the facet planes' corners, where
/// facet `k` spans `z_k ± (facet/2)(|p_k| + |q_k|)`. For a relief budget (e.g. the flute length): when it is
/// exceeded, anneal again with a larger `relief_weight`.
pub(crate) fn relief(a: &super::Arrangement, facet: f64) -> f64 {
    let z = facet_heights(&a.p, &a.q, a.w, a.h, facet);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (k, zk) in z.iter().enumerate() {
        let half = 0.5 * facet * (a.p[k].abs() + a.q[k].abs());
        lo = lo.min(zk - half);
        hi = hi.max(zk + half);
    }
    hi - lo
}

/// Stencil of a facet's slope change on the field it drives: `(dx, dy, coefficient)` per unit `δp` (`[0]`) and
/// unit `δq` (`[1]`), offsets from the facet.
type Stencil = [&'static [(isize, isize, f64)]; 2];

/// The plaquette curl `c`: a change at facet `(x,y)` moves the plaquettes `(x,y), (x−1,y), (x,y−1), (x−1,y−1)`.
const CURL: Stencil = [
    &[(0, 0, 0.5), (-1, 0, 0.5), (0, -1, -0.5), (-1, -1, -0.5)],
    &[(0, 0, -0.5), (-1, 0, 0.5), (0, -1, -0.5), (-1, -1, 0.5)],
];

/// The facet divergence `d`: a change at facet `(x,y)` moves its four neighbours, not itself.
const DIV: Stencil = [&[(1, 0, -0.5), (-1, 0, 0.5)], &[(0, 1, -0.5), (0, -1, 0.5)]];

/// `i + d` on a cycle of `n`.
#[inline]
fn wrap(i: usize, d: isize, n: usize) -> usize {
    (i as isize + d).rem_euclid(n as isize) as usize
}

/// One quadratic form `xᵀ T x` of a field `x` that facet slopes drive through a stencil, with `f = T x`
/// maintained. A swap moves `v = (δp, δq)` into facet `a` and `−v` into facet `b`, so everything it needs is
/// tabulated by facet offset: `K_α = T ∗ σ_α` (the response of `f` to a unit slope change) and
/// `M_αβ(r) = Σ_j σ_α(j) K_β(j + r)`, with `M_qp(r) = M_pq(−r)` (T symmetric). Then, `r = a − b`,
/// `δ(xᵀTx) = 2 Σ_α v_α (u_α(a) − u_α(b)) + 2 vᵀ(M(0) − M(r))v` (M symmetrised), `u_α(k) = Σ_s σ_α(s) f(k+s)`,
/// and on acceptance `f += Σ_α v_α (K_α(· − a) − K_α(· − b))`: four shifted copies, O(4N).
#[derive(Clone, Debug)]
struct Quadratic {
    w: usize,
    h: usize,
    stencil: Stencil,
    /// `K_p, K_q` by offset `dy·w + dx`.
    kern: [Vec<f64>; 2],
    /// `M_pp, M_pq, M_qq` by offset.
    m: [Vec<f64>; 3],
    /// `f = T x`.
    field: Vec<f64>,
    /// Per facet and slope component, the field indices its stencil reads (`stencil[α].len()` per facet).
    taps: [Vec<u32>; 2],
}

impl Quadratic {
    fn new(table: &[f64], stencil: Stencil, w: usize, h: usize) -> Self {
        let n = w * h;
        let shifted_sum = |t: &[f64], st: &[(isize, isize, f64)], sign: isize| {
            let mut out = vec![0.0; n];
            for &(dx, dy, v) in st {
                add_shifted(&mut out, t, w, h, (wrap(0, sign * dx, w), wrap(0, sign * dy, h)), v);
            }
            out
        };
        // K_α(j) = Σ_s σ_α(s) T(j − s); M_αβ(r) = Σ_s σ_α(s) K_β(r + s)
        let kern = [shifted_sum(table, stencil[0], 1), shifted_sum(table, stencil[1], 1)];
        let m = [
            shifted_sum(&kern[0], stencil[0], -1),
            shifted_sum(&kern[1], stencil[0], -1),
            shifted_sum(&kern[1], stencil[1], -1),
        ];
        let taps = [0, 1].map(|alpha: usize| {
            (0..n)
                .flat_map(|k| {
                    let (x, y) = (k % w, k / w);
                    stencil[alpha]
                        .iter()
                        .map(move |&(dx, dy, _)| (wrap(y, dy, h) * w + wrap(x, dx, w)) as u32)
                })
                .collect()
        });
        Self {
            w,
            h,
            stencil,
            kern,
            m,
            field: Vec::new(),
            taps,
        }
    }

    #[inline]
    fn offset(&self, (xa, ya): (usize, usize), (xb, yb): (usize, usize)) -> usize {
        let dx = if xa >= xb { xa - xb } else { xa + self.w - xb };
        let dy = if ya >= yb { ya - yb } else { ya + self.h - yb };
        dy * self.w + dx
    }

    /// `u_α(k) = Σ_s σ_α(s) f(k + s)`.
    #[inline]
    fn drive(&self, alpha: usize, (x, y): (usize, usize)) -> f64 {
        let st = self.stencil[alpha];
        let k = (y * self.w + x) * st.len();
        st.iter()
            .zip(&self.taps[alpha][k..k + st.len()])
            .map(|(&(_, _, v), &i)| v * self.field[i as usize])
            .sum()
    }

    /// The change of the form when `v = (dp, dq)` moves into facet `a` and out of facet `b` (`a ≠ b`).
    fn change(&self, a: (usize, usize), b: (usize, usize), (dp, dq): (f64, f64)) -> f64 {
        let lin = dp * (self.drive(0, a) - self.drive(0, b)) + dq * (self.drive(1, a) - self.drive(1, b));
        let (r, rn) = (self.offset(a, b), self.offset(b, a));
        let [pp, pq, qq] = &self.m;
        let quad = dp * dp * (pp[0] - pp[r]) + dp * dq * (2.0 * pq[0] - pq[r] - pq[rn]) + dq * dq * (qq[0] - qq[r]);
        2.0 * lin + 2.0 * quad
    }

    /// Apply the move to `f`.
    fn commit(&mut self, a: (usize, usize), b: (usize, usize), (dp, dq): (f64, f64)) {
        let (w, h) = (self.w, self.h);
        for (alpha, v) in [(0, dp), (1, dq)] {
            add_shifted(&mut self.field, &self.kern[alpha], w, h, a, v);
            add_shifted(&mut self.field, &self.kern[alpha], w, h, b, -v);
        }
    }
}

/// A swap whose energy change was returned but whose field update is not yet applied.
#[derive(Clone, Copy, Debug)]
struct Pending {
    a: (usize, usize),
    b: (usize, usize),
    /// `(δp, δq)` into `a`.
    v: (f64, f64),
    /// The weighted energy change it returned.
    delta: f64,
}

/// The incrementally maintained S and R terms of one arrangement (built only when a weight is non-zero; a
/// term whose weight is 0 has no tables and costs nothing).
#[derive(Clone, Debug)]
pub(crate) struct StepTerms {
    w: usize,
    h: usize,
    step_weight: f64,
    relief_weight: f64,
    /// `cᵀGc` on the plaquettes, `f = ψ`.
    steps: Option<Quadratic>,
    /// `dᵀG²d` on the facets, `f = ζ`.
    heights: Option<Quadratic>,
    pending: Option<Pending>,
}

impl StepTerms {
    /// Tables and fields for the slopes `p`, `q` of a `w × h` arrangement.
    pub(crate) fn new(w: usize, h: usize, step_weight: f64, relief_weight: f64, p: &[f64], q: &[f64]) -> Self {
        let (g, g2) = green_tables(w, h);
        let mut t = Self {
            w,
            h,
            step_weight,
            relief_weight,
            steps: (step_weight != 0.0).then(|| Quadratic::new(&g, CURL, w, h)),
            heights: (relief_weight != 0.0).then(|| Quadratic::new(&g2, DIV, w, h)),
            pending: None,
        };
        t.refresh(p, q);
        t
    }

    /// Recompute ψ and ζ from the slopes by FFT (after a shuffle, or to shed rounding drift); drops a pending
    /// update, which the slopes already contain.
    pub(crate) fn refresh(&mut self, p: &[f64], q: &[f64]) {
        let (w, h) = (self.w, self.h);
        let (c, d) = curl_and_divergence(p, q, w, h);
        if let Some(s) = self.steps.as_mut() {
            // ψ = G c = −L⁻¹c
            s.field = solve_periodic(w, h, &c).iter().map(|v| -v).collect();
        }
        if let Some(r) = self.heights.as_mut() {
            // ζ = L⁻²d
            r.field = solve_periodic(w, h, &solve_periodic(w, h, &d));
        }
        self.pending = None;
    }

    /// Apply the pending update, if any: `ψ += G δc`, `ζ += G² δd`.
    pub(crate) fn commit(&mut self) {
        if let Some(pd) = self.pending.take() {
            for f in [self.steps.as_mut(), self.heights.as_mut()].into_iter().flatten() {
                f.commit(pd.a, pd.b, pd.v);
            }
        }
    }

    /// The weighted change `step_weight·δ(S/a²) + relief_weight·δ(Σz²/a²)` of swapping the facets at columns
    /// and rows `a ≠ b`,
    /// where the slopes at `a` change by `(dp, dq)` and those at `b` by `(−dp, −dq)`. Call it once per swap
    /// (the caller swaps the slopes); swapping the same pair again undoes the pending change for free.
    pub(crate) fn swap(&mut self, a: (usize, usize), b: (usize, usize), dp: f64, dq: f64) -> f64 {
        if let Some(pd) = &self.pending {
            if (pd.a, pd.b) == (a, b) || (pd.a, pd.b) == (b, a) {
                let delta = pd.delta;
                self.pending = None;
                return -delta;
            }
        }
        self.commit();
        let v = (dp, dq);
        let mut delta = 0.0;
        if let Some(s) = &self.steps {
            delta += self.step_weight * s.change(a, b, v);
        }
        if let Some(r) = &self.heights {
            delta += self.relief_weight * r.change(a, b, v);
        }
        self.pending = Some(Pending { a, b, v, delta });
        delta
    }

    /// `(ψ, ζ)` with the pending update applied (empty when off; for tests).
    #[cfg(test)]
    pub(crate) fn fields(&mut self) -> (Vec<f64>, Vec<f64>) {
        self.commit();
        let f = |q: &Option<Quadratic>| q.as_ref().map_or(Vec::new(), |q| q.field.clone());
        (f(&self.steps), f(&self.heights))
    }
}

/// `field += v · T(· − (xi, yi))`: one shifted copy of the table, row by row in two contiguous runs.
fn add_shifted(field: &mut [f64], table: &[f64], w: usize, h: usize, (xi, yi): (usize, usize), v: f64) {
    for y in 0..h {
        let dy = if y >= yi { y - yi } else { y + h - yi };
        let t = &table[dy * w..(dy + 1) * w];
        let f = &mut field[y * w..(y + 1) * w];
        let (f_lo, f_hi) = f.split_at_mut(xi);
        // x ≥ xi: offset x − xi; x < xi: offset x + w − xi
        f_hi.iter_mut().zip(&t[..w - xi]).for_each(|(f, t)| *f += v * t);
        f_lo.iter_mut().zip(&t[w - xi..]).for_each(|(f, t)| *f += v * t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::facets::poisson::edge_steps;
    use rand::{Rng, SeedableRng};

    fn slopes(n: usize, seed: u64, mean: (f64, f64)) -> (Vec<f64>, Vec<f64>) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        (0..n)
            .map(|_| (mean.0 + rng.gen_range(-0.5..0.5), mean.1 + rng.gen_range(-0.5..0.5)))
            .unzip()
    }

    /// `xᵀ T x` by the table, summed pair by pair (no FFT, no ψ).
    fn table_form(table: &[f64], x: &[f64], w: usize) -> f64 {
        let n = x.len();
        let h = n / w;
        let mut s = 0.0;
        for i in 0..n {
            for j in 0..n {
                let (dx, dy) = ((i % w + w - j % w) % w, (i / w + h - j / w) % h);
                s += x[i] * x[j] * table[dy * w + dx];
            }
        }
        s
    }

    /// The Hodge identity against the Poisson solver: the squared steps the solver's heights leave equal
    /// `cᵀGc + N(p̄² + q̄²)`, and the solver's heights have `Σz²/a² = dᵀG²d` — both by the table and by the FFT.
    #[test]
    fn step_and_height_forms_equal_the_poisson_integration() {
        let a_mm = 0.7;
        for (w, h) in [(12, 12), (7, 5), (2, 3), (6, 1), (16, 9)] {
            for (seed, mean) in [(1, (0.0, 0.0)), (2, (0.1, -0.2))] {
                let (mut p, mut q) = slopes(w * h, seed + (w * h) as u64, (0.0, 0.0));
                let n = (w * h) as f64;
                let (pm, qm) = (p.iter().sum::<f64>() / n, q.iter().sum::<f64>() / n);
                p.iter_mut().for_each(|v| *v += mean.0 - pm);
                q.iter_mut().for_each(|v| *v += mean.1 - qm);
                let mut z = vec![0.0; w * h];
                PoissonSolver::new(w, h).facet_heights(&p, &q, a_mm, &mut z);
                let (sx, sy) = edge_steps(&p, &q, &z, w, h, a_mm);
                let steps = sx.iter().chain(&sy).map(|s| s * s).sum::<f64>() / (a_mm * a_mm);
                let heights = z.iter().map(|v| v * v).sum::<f64>() / (a_mm * a_mm);

                let (g, g2) = green_tables(w, h);
                let (c, d) = curl_and_divergence(&p, &q, w, h);
                assert!(c.iter().sum::<f64>().abs() < 1e-12, "the curl sums to zero");
                let harmonic = n * (mean.0 * mean.0 + mean.1 * mean.1);
                let by_table = (table_form(&g, &c, w) + harmonic, table_form(&g2, &d, w));
                let by_fft = step_and_height_sq(&p, &q, w, h);
                for (name, got, want) in [
                    ("S by table", by_table.0, steps),
                    ("S by FFT", by_fft.0, steps),
                    ("Σz² by table", by_table.1, heights),
                    ("Σz² by FFT", by_fft.1, heights),
                ] {
                    assert!(
                        (got - want).abs() < 1e-9 * want.max(1.0),
                        "{w}×{h} mean {mean:?} {name}: {got} vs {want}"
                    );
                }
                let z2 = facet_heights(&p, &q, w, h, a_mm);
                assert!(z.iter().zip(&z2).all(|(a, b)| (a - b).abs() < 1e-12));
            }
        }
    }

    /// A single column (solved as a row): each x-edge joins a facet to itself, so its step is `a·p`, and the
    /// y-edges are a 1D cycle whose heights absorb everything but the mean gradient: `S/a² = Σp² + N q̄²`.
    #[test]
    fn a_single_column_leaves_its_x_slopes_and_mean_y_slope_as_steps() {
        let (p, q) = slopes(6, 4, (0.05, 0.1));
        let (steps, _) = step_and_height_sq(&p, &q, 1, 6);
        let qm = q.iter().sum::<f64>() / 6.0;
        let want = p.iter().map(|v| v * v).sum::<f64>() + 6.0 * qm * qm;
        assert!((steps - want).abs() < 1e-12, "{steps} vs {want}");
    }

    /// The relief of the facet planes bounds the rasterised heightfield's range from above, by at most the
    /// corners the pixel centres miss (half a pitch along each axis at either extreme).
    #[test]
    fn relief_bounds_the_rasterised_range() {
        use crate::stages::facets::{rasterise, Arrangement, FacetsConfig};
        let (w, h) = (8, 6);
        let (p, q) = slopes(w * h, 9, (0.0, 0.0));
        let s: Vec<(f64, f64)> = p.iter().copied().zip(q.iter().copied()).collect();
        let a = Arrangement::new(w, h, &s, 0.0);
        let cfg = FacetsConfig {
            facets_x: w,
            facets_y: h,
            facet_mm: 1.0,
            pitch_um: 10.0,
            ..Default::default()
        };
        let mut z = vec![0.0; w * h];
        PoissonSolver::new(w, h).facet_heights(&a.p, &a.q, cfg.facet_mm, &mut z);
        let (lo, hi) = rasterise(&a, &z, &cfg).range();
        let r = relief(&a, cfg.facet_mm);
        let missed = 0.010 * p.iter().zip(&q).map(|(p, q)| p.abs() + q.abs()).fold(0.0, f64::max);
        assert!(
            r >= hi - lo - 1e-12 && r <= hi - lo + missed,
            "{r} vs {} (+{missed})",
            hi - lo
        );
    }
}
