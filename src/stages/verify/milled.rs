//! How the milled surface's slopes are measured (DESIGN.md §6.1).
//!
//! Two choices decide the milled NDF as much as the cut does, so both are made here and stated in the report:
//!
//! - **The window is a whole number of tiles.** The design is a tile repeated from the work origin; a
//!   window that holds part of a tile weights its facets unequally (the design's own slope variance inside a
//!   window of the area less about 2r per side was 0.83–1.09× the tile's). The window is the largest whole
//!   number of tile periods that fits, per axis, in the interior (cells at least the edge band away from the
//!   stock's edge), centred in it. Where not even one tile fits, the whole interior is used and the report
//!   says so.
//! - **The scallops' slopes come from their analytic lobe.** A raster of a ball of radius `r` at stepover
//!   `s` leaves circular grooves whose slopes across the passes run over `±t_max`, `t_max = (s/2)/√(r² −
//!   s²/4)`, with a cusp between passes; central differences at the stock pitch (5 µm against a 45 µm
//!   stepover) straddle every cusp and captured only about 60% of the scallops' slope variance. So the
//!   slope at a cell is the *mean slope over one stepover across the passes* — across them
//!   `(z(c + n s/2) − z(c − n s/2)) / s`, along them the central difference averaged over the same window —
//!   which removes a periodic groove exactly and keeps everything wider than a stepover (facets, the
//!   ball's fillets in concave corners, steps). The grooves' own slopes are then put back by convolving
//!   with the scallop lobe ([`crate::stages::ndf::Kernel::scallop`]), the same lobe the design is convolved with.
//!   The lobe is that of grooves on a level surface; on a facet tilted by `β` across the passes the grooves'
//!   slopes spread by about `(1 + tan²β)^{3/2}` more (balls `s·√(1 + tan²β)` apart along the facet, slopes
//!   read through `d tan/dβ`), their variance by `(1 + tan²β)³`, which the lobe leaves out: at the default
//!   job's rms facet slope (tan β ≈ 0.14) that is 6% of the scallop part, under 1% of the total variance.

use crate::base::heightfield::Heightfield;
use crate::base::surface;
use serde::{Deserialize, Serialize};

/// How the milled NDF was measured (`metrics.json` `measurement`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// The cells measured.
    pub window: Window,
    /// The edge band left out, cells.
    pub margin_cells: usize,
    /// … and in mm.
    pub margin_mm: f64,
    /// The scallop lobe convolved back (its label: ball radius, stepover, angle, polish).
    pub scallops: String,
    /// The machinable cone the slope variances are compared within, degrees.
    pub cone_deg: f64,
    /// The fraction of the target's half-angle mass beyond that cone, which no facet draws:
    /// `g + (1 − g)·b`, `g` the mass beyond the NDF grid (`ndf.json` `mass_beyond_grid`, steeper than any cell)
    /// and `b` the observed grid's mass outside the cone. The part inside the grid counts against the L1,
    /// correlation and Jensen–Shannon figures; the report's steepest-facet row quotes this figure.
    pub target_mass_beyond_cone: f64,
    /// Fraction of the milled slopes beyond the NDF grid (steep walls), left out of the NDF.
    pub outside_grid: f64,
}

/// The cells measured: `nx × ny` from `(i0, j0)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// First column.
    pub i0: usize,
    /// First row.
    pub j0: usize,
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Whole tiles along x and y (0 where not even one fits and the window is the whole interior).
    pub tiles: [usize; 2],
    /// Side along x and y, mm.
    pub size_mm: [f64; 2],
}

impl Window {
    /// `nx × ny` cells from `(i0, j0)` of a grid at `pitch_mm`, holding `tiles` whole tiles.
    pub fn new(i0: usize, j0: usize, nx: usize, ny: usize, tiles: [usize; 2], pitch_mm: f64) -> Self {
        Self {
            i0,
            j0,
            nx,
            ny,
            tiles,
            size_mm: [nx as f64 * pitch_mm, ny as f64 * pitch_mm],
        }
    }

    /// The window is a whole number of tiles along both axes.
    pub fn whole(&self) -> bool {
        self.tiles[0] > 0 && self.tiles[1] > 0
    }
}

/// The largest whole-tile window in the interior of the milled surface `hf` (cells at least `margin` from each edge), centred;
/// the whole interior along an axis where no tile period fits. `None` when the interior is empty.
pub fn window(hf: &Heightfield, margin: usize, tile_mm: [f64; 2]) -> Option<Window> {
    let p = hf.pitch_mm;
    let axis = |n: usize, period: f64| -> Option<(usize, usize, usize)> {
        let inner = n.checked_sub(2 * margin).filter(|&v| v > 2)?;
        let per = period / p;
        let k = (inner as f64 / per + 1e-9).floor() as usize;
        if k == 0 {
            return Some((margin, inner, 0));
        }
        let cells = ((k as f64 * per).round() as usize).min(inner);
        Some((margin + (inner - cells) / 2, cells, k))
    };
    let (i0, nx, kx) = axis(hf.nx, tile_mm[0])?;
    let (j0, ny, ky) = axis(hf.ny, tile_mm[1])?;
    Some(Window::new(i0, j0, nx, ny, [kx, ky], p))
}

/// Cells needed beyond the window on each side by [`slopes`] at this stepover: half a stepover plus the
/// interpolation and the central difference.
pub fn reach_cells(pitch_mm: f64, stepover_mm: f64) -> usize {
    (0.5 * stepover_mm / pitch_mm).ceil() as usize + 2
}

/// Slopes `(∂z/∂x, ∂z/∂y)` of the cells of `win`, each the mean slope over one stepover across the passes
/// (module notes; [`surface::stepover_slopes`]); the passes run at `angle_deg` from x. The window must lie
/// [`reach_cells`] inside the grid.
pub fn slopes(hf: &Heightfield, win: &Window, angle_deg: f64, stepover_mm: f64) -> Vec<(f64, f64)> {
    surface::stepover_slopes(hf, [win.i0, win.j0, win.nx, win.ny], angle_deg, stepover_mm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ideal ball grooves at stepover `s` on the plane `z = a x + b y` (passes along x): each cell's height
    /// is the lowest of the balls centred on the pass lines, exact circles.
    fn grooved_plane(n: usize, pitch: f64, r: f64, s: f64, a: f64, b: f64) -> Heightfield {
        let mut hf = Heightfield::flat(n, n, pitch, false, 0.0);
        for j in 0..n {
            for i in 0..n {
                let (x, y) = ((i as f64 + 0.5) * pitch, (j as f64 + 0.5) * pitch);
                let k = (y / s).round();
                let mut best = f64::INFINITY;
                for kk in [k - 1.0, k, k + 1.0] {
                    let dy = y - kk * s;
                    if dy.abs() < r {
                        // the ball centre rides the plane: tip at z = a x + b y_k
                        let zc = a * x + b * kk * s + r;
                        best = best.min(zc - (r * r - dy * dy).sqrt());
                    }
                }
                hf.z_mm[j * n + i] = best;
            }
        }
        hf
    }

    #[test]
    fn the_window_holds_whole_tiles_and_is_centred() {
        let sim = Heightfield::flat(1000, 700, 0.01, false, 0.0);
        // 10 mm by 7 mm, 3 mm tiles, 50-cell band: 9 mm inner x holds 3 tiles, 6 mm inner y holds 2
        let w = window(&sim, 50, [3.0, 3.0]).unwrap();
        assert_eq!((w.tiles, w.nx, w.ny), ([3, 2], 900, 600));
        assert_eq!((w.i0, w.j0), (50, 50));
        let w = window(&sim, 50, [4.0, 2.5]).unwrap();
        assert_eq!((w.tiles, w.nx, w.ny), ([2, 2], 800, 500));
        assert_eq!((w.i0, w.j0), (100, 100));
        // a tile larger than the interior: the whole interior, and no tiles
        let w = window(&sim, 50, [12.0, 12.0]).unwrap();
        assert!(!w.whole() && w.nx == 900 && w.ny == 600);
    }

    #[test]
    fn the_stepover_mean_removes_the_grooves_and_keeps_the_plane() {
        // a plane grooved by a 0.25 mm ball at 44.7 µm stepover, sampled at 5 µm as the default job is
        let (r, s, p) = (0.25, 0.0447, 0.005);
        for (a, b) in [(0.0, 0.0), (0.2, -0.1), (-0.3, 0.3)] {
            let sim = grooved_plane(200, p, r, s, a, b);
            let w = Window {
                i0: 20,
                j0: 20,
                nx: 160,
                ny: 160,
                tiles: [0, 0],
                size_mm: [0.8, 0.8],
            };
            let sl = slopes(&sim, &w, 0.0, s);
            let n = sl.len() as f64;
            let (mp, mq) = sl.iter().fold((0.0, 0.0), |acc, v| (acc.0 + v.0 / n, acc.1 + v.1 / n));
            let vq = sl.iter().map(|v| (v.1 - mq).powi(2)).sum::<f64>() / n;
            assert!((mp - a).abs() < 1e-9, "x slope {mp} vs {a}");
            assert!((mq - b).abs() < 2e-3, "y slope {mq} vs {b}");
            // the groove's own variance is 0.0027; what is left is the linear interpolation's across the cusps,
            // at most (Δt·p/(2s))² with Δt ≈ 2·t_max·(1 + b²) the slope jump at a cusp: 1.4e-4 at b = 0.3
            assert!(vq < 1.4e-4, "left {vq} of the groove variance at slope ({a}, {b})");
        }
    }

    #[test]
    fn central_differences_at_the_stock_pitch_miss_part_of_the_groove_variance() {
        // the reason for the analytic lobe: the exact groove variance against what 5 µm central
        // differences see (the analytic value is ∫ t² over the arc, weighted by projected area)
        let (r, s, p) = (0.25, 0.0447, 0.005);
        let hf = grooved_plane(400, p, r, s, 0.0, 0.0);
        let mut acc = (0.0, 0usize);
        for j in 20..380 {
            for i in 20..380 {
                let d = (hf.at(i, j + 1) - hf.at(i, j - 1)) / (2.0 * p);
                acc.0 += d * d;
                acc.1 += 1;
            }
        }
        let central = acc.0 / acc.1 as f64;
        // exact: y uniform over [−s/2, s/2], slope t = y/√(r² − y²)
        let exact = (0..100_000)
            .map(|k| {
                let y = -s / 2.0 + s * (k as f64 + 0.5) / 100_000.0;
                y * y / (r * r - y * y)
            })
            .sum::<f64>()
            / 100_000.0;
        let ratio = central / exact;
        assert!(
            ratio < 0.8 && ratio > 0.3,
            "central differences saw {ratio:.3} of the groove variance"
        );
    }
}
