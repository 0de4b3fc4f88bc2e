//! Sampling N facet slopes from a target NDF (Section 7.2, "Sampling").
//!
//! 1. **Importance samples** through the inverse CDF of the slope grid (rows by their marginal, then the
//!    cell within the row, uniform inside the cell), driven either by a Halton (2, 3) sequence (low
//!    discrepancy) or by i.i.d. uniforms (plain importance sampling, for comparison).
//! 2. **Lloyd iterations** toward a centroidal Voronoi tessellation (CVT): each site moves to the weighted
//!    centroid of its Voronoi cell. Cells come from `spade`'s Delaunay triangulation: a site's cell is the
//!    slope domain clipped by the bisectors to its Delaunay neighbours. Centroids are integrated over a
//!    supersampled copy of the density grid.
//!
//! **Weight.** A CVT under density ρ places points with density ∝ ρ^{d/(d+2)} (Gersho's conjecture; Du,
//! Faber & Gunzburger 1999), i.e. ρ^{1/2} in the slope plane, which would over-sample the tails. The cells are
//! therefore weighted by ρ², so the sites follow ρ itself.

use crate::base::slope::SlopeGrid;
use rand::Rng;
use spade::{DelaunayTriangulation, Point2, Triangulation};

/// Inverse-CDF sampler of a slope grid (piecewise-constant density over cells).
pub struct InverseCdf<'a> {
    grid: &'a SlopeGrid,
    /// Cumulative row masses, `ny + 1` entries from 0 to 1.
    rows: Vec<f64>,
    /// Per row, cumulative cell masses within the row, `nx + 1` entries from 0 to 1.
    cols: Vec<Vec<f64>>,
}

impl<'a> InverseCdf<'a> {
    /// Build the CDF tables; the grid must have positive mass.
    pub fn new(grid: &'a SlopeGrid) -> Self {
        let d = &grid.domain;
        let mut rows = vec![0.0; d.ny + 1];
        let mut cols = Vec::with_capacity(d.ny);
        for j in 0..d.ny {
            let mut c = vec![0.0; d.nx + 1];
            for i in 0..d.nx {
                c[i + 1] = c[i] + grid.at(i, j);
            }
            let total = c[d.nx];
            rows[j + 1] = rows[j] + total;
            if total > 0.0 {
                c.iter_mut().for_each(|v| *v /= total);
            }
            cols.push(c);
        }
        let total = rows[d.ny];
        rows.iter_mut().for_each(|v| *v /= total);
        Self { grid, rows, cols }
    }

    /// The slope `(p, q)` of the uniforms `(u, v)` in `[0, 1)²`.
    pub fn sample(&self, u: f64, v: f64) -> (f64, f64) {
        let d = &self.grid.domain;
        let (j, fv) = invert(&self.rows, v);
        let (i, fu) = invert(&self.cols[j], u);
        (d.p_min + (i as f64 + fu) * d.dp(), d.q_min + (j as f64 + fv) * d.dq())
    }
}

/// Index of the bin of `cdf` containing `u` and the fraction within it.
fn invert(cdf: &[f64], u: f64) -> (usize, f64) {
    let n = cdf.len() - 1;
    // first k with cdf[k+1] > u, skipping empty bins
    let k = cdf.partition_point(|c| *c <= u).clamp(1, n) - 1;
    let w = cdf[k + 1] - cdf[k];
    let f = if w > 0.0 {
        ((u - cdf[k]) / w).clamp(0.0, 1.0 - 1e-12)
    } else {
        0.5
    };
    (k, f)
}

/// The radical inverse of `i` in base `b` (the Halton sequence's coordinate).
pub fn radical_inverse(mut i: u64, b: u64) -> f64 {
    let (mut f, mut r) = (1.0, 0.0);
    while i > 0 {
        f /= b as f64;
        r += f * (i % b) as f64;
        i /= b;
    }
    r
}

/// `n` low-discrepancy importance samples (Halton 2, 3, starting at index 1).
pub fn halton_samples(grid: &SlopeGrid, n: usize) -> Vec<(f64, f64)> {
    let cdf = InverseCdf::new(grid);
    (1..=n as u64)
        .map(|i| cdf.sample(radical_inverse(i, 2), radical_inverse(i, 3)))
        .collect()
}

/// `n` i.i.d. importance samples.
pub fn random_samples<R: Rng>(grid: &SlopeGrid, n: usize, rng: &mut R) -> Vec<(f64, f64)> {
    let cdf = InverseCdf::new(grid);
    (0..n).map(|_| cdf.sample(rng.gen::<f64>(), rng.gen::<f64>())).collect()
}

/// Clip a convex polygon by the half-plane `(x − m)·n ≤ 0` (Sutherland–Hodgman, one plane).
fn clip(poly: &[(f64, f64)], m: (f64, f64), n: (f64, f64)) -> Vec<(f64, f64)> {
    let side = |p: (f64, f64)| (p.0 - m.0) * n.0 + (p.1 - m.1) * n.1;
    let mut out = Vec::with_capacity(poly.len() + 1);
    for k in 0..poly.len() {
        let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
        let (sa, sb) = (side(a), side(b));
        if sa <= 0.0 {
            out.push(a);
        }
        if (sa <= 0.0) != (sb <= 0.0) {
            let t = sa / (sa - sb);
            out.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
        }
    }
    out
}

/// What the Lloyd iterations did.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LloydReport {
    /// Iterations run.
    pub iterations: usize,
    /// RMS site movement of the last iteration, in slope units.
    pub last_rms_move: f64,
}

/// Move `sites` toward a CVT of `grid` weighted by ρ² (see the module notes), `iterations` Lloyd steps,
/// centroids integrated on a grid supersampled `supersample` times per axis (bilinear density).
pub fn lloyd(
    grid: &SlopeGrid,
    sites: &mut [(f64, f64)],
    iterations: usize,
    supersample: usize,
    exponent: f64,
) -> LloydReport {
    let d = grid.domain;
    let s = supersample.max(1);
    let (fx, fy) = (d.nx * s, d.ny * s);
    let (sdp, sdq) = (d.dp() / s as f64, d.dq() / s as f64);
    let weight: Vec<f64> = (0..fx * fy)
        .map(|k| {
            let (i, j) = (k % fx, k / fx);
            let r = grid.sample(d.p_min + (i as f64 + 0.5) * sdp, d.q_min + (j as f64 + 0.5) * sdq);
            r.powf(exponent)
        })
        .collect();
    let domain_poly = [
        (d.p_min, d.q_min),
        (d.p_max, d.q_min),
        (d.p_max, d.q_max),
        (d.p_min, d.q_max),
    ];
    let mut report = LloydReport {
        iterations: 0,
        last_rms_move: 0.0,
    };
    for _ in 0..iterations {
        let mut tri: DelaunayTriangulation<Point2<f64>> = DelaunayTriangulation::new();
        let mut handle_to_site = vec![usize::MAX; sites.len()];
        for (k, site) in sites.iter_mut().enumerate() {
            // Coincident sites would share a vertex: nudge until the insertion makes a new one.
            let mut nudge = 0u32;
            loop {
                let h = tri.insert(Point2::new(site.0, site.1)).expect("finite slope sites");
                if h.index() >= handle_to_site.len() || handle_to_site[h.index()] == usize::MAX {
                    if h.index() >= handle_to_site.len() {
                        handle_to_site.resize(h.index() + 1, usize::MAX);
                    }
                    handle_to_site[h.index()] = k;
                    break;
                }
                nudge += 1;
                site.0 += 1e-9 * d.dp() * nudge as f64;
            }
        }
        let mut new_sites = sites.to_vec();
        for v in tri.vertices() {
            let k = handle_to_site[v.fix().index()];
            let sp = v.position();
            let mut poly = domain_poly.to_vec();
            for e in v.out_edges() {
                let t = e.to().position();
                let m = ((sp.x + t.x) / 2.0, (sp.y + t.y) / 2.0);
                poly = clip(&poly, m, (t.x - sp.x, t.y - sp.y));
                if poly.is_empty() {
                    break;
                }
            }
            if let Some(c) = weighted_centroid(&poly, &weight, fx, fy, (d.p_min, d.q_min), (sdp, sdq)) {
                new_sites[k] = c;
            }
        }
        let ms: f64 = sites
            .iter()
            .zip(&new_sites)
            .map(|(a, b)| (a.0 - b.0).powi(2) + (a.1 - b.1).powi(2))
            .sum::<f64>()
            / sites.len() as f64;
        sites.copy_from_slice(&new_sites);
        report.iterations += 1;
        report.last_rms_move = ms.sqrt();
    }
    report
}

/// Weighted centroid of a convex polygon over a gridded weight (cells whose centres fall inside).
fn weighted_centroid(
    poly: &[(f64, f64)],
    weight: &[f64],
    nx: usize,
    ny: usize,
    origin: (f64, f64),
    step: (f64, f64),
) -> Option<(f64, f64)> {
    if poly.len() < 3 {
        return None;
    }
    let ymin = poly.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let ymax = poly.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    let j0 = (((ymin - origin.1) / step.1 - 0.5).ceil().max(0.0)) as usize;
    let j1 = (((ymax - origin.1) / step.1 - 0.5).floor()).min(ny as f64 - 1.0);
    if j1 < 0.0 {
        return None;
    }
    let (mut w, mut wp, mut wq) = (0.0, 0.0, 0.0);
    for j in j0..=j1 as usize {
        let y = origin.1 + (j as f64 + 0.5) * step.1;
        let (mut xl, mut xr) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..poly.len() {
            let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
            if (a.1 <= y && b.1 >= y) || (b.1 <= y && a.1 >= y) {
                let x = if (b.1 - a.1).abs() < 1e-300 {
                    a.0.min(b.0)
                } else {
                    a.0 + (y - a.1) / (b.1 - a.1) * (b.0 - a.0)
                };
                let x2 = if (b.1 - a.1).abs() < 1e-300 { a.0.max(b.0) } else { x };
                xl = xl.min(x);
                xr = xr.max(x2);
            }
        }
        if xl > xr {
            continue;
        }
        let i0 = (((xl - origin.0) / step.0 - 0.5).ceil().max(0.0)) as usize;
        let i1 = ((xr - origin.0) / step.0 - 0.5).floor().min(nx as f64 - 1.0);
        if i1 < 0.0 {
            continue;
        }
        let row = &weight[j * nx..(j + 1) * nx];
        for (i, r) in row.iter().enumerate().take(i1 as usize + 1).skip(i0) {
            let x = origin.0 + (i as f64 + 0.5) * step.0;
            w += r;
            wp += r * x;
            wq += r * y;
        }
    }
    (w > 0.0).then(|| (wp / w, wq / w))
}

/// Two-dimensional Kolmogorov–Smirnov distance between samples and a grid density: the largest difference
/// between the empirical and the true mass of the quadrants anchored at every grid vertex, over the four
/// quadrant orientations (Fasano & Franceschini 1987). 0 is perfect; smaller means lower discrepancy.
pub fn ks_distance(grid: &SlopeGrid, samples: &[(f64, f64)]) -> f64 {
    let d = &grid.domain;
    let (nx, ny) = (d.nx, d.ny);
    let mut counts = vec![0.0; nx * ny];
    for (p, q) in samples {
        let i = (((p - d.p_min) / d.dp()).floor() as isize).clamp(0, nx as isize - 1) as usize;
        let j = (((q - d.q_min) / d.dq()).floor() as isize).clamp(0, ny as isize - 1) as usize;
        counts[j * nx + i] += 1.0 / samples.len() as f64;
    }
    let mass: Vec<f64> = {
        let total: f64 = grid.density.iter().sum();
        grid.density.iter().map(|v| v / total).collect()
    };
    // prefix sums (lower-left quadrants) of both, (nx+1)×(ny+1)
    let prefix = |v: &[f64]| {
        let mut s = vec![0.0; (nx + 1) * (ny + 1)];
        for j in 0..ny {
            for i in 0..nx {
                s[(j + 1) * (nx + 1) + i + 1] =
                    v[j * nx + i] + s[j * (nx + 1) + i + 1] + s[(j + 1) * (nx + 1) + i] - s[j * (nx + 1) + i];
            }
        }
        s
    };
    let (se, sm) = (prefix(&counts), prefix(&mass));
    let at = |s: &[f64], i: usize, j: usize| s[j * (nx + 1) + i];
    let mut worst: f64 = 0.0;
    for j in 0..=ny {
        for i in 0..=nx {
            let quads = |s: &[f64]| {
                let ll = at(s, i, j);
                let lr = at(s, nx, j) - ll;
                let ul = at(s, i, ny) - ll;
                let ur = at(s, nx, ny) - ll - lr - ul;
                [ll, lr, ul, ur]
            };
            let (a, b) = (quads(&se), quads(&sm));
            for k in 0..4 {
                worst = worst.max((a[k] - b[k]).abs());
            }
        }
    }
    worst
}

/// Energy-distance two-sample permutation test (Székely & Rizzo 2004) between `x` and `y`:
/// returns `(statistic, p_value)` with `permutations` random relabellings.
pub fn energy_test<R: Rng>(x: &[(f64, f64)], y: &[(f64, f64)], permutations: usize, rng: &mut R) -> (f64, f64) {
    let pooled: Vec<(f64, f64)> = x.iter().chain(y).copied().collect();
    let n = pooled.len();
    let dist: Vec<f64> = (0..n * n)
        .map(|k| {
            let (a, b) = (pooled[k / n], pooled[k % n]);
            ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt()
        })
        .collect();
    let total: f64 = dist.iter().sum();
    let stat = |label: &[bool]| -> f64 {
        let (mut sxx, mut syy) = (0.0, 0.0);
        let (nx, ny) = (
            label.iter().filter(|l| **l).count() as f64,
            label.iter().filter(|l| !**l).count() as f64,
        );
        for a in 0..n {
            let row = &dist[a * n..(a + 1) * n];
            let (mut rx, mut ry) = (0.0, 0.0);
            for (b, v) in row.iter().enumerate() {
                if label[b] {
                    rx += v;
                } else {
                    ry += v;
                }
            }
            if label[a] {
                sxx += rx;
            } else {
                syy += ry;
            }
        }
        let sxy = (total - sxx - syy) / 2.0;
        2.0 * sxy / (nx * ny) - sxx / (nx * nx) - syy / (ny * ny)
    };
    let mut label: Vec<bool> = (0..n).map(|k| k < x.len()).collect();
    let observed = stat(&label);
    let mut exceed = 0usize;
    for _ in 0..permutations {
        // Fisher–Yates shuffle of the labels
        for k in (1..n).rev() {
            let r = rng.gen_range(0..=k);
            label.swap(k, r);
        }
        if stat(&label) >= observed {
            exceed += 1;
        }
    }
    (observed, (exceed + 1) as f64 / (permutations + 1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::SlopeDomain;
    use rand::SeedableRng;

    fn gaussian_grid(sigma: f64) -> SlopeGrid {
        let mut g = SlopeGrid::from_fn(SlopeDomain::square(128, 1.5), |p, q| {
            (-(p * p + q * q) / (2.0 * sigma * sigma)).exp()
        });
        g.normalise();
        g
    }

    #[test]
    fn inverse_cdf_maps_quantiles() {
        let g = gaussian_grid(0.2);
        let cdf = InverseCdf::new(&g);
        let (p, q) = cdf.sample(0.5, 0.5);
        assert!(p.abs() < 0.03 && q.abs() < 0.03, "median ({p}, {q})");
        // the 84th percentile of a Gaussian is one σ
        let (_, q) = cdf.sample(0.5, 0.8413);
        assert!((q - 0.2).abs() < 0.01, "{q}");
    }

    #[test]
    fn clip_keeps_the_near_side() {
        let sq = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
        let c = clip(&sq, (0.5, 0.5), (1.0, 0.0));
        let area: f64 = (0..c.len())
            .map(|k| {
                let (a, b) = (c[k], c[(k + 1) % c.len()]);
                a.0 * b.1 - b.0 * a.1
            })
            .sum::<f64>()
            / 2.0;
        assert!((area - 0.5).abs() < 1e-12 && c.iter().all(|p| p.0 <= 0.5 + 1e-12));
    }

    #[test]
    fn cvt_follows_the_density_and_beats_random_sampling() {
        let g = gaussian_grid(0.2);
        let n = 400;
        let mut sites = halton_samples(&g, n);
        let before = ks_distance(&g, &sites);
        let rep = lloyd(&g, &mut sites, 30, 2, 2.0);
        let after = ks_distance(&g, &sites);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let random = ks_distance(&g, &random_samples(&g, n, &mut rng));
        let var = sites.iter().map(|s| s.0 * s.0).sum::<f64>() / n as f64;
        assert!(
            (var - 0.04).abs() < 0.04 * 0.05,
            "CVT variance {var} (ρ² weighting keeps it at σ²)"
        );
        assert!(
            after < random,
            "CVT {after} vs random {random} (Halton {before}, {rep:?})"
        );
    }

    #[test]
    fn energy_test_separates_different_distributions() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let a = random_samples(&gaussian_grid(0.2), 150, &mut rng);
        let b = random_samples(&gaussian_grid(0.2), 150, &mut rng);
        let c = random_samples(&gaussian_grid(0.3), 150, &mut rng);
        let (_, p_same) = energy_test(&a, &b, 99, &mut rng);
        let (_, p_diff) = energy_test(&a, &c, 99, &mut rng);
        assert!(p_same > 0.05, "same distribution rejected: p = {p_same}");
        assert!(p_diff < 0.05, "different distributions accepted: p = {p_diff}");
    }
}
