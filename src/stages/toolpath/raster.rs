//! Raster passes over the periodic design repeated across the work area, at any angle.
//!
//! The work area `[0, Ax] × [0, Ay]` (mm, origin at its lower-left corner, z = 0 the stock top) is covered by
//! the design tile repeated periodically. Passes run along `u`, the raster direction at `angle` from x, and
//! step across in `v`: `(x, y) = (u cosθ − v sinθ, u sinθ + v cosθ)`. The design is sampled on a `(u, v)` grid
//! of the tile's pitch covering the area plus a margin of the cutter radius, exactly at the tile's samples
//! when the angle is 0° (bilinearly between them otherwise), and the drop-cutter runs on that grid.

use crate::base::heightfield::Heightfield;
use crate::cut::dropcutter::{DropCutter, Edge};
use crate::cut::tool::Shape;
use crate::gcode::moves::P3;
use rayon::prelude::*;

/// The design on the rotated `(u, v)` grid.
pub struct RotatedDesign {
    /// Heights on the grid (not periodic), `u` along rows.
    pub hf: Heightfield,
    /// `u` of grid column 0's left edge.
    pub u0: f64,
    /// `v` of grid row 0's bottom edge.
    pub v0: f64,
    cos: f64,
    sin: f64,
    /// The area, mm.
    pub area: (f64, f64),
}

impl RotatedDesign {
    /// Sample the periodic `tile` over `area` rotated by `angle_deg`, with `margin_mm` around it.
    pub fn new(tile: &Heightfield, area: (f64, f64), angle_deg: f64, margin_mm: f64) -> Self {
        let (sin, cos) = angle_deg.to_radians().sin_cos();
        let (sin, cos) = (snap(sin), snap(cos));
        let p = tile.pitch_mm;
        // area corners in (u, v)
        let corners = [(0.0, 0.0), (area.0, 0.0), (0.0, area.1), (area.0, area.1)];
        let uv: Vec<(f64, f64)> = corners
            .iter()
            .map(|&(x, y)| (x * cos + y * sin, -x * sin + y * cos))
            .collect();
        let umin = uv.iter().map(|c| c.0).fold(f64::INFINITY, f64::min);
        let umax = uv.iter().map(|c| c.0).fold(f64::NEG_INFINITY, f64::max);
        let vmin = uv.iter().map(|c| c.1).fold(f64::INFINITY, f64::min);
        let vmax = uv.iter().map(|c| c.1).fold(f64::NEG_INFINITY, f64::max);
        // grid edges on multiples of the pitch, so 0° lands exactly on the tile's samples
        let u0 = ((umin - margin_mm) / p).floor() * p;
        let v0 = ((vmin - margin_mm) / p).floor() * p;
        // the caller bounds the cells (`toolpath::MAX_GRID_CELLS`); at least one cell either way, so a
        // degenerate size never reaches `par_chunks_mut(0)`
        let nu = (((umax + margin_mm - u0) / p).ceil() as usize).saturating_add(1).max(1);
        let nv = (((vmax + margin_mm - v0) / p).ceil() as usize).saturating_add(1).max(1);
        let mut hf = Heightfield::flat(nu, nv, p, false, 0.0);
        hf.z_mm.par_chunks_mut(nu).enumerate().for_each(|(j, row)| {
            let v = v0 + (j as f64 + 0.5) * p;
            for (i, z) in row.iter_mut().enumerate() {
                let u = u0 + (i as f64 + 0.5) * p;
                *z = periodic_bilinear(tile, u * cos - v * sin, u * sin + v * cos);
            }
        });
        Self {
            hf,
            u0,
            v0,
            cos,
            sin,
            area,
        }
    }

    /// Work coordinates of a `(u, v)` point.
    #[inline]
    pub fn to_xy(&self, u: f64, v: f64) -> (f64, f64) {
        (u * self.cos - v * self.sin, u * self.sin + v * self.cos)
    }

    /// `(u, v)` of a work point.
    #[inline]
    pub fn to_uv(&self, x: f64, y: f64) -> (f64, f64) {
        (x * self.cos + y * self.sin, -x * self.sin + y * self.cos)
    }

    /// `(cos θ, sin θ)` of the raster angle.
    pub fn cos_sin(&self) -> (f64, f64) {
        (self.cos, self.sin)
    }

    /// `(v_min, v_max)` of the area.
    pub fn v_range(&self) -> (f64, f64) {
        let c = [
            (0.0, 0.0),
            (self.area.0, 0.0),
            (0.0, self.area.1),
            (self.area.0, self.area.1),
        ];
        let vs: Vec<f64> = c.iter().map(|&(x, y)| -x * self.sin + y * self.cos).collect();
        (
            vs.iter().copied().fold(f64::INFINITY, f64::min),
            vs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        )
    }

    fn inside(&self, x: f64, y: f64) -> bool {
        let e = 1e-9;
        x >= -e && y >= -e && x <= self.area.0 + e && y <= self.area.1 + e
    }

    /// The CL points of a pass at `v` with `cutter`, inside the area, in increasing `u`, each z mapped by
    /// `zmap` (e.g. raised to a roughing layer).
    pub fn pass(&self, dc: &DropCutter, v: f64, zmap: impl Fn(f64) -> f64) -> Vec<P3> {
        let mut row = vec![0.0; self.hf.nx];
        dc.row(v - self.v0, &mut row);
        let cols = self.pass_columns(v);
        self.pass_points(v, cols.start, &row[cols], zmap)
    }

    /// The grid columns of a pass at `v` whose points lie inside the area (one interval: a line meets the
    /// rectangle in one segment).
    pub fn pass_columns(&self, v: f64) -> std::ops::Range<usize> {
        let p = self.hf.pitch_mm;
        let inside = |i: usize| {
            let (x, y) = self.to_xy(self.u0 + (i as f64 + 0.5) * p, v);
            self.inside(x, y)
        };
        match (0..self.hf.nx).position(inside) {
            Some(a) => a..(a + (a..self.hf.nx).take_while(|&i| inside(i)).count()),
            None => 0..0,
        }
    }

    /// The points of a pass at `v` over the columns `i0 .. i0 + z.len()`, with tip heights `z` mapped by `zmap`.
    pub fn pass_points(&self, v: f64, i0: usize, z: &[f64], zmap: impl Fn(f64) -> f64) -> Vec<P3> {
        let p = self.hf.pitch_mm;
        z.iter()
            .enumerate()
            .map(|(k, z)| {
                let (x, y) = self.to_xy(self.u0 + ((i0 + k) as f64 + 0.5) * p, v);
                [x, y, zmap(*z)]
            })
            .collect()
    }

    /// A drop-cutter over this grid.
    pub fn cutter(&self, cutter: Shape) -> DropCutter<'_> {
        DropCutter::new(&self.hf, cutter, Edge::Open)
    }

    /// CL height at a work point (direct summation; used for links between passes and for checks).
    pub fn cl_at(&self, dc: &DropCutter, x: f64, y: f64) -> f64 {
        let (u, v) = (x * self.cos + y * self.sin, -x * self.sin + y * self.cos);
        dc.point(u - self.u0, v - self.v0)
    }
}

/// Round tiny sines/cosines to exact 0, ±1 so that multiples of 90° are exact.
fn snap(v: f64) -> f64 {
    if v.abs() < 1e-12 {
        0.0
    } else if (v.abs() - 1.0).abs() < 1e-12 {
        v.signum()
    } else {
        v
    }
}

/// Bilinear interpolation of a periodic heightfield between its samples at `(x, y)` (mm).
pub fn periodic_bilinear(hf: &Heightfield, x: f64, y: f64) -> f64 {
    // positions within 1e-9 of a sample are that sample (so 0° and 90° rasters read the tile exactly)
    let snap = |f: f64| if (f - f.round()).abs() < 1e-9 { f.round() } else { f };
    let (fx, fy) = (snap(x / hf.pitch_mm - 0.5), snap(y / hf.pitch_mm - 0.5));
    let (ix, iy) = (fx.floor(), fy.floor());
    let (tx, ty) = (fx - ix, fy - iy);
    let (nx, ny) = (hf.nx as i64, hf.ny as i64);
    let at = |i: i64, j: i64| hf.at(i.rem_euclid(nx) as usize, j.rem_euclid(ny) as usize);
    let (i, j) = (ix as i64, iy as i64);
    if tx < 1e-9 && ty < 1e-9 {
        return at(i, j);
    }
    (1.0 - ty) * ((1.0 - tx) * at(i, j) + tx * at(i + 1, j)) + ty * ((1.0 - tx) * at(i, j + 1) + tx * at(i + 1, j + 1))
}

/// Stepover for a target scallop height with a ball of radius `r`: `s = 2·sqrt(2 r h − h²)` (DESIGN.md §4).
pub fn stepover_for_scallop(r: f64, h: f64) -> f64 {
    2.0 * (2.0 * r * h - h * h).max(0.0).sqrt()
}

/// Scallop height left by a ball of radius `r` at stepover `s`: `h = r − sqrt(r² − (s/2)²)`.
pub fn scallop_for_stepover(r: f64, s: f64) -> f64 {
    r - (r * r - s * s / 4.0).max(0.0).sqrt()
}

/// Pass positions `v` covering `[vmin, vmax]` at most `s` apart, both ends included.
pub fn pass_positions(vmin: f64, vmax: f64, s: f64) -> Vec<f64> {
    let n = ((vmax - vmin) / s).ceil().max(1.0) as usize;
    (0..=n).map(|k| vmin + (vmax - vmin) * k as f64 / n as f64).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scallop_and_stepover_are_inverse() {
        for (r, h) in [(0.5, 0.001), (1.0, 0.01), (0.25, 0.0002)] {
            let s = stepover_for_scallop(r, h);
            assert!((scallop_for_stepover(r, s) - h).abs() < 1e-12);
            assert!((s - (8.0 * r * h).sqrt()).abs() < 0.01 * s, "≈ sqrt(8 r h)");
        }
    }

    #[test]
    fn zero_degrees_samples_the_tile_exactly() {
        let mut tile = Heightfield::flat(10, 8, 0.1, true, 0.0);
        for (k, z) in tile.z_mm.iter_mut().enumerate() {
            *z = -(k as f64) * 0.001;
        }
        let d = RotatedDesign::new(&tile, (2.5, 1.3), 0.0, 0.3);
        for j in 0..d.hf.ny {
            for i in 0..d.hf.nx {
                let (u, v) = (d.u0 + (i as f64 + 0.5) * 0.1, d.v0 + (j as f64 + 0.5) * 0.1);
                let (ti, tj) = (
                    ((u / 0.1 - 0.5).round() as i64).rem_euclid(10),
                    ((v / 0.1 - 0.5).round() as i64).rem_euclid(8),
                );
                assert_eq!(d.hf.at(i, j), tile.at(ti as usize, tj as usize));
            }
        }
    }

    #[test]
    fn ninety_degrees_covers_the_area() {
        let tile = Heightfield::flat(10, 10, 0.1, true, -0.1);
        let d = RotatedDesign::new(&tile, (2.0, 1.0), 90.0, 0.2);
        let (vmin, vmax) = d.v_range();
        assert!((vmin + 2.0).abs() < 1e-12 && vmax.abs() < 1e-12, "{vmin} {vmax}");
        let dc = d.cutter(Shape::Ball { diameter_mm: 0.3 });
        let pts = d.pass(&dc, -1.0, |z| z);
        // a pass at v = -1 runs along y at x = 1; over a flat tile the ball's tip sits on it, or below by at
        // most the sag between samples
        let sag = 0.1f64 * 0.1 / (4.0 * 0.15);
        assert!(pts
            .iter()
            .all(|p| (p[0] - 1.0).abs() < 1e-9 && p[2] <= -0.1 + 1e-12 && p[2] >= -0.1 - sag));
        assert!(pts.first().unwrap()[1] < 0.1 && pts.last().unwrap()[1] > 0.9);
    }
}
