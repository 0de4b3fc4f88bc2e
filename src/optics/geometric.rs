//! Geometric optics of a heightfield: its slope distribution and the microfacet BRDF it implies.
//!
//! The NDF of a surface is the density of its normals per unit of projected area (Eq. 6). On a regular grid
//! every sample stands for the same projected area, so the slope density `P22` is simply the histogram of
//! the samples' slopes; central differences give the slopes and each is splatted bilinearly onto the slope
//! grid. Dong et al. (2015) filter the heights first with a Gaussian below the scale the light resolves:
//! `prefilter_um` is that Gaussian's σ (0: none).
//!
//! The BRDF is Eq. 5 with `D = P22 / cos⁴θ` looked up in the grid, Fresnel from the material and the
//! separable Smith masking computed from the same grid (as in `ndf::halfangle`).

use crate::brdf::{ConductorIor, Rgb};
use crate::geometry::{half_vector, normal_to_slope, Vec3};
use crate::heightfield::Heightfield;
use crate::slope::{splat, SlopeDomain, SlopeGrid, SmithTable};
use rayon::prelude::*;

/// Slopes of a heightfield by central differences, after an optional Gaussian pre-filter (σ in µm).
/// Periodic fields wrap; others skip a border of `margin` samples (and at least one).
pub fn slopes(hf: &Heightfield, prefilter_um: f64, margin: usize) -> Vec<(f64, f64)> {
    let filtered;
    let hf = if prefilter_um > 0.0 {
        filtered = gaussian(hf, prefilter_um * 1e-3);
        &filtered
    } else {
        hf
    };
    let (nx, ny, h) = (hf.nx, hf.ny, hf.pitch_mm);
    let (m, wrap) = if hf.periodic { (0, true) } else { (margin.max(1), false) };
    if nx <= 2 * m || ny <= 2 * m {
        return vec![];
    }
    (m..ny - m)
        .into_par_iter()
        .flat_map_iter(|j| {
            (m..nx - m).map(move |i| {
                let (il, ir) = if wrap {
                    ((i + nx - 1) % nx, (i + 1) % nx)
                } else {
                    (i - 1, i + 1)
                };
                let (jd, ju) = if wrap {
                    ((j + ny - 1) % ny, (j + 1) % ny)
                } else {
                    (j - 1, j + 1)
                };
                (
                    (hf.at(ir, j) - hf.at(il, j)) / (2.0 * h),
                    (hf.at(i, ju) - hf.at(i, jd)) / (2.0 * h),
                )
            })
        })
        .collect()
}

/// Slopes `(∂z/∂x, ∂z/∂y)` of the cells `[i0, j0, nx, ny]` of `hf`, each the mean slope over one stepover
/// `s` across raster passes at `angle_deg` from x: across them `(z(c + n s/2) − z(c − n s/2)) / s`, along
/// them the central difference averaged over the same window (bilinear samples; a periodic grid wraps, a
/// bounded one is clamped at its edge). A groove of period `s` across the passes is removed exactly and
/// everything wider kept (`verify::milled` explains why the milled surface is measured so).
pub fn stepover_slopes(hf: &Heightfield, cells: [usize; 4], angle_deg: f64, stepover_mm: f64) -> Vec<(f64, f64)> {
    let [i0, j0, wn, hn] = cells;
    let p = hf.pitch_mm;
    let (sin, cos) = angle_deg.to_radians().sin_cos();
    let t = (cos, sin); // along the passes, in cells per cell
    let n = (-sin, cos); // across
    let half = 0.5 * stepover_mm / p; // cells
                                      // the across-window, sampled at K midpoints
    let k = ((2.0 * half).ceil() as usize).max(2) + 1;
    let offs: Vec<f64> = (0..k)
        .map(|m| -half + 2.0 * half * (m as f64 + 0.5) / k as f64)
        .collect();
    let (nx, ny, periodic) = (hf.nx, hf.ny, hf.periodic);
    let z = &hf.z_mm;
    let at = move |x: f64, y: f64| -> f64 {
        // bilinear in cell-centre coordinates
        if periodic {
            let (fx, fy) = (x.floor(), y.floor());
            let (i, j) = (
                (fx as i64).rem_euclid(nx as i64) as usize,
                (fy as i64).rem_euclid(ny as i64) as usize,
            );
            let (i1, j1) = ((i + 1) % nx, (j + 1) % ny);
            let (tx, ty) = (x - fx, y - fy);
            let a = z[j * nx + i] * (1.0 - tx) + z[j * nx + i1] * tx;
            let b = z[j1 * nx + i] * (1.0 - tx) + z[j1 * nx + i1] * tx;
            return a * (1.0 - ty) + b * ty;
        }
        let x = x.clamp(0.0, (nx - 1) as f64);
        let y = y.clamp(0.0, (ny - 1) as f64);
        let (i, j) = ((x.floor() as usize).min(nx - 2), (y.floor() as usize).min(ny - 2));
        let (fx, fy) = (x - i as f64, y - j as f64);
        let a = z[j * nx + i] * (1.0 - fx) + z[j * nx + i + 1] * fx;
        let b = z[(j + 1) * nx + i] * (1.0 - fx) + z[(j + 1) * nx + i + 1] * fx;
        a * (1.0 - fy) + b * fy
    };
    (j0..j0 + hn)
        .into_par_iter()
        .flat_map_iter(|j| {
            let offs = &offs;
            (i0..i0 + wn).map(move |i| {
                let (x, y) = (i as f64, j as f64);
                let across =
                    (at(x + n.0 * half, y + n.1 * half) - at(x - n.0 * half, y - n.1 * half)) / (2.0 * half * p);
                let along = offs
                    .iter()
                    .map(|o| {
                        let (cx, cy) = (x + n.0 * o, y + n.1 * o);
                        at(cx + t.0, cy + t.1) - at(cx - t.0, cy - t.1)
                    })
                    .sum::<f64>()
                    / (offs.len() as f64 * 2.0 * p);
                (t.0 * along + n.0 * across, t.1 * along + n.1 * across)
            })
        })
        .collect()
}

/// Separable Gaussian blur of the heights with σ in mm (wrapping when periodic, clamping otherwise).
pub fn gaussian(hf: &Heightfield, sigma_mm: f64) -> Heightfield {
    let s = sigma_mm / hf.pitch_mm;
    let rad = (3.0 * s).ceil() as isize;
    let w: Vec<f64> = (-rad..=rad)
        .map(|k| (-(k as f64).powi(2) / (2.0 * s * s)).exp())
        .collect();
    let sum: f64 = w.iter().sum();
    let w: Vec<f64> = w.iter().map(|v| v / sum).collect();
    let (nx, ny) = (hf.nx as isize, hf.ny as isize);
    let idx = |i: isize, n: isize| if hf.periodic { i.rem_euclid(n) } else { i.clamp(0, n - 1) } as usize;
    let mut tmp = hf.clone();
    tmp.z_mm.par_chunks_mut(hf.nx).enumerate().for_each(|(j, row)| {
        for (i, v) in row.iter_mut().enumerate() {
            *v = (-rad..=rad)
                .map(|k| w[(k + rad) as usize] * hf.at(idx(i as isize + k, nx), j))
                .sum();
        }
    });
    let mut out = tmp.clone();
    out.z_mm.par_chunks_mut(hf.nx).enumerate().for_each(|(j, row)| {
        for (i, v) in row.iter_mut().enumerate() {
            *v = (-rad..=rad)
                .map(|k| w[(k + rad) as usize] * tmp.at(i, idx(j as isize + k, ny)))
                .sum();
        }
    });
    out
}

/// The slope density of a set of equal-area slopes on `domain` (bilinear splatting), normalised over the
/// grid; also returns the fraction of slopes that fell outside it.
pub fn ndf_of_slopes(slopes: &[(f64, f64)], domain: SlopeDomain) -> (SlopeGrid, f64) {
    ndf_of_weighted_slopes(slopes, None, domain)
}

/// [`ndf_of_slopes`] with a weight per slope (its share of the area; `None`: all alike); the fraction
/// outside is of the weight.
pub fn ndf_of_weighted_slopes(slopes: &[(f64, f64)], weights: Option<&[f64]>, domain: SlopeDomain) -> (SlopeGrid, f64) {
    let empty = || SlopeGrid {
        domain,
        density: vec![0.0; domain.len()],
    };
    const CHUNK: usize = 65_536;
    let (mut g, outside, total) = slopes
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(k, chunk)| {
            let mut g = empty();
            let (mut out, mut total) = (0.0, 0.0);
            for (n, (p, q)) in chunk.iter().enumerate() {
                let w = weights.map_or(1.0, |w| w[k * CHUNK + n]);
                total += w;
                if *p < domain.p_min || *p > domain.p_max || *q < domain.q_min || *q > domain.q_max {
                    out += w;
                    continue;
                }
                splat(&mut g, *p, *q, w);
            }
            (g, out, total)
        })
        .reduce(
            || (empty(), 0.0, 0.0),
            |mut a, b| {
                a.0.density.iter_mut().zip(&b.0.density).for_each(|(x, y)| *x += y);
                (a.0, a.1 + b.1, a.2 + b.2)
            },
        );
    g.normalise();
    let frac = if total > 0.0 { outside / total } else { 0.0 };
    (g, frac)
}

/// The NDF of a heightfield on `domain` (see the module notes); `(density, fraction outside the grid)`.
pub fn ndf(hf: &Heightfield, domain: SlopeDomain, prefilter_um: f64, margin: usize) -> (SlopeGrid, f64) {
    ndf_of_slopes(&slopes(hf, prefilter_um, margin), domain)
}

/// A microfacet BRDF (Eq. 5) whose NDF is a slope grid.
pub struct MicrofacetBrdf {
    ndf: SlopeGrid,
    smith: SmithTable,
    /// Fresnel material; `None` is a perfect mirror.
    pub material: Option<ConductorIor>,
}

impl MicrofacetBrdf {
    /// Build from a (normalised) slope density.
    pub fn new(ndf: SlopeGrid, material: Option<ConductorIor>) -> Self {
        let smith = SmithTable::new(&ndf, 64, 32);
        Self { ndf, smith, material }
    }

    /// `D(wm) = P22(p, q) / cos⁴θm`.
    pub fn d(&self, wm: &Vec3) -> f64 {
        match normal_to_slope(wm) {
            Some((p, q)) => self.ndf.sample(p, q) / wm.z.powi(4),
            None => 0.0,
        }
    }

    /// `f(wi, wo)` in RGB, without the cosine.
    pub fn eval(&self, wi: &Vec3, wo: &Vec3) -> Rgb {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return [0.0; 3];
        }
        let Some(wh) = half_vector(wi, wo) else {
            return [0.0; 3];
        };
        let g = self.smith.g1(wi) * self.smith.g1(wo);
        let v = self.d(&wh) * g / (4.0 * wi.z * wo.z);
        let f = match &self.material {
            Some(m) => m.reflectance(wi.dot(&wh)),
            None => [1.0; 3],
        };
        f.map(|c| c * v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{Family, Microfacet};
    use rand::{Rng, SeedableRng};

    #[test]
    fn a_tilted_plane_has_one_slope() {
        let mut hf = Heightfield::flat(64, 64, 0.01, false, 0.0);
        for j in 0..64 {
            for i in 0..64 {
                hf.z_mm[j * 64 + i] = 0.2 * i as f64 * 0.01 - 0.1 * j as f64 * 0.01;
            }
        }
        let s = slopes(&hf, 0.0, 1);
        assert!(s
            .iter()
            .all(|(p, q)| (p - 0.2).abs() < 1e-12 && (q + 0.1).abs() < 1e-12));
        let (g, out) = ndf(&hf, SlopeDomain::square(64, 1.0), 0.0, 1);
        assert_eq!(out, 0.0);
        let st = g.stats();
        assert!((st.mean[0] - 0.2).abs() < 1e-9 && (st.mean[1] + 0.1).abs() < 1e-9);
    }

    #[test]
    fn gaussian_slopes_give_a_beckmann_ndf() {
        // Independent Gaussian slopes of variance α²/2 are the Beckmann distribution (P22 is their density).
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let sigma: f64 = 0.2;
        let normal = |rng: &mut rand_pcg::Pcg64Mcg| -> f64 {
            let (u, v): (f64, f64) = (rng.gen(), rng.gen());
            (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let s: Vec<(f64, f64)> = (0..400_000)
            .map(|_| (sigma * normal(&mut rng), sigma * normal(&mut rng)))
            .collect();
        let domain = SlopeDomain::square(64, 1.2);
        let (g, _) = ndf_of_slopes(&s, domain);
        let m = Microfacet::new(Family::Beckmann, sigma * 2f64.sqrt(), sigma * 2f64.sqrt()).unwrap();
        let mut exact = SlopeGrid::from_fn(domain, |p, q| m.p22(p, q));
        exact.normalise();
        let l1 = g.relative_l1(&exact);
        assert!(l1 < 0.05, "relative L1 {l1}");
        // and its BRDF is the Beckmann model's (up to the masking's quadrature)
        let brdf = MicrofacetBrdf::new(g, None);
        let analytic = crate::brdf::Brdf::parse("beckmann:alpha=0.28284271247461906").unwrap();
        let (wi, wo) = (
            crate::geometry::spherical(0.3, 0.0),
            crate::geometry::spherical(0.35, 3.0),
        );
        let (a, b) = (brdf.eval(&wi, &wo)[0], analytic.eval(&wi, &wo)[0]);
        assert!((a - b).abs() < 0.05 * b, "{a} vs {b}");
    }

    #[test]
    fn prefilter_smooths_slopes() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2);
        let mut hf = Heightfield::flat(128, 128, 0.001, true, 0.0);
        hf.z_mm.iter_mut().for_each(|v| *v = rng.gen_range(-0.001..0.001));
        let var = |s: &[(f64, f64)]| s.iter().map(|(p, _)| p * p).sum::<f64>() / s.len() as f64;
        let raw = var(&slopes(&hf, 0.0, 1));
        let smooth = var(&slopes(&hf, 3.0, 1));
        assert!(smooth < 0.1 * raw, "{smooth} vs {raw}");
    }
}
