//! The coarse search: every quarter turn and small angle, each with the translation that maximises the
//! masked normalised cross-correlation (Padfield 2012, "Masked object registration in the Fourier domain")
//! of the two surfaces' *slopes*: the differences along x and along y are two channels of one signal. Slopes
//! are what tells one design from another (each facet its own), and a plane (the scan's tilt) only adds a
//! constant to them, which the correlation removes; heights are dominated by the relief's long waves, which
//! a scan of part of the part shares with many wrong poses.
//!
//! For the simulation's channel `a` (mask `m₁`) and the rotated scan's `b` (mask `m₂`), every translation
//! `d` at once, each sum over both channels:
//!
//! ```text
//!   N = m₁ ⋆ m₂,  Sa = a m₁ ⋆ m₂,  Sb = m₁ ⋆ b m₂,  Saa = a² m₁ ⋆ m₂,  Sbb = m₁ ⋆ b² m₂,  Sab = a m₁ ⋆ b m₂
//!   NCC(d) = Σ (Sab − Sa·Sb/N) / √(Σ (Saa − Sa²/N) · Σ (Sbb − Sb²/N))
//! ```
//!
//! where `(f ⋆ g)(d) = Σᵢ f(i) g(i + d)` is a correlation by FFT, zero-padded so that no translation wraps.
//! The correlation is only taken where the overlap `N` holds at least [`MIN_OVERLAP`] of the smaller of the two
//! areas: a few cells correlate by chance.

use super::{Grid, Pose};
use crate::base::fft2::RealFft2;
use rustfft::num_complex::Complex64;

/// Share of the smaller area (simulation or scan, in measured cells) a translation must overlap to count.
pub const MIN_OVERLAP: f64 = 0.25;

/// The best pose found at one level and its correlation.
#[derive(Clone, Copy, Debug)]
pub(super) struct Found {
    pub pose: Pose,
    pub ncc: f64,
}

/// The simulation's side of the correlations, transformed once for every candidate angle.
pub(super) struct Searcher<'a> {
    sim: &'a Grid,
    scan: &'a Grid,
    fft: RealFft2,
    /// `m₁`, `a m₁`, `a² m₁` spectra of each slope channel, conjugated.
    spectra: [[Vec<Complex64>; 3]; 2],
    size: (usize, usize),
    min_cells: f64,
    /// Mean square slope (about its mean) per cell and channel, of the simulation and of the scan: an
    /// overlap whose slope variance is a thousandth of it is flat, and its correlation a ratio of rounding.
    power: [f64; 2],
    /// The simulation's and the scan's centres, mm (of the full grids).
    centres: ([f64; 2], [f64; 2]),
}

impl<'a> Searcher<'a> {
    /// Both grids at one pitch (the coarse level).
    pub fn new(sim: &'a Grid, scan: &'a Grid, centres: ([f64; 2], [f64; 2])) -> Self {
        // the rotated scan's box is at most its diagonal on a side
        let diag = ((scan.nx * scan.nx + scan.ny * scan.ny) as f64).sqrt().ceil() as usize + 2;
        let size = (sim.nx + diag, sim.ny + diag);
        let mut fft = RealFft2::new(size.0, size.1);
        let mut spec = |f: &[f64]| {
            let mut s = fft.forward_spectrum(f, sim.nx, sim.ny);
            s.iter_mut().for_each(|c| *c = c.conj());
            s
        };
        let sim_slopes = slopes(sim);
        let spectra = sim_slopes.clone().map(|ch| moments(&ch).map(|f| spec(&f)));
        let scan_slopes = slopes(scan);
        // (cells, power) over both channels
        let stats = |chs: &[Grid; 2]| {
            let cells = 0.5 * chs.iter().map(|c| c.valid_count() as f64).sum::<f64>();
            let sq: f64 = chs.iter().map(|c| moments(c)[2].iter().sum::<f64>()).sum();
            (cells, sq / (2.0 * cells).max(1.0))
        };
        let ((sim_cells, sim_power), (scan_cells, scan_power)) = (stats(&sim_slopes), stats(&scan_slopes));
        // overlaps counted in cells with a slope, as `n` counts them
        let min_cells = (MIN_OVERLAP * sim_cells.min(scan_cells)).max(16.0);
        Self {
            sim,
            scan,
            fft,
            spectra,
            size,
            min_cells,
            power: [sim_power, scan_power],
            centres,
        }
    }

    /// The best translation of the scan turned by `quarter_turns`·90° + `angle_deg`: the pose and its NCC.
    pub fn best(&mut self, quarter_turns: u8, angle_deg: f64) -> Option<Found> {
        let pose = Pose {
            quarter_turns,
            angle_deg,
            shift_mm: [0.0; 2],
            plane: [0.0; 3],
            mirrored: false,
        };
        let (g, origin) = self.rotated(&pose);
        let (lx, ly) = self.size;
        let zeros = || vec![0.0; lx * ly];
        let (mut num, mut den_a, mut den_b, mut n) = (zeros(), zeros(), zeros(), zeros());
        for (c, ch) in slopes(&g).iter().enumerate() {
            let [m, b, b2] = moments(ch);
            let mut corr = |input: &[f64], s: usize| {
                let spec = &self.spectra[c][s];
                let mut out = zeros();
                self.fft.filter(input, (g.nx, g.ny), &mut out, (lx, ly), |kx, col| {
                    for (ky, v) in col.iter_mut().enumerate() {
                        *v *= spec[kx * ly + ky];
                    }
                });
                out
            };
            let (nc, sa, saa) = (corr(&m, 0), corr(&m, 1), corr(&m, 2));
            let (sb, sbb, sab) = (corr(&b, 0), corr(&b2, 0), corr(&b, 1));
            for k in 0..lx * ly {
                let nn = nc[k].max(1e-9);
                num[k] += sab[k] - sa[k] * sb[k] / nn;
                den_a[k] += saa[k] - sa[k] * sa[k] / nn;
                den_b[k] += sbb[k] - sb[k] * sb[k] / nn;
                n[k] += 0.5 * nc[k];
            }
        }
        let mut best: Option<(f64, usize)> = None;
        for k in 0..lx * ly {
            if n[k] < self.min_cells {
                continue;
            }
            // (`min_cells` is at least 16: a handful of cells correlates by chance)
            let (va, vb) = (den_a[k], den_b[k]);
            let flat = 2e-3 * n[k];
            if !(va > flat * self.power[0] && vb > flat * self.power[1]) {
                continue;
            }
            let r = num[k] / (va * vb).sqrt();
            // beyond 1 (or NaN) is rounding over a near-flat overlap, not a match
            if r.is_nan() || r > 1.0 + 1e-6 {
                continue;
            }
            if best.is_none_or(|(v, _)| r > v) {
                best = Some((r, k));
            }
        }
        let (ncc, k) = best?;
        // index k holds the translation d (mod the padded size) pairing sim cell i with rotated cell i + d;
        // d runs over [−(n_sim − 1), n_rot − 1], which the padded size holds without overlap
        let wrap = |v: usize, n_rot: usize, l: usize| if v < n_rot { v as f64 } else { v as f64 - l as f64 };
        let d = [wrap(k % lx, g.nx, lx), wrap(k / lx, g.ny, ly)];
        let p = self.sim.pitch_mm;
        let at = [origin[0] + d[0] * p, origin[1] + d[1] * p];
        // the sim point x meets the rotated cell at x + at, the scan point R(φ)(x + at − c_sim) + c_scan
        let (c, s) = (pose.phi().cos(), pose.phi().sin());
        Some(Found {
            pose: Pose {
                shift_mm: [c * at[0] - s * at[1], s * at[0] + c * at[1]],
                ..pose
            },
            ncc,
        })
    }

    /// The scan turned into the simulation's frame, on a grid of the simulation's pitch covering it; returns
    /// the grid and the sim-frame position (mm) of its corner.
    fn rotated(&self, pose: &Pose) -> (Grid, [f64; 2]) {
        let (sim, scan) = (self.sim, self.scan);
        let p = sim.pitch_mm;
        let (c, s) = (pose.phi().cos(), pose.phi().sin());
        let (sc, cc) = self.centres;
        // scan corners to the sim frame: x = R(−φ)(X − c_scan) + c_sim
        let (w, h) = (scan.nx as f64 * scan.pitch_mm, scan.ny as f64 * scan.pitch_mm);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (x, y) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
            let (dx, dy) = (x - cc[0], y - cc[1]);
            let q = [c * dx + s * dy + sc[0], -s * dx + c * dy + sc[1]];
            for a in 0..2 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        let diag = ((scan.nx * scan.nx + scan.ny * scan.ny) as f64).sqrt().ceil() as usize + 2;
        let nx = (((hi[0] - lo[0]) / p).ceil() as usize).clamp(1, diag);
        let ny = (((hi[1] - lo[1]) / p).ceil() as usize).clamp(1, diag);
        let mut g = Grid {
            nx,
            ny,
            pitch_mm: p,
            z: vec![0.0; nx * ny],
            valid: vec![false; nx * ny],
        };
        for j in 0..ny {
            for i in 0..nx {
                let x = [lo[0] + (i as f64 + 0.5) * p, lo[1] + (j as f64 + 0.5) * p];
                let (dx, dy) = (x[0] - sc[0], x[1] - sc[1]);
                let q = [c * dx - s * dy + cc[0], s * dx + c * dy + cc[1]];
                if let Some(v) = scan.sample(q[0], q[1]) {
                    g.z[j * nx + i] = v;
                    g.valid[j * nx + i] = true;
                }
            }
        }
        (g, lo)
    }
}

/// The mask `m`, the heights less their mean `z m` and their squares `z² m`, zero where missing.
fn moments(g: &Grid) -> [Vec<f64>; 3] {
    let mean = g.mean();
    let (mut m, mut a, mut a2) = (vec![0.0; g.z.len()], vec![0.0; g.z.len()], vec![0.0; g.z.len()]);
    for (k, (z, ok)) in g.z.iter().zip(&g.valid).enumerate() {
        if *ok {
            let v = z - mean;
            (m[k], a[k], a2[k]) = (1.0, v, v * v);
        }
    }
    [m, a, a2]
}

/// The central differences along x and along y (heights per cell), measured where both neighbours are.
fn slopes(g: &Grid) -> [Grid; 2] {
    let mut out = [g.clone(), g.clone()];
    for (c, step) in [1, g.nx].into_iter().enumerate() {
        let o = &mut out[c];
        for j in 0..g.ny {
            for i in 0..g.nx {
                let k = j * g.nx + i;
                let inside = if c == 0 {
                    i >= 1 && i + 1 < g.nx
                } else {
                    j >= 1 && j + 1 < g.ny
                };
                let ok = inside && g.valid[k - step] && g.valid[k + step];
                o.valid[k] = ok;
                o.z[k] = if ok { 0.5 * (g.z[k + step] - g.z[k - step]) } else { 0.0 };
            }
        }
    }
    out
}
