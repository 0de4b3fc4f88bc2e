//! Curved facets: each facet a shallow dome whose normals sweep its own cell of slope space (docs/DESIGN.md
//! §3.4), so that `N` facets draw a continuous NDF instead of `N` spikes.
//!
//! The CVT gives each sampled slope `s_k` a Voronoi cell `V_k` of equal mass under the target density `ρ`.
//! A flat facet puts all of that mass on `s_k`. A facet whose slope varies linearly across it,
//! `s(d) = s_k − H_k d` for the offset `d` from its centre (height `z_k + s_k·d − ½ dᵀ H_k d`), spreads its
//! area uniformly over a parallelogram of slopes centred on `s_k` with covariance `H_k Σ_d H_kᵀ`, where
//! `Σ_d = a²/12 · I` is the covariance of a uniform offset over a square facet of side `a`. Matching it to
//! the cell's second moment about its site, `M_k = ∫_{V_k} ρ (s − s_k)(s − s_k)ᵀ / ∫_{V_k} ρ`, gives
//!
//! `H_k = √(12 M_k) / a`   (the symmetric positive semi-definite square root),
//!
//! a dome (concave from below, convex to the ball): a ball of any radius reaches every point of its top, so
//! curving the facets costs no reach of their own; the valleys between facets are what the ball fills, as
//! with flat facets. The mean slope of a dome is `s_k`, so the arrangement and the periodic Poisson
//! integration of the facet slopes stand as they are; the edge heights of two neighbouring domes differ by
//! their sags `a²/8 · (H_xx)` across an x edge (`H_yy` across a y edge), which the integration takes into
//! its edge gradients (`facets::integrate`).

use crate::base::slope::SlopeGrid;
use spade::{DelaunayTriangulation, Point2, Triangulation};

/// Density samples per grid cell and axis over which the cells' moments are summed.
const MOMENT_SUPERSAMPLE: usize = 2;

/// Each site's second moment `[Mpp, Mpq, Mqq]` about itself over its Voronoi cell under `density`
/// (zero for a site whose cell holds no mass). Cells are found by nearest site (spade's Delaunay
/// triangulation); coincident sites share their cell's moment.
pub fn cell_moments(density: &SlopeGrid, sites: &[(f64, f64)]) -> Vec<[f64; 3]> {
    let n = sites.len();
    let mut tri: DelaunayTriangulation<Point2<f64>> = DelaunayTriangulation::new();
    // vertex index → the sites at it (coincident sites merge into one vertex)
    let mut at_vertex: Vec<Vec<usize>> = vec![];
    for (k, s) in sites.iter().enumerate() {
        let Ok(h) = tri.insert(Point2::new(s.0, s.1)) else {
            continue;
        };
        if h.index() >= at_vertex.len() {
            at_vertex.resize(h.index() + 1, vec![]);
        }
        at_vertex[h.index()].push(k);
    }
    let d = density.domain;
    let s = MOMENT_SUPERSAMPLE;
    let (fx, fy) = (d.nx * s, d.ny * s);
    let (sdp, sdq) = (d.dp() / s as f64, d.dq() / s as f64);
    // per vertex: mass and the moment sums about the vertex
    let mut acc = vec![[0.0f64; 4]; at_vertex.len()];
    for j in 0..fy {
        let q = d.q_min + (j as f64 + 0.5) * sdq;
        for i in 0..fx {
            let p = d.p_min + (i as f64 + 0.5) * sdp;
            let w = density.sample(p, q);
            if w <= 0.0 {
                continue;
            }
            let Some(v) = tri.nearest_neighbor(Point2::new(p, q)) else {
                continue;
            };
            let c = v.position();
            let (dp, dq) = (p - c.x, q - c.y);
            let a = &mut acc[v.fix().index()];
            a[0] += w;
            a[1] += w * dp * dp;
            a[2] += w * dp * dq;
            a[3] += w * dq * dq;
        }
    }
    let mut out = vec![[0.0; 3]; n];
    for (v, ks) in at_vertex.iter().enumerate() {
        let a = acc[v];
        if a[0] > 0.0 {
            for &k in ks {
                out[k] = [a[1] / a[0], a[2] / a[0], a[3] / a[0]];
            }
        }
    }
    out
}

/// The dome's curvature `H = √(12 M) / a` for a second moment `M = [Mpp, Mpq, Mqq]` and a facet of side
/// `a` mm: `[Hxx, Hxy, Hyy]`, 1/mm. The square root of a symmetric 2 × 2 matrix `M` with determinant `δ`
/// and trace `τ` is `(M + √δ I) / √(τ + 2√δ)`.
pub fn curvature(moment: [f64; 3], facet_mm: f64) -> [f64; 3] {
    let m = moment.map(|v| 12.0 * v);
    let det = (m[0] * m[2] - m[1] * m[1]).max(0.0);
    let sd = det.sqrt();
    let t = m[0] + m[2] + 2.0 * sd;
    if !(t > 0.0 && facet_mm > 0.0) {
        return [0.0; 3];
    }
    let r = t.sqrt() * facet_mm;
    [(m[0] + sd) / r, m[1] / r, (m[2] + sd) / r]
}

/// The height of a dome of curvature `h` at the offset `(dx, dy)` from its centre, relative to its centre:
/// `−½ dᵀ H d`.
pub fn sag(h: &[f64; 3], dx: f64, dy: f64) -> f64 {
    -0.5 * (h[0] * dx * dx + 2.0 * h[1] * dx * dy + h[2] * dy * dy)
}

/// The difference of the two domes' sags at the midpoint of each edge, mm, `(x-edges, y-edges)`: across the
/// x edge from facet `k` to its right neighbour `r`, `(H_xx,r − H_xx,k) · a²/8` (the right facet's left edge
/// minus the left facet's right edge drop), and likewise with `H_yy` across y edges. Two facets meet
/// without a step when their centre heights differ by `a/2 (p_k + p_r)` plus this.
pub fn edge_sag_differences(curv: &[[f64; 3]], w: usize, h: usize, facet_mm: f64) -> (Vec<f64>, Vec<f64>) {
    let mut cx = vec![0.0; w * h];
    let mut cy = vec![0.0; w * h];
    if curv.is_empty() {
        return (cx, cy);
    }
    let e = facet_mm * facet_mm / 8.0;
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            let r = y * w + (x + 1) % w;
            let u = ((y + 1) % h) * w + x;
            cx[k] = (curv[r][0] - curv[k][0]) * e;
            cy[k] = (curv[u][2] - curv[k][2]) * e;
        }
    }
    (cx, cy)
}

/// The curvature of a dome whose slopes are scaled per axis by `scale` (`s ↦ C s`, `C = diag(scale)`):
/// its slopes' second moment `M = (a²/12) H²` becomes `C M C`, whose dome is [`curvature`] of it.
pub fn rescaled(h: [f64; 3], scale: [f64; 2], facet_mm: f64) -> [f64; 3] {
    let s = facet_mm * facet_mm / 12.0;
    let m = [
        s * (h[0] * h[0] + h[1] * h[1]),
        s * (h[0] * h[1] + h[1] * h[2]),
        s * (h[1] * h[1] + h[2] * h[2]),
    ];
    let [cx, cy] = scale;
    curvature([cx * cx * m[0], cx * cy * m[1], cy * cy * m[2]], facet_mm)
}

/// Slopes over an arrangement's facets, each facet's area alike: flat facets give their slope once each;
/// curved facets `per_axis²` slopes each, at the centres of a `per_axis × per_axis` grid over the facet
/// (`s_k − H_k d`), so that the set is the facets' own distribution of slopes.
pub fn facet_slopes(a: &super::Arrangement, facet_mm: f64, per_axis: usize) -> Vec<(f64, f64)> {
    let flat = a.p.iter().copied().zip(a.q.iter().copied());
    if a.curvature_per_mm.is_empty() {
        return flat.collect();
    }
    let m = per_axis.max(1);
    let offsets: Vec<f64> = (0..m).map(|i| ((i as f64 + 0.5) / m as f64 - 0.5) * facet_mm).collect();
    let mut out = Vec::with_capacity(a.p.len() * m * m);
    for ((p, q), h) in flat.zip(&a.curvature_per_mm) {
        for &dy in &offsets {
            for &dx in &offsets {
                out.push((p - h[0] * dx - h[1] * dy, q - h[1] * dx - h[2] * dy));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::SlopeDomain;

    #[test]
    fn the_curvature_reproduces_the_moment_through_a_uniform_facet() {
        // H Σ_d H with Σ_d = a²/12 I must give M back, for an anisotropic, correlated M
        let (m, a) = ([0.004, 0.0012, 0.0025], 0.8);
        let h = curvature(m, a);
        let s = a * a / 12.0;
        let back = [
            s * (h[0] * h[0] + h[1] * h[1]),
            s * (h[0] * h[1] + h[1] * h[2]),
            s * (h[1] * h[1] + h[2] * h[2]),
        ];
        for k in 0..3 {
            assert!((back[k] - m[k]).abs() < 1e-12, "{back:?} vs {m:?}");
        }
        assert_eq!(curvature([0.0; 3], 1.0), [0.0; 3]);
        // scaling the slopes by C scales the moment to C M C
        let r = rescaled(h, [1.3, 0.7], a);
        let back = [
            s * (r[0] * r[0] + r[1] * r[1]),
            s * (r[0] * r[1] + r[1] * r[2]),
            s * (r[1] * r[1] + r[2] * r[2]),
        ];
        let want = [1.69 * m[0], 0.91 * m[1], 0.49 * m[2]];
        for k in 0..3 {
            assert!((back[k] - want[k]).abs() < 1e-12, "{back:?} vs {want:?}");
        }
    }

    #[test]
    fn one_site_on_a_uniform_square_has_the_square_s_moment() {
        // a uniform density on [-0.5, 0.5]² and a single site at its centre: M = 1/12 I (to the grid's
        // midpoint rule and the bilinear sampling's fall-off in the outermost half cells, 1e-3)
        let d = SlopeDomain::square(64, 0.5);
        let mut g = SlopeGrid::from_fn(d, |_, _| 1.0);
        g.normalise();
        let m = cell_moments(&g, &[(0.0, 0.0)]);
        let want = 1.0 / 12.0;
        assert!((m[0][0] - want).abs() < 1e-3 && (m[0][2] - want).abs() < 1e-3, "{m:?}");
        assert!(m[0][1].abs() < 1e-12, "{m:?}");
        // two sites split it in halves along p: each half's moment about its own centre is (1/2)²/12 in p
        let m = cell_moments(&g, &[(-0.25, 0.0), (0.25, 0.0)]);
        for c in m {
            assert!((c[0] - want / 4.0).abs() < 1e-3 && (c[2] - want).abs() < 1e-3, "{c:?}");
        }
    }

    /// The law of total variance: the curved facets' slopes have the sites' covariance plus the domes' mean
    /// second moment (each dome spreads its facet's area over `H² a²/12` about its site), which flat facets
    /// (the sites alone) lack; and the rasterised heightfield's finite differences inside the facets (a
    /// second method) have the covariance `facet_slopes` counts. (On this GGX α 0.15 target with 100
    /// facets the sites carry 0.70 of the target's variance within the cone and the domes add 0.085: the
    /// CVT's cells are not of equal mass in the tails, where the rest is missing.)
    #[test]
    fn curved_facets_carry_the_target_s_variance_and_the_heightfield_agrees() {
        use crate::stages::brdf::Brdf;
        use crate::stages::facets::{self, FacetsConfig};
        use crate::stages::ndf::{self, NdfConfig};
        let n = ndf::run(
            &NdfConfig {
                res: 128,
                ..Default::default()
            },
            &Brdf::parse("ggx:alpha=0.15").unwrap(),
            None,
        )
        .unwrap();
        let cfg = FacetsConfig {
            facets_x: 10,
            facets_y: 10,
            facet_mm: 1.0,
            pitch_um: 10.0,
            ..Default::default()
        };
        let cone = cfg.max_slope_deg.to_radians().tan();
        let target = n.target.within_cone(cone).stats().cov;
        let sites = facets::sites(&cfg, &n.target).unwrap();
        let flat = facets::run_from(&cfg, &sites).unwrap();
        let curved = facets::run_from(&cfg, &sites.curved()).unwrap();
        let cov = |v: &[(f64, f64)]| {
            let k = v.len() as f64;
            let (mp, mq) = v.iter().fold((0.0, 0.0), |a, s| (a.0 + s.0 / k, a.1 + s.1 / k));
            let pp = v.iter().map(|s| (s.0 - mp).powi(2)).sum::<f64>() / k;
            let qq = v.iter().map(|s| (s.1 - mq).powi(2)).sum::<f64>() / k;
            [pp, qq]
        };
        let c_flat = cov(&facet_slopes(&flat.arrangement, 1.0, 16));
        let c_curved = cov(&facet_slopes(&curved.arrangement, 1.0, 16));
        let k = curved.arrangement.curvature_per_mm.len() as f64;
        let spread = curved.arrangement.curvature_per_mm.iter().fold([0.0, 0.0], |acc, h| {
            // M = (a²/12) H², a = 1 mm; the 16 × 16 midpoint grid holds (1 − 1/16²) of a uniform's variance
            let g = (1.0 - 1.0 / 256.0) / 12.0;
            [
                acc[0] + g * (h[0] * h[0] + h[1] * h[1]) / k,
                acc[1] + g * (h[1] * h[1] + h[2] * h[2]) / k,
            ]
        });
        for a in 0..2 {
            let want = c_flat[a] + spread[a];
            assert!(spread[a] > 0.05 * target[a][a], "axis {a}: the domes add {}", spread[a]);
            assert!(
                (c_curved[a] / want - 1.0).abs() < 1e-9,
                "axis {a}: {} vs {want}",
                c_curved[a]
            );
        }
        // finite differences of the heightfield inside each facet (one sample from every edge)
        let hf = &curved.heightfield;
        let m = cfg.samples_per_facet();
        let mut fd = vec![];
        for j in 0..hf.ny {
            for i in 0..hf.nx {
                let (u, v) = (i % m, j % m);
                if u == 0 || v == 0 || u + 1 >= m || v + 1 >= m {
                    continue;
                }
                let p = (hf.at(i + 1, j) - hf.at(i - 1, j)) / (2.0 * hf.pitch_mm);
                let q = (hf.at(i, j + 1) - hf.at(i, j - 1)) / (2.0 * hf.pitch_mm);
                fd.push((p, q));
            }
        }
        let c_fd = cov(&fd);
        for a in 0..2 {
            assert!(
                (c_fd[a] / c_curved[a] - 1.0).abs() < 0.03,
                "axis {a}: {c_fd:?} vs {c_curved:?}"
            );
        }
    }
}
