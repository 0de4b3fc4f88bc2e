//! Heightfields: a regular grid of heights in mm with `pitch_mm` in x and y, row-major (rows along y),
//! origin at its corner, sample `(i, j)` at `((i + ½)·pitch, (j + ½)·pitch)`. Every heightfield says
//! whether it is periodic (tileable). The stock top is z = 0 and cuts go to negative z.

use crate::base::plot::{viridis, Heatmap, Scale};
use crate::base::Invalid;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A heightfield in mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Heightfield {
    /// Samples along x.
    pub nx: usize,
    /// Samples along y.
    pub ny: usize,
    /// Sample spacing in x and y, mm.
    pub pitch_mm: f64,
    /// True when the field tiles: sample `nx` is sample `0` again.
    pub periodic: bool,
    /// Heights in mm, row-major, rows along y.
    pub z_mm: Vec<f64>,
}

impl Heightfield {
    /// A flat field at height `z`.
    pub fn flat(nx: usize, ny: usize, pitch_mm: f64, periodic: bool, z: f64) -> Self {
        Self {
            nx,
            ny,
            pitch_mm,
            periodic,
            z_mm: vec![z; nx * ny],
        }
    }

    /// The same grid (size, pitch, periodicity) with the heights `z_mm`, which must have as many samples.
    #[must_use]
    pub fn with_heights(&self, z_mm: Vec<f64>) -> Self {
        debug_assert_eq!(z_mm.len(), self.nx * self.ny);
        Self {
            nx: self.nx,
            ny: self.ny,
            pitch_mm: self.pitch_mm,
            periodic: self.periodic,
            z_mm,
        }
    }

    /// The height at sample `(i, j)`.
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.z_mm[j * self.nx + i]
    }

    /// Size in mm `(x, y)`.
    pub fn size_mm(&self) -> (f64, f64) {
        (self.nx as f64 * self.pitch_mm, self.ny as f64 * self.pitch_mm)
    }

    /// `(min, max)` height.
    pub fn range(&self) -> (f64, f64) {
        self.z_mm
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)))
    }

    /// Check the invariants: sizes, a positive finite pitch, finite heights.
    pub fn check_invariants(&self) -> Result<(), Invalid> {
        if self.nx == 0 || self.ny == 0 {
            return Err(Invalid(format!("heightfield is empty ({}×{})", self.nx, self.ny)));
        }
        if self.nx.checked_mul(self.ny) != Some(self.z_mm.len()) {
            return Err(Invalid(format!(
                "{} heights for a {}×{} grid",
                self.z_mm.len(),
                self.nx,
                self.ny
            )));
        }
        if !(self.pitch_mm.is_finite() && self.pitch_mm > 0.0) {
            return Err(Invalid(format!("pitch_mm must be positive, got {}", self.pitch_mm)));
        }
        if let Some(k) = self.z_mm.iter().position(|v| !v.is_finite()) {
            return Err(Invalid(format!(
                "height {k} (x {}, y {}) is not finite",
                k % self.nx,
                k / self.nx
            )));
        }
        Ok(())
    }

    /// Write the heights as a `.npy` array of shape `(ny, nx)`, mm, in single precision (`float32`: half the
    /// bytes of `float64`, and at most 0.06 nm off on a height of 1 mm, far below any cut or step grid).
    pub fn write_npy(&self, path: &Path) -> Result<(), crate::base::io::WriteError> {
        crate::base::npy::write_f32_2d(path, self.ny, self.nx, &self.z_mm)
    }

    /// A shaded relief (hill shading lit from the upper left, tinted by height) with axes in mm, at most
    /// `max_px` pixels on its longer side (box-averaged down).
    pub fn relief_png(&self, title: &str, max_px: usize) -> crate::base::plot::Canvas {
        self.relief_in(title, max_px, [0.0, 0.0], self.range())
    }

    /// [`Self::relief_png`] with its first cell's corner at `origin_mm` on the axes and the colours spanning
    /// the heights `range_mm` (low, high; heights beyond take the end colours), so that two reliefs can be
    /// read on one scale.
    pub fn relief_in(
        &self,
        title: &str,
        max_px: usize,
        origin_mm: [f64; 2],
        range_mm: (f64, f64),
    ) -> crate::base::plot::Canvas {
        let f = self.nx.max(self.ny).div_ceil(max_px).max(1);
        let (w, h) = (self.nx / f, self.ny / f);
        let (w, h) = (w.max(1), h.max(1));
        let mut z = vec![0.0; w * h];
        for j in 0..h {
            for i in 0..w {
                let mut s = 0.0;
                for dj in 0..f {
                    for di in 0..f {
                        s += self.at((i * f + di).min(self.nx - 1), (j * f + dj).min(self.ny - 1));
                    }
                }
                z[j * w + i] = s / (f * f) as f64;
            }
        }
        let step = self.pitch_mm * f as f64;
        let (lo, hi) = range_mm;
        let span = (hi - lo).max(1e-12);
        let light = crate::base::geometry::Vec3::new(-1.0, 1.0, 1.4).normalize();
        let at = |i: isize, j: isize| -> f64 {
            let (i, j) = if self.periodic {
                (i.rem_euclid(w as isize) as usize, j.rem_euclid(h as isize) as usize)
            } else {
                (i.clamp(0, w as isize - 1) as usize, j.clamp(0, h as isize - 1) as usize)
            };
            z[j * w + i]
        };
        let rgb: Vec<[u8; 3]> = (0..w * h)
            .map(|k| {
                let (i, j) = ((k % w) as isize, (k / w) as isize);
                let dzdx = (at(i + 1, j) - at(i - 1, j)) / (2.0 * step);
                let dzdy = (at(i, j + 1) - at(i, j - 1)) / (2.0 * step);
                let n = crate::base::geometry::Vec3::new(-dzdx, -dzdy, 1.0).normalize();
                let shade = n.dot(&light).max(0.0);
                let c = viridis(((z[k] - lo) / span).clamp(0.0, 1.0));
                c.map(|v| (v as f64 * (0.25 + 0.75 * shade)).round().clamp(0.0, 255.0) as u8)
            })
            .collect();
        let (sx, sy) = self.size_mm();
        let zum: Vec<f64> = z.iter().map(|v| v * 1000.0).collect();
        Heatmap {
            values: &zum,
            nx: w,
            ny: h,
            x_range: (origin_mm[0], origin_mm[0] + sx),
            y_range: (origin_mm[1], origin_mm[1] + sy),
            title: title.to_string(),
            x_label: "x (mm)".into(),
            y_label: "y (mm)".into(),
            value_label: "z (µm)".into(),
            scale: Scale::Linear,
            value_max: Some(hi * 1000.0),
            value_min: Some(lo * 1000.0),
            plot_px: 640,
            rgb: Some(&rgb),
        }
        .render()
    }
}
