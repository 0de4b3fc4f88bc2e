//! MERL BRDF database `.binary` files (Matusik, Pfister, Brand & McMillan 2003).
//!
//! Layout: three little-endian `i32` dimensions `(90, 90, 180)` for `(θh, θd, φd)`, then
//! `3 × 1,458,000` little-endian `f64` as whole R, G, B blocks. The index of a sample is
//! `φd + 180·θd + 180·90·θh` with the bins
//! - `θh`: `floor(sqrt(θh / (π/2)) · 90)` (non-linear: dense near the specular peak),
//! - `θd`: `floor(θd / (π/2) · 90)`,
//! - `φd`: folded into `[0, π)` by reciprocity, `floor(φd / π · 180)`.
//!
//! Stored values are scaled per channel: R × 1/1500, G × 1.15/1500, B × 1.66/1500 give reflectance.
//! Negative values mark samples below the horizon.
//!
//! **Sample positions.** [`Merl::from_fn`] writes each bin's value at the bin's centre in its own
//! coordinate (`sqrt`-mapped for θh), and [`Merl::eval`] interpolates linearly between bin centres in the
//! same coordinates, skipping below-horizon samples. The original MERL reader looks up the nearest bin;
//! interpolation removes its staircase (θh bins are up to 1.6° wide at 60°).

use super::{BrdfError, Rgb};
use crate::base::geometry::{from_half_diff, to_half_diff, Vec3};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Read;
use std::path::Path;

/// Bins along θh.
pub const N_THETA_H: usize = 90;
/// Bins along θd.
pub const N_THETA_D: usize = 90;
/// Bins along φd (over `[0, π)`).
pub const N_PHI_D: usize = 180;
/// Samples per channel.
pub const N_SAMPLES: usize = N_THETA_H * N_THETA_D * N_PHI_D;
/// File size in bytes: header plus three channels of `f64`.
pub const FILE_BYTES: usize = 12 + 3 * N_SAMPLES * 8;
/// Per-channel scale from stored values to reflectance.
pub const SCALE: Rgb = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];

/// A MERL measurement, held as reflectance (scale applied), channel-major like the file.
#[derive(Clone, Debug)]
pub struct Merl {
    /// `3 × N_SAMPLES` values: R block, G block, B block; negative = below the horizon.
    pub data: Vec<f64>,
}

#[inline]
fn index(th: usize, td: usize, pd: usize) -> usize {
    pd + N_PHI_D * (td + N_THETA_D * th)
}

/// Continuous bin coordinates `(u_θh, u_θd, u_φd)` of a configuration; bin centres sit at integers.
#[inline]
fn coords(theta_h: f64, theta_d: f64, phi_d: f64) -> (f64, f64, f64) {
    let uh = (theta_h.max(0.0) / FRAC_PI_2).sqrt() * N_THETA_H as f64 - 0.5;
    let ud = theta_d / FRAC_PI_2 * N_THETA_D as f64 - 0.5;
    let up = phi_d.rem_euclid(PI) / PI * N_PHI_D as f64 - 0.5;
    (uh, ud, up)
}

/// The configuration at the centre of bin `(th, td, pd)`.
#[inline]
fn bin_centre(th: usize, td: usize, pd: usize) -> (f64, f64, f64) {
    let u = (th as f64 + 0.5) / N_THETA_H as f64;
    (
        u * u * FRAC_PI_2,
        (td as f64 + 0.5) / N_THETA_D as f64 * FRAC_PI_2,
        (pd as f64 + 0.5) / N_PHI_D as f64 * PI,
    )
}

impl Merl {
    /// Read a `.binary` file. A wrong header, a wrong size or a non-finite value is an error naming the file.
    pub fn read(path: &Path) -> Result<Self, BrdfError> {
        let io = |source| {
            BrdfError::Io(crate::base::io::ReadError {
                path: path.to_path_buf(),
                source,
            })
        };
        let fmt = |reason: String| BrdfError::Format {
            path: path.to_path_buf(),
            reason,
        };
        let mut f = std::fs::File::open(path).map_err(io)?;
        let len = f.metadata().map_err(io)?.len() as usize;
        let mut header = [0u8; 12];
        if len < 12 {
            return Err(fmt(format!(
                "not a MERL .binary file: {len} bytes, shorter than the 12-byte header"
            )));
        }
        f.read_exact(&mut header).map_err(io)?;
        let dims: Vec<i32> = header
            .chunks_exact(4)
            .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        if dims != [N_THETA_H as i32, N_THETA_D as i32, N_PHI_D as i32] {
            return Err(fmt(format!(
                "MERL header gives dimensions {dims:?}, expected [90, 90, 180]"
            )));
        }
        if len != FILE_BYTES {
            return Err(fmt(format!(
                "MERL file has {len} bytes, expected {FILE_BYTES} (12-byte header + 3 × 1,458,000 f64){}",
                if len < FILE_BYTES {
                    ": truncated"
                } else {
                    ": trailing data"
                }
            )));
        }
        let mut bytes = vec![0u8; FILE_BYTES - 12];
        f.read_exact(&mut bytes).map_err(io)?;
        let mut data: Vec<f64> = bytes
            .par_chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        if let Some(k) = data.iter().position(|v| !v.is_finite()) {
            let (c, s) = (k / N_SAMPLES, k % N_SAMPLES);
            return Err(fmt(format!(
                "value {} of channel {} (byte offset {}) is not finite",
                s,
                ["R", "G", "B"][c],
                12 + 8 * k
            )));
        }
        data.par_chunks_mut(N_SAMPLES)
            .zip(SCALE.par_iter())
            .for_each(|(ch, s)| ch.iter_mut().for_each(|v| *v *= s));
        Ok(Self { data })
    }

    /// Tabulate `f(wi, wo)` (RGB reflectance) at every bin centre; below-horizon samples are marked −1.
    pub fn from_fn<F>(f: F) -> Self
    where
        F: Fn(&Vec3, &Vec3) -> Rgb + Sync,
    {
        let mut data = vec![0.0; 3 * N_SAMPLES];
        let values: Vec<Rgb> = (0..N_SAMPLES)
            .into_par_iter()
            .map(|k| {
                let (pd, td, th) = (k % N_PHI_D, (k / N_PHI_D) % N_THETA_D, k / (N_PHI_D * N_THETA_D));
                let (theta_h, theta_d, phi_d) = bin_centre(th, td, pd);
                let (wi, wo) = from_half_diff(theta_h, 0.0, theta_d, phi_d);
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    [-1.0; 3]
                } else {
                    f(&wi, &wo)
                }
            })
            .collect();
        for (k, v) in values.iter().enumerate() {
            for c in 0..3 {
                data[c * N_SAMPLES + k] = v[c];
            }
        }
        Self { data }
    }

    /// Write a `.binary` file (atomically), undoing the per-channel scale; below-horizon samples stay −1.
    pub fn write(&self, path: &Path) -> Result<(), crate::base::io::WriteError> {
        crate::base::io::write_atomic_with(path, |w| {
            for d in [N_THETA_H as i32, N_THETA_D as i32, N_PHI_D as i32] {
                w.write_all(&d.to_le_bytes())?;
            }
            let mut buf = Vec::with_capacity(N_SAMPLES * 8);
            for (c, ch) in self.data.chunks_exact(N_SAMPLES).enumerate() {
                buf.clear();
                for v in ch {
                    let raw = if *v < 0.0 { -1.0 } else { v / SCALE[c] };
                    buf.extend_from_slice(&raw.to_le_bytes());
                }
                w.write_all(&buf)?;
            }
            Ok(())
        })
    }

    /// `f(wi, wo)` in RGB by trilinear interpolation between bin centres (see the module notes).
    pub fn eval(&self, wi: &Vec3, wo: &Vec3) -> Rgb {
        let Some((theta_h, _phi_h, theta_d, phi_d)) = to_half_diff(wi, wo) else {
            return [0.0; 3];
        };
        let (uh, ud, up) = coords(theta_h, theta_d, phi_d);
        let clamp_axis = |u: f64, n: usize| -> (usize, usize, f64) {
            let u = u.clamp(0.0, (n - 1) as f64);
            let i0 = u.floor() as usize;
            let i1 = (i0 + 1).min(n - 1);
            (i0, i1, u - i0 as f64)
        };
        let (h0, h1, fh) = clamp_axis(uh, N_THETA_H);
        let (d0, d1, fd) = clamp_axis(ud, N_THETA_D);
        // φd is periodic with period π (180 bins).
        let p0f = up.floor();
        let fp = up - p0f;
        let p0 = (p0f as isize).rem_euclid(N_PHI_D as isize) as usize;
        let p1 = (p0 + 1) % N_PHI_D;
        let mut acc = [0.0; 3];
        let mut wsum = 0.0;
        for (h, wh) in [(h0, 1.0 - fh), (h1, fh)] {
            for (d, wd) in [(d0, 1.0 - fd), (d1, fd)] {
                for (p, wp) in [(p0, 1.0 - fp), (p1, fp)] {
                    let w = wh * wd * wp;
                    if w == 0.0 {
                        continue;
                    }
                    let k = index(h, d, p);
                    if self.data[k] < 0.0 {
                        continue;
                    }
                    for (c, a) in acc.iter_mut().enumerate() {
                        *a += w * self.data[c * N_SAMPLES + k];
                    }
                    wsum += w;
                }
            }
        }
        if wsum <= 0.0 {
            return [0.0; 3];
        }
        acc.map(|a| a / wsum)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::geometry::spherical;
    use crate::stages::brdf::Brdf;

    #[test]
    fn index_matches_the_documented_layout() {
        assert_eq!(index(0, 0, 1), 1);
        assert_eq!(index(0, 1, 0), 180);
        assert_eq!(index(1, 0, 0), 180 * 90);
        assert_eq!(index(89, 89, 179), N_SAMPLES - 1);
    }

    #[test]
    fn bin_centres_fall_in_their_bins() {
        for (th, td, pd) in [(0, 0, 0), (17, 45, 90), (89, 89, 179)] {
            let (a, b, c) = bin_centre(th, td, pd);
            let (uh, ud, up) = coords(a, b, c);
            assert!((uh - th as f64).abs() < 1e-9 && (ud - td as f64).abs() < 1e-9 && (up - pd as f64).abs() < 1e-9);
            // and the documented floor formulas give the same bin
            assert_eq!(((a / FRAC_PI_2).sqrt() * 90.0).floor() as usize, th);
            assert_eq!((b / FRAC_PI_2 * 90.0).floor() as usize, td);
            assert_eq!((c / PI * 180.0).floor() as usize, pd);
        }
    }

    #[test]
    fn write_read_round_trip_reproduces_the_model() {
        let brdf = Brdf::parse("beckmann:alpha=0.2,material=gold").unwrap();
        let merl = Merl::from_fn(|wi, wo| brdf.eval(wi, wo));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.binary");
        merl.write(&path).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len() as usize, FILE_BYTES);
        let back = Merl::read(&path).unwrap();
        let max_rel = merl
            .data
            .iter()
            .zip(&back.data)
            .filter(|(a, _)| **a >= 0.0)
            .map(|(a, b)| (a - b).abs() / a.abs().max(1e-300))
            .fold(0.0, f64::max);
        assert!(max_rel < 1e-14, "values changed in the round trip: {max_rel}");
        let below = |m: &Merl| m.data.iter().filter(|v| **v < 0.0).count();
        assert!(
            below(&merl) > 0 && below(&merl) == below(&back),
            "below-horizon marks must survive"
        );
        // Between bin centres the interpolated value follows the model on a smooth part of the lobe.
        for (ti, to, dphi) in [(0.3, 0.35, 3.0), (0.5, 0.45, 2.9), (0.8, 0.7, 3.1)] {
            let (wi, wo) = (spherical(ti, 0.2), spherical(to, 0.2 + dphi));
            let (a, b) = (brdf.eval(&wi, &wo), back.eval(&wi, &wo));
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 0.03 * a[c], "{ti},{to}: {a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn bad_files_are_errors_not_panics() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.binary");
        std::fs::write(&p, [1u8, 2, 3]).unwrap();
        assert!(Merl::read(&p).unwrap_err().to_string().contains("shorter than"));
        let mut header = Vec::new();
        for d in [90i32, 90, 360] {
            header.extend_from_slice(&d.to_le_bytes());
        }
        std::fs::write(&p, &header).unwrap();
        assert!(Merl::read(&p)
            .unwrap_err()
            .to_string()
            .contains("expected [90, 90, 180]"));
        let mut trunc = Vec::new();
        for d in [90i32, 90, 180] {
            trunc.extend_from_slice(&d.to_le_bytes());
        }
        trunc.extend_from_slice(&[0u8; 800]);
        std::fs::write(&p, &trunc).unwrap();
        let e = Merl::read(&p).unwrap_err().to_string();
        assert!(e.contains("truncated") && e.contains("bad.binary"), "{e}");
    }
}
