//! Lucy–Richardson deconvolution in slope space (Section 7.1), with FFT convolution.
//!
//! The surface a mill cuts shows its facet NDF **convolved** with the base material's own lobe: slopes of a
//! sum of independent heightfields add, so their slope densities convolve. Lucy–Richardson removes that blur
//! while keeping the estimate non-negative and its mass that of the observation:
//!
//! `D ← D · (K̂ ⊛ (O / (D ⊛ K)))`, with `K` the base lobe (unit sum) and `K̂` its mirror.
//!
//! The slope plane is not periodic, so convolutions are linear: the grid is zero-padded to at least
//! `n + m` per axis (`m` the kernel half-width), the kernel is stored centred at index 0 with wrap-around, so
//! the output needs no shift and the mirrored kernel's spectrum is the complex conjugate. The FFTs are
//! [`crate::base::fft2::RealFft2`], planned once.

use crate::base::fft2::RealFft2;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// Cells per partial sum of an iteration's change: fixed, so the sums do not depend on the schedule.
const SUM_CHUNK: usize = 4096;

/// Smallest even length ≥ `n` whose only prime factors are 2, 3 and 5 (fast for rustfft).
pub fn fast_len(n: usize) -> usize {
    let mut m = n.max(2);
    loop {
        let mut k = m;
        for p in [2, 3, 5] {
            while k % p == 0 {
                k /= p;
            }
        }
        if k == 1 && m % 2 == 0 {
            return m;
        }
        m += 1;
    }
}

/// Linear 2D convolution of an `nx × ny` grid with a fixed odd-sized kernel, "same" size output.
pub struct Convolver {
    nx: usize,
    ny: usize,
    fft: RealFft2,
    /// Kernel spectrum, column-major `[kx][ky]`.
    kernel: Vec<Complex64>,
}

impl Convolver {
    /// Plan a convolution of `nx × ny` grids with `kernel` (`kw × kh`, both odd, centre at the middle).
    pub fn new(nx: usize, ny: usize, kernel: &[f64], kw: usize, kh: usize) -> Self {
        assert!(kw % 2 == 1 && kh % 2 == 1, "kernel sides must be odd");
        assert_eq!(kernel.len(), kw * kh);
        let (mx, my) = (kw / 2, kh / 2);
        let (px, py) = (fast_len(nx + mx), fast_len(ny + my));
        let mut fft = RealFft2::new(px, py);
        // Kernel centred at index 0 with wrap-around.
        let mut kgrid = vec![0.0; px * py];
        for j in 0..kh {
            for i in 0..kw {
                let x = (i as isize - mx as isize).rem_euclid(px as isize) as usize;
                let y = (j as isize - my as isize).rem_euclid(py as isize) as usize;
                kgrid[y * px + x] = kernel[j * kw + i];
            }
        }
        let kernel = fft.forward_spectrum(&kgrid, px, py);
        Self { nx, ny, fft, kernel }
    }

    /// The padded FFT size `(px, py)`.
    pub fn padded_size(&self) -> (usize, usize) {
        self.fft.size()
    }

    /// `out = input ⊛ K` (or `⊛ K̂`, the mirrored kernel, when `mirror`), same size as the input.
    pub fn convolve(&mut self, input: &[f64], out: &mut [f64], mirror: bool) {
        let (nx, ny) = (self.nx, self.ny);
        assert_eq!(input.len(), nx * ny);
        assert_eq!(out.len(), nx * ny);
        let py = self.fft.size().1;
        let kernel = &self.kernel;
        self.fft.filter(input, (nx, ny), out, (nx, ny), |kx, col| {
            let k = &kernel[kx * py..(kx + 1) * py];
            if mirror {
                col.iter_mut().zip(k).for_each(|(c, k)| *c *= k.conj());
            } else {
                col.iter_mut().zip(k).for_each(|(c, k)| *c *= k);
            }
        });
    }
}

/// Why the iteration stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StoppedBy {
    /// The relative L1 change of an iteration fell below the tolerance.
    Tolerance,
    /// The iteration count was reached.
    Count,
    /// No deconvolution was asked for (no base lobe).
    None,
}

impl StoppedBy {
    /// Why the iterations stopped, for people.
    pub fn describe(self) -> &'static str {
        match self {
            StoppedBy::Tolerance => "stopped when an iteration changed the estimate by less than the tolerance",
            StoppedBy::Count => "stopped at the iteration limit",
            StoppedBy::None => "none needed: no base lobe",
        }
    }
}

/// What a Lucy–Richardson run did.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LrReport {
    /// Always `"lucy-richardson"` (or `"none"`).
    pub method: &'static str,
    /// Iterations run.
    pub iterations: usize,
    /// The iteration limit.
    pub max_iterations: usize,
    /// The tolerance on the relative L1 change per iteration (0 disables it).
    pub tolerance: f64,
    /// Why it stopped.
    pub stopped_by: StoppedBy,
    /// Relative L1 change of the last iteration.
    pub last_change: f64,
}

impl LrReport {
    /// The report of a run that was not asked for.
    pub fn none() -> Self {
        Self {
            method: "none",
            iterations: 0,
            max_iterations: 0,
            tolerance: 0.0,
            stopped_by: StoppedBy::None,
            last_change: 0.0,
        }
    }
}

/// A planned Lucy–Richardson deconvolution for a fixed grid size and kernel.
pub struct LucyRichardson {
    conv: Convolver,
    est: Vec<f64>,
    ratio: Vec<f64>,
    corr: Vec<f64>,
}

impl LucyRichardson {
    /// Plan for `nx × ny` grids and a `kw × kh` kernel (odd sides, centred); the kernel is normalised to
    /// unit sum here so the blur preserves mass.
    pub fn new(nx: usize, ny: usize, kernel: &[f64], kw: usize, kh: usize) -> Self {
        let s: f64 = kernel.iter().sum();
        let k: Vec<f64> = kernel.iter().map(|v| v / s).collect();
        Self {
            conv: Convolver::new(nx, ny, &k, kw, kh),
            est: vec![0.0; nx * ny],
            ratio: vec![0.0; nx * ny],
            corr: vec![0.0; nx * ny],
        }
    }

    /// The padded FFT size.
    pub fn padded_size(&self) -> (usize, usize) {
        self.conv.padded_size()
    }

    /// Deconvolve `observed` into `estimate` (which holds the starting guess, e.g. `observed` itself).
    /// Stops after `max_iterations` or when an iteration changes the estimate by less than `tolerance`
    /// (relative L1).
    pub fn run(&mut self, observed: &[f64], estimate: &mut [f64], max_iterations: usize, tolerance: f64) -> LrReport {
        let omax = observed.iter().copied().fold(0.0, f64::max);
        let eps = 1e-12 * omax.max(f64::MIN_POSITIVE);
        let mut report = LrReport {
            method: "lucy-richardson",
            iterations: 0,
            max_iterations,
            tolerance,
            stopped_by: StoppedBy::Count,
            last_change: f64::NAN,
        };
        for it in 0..max_iterations {
            self.conv.convolve(estimate, &mut self.est, false);
            self.ratio
                .par_iter_mut()
                .zip(observed.par_iter().zip(self.est.par_iter()))
                .for_each(|(r, (o, e))| *r = if *e > eps { o / e } else { 0.0 });
            self.conv.convolve(&self.ratio, &mut self.corr, true);
            // summed per fixed chunk, then the chunks in order: the same sums whatever the threads do
            // (a rayon `reduce` pairs partial sums as the work was stolen, and moved the last digits)
            let (change, total) = estimate
                .par_chunks_mut(SUM_CHUNK)
                .zip(self.corr.par_chunks(SUM_CHUNK))
                .map(|(ds, cs)| {
                    let mut s = (0.0, 0.0);
                    for (d, c) in ds.iter_mut().zip(cs) {
                        let new = (*d * c.max(0.0)).max(0.0);
                        s.0 += (new - *d).abs();
                        s.1 += new;
                        *d = new;
                    }
                    s
                })
                .collect::<Vec<_>>()
                .into_iter()
                .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            report.iterations = it + 1;
            report.last_change = if total > 0.0 { change / total } else { 0.0 };
            if tolerance > 0.0 && report.last_change < tolerance {
                report.stopped_by = StoppedBy::Tolerance;
                break;
            }
        }
        report
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct linear convolution, "same" size, kernel centred — the slow reference.
    fn naive(input: &[f64], nx: usize, ny: usize, k: &[f64], kw: usize, kh: usize, mirror: bool) -> Vec<f64> {
        let (mx, my) = (kw as isize / 2, kh as isize / 2);
        let mut out = vec![0.0; nx * ny];
        for y in 0..ny as isize {
            for x in 0..nx as isize {
                let mut acc = 0.0;
                for dy in -my..=my {
                    for dx in -mx..=mx {
                        let (sx, sy) = (x - dx, y - dy);
                        if sx < 0 || sy < 0 || sx >= nx as isize || sy >= ny as isize {
                            continue;
                        }
                        let (kx, ky) = if mirror { (-dx, -dy) } else { (dx, dy) };
                        acc +=
                            k[((ky + my) * kw as isize + kx + mx) as usize] * input[(sy * nx as isize + sx) as usize];
                    }
                }
                out[(y * nx as isize + x) as usize] = acc;
            }
        }
        out
    }

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn fft_convolution_matches_direct_sum() {
        let mut seed = 42;
        for (nx, ny, kw, kh) in [(17, 12, 5, 3), (32, 32, 9, 9), (31, 20, 7, 11)] {
            let input: Vec<f64> = (0..nx * ny).map(|_| lcg(&mut seed)).collect();
            let k: Vec<f64> = (0..kw * kh).map(|_| lcg(&mut seed)).collect();
            let mut c = Convolver::new(nx, ny, &k, kw, kh);
            for mirror in [false, true] {
                let mut out = vec![0.0; nx * ny];
                c.convolve(&input, &mut out, mirror);
                let reference = naive(&input, nx, ny, &k, kw, kh, mirror);
                let err = out
                    .iter()
                    .zip(&reference)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(err < 1e-12, "{nx}×{ny} k {kw}×{kh} mirror {mirror}: {err}");
            }
        }
    }

    #[test]
    fn fast_len_is_smooth_and_even() {
        assert_eq!(fast_len(310), 320);
        assert_eq!(fast_len(7), 8);
        assert_eq!(fast_len(257), 270);
    }

    #[test]
    fn lr_recovers_a_blurred_point_pair_and_keeps_mass_and_sign() {
        let (n, kw) = (48, 9);
        let k: Vec<f64> = (0..kw * kw)
            .map(|t| {
                let (x, y) = ((t % kw) as f64 - 4.0, (t / kw) as f64 - 4.0);
                (-(x * x + y * y) / 4.0).exp()
            })
            .collect();
        let mut truth = vec![0.0; n * n];
        truth[20 * n + 20] = 1.0;
        truth[26 * n + 24] = 0.5;
        let mut conv = Convolver::new(
            n,
            n,
            &k.iter().map(|v| v / k.iter().sum::<f64>()).collect::<Vec<_>>(),
            kw,
            kw,
        );
        let mut observed = vec![0.0; n * n];
        conv.convolve(&truth, &mut observed, false);
        let mut lr = LucyRichardson::new(n, n, &k, kw, kw);
        let mut est = vec![1.0 / (n * n) as f64 * 1.5; n * n];
        let rep = lr.run(&observed, &mut est, 500, 0.0);
        assert_eq!(rep.stopped_by, StoppedBy::Count);
        assert!(est.iter().all(|v| *v >= 0.0));
        let mass: f64 = est.iter().sum();
        assert!((mass - 1.5).abs() < 1e-6, "mass {mass}");
        // The two spikes re-emerge far sharper than the blur.
        assert!(est[20 * n + 20] > 0.5, "peak {}", est[20 * n + 20]);
        assert!(est[26 * n + 24] > 0.2, "peak {}", est[26 * n + 24]);
    }
}
