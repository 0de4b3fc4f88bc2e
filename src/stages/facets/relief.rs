//! Facet heights within a relief budget (DESIGN.md §3.2).
//!
//! Poisson integration (Eqs. 20–21) gives the heights `z` that minimise the squared steps at all facet
//! edges, and nothing bounds their range: it grows like a random walk of the slopes, `√N·σ·a`. A facet `k`
//! with slopes `(p, q)` spans `z_k ± e_k`, `e_k = ½a(|p| + |q|)`, so the tile's relief is
//! `max(z + e) − min(z − e)`. To keep it within a budget `B` the heights solve the same least-squares
//! problem with box constraints, `L + e_k ≤ z_k ≤ L + B − e_k`: where the unconstrained surface would climb
//! out of the band, the facets are held inside it and the difference becomes deliberate steps at the
//! edges around them. The problem is convex; projected Gauss–Seidel (each facet set to the mean of what its
//! four edges ask, then clipped to its box) converges to its minimum. The band's floor `L` is chosen, among
//! the unconstrained heights' quantiles, to clip the least.

/// Relief of a facet arrangement with heights `z`: `max(z + e) − min(z − e)`, mm.
pub fn relief_mm(p: &[f64], q: &[f64], z: &[f64], facet_mm: f64) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..z.len() {
        let e = 0.5 * facet_mm * (p[k].abs() + q[k].abs());
        lo = lo.min(z[k] - e);
        hi = hi.max(z[k] + e);
    }
    hi - lo
}

/// Clip the Poisson heights `z` of a cyclic `w × h` arrangement into a relief budget `budget_mm`, keeping
/// the squared edge steps least within the band `[floor, floor + budget]` (module notes). Returns the floor,
/// or `None` when even one facet alone is taller than the budget (then `z` is unchanged). A relief already
/// within the budget is left as it is (its floor is returned).
pub fn bound(p: &[f64], q: &[f64], z: &mut [f64], w: usize, h: usize, facet_mm: f64, budget_mm: f64) -> Option<f64> {
    let n = w * h;
    let a = facet_mm;
    let e: Vec<f64> = (0..n).map(|k| 0.5 * a * (p[k].abs() + q[k].abs())).collect();
    if e.iter().any(|&e| 2.0 * e > budget_mm) {
        return None;
    }
    if relief_mm(p, q, z, a) <= budget_mm {
        return Some((0..n).map(|k| z[k] - e[k]).fold(f64::INFINITY, f64::min));
    }
    // the floor L that clips least: try the lower ends z − e at a spread of quantiles
    let mut lows: Vec<f64> = (0..n).map(|k| z[k] - e[k]).collect();
    lows.sort_by(f64::total_cmp);
    let clip = |floor: f64| -> f64 {
        (0..n)
            .map(|k| {
                let (lo, hi) = (floor + e[k], floor + budget_mm - e[k]);
                (lo - z[k]).max(0.0) + (z[k] - hi).max(0.0)
            })
            .sum()
    };
    let floor = (0..=64)
        .map(|i| lows[(i * (n - 1)) / 64])
        .min_by(|x, y| clip(*x).total_cmp(&clip(*y)))
        .unwrap_or(lows[0]);
    let lo: Vec<f64> = (0..n).map(|k| floor + e[k]).collect();
    let hi: Vec<f64> = (0..n).map(|k| floor + budget_mm - e[k]).collect();
    for k in 0..n {
        z[k] = z[k].clamp(lo[k], hi[k]);
    }
    // projected Gauss–Seidel on Σ (z_r − z_k − a·g)²: the four edges of facet k each ask for a height
    let idx = |x: usize, y: usize| (y % h) * w + (x % w);
    for _ in 0..500 {
        let mut moved = 0.0f64;
        for y in 0..h {
            for x in 0..w {
                let k = idx(x, y);
                let (r, l) = (idx(x + 1, y), idx(x + w - 1, y));
                let (u, d) = (idx(x, y + 1), idx(x, y + h - 1));
                let gx_r = 0.5 * (p[k] + p[r]);
                let gx_l = 0.5 * (p[l] + p[k]);
                let gy_u = 0.5 * (q[k] + q[u]);
                let gy_d = 0.5 * (q[d] + q[k]);
                let want = 0.25 * ((z[r] - a * gx_r) + (z[l] + a * gx_l) + (z[u] - a * gy_u) + (z[d] + a * gy_d));
                let v = want.clamp(lo[k], hi[k]);
                moved = moved.max((v - z[k]).abs());
                z[k] = v;
            }
        }
        if moved < 1e-10 * a {
            break;
        }
    }
    Some(floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::facets::poisson::{edge_steps, PoissonSolver};
    use rand::{Rng, SeedableRng};

    fn arrangement(w: usize, h: usize, s: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut p: Vec<f64> = (0..w * h).map(|_| rng.gen_range(-s..s)).collect();
        let mut q: Vec<f64> = (0..w * h).map(|_| rng.gen_range(-s..s)).collect();
        let (mp, mq) = (
            p.iter().sum::<f64>() / p.len() as f64,
            q.iter().sum::<f64>() / q.len() as f64,
        );
        p.iter_mut().for_each(|v| *v -= mp);
        q.iter_mut().for_each(|v| *v -= mq);
        (p, q)
    }

    fn sq_steps(p: &[f64], q: &[f64], z: &[f64], w: usize, h: usize) -> f64 {
        let (sx, sy) = edge_steps(p, q, z, w, h, 1.0);
        sx.iter().chain(&sy).map(|s| s * s).sum()
    }

    #[test]
    fn the_budget_holds_and_the_steps_are_the_least_within_it() {
        let (w, h) = (12, 12);
        for seed in 0..5 {
            let (p, q) = arrangement(w, h, 0.5, seed);
            let mut z = vec![0.0; w * h];
            PoissonSolver::new(w, h).facet_heights(&p, &q, 1.0, &mut z);
            let free = relief_mm(&p, &q, &z, 1.0);
            let tallest = (0..w * h).map(|k| p[k].abs() + q[k].abs()).fold(0.0, f64::max);
            let budget = (0.6 * free).max(tallest + 0.05);
            assert!(budget < free, "seed {seed}: the budget must bind");
            let poisson = sq_steps(&p, &q, &z, w, h);
            let mut zb = z.clone();
            let floor = bound(&p, &q, &mut zb, w, h, 1.0, budget).unwrap();
            assert!(relief_mm(&p, &q, &zb, 1.0) <= budget + 1e-9, "seed {seed}");
            let bounded = sq_steps(&p, &q, &zb, w, h);
            // dearer than free Poisson (its unconstrained minimum), and no move of one facet within its box
            // lowers the steps: the optimality condition of the box-constrained (convex) minimum
            assert!(bounded >= poisson - 1e-9);
            for k in 0..w * h {
                let e = 0.5 * (p[k].abs() + q[k].abs());
                for dz in [-1e-4, 1e-4] {
                    let mut t = zb.clone();
                    t[k] += dz;
                    if t[k] >= floor + e - 1e-12 && t[k] <= floor + budget - e + 1e-12 {
                        assert!(
                            sq_steps(&p, &q, &t, w, h) >= bounded - 1e-9,
                            "facet {k} could move by {dz}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_relief_within_the_budget_is_left_alone_and_an_impossible_one_refused() {
        let (w, h) = (6, 6);
        let (p, q) = arrangement(w, h, 0.3, 9);
        let mut z = vec![0.0; w * h];
        PoissonSolver::new(w, h).facet_heights(&p, &q, 1.0, &mut z);
        let before = z.clone();
        assert!(bound(&p, &q, &mut z, w, h, 1.0, 100.0).is_some());
        assert_eq!(z, before);
        assert!(bound(&p, &q, &mut z, w, h, 1.0, 0.01).is_none());
        assert_eq!(z, before);
    }
}
