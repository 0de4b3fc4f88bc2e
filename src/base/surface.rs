//! A surface's slopes and its normal distribution (Eq. 6), the geometric measurement shared by the design
//! loop's as-milled model, the verification of the simulated cut and `analyze`.
//!
//! The NDF of a surface is the density of its normals per unit of projected area (Eq. 6). On a regular grid
//! every sample stands for the same projected area, so the slope density `P22` is simply the histogram of
//! the samples' slopes; central differences give the slopes and each is splatted bilinearly onto the slope
//! grid. Dong et al. (2015) filter the heights first with a Gaussian below the scale the light resolves:
//! `prefilter_um` is that Gaussian's σ (0: none).

use crate::base::heightfield::Heightfield;
use crate::base::slope::{splat, SlopeDomain, SlopeGrid};
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
///
/// Every sample sits at a fixed offset from its cell, and bilinear interpolation is linear in the heights,
/// so each of the two differences is one fixed stencil of weighted neighbours (`StepoverStencil`): a cell
/// costs a few dozen multiply-adds along contiguous rows instead of a dozen interpolations. Cells of a
/// bounded grid whose stencil reaches past its edge are sampled one by one, clamped.
pub fn stepover_slopes(hf: &Heightfield, cells: [usize; 4], angle_deg: f64, stepover_mm: f64) -> Vec<(f64, f64)> {
    let [i0, j0, wn, hn] = cells;
    let st = StepoverStencil::new(hf.pitch_mm, angle_deg, stepover_mm);
    let (nx, ny) = (hf.nx, hf.ny);
    let [dx_lo, dy_lo, dx_hi, dy_hi] = st.reach();
    // on a bounded grid, the columns and rows whose stencil stays inside
    let inside = |i: usize, lo: isize, hi: isize, n: usize| i as isize + lo >= 0 && i as isize + hi < n as isize;
    let mut out = vec![(0.0, 0.0); wn * hn];
    out.par_chunks_mut(wn.max(1)).enumerate().for_each(|(r, row)| {
        let j = j0 + r;
        let (mut across, mut along) = (vec![0.0; wn], vec![0.0; wn]);
        let periodic = hf.periodic;
        let rows_inside = periodic || inside(j, dy_lo, dy_hi, ny);
        // the run of columns taken by the stencil: all on a periodic grid, the inner ones on a bounded one
        let (a, b) = if periodic {
            (0, wn)
        } else if rows_inside {
            let a = (0..wn).find(|&k| inside(i0 + k, dx_lo, dx_hi, nx)).unwrap_or(wn);
            let b = (a..wn).find(|&k| !inside(i0 + k, dx_lo, dx_hi, nx)).unwrap_or(wn);
            (a, b)
        } else {
            (0, 0)
        };
        if a < b {
            for (taps, acc) in [(&st.across, &mut across), (&st.along, &mut along)] {
                for &(dx, dy, w) in taps {
                    let src = (j as isize + dy).rem_euclid(ny as isize) as usize;
                    let src = &hf.z_mm[src * nx..(src + 1) * nx];
                    let start = ((i0 + a) as isize + dx).rem_euclid(nx as isize) as usize;
                    add_wrapped(&mut acc[a..b], src, start, w);
                }
            }
        }
        for (k, o) in row.iter_mut().enumerate() {
            let (ac, al) = if (a..b).contains(&k) {
                (across[k], along[k])
            } else {
                st.direct(hf, i0 + k, j)
            };
            *o = (st.t.0 * al + st.n.0 * ac, st.t.1 * al + st.n.1 * ac);
        }
    });
    out
}

/// `acc[k] += w · src[(start + k) mod len]`, in contiguous runs.
fn add_wrapped(acc: &mut [f64], src: &[f64], start: usize, w: f64) {
    let n = src.len();
    let mut k = 0;
    let mut at = start;
    while k < acc.len() {
        let run = (n - at).min(acc.len() - k);
        acc[k..k + run]
            .iter_mut()
            .zip(&src[at..at + run])
            .for_each(|(a, s)| *a += w * s);
        k += run;
        at = 0;
    }
}

/// The two differences of [`stepover_slopes`] as weighted neighbours `(dx, dy, weight)` of a cell, each
/// already divided by its length: `across` gives the slope across the passes, `along` the mean slope along
/// them.
struct StepoverStencil {
    /// Along the passes, in cells per cell.
    t: (f64, f64),
    /// Across them.
    n: (f64, f64),
    /// Half a stepover, cells.
    half: f64,
    /// The across-window's sample offsets, cells.
    offs: Vec<f64>,
    pitch_mm: f64,
    across: Vec<(isize, isize, f64)>,
    along: Vec<(isize, isize, f64)>,
}

impl StepoverStencil {
    fn new(pitch_mm: f64, angle_deg: f64, stepover_mm: f64) -> Self {
        let p = pitch_mm;
        let (sin, cos) = angle_deg.to_radians().sin_cos();
        let (t, n) = ((cos, sin), (-sin, cos));
        let half = 0.5 * stepover_mm / p;
        // the across-window, sampled at K midpoints
        let k = ((2.0 * half).ceil() as usize).max(2) + 1;
        let offs: Vec<f64> = (0..k)
            .map(|m| -half + 2.0 * half * (m as f64 + 0.5) / k as f64)
            .collect();
        let mut across = std::collections::BTreeMap::new();
        let c = 1.0 / (2.0 * half * p);
        bilinear_taps(&mut across, n.0 * half, n.1 * half, c);
        bilinear_taps(&mut across, -n.0 * half, -n.1 * half, -c);
        let mut along = std::collections::BTreeMap::new();
        let c = 1.0 / (offs.len() as f64 * 2.0 * p);
        for o in &offs {
            let (cx, cy) = (n.0 * o, n.1 * o);
            bilinear_taps(&mut along, cx + t.0, cy + t.1, c);
            bilinear_taps(&mut along, cx - t.0, cy - t.1, -c);
        }
        let list = |m: std::collections::BTreeMap<(isize, isize), f64>| {
            m.into_iter()
                .filter(|(_, w)| *w != 0.0)
                .map(|((dy, dx), w)| (dx, dy, w))
                .collect()
        };
        Self {
            t,
            n,
            half,
            offs,
            pitch_mm,
            across: list(across),
            along: list(along),
        }
    }

    /// `[dx_min, dy_min, dx_max, dy_max]` over both stencils.
    fn reach(&self) -> [isize; 4] {
        self.across
            .iter()
            .chain(&self.along)
            .fold([0, 0, 0, 0], |[a, b, c, d], &(dx, dy, _)| {
                [a.min(dx), b.min(dy), c.max(dx), d.max(dy)]
            })
    }

    /// `(across, along)` at cell `(i, j)` from bilinear samples one by one (a periodic grid wraps, a bounded
    /// one is clamped at its edge): the definition the stencils expand.
    fn direct(&self, hf: &Heightfield, i: usize, j: usize) -> (f64, f64) {
        let (t, n, half, p) = (self.t, self.n, self.half, self.pitch_mm);
        let (x, y) = (i as f64, j as f64);
        let at = |x: f64, y: f64| bilinear(hf, x, y);
        let across = (at(x + n.0 * half, y + n.1 * half) - at(x - n.0 * half, y - n.1 * half)) / (2.0 * half * p);
        let along = self
            .offs
            .iter()
            .map(|o| {
                let (cx, cy) = (x + n.0 * o, y + n.1 * o);
                at(cx + t.0, cy + t.1) - at(cx - t.0, cy - t.1)
            })
            .sum::<f64>()
            / (self.offs.len() as f64 * 2.0 * p);
        (across, along)
    }
}

/// Add `c ×` the bilinear weights of the point `(ox, oy)` cells from a cell centre to `taps`, keyed `(dy, dx)`
/// so that a row's taps come together.
fn bilinear_taps(taps: &mut std::collections::BTreeMap<(isize, isize), f64>, ox: f64, oy: f64, c: f64) {
    let (fx, fy) = (ox.floor(), oy.floor());
    let (tx, ty) = (ox - fx, oy - fy);
    let (a, b) = (fx as isize, fy as isize);
    for (dx, dy, w) in [
        (0, 0, (1.0 - tx) * (1.0 - ty)),
        (1, 0, tx * (1.0 - ty)),
        (0, 1, (1.0 - tx) * ty),
        (1, 1, tx * ty),
    ] {
        *taps.entry((b + dy, a + dx)).or_insert(0.0) += c * w;
    }
}

/// The bilinear height at `(x, y)` in cell-centre coordinates: wrapped on a periodic grid, clamped to the
/// grid on a bounded one.
fn bilinear(hf: &Heightfield, x: f64, y: f64) -> f64 {
    let (nx, ny, z) = (hf.nx, hf.ny, &hf.z_mm);
    if hf.periodic {
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
        // merged in chunk order, not as rayon's `reduce` pairs them (which follows the work stealing and
        // moved the last digits from run to run)
        .collect::<Vec<_>>()
        .into_iter()
        .fold((empty(), 0.0, 0.0), |mut a, b| {
            a.0.density.iter_mut().zip(&b.0.density).for_each(|(x, y)| *x += y);
            (a.0, a.1 + b.1, a.2 + b.2)
        });
    g.normalise();
    let frac = if total > 0.0 { outside / total } else { 0.0 };
    (g, frac)
}

/// The NDF of a heightfield on `domain` (see the module notes); `(density, fraction outside the grid)`.
pub fn ndf(hf: &Heightfield, domain: SlopeDomain, prefilter_um: f64, margin: usize) -> (SlopeGrid, f64) {
    ndf_of_slopes(&slopes(hf, prefilter_um, margin), domain)
}

#[cfg(test)]
mod tests {
    use super::*;
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

    /// The stencils give what sampling the heights one by one gives, on a periodic grid and inside and at the
    /// edges of a bounded one, at raster angles that put the samples between cells.
    #[test]
    fn stepover_stencils_equal_bilinear_sampling() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        for periodic in [true, false] {
            let mut hf = Heightfield::flat(37, 29, 0.01, periodic, 0.0);
            hf.z_mm.iter_mut().for_each(|v| *v = rng.gen_range(-0.05..0.05));
            for (angle, stepover) in [(0.0, 0.045), (90.0, 0.03), (17.0, 0.061), (-135.0, 0.02)] {
                let st = StepoverStencil::new(hf.pitch_mm, angle, stepover);
                let got = stepover_slopes(&hf, [0, 0, 37, 29], angle, stepover);
                let mut worst = 0.0f64;
                for j in 0..29 {
                    for i in 0..37 {
                        let (ac, al) = st.direct(&hf, i, j);
                        let want = (st.t.0 * al + st.n.0 * ac, st.t.1 * al + st.n.1 * ac);
                        let g = got[j * 37 + i];
                        worst = worst.max((g.0 - want.0).abs()).max((g.1 - want.1).abs());
                    }
                }
                assert!(worst < 1e-12, "periodic {periodic}, {angle}°: {worst}");
                // a window inside the grid is the same cells of the whole
                let win = stepover_slopes(&hf, [5, 4, 20, 13], angle, stepover);
                for j in 0..13 {
                    for i in 0..20 {
                        assert_eq!(win[j * 20 + i], got[(j + 4) * 37 + i + 5]);
                    }
                }
            }
        }
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
