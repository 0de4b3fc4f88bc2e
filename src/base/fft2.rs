//! Planned 2D real FFT filtering: `out = IFFT2(H ⊙ FFT2(in))` on an `nx × ny` grid, the building block of
//! FFT convolution (`ndf::deconvolve`) and of the periodic Poisson solver (`facets::poisson`).
//!
//! Conventions (as RustFFT's): forward transforms are unnormalised, `filter` applies the `1/(nx·ny)` factor.
//! Rows are real-FFT'd (`realfft`), giving `hx = nx/2 + 1` columns of frequencies `kx = 0..hx`; the filter
//! sees one column at a time, `ky = 0..ny` contiguous, after its forward FFT and before its inverse, so the
//! column stays in cache. Rows of the input beyond `rows` are zero and are not transformed; only the output
//! rows asked for are inverted. Plans and buffers are made once in [`RealFft2::new`]; rows and columns run in
//! parallel with rayon.

use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::{num_complex::Complex64, Fft, FftPlanner};
use std::sync::Arc;

/// A planned 2D real FFT of a fixed size.
pub struct RealFft2 {
    nx: usize,
    ny: usize,
    r2c: Arc<dyn RealToComplex<f64>>,
    c2r: Arc<dyn ComplexToReal<f64>>,
    col_fwd: Arc<dyn Fft<f64>>,
    col_inv: Arc<dyn Fft<f64>>,
    /// Row spectra, `ny × hx`.
    spec: Vec<Complex64>,
    /// Column-major spectra, `hx × ny`.
    spec_t: Vec<Complex64>,
}

impl RealFft2 {
    /// Plan transforms for an `nx × ny` grid (`nx` along rows, the fast axis).
    pub fn new(nx: usize, ny: usize) -> Self {
        assert!(nx >= 2 && ny >= 1, "grid too small for an FFT");
        let mut rp = RealFftPlanner::<f64>::new();
        let mut cp = FftPlanner::<f64>::new();
        let hx = nx / 2 + 1;
        Self {
            nx,
            ny,
            r2c: rp.plan_fft_forward(nx),
            c2r: rp.plan_fft_inverse(nx),
            col_fwd: cp.plan_fft_forward(ny),
            col_inv: cp.plan_fft_inverse(ny),
            spec: vec![Complex64::default(); hx * ny],
            spec_t: vec![Complex64::default(); hx * ny],
        }
    }

    /// `(nx, ny)`.
    pub fn size(&self) -> (usize, usize) {
        (self.nx, self.ny)
    }

    /// Number of frequency columns `nx/2 + 1`.
    pub fn half_width(&self) -> usize {
        self.nx / 2 + 1
    }

    /// Real FFT of `rows` rows of `input` (each `cols` values, row stride `cols`), zero-padded to the grid,
    /// then transposed into `spec_t`.
    fn rows_forward(&mut self, input: &[f64], cols: usize, rows: usize) {
        assert!(cols <= self.nx && rows <= self.ny && input.len() >= rows * cols);
        let (nx, ny, hx) = (self.nx, self.ny, self.half_width());
        let r2c = &self.r2c;
        let (head, tail) = self.spec.split_at_mut(rows * hx);
        tail.iter_mut().for_each(|c| *c = Complex64::default());
        head.par_chunks_mut(hx).enumerate().for_each_init(
            || (vec![0.0; nx], r2c.make_scratch_vec()),
            |(buf, scratch), (j, out)| {
                buf[..cols].copy_from_slice(&input[j * cols..(j + 1) * cols]);
                buf[cols..].iter_mut().for_each(|v| *v = 0.0);
                r2c.process_with_scratch(buf, out, scratch).expect("row FFT lengths");
            },
        );
        transpose(&self.spec, &mut self.spec_t, ny, hx, hx);
    }

    /// The unnormalised forward spectrum, column-major `[kx][ky]` (`hx × ny`).
    pub fn forward_spectrum(&mut self, input: &[f64], cols: usize, rows: usize) -> Vec<Complex64> {
        self.rows_forward(input, cols, rows);
        let f = &self.col_fwd;
        self.spec_t.par_chunks_mut(self.ny).for_each_init(
            || vec![Complex64::default(); f.get_inplace_scratch_len()],
            |s, col| f.process_with_scratch(col, s),
        );
        self.spec_t.clone()
    }

    /// `out = IFFT2(H ⊙ FFT2(in)) / (nx·ny)`, where `h(kx, column)` multiplies column `kx` of the spectrum
    /// in place (`column[ky]`). The input is `(cols, rows)` (zero-padded), the output the top-left
    /// `(out_cols, out_rows)` of the result.
    pub fn filter<H>(
        &mut self,
        input: &[f64],
        (cols, rows): (usize, usize),
        out: &mut [f64],
        (out_cols, out_rows): (usize, usize),
        h: H,
    ) where
        H: Fn(usize, &mut [Complex64]) + Sync,
    {
        assert!(out_cols <= self.nx && out_rows <= self.ny && out.len() >= out_cols * out_rows);
        let (nx, ny, hx) = (self.nx, self.ny, self.half_width());
        self.rows_forward(input, cols, rows);
        let (fwd, inv) = (&self.col_fwd, &self.col_inv);
        let scratch_len = fwd.get_inplace_scratch_len().max(inv.get_inplace_scratch_len());
        let scale = 1.0 / (nx * ny) as f64;
        self.spec_t.par_chunks_mut(ny).enumerate().for_each_init(
            || vec![Complex64::default(); scratch_len],
            |s, (kx, col)| {
                fwd.process_with_scratch(col, s);
                h(kx, col);
                col.iter_mut().for_each(|c| *c *= scale);
                inv.process_with_scratch(col, s);
            },
        );
        transpose(&self.spec_t, &mut self.spec, hx, ny, out_rows);
        let c2r = &self.c2r;
        self.spec[..out_rows * hx]
            .par_chunks_mut(hx)
            .zip(out.par_chunks_mut(out_cols))
            .for_each_init(
                || (vec![0.0; nx], c2r.make_scratch_vec()),
                |(buf, scratch), (row, o)| {
                    // The DC and Nyquist terms of a real signal's spectrum are real; round-off may leave a
                    // tiny imaginary part that realfft refuses.
                    row[0].im = 0.0;
                    if nx % 2 == 0 {
                        row[hx - 1].im = 0.0;
                    }
                    c2r.process_with_scratch(row, buf, scratch).expect("row iFFT lengths");
                    o.copy_from_slice(&buf[..out_cols]);
                },
            );
    }
}

/// Blocked transpose: `src` holds `w` runs of length `h` (`src[i·h + j]`); write its first `rows` entries of
/// each run as rows of `dst` (`dst[j·w + i]`, `j < rows`).
fn transpose(src: &[Complex64], dst: &mut [Complex64], w: usize, h: usize, rows: usize) {
    const B: usize = 32;
    for jb in (0..rows).step_by(B) {
        for ib in (0..w).step_by(B) {
            for j in jb..(jb + B).min(rows) {
                for i in ib..(ib + B).min(w) {
                    dst[j * w + i] = src[i * h + j];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// Naive 2D DFT of a real grid, the slow reference.
    fn dft(input: &[f64], nx: usize, ny: usize) -> Vec<Complex64> {
        let mut out = vec![Complex64::default(); nx * ny];
        for ky in 0..ny {
            for kx in 0..nx {
                let mut acc = Complex64::default();
                for y in 0..ny {
                    for x in 0..nx {
                        let ph = -TAU * ((kx * x) as f64 / nx as f64 + (ky * y) as f64 / ny as f64);
                        acc += input[y * nx + x] * Complex64::new(ph.cos(), ph.sin());
                    }
                }
                out[ky * nx + kx] = acc;
            }
        }
        out
    }

    #[test]
    fn forward_matches_a_naive_dft() {
        let (nx, ny) = (10, 6);
        let input: Vec<f64> = (0..nx * ny).map(|k| ((k * 7919) % 31) as f64 / 31.0 - 0.4).collect();
        let mut f = RealFft2::new(nx, ny);
        let spec = f.forward_spectrum(&input, nx, ny);
        let reference = dft(&input, nx, ny);
        for kx in 0..nx / 2 + 1 {
            for ky in 0..ny {
                let d = spec[kx * ny + ky] - reference[ky * nx + kx];
                assert!(d.norm() < 1e-10, "({kx},{ky}): {d}");
            }
        }
    }

    #[test]
    fn identity_filter_round_trips() {
        let (nx, ny) = (12, 9);
        let input: Vec<f64> = (0..nx * ny).map(|k| (k as f64 * 0.37).sin()).collect();
        let mut f = RealFft2::new(nx, ny);
        let mut out = vec![0.0; nx * ny];
        f.filter(&input, (nx, ny), &mut out, (nx, ny), |_, _| {});
        let err = input.iter().zip(&out).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-12, "{err}");
    }
}
