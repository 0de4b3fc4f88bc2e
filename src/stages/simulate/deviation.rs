//! The simulated surface against the design: what was left above it, what was cut below it, and where no
//! program with this bit could have followed it.
//!
//! The design is a tile repeated from the work origin `(0, 0)` (sample `(k, l)` at `((k + ½)·p, (l + ½)·p)`),
//! read at the stock's cell centres by bilinear interpolation. **Reach** is a property of the design and the
//! bit alone: the best any raster of this bit can leave, however fine, is the design's *opening* by the bit —
//! the erosion of the drop-cutter CL surface, `O(x) = min_{|u| ≤ R} CL(x + u) + prof(|u|)` with
//! `CL(x) = max_{|u| ≤ R} h(x + u) − prof(|u|)` (DESIGN.md §4), both over the design's samples. Where `O`
//! stands above the design by more than [`REACH_TOLERANCE_UM`] at any of the four samples around a cell,
//! the cell is *unreachable* (a concave corner narrower than the bit). The tolerance covers the sampling of
//! the opening itself: a ball touching a sloped design between samples sits up to `p²(1 + s²)^{3/2} / (8r)`
//! above it (0.07 µm for a 1 mm ball at 10 µm pitch and slope 1).
//!
//! Only the interior is assessed: cells at least twice the tool radius plus one cell from the stock's edge.
//! The default stock is the tool-centre extents plus one radius, and the opening at a cell may rest on a bit
//! centred up to a radius away from it — a position the program can only have visited if it lies within its
//! extents.

use super::{Shape, Simulation};
use crate::base::heightfield::Heightfield;
use crate::cut::morphology::opening;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use crate::cut::morphology::REACH_TOLERANCE_UM;

/// A largest value and where it is.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Extreme {
    /// The value, µm.
    pub um: f64,
    /// Work `[x, y]` of the cell, mm.
    pub at_mm: [f64; 2],
}

impl Extreme {
    fn none() -> Self {
        Self {
            um: f64::NEG_INFINITY,
            at_mm: [f64::NAN; 2],
        }
    }
    fn take(&mut self, um: f64, at: [f64; 2]) {
        if um > self.um {
            *self = Self { um, at_mm: at };
        }
    }
    fn max(self, o: Self) -> Self {
        if o.um > self.um {
            o
        } else {
            self
        }
    }
}

/// The simulated surface against the design, over the stock's grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Deviation {
    /// Grid cells along x (the simulation's).
    pub nx: usize,
    /// Grid cells along y.
    pub ny: usize,
    /// Cell side, mm.
    pub pitch_mm: f64,
    /// Work x, y of the grid's lower-left corner, mm.
    pub origin_mm: [f64; 2],
    /// Simulated minus design height per cell, µm, row-major; NaN outside the assessed interior.
    #[serde(skip)]
    pub map_um: Vec<f32>,
    /// Per cell: the bit cannot reach the design there (see the module comment).
    #[serde(skip)]
    pub unreachable: Vec<bool>,
    /// Distance from the stock edge within which cells are not assessed, mm.
    pub interior_margin_mm: f64,
    /// Cells assessed.
    pub interior_cells: usize,
    /// Assessed cells that are unreachable.
    pub unreachable_cells: usize,
    /// `unreachable_cells / interior_cells`.
    pub unreachable_fraction: f64,
    /// Reach tolerance used, µm.
    pub reach_tolerance_um: f64,
    /// Largest height of material left above the design, µm (negative: every cell is below it).
    pub max_over_um: f64,
    /// Where, work mm.
    pub max_over_at_mm: [f64; 2],
    /// Largest depth cut below the design (a gouge), µm (negative: every cell is above it).
    pub max_under_um: f64,
    /// Where, work mm.
    pub max_under_at_mm: [f64; 2],
    /// Largest height left above the design where it is reachable, µm.
    pub max_over_reachable_um: f64,
    /// Where, work mm.
    pub max_over_reachable_at_mm: [f64; 2],
    /// Largest height left above the opening (what an infinitely fine raster of this bit leaves), µm.
    pub max_above_opening_um: f64,
    /// Where, work mm.
    pub max_above_opening_at_mm: [f64; 2],
    /// Root mean square of simulated − design over the reachable cells, µm.
    pub rms_reachable_um: f64,
}

/// The design (and its opening) over a window of its samples, non-periodic, or the whole periodic tile.
struct Window {
    nx: usize,
    ny: usize,
    /// Design sample index of the window's column 0 / row 0 (the window's samples are the design's).
    k0: i64,
    l0: i64,
    periodic: bool,
    pitch: f64,
    h: Vec<f64>,
    open: Vec<f64>,
}

impl Window {
    /// Indices of the four samples around work `(x, y)` and the bilinear weights, None outside the window.
    #[inline]
    fn corners(&self, x: f64, y: f64) -> Option<([usize; 4], f64, f64)> {
        let (fx, fy) = (x / self.pitch - 0.5, y / self.pitch - 0.5);
        let (ix, iy) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - ix, fy - iy);
        let (i, j) = (ix as i64 - self.k0, iy as i64 - self.l0);
        let (nx, ny) = (self.nx as i64, self.ny as i64);
        let idx = |a: i64, b: i64| -> Option<usize> {
            if self.periodic {
                Some((b.rem_euclid(ny) * nx + a.rem_euclid(nx)) as usize)
            } else if a < 0 || b < 0 || a >= nx || b >= ny {
                None
            } else {
                Some((b * nx + a) as usize)
            }
        };
        Some(([idx(i, j)?, idx(i + 1, j)?, idx(i, j + 1)?, idx(i + 1, j + 1)?], tx, ty))
    }
}

#[inline]
fn bilinear(v: &[f64], c: [usize; 4], tx: f64, ty: f64) -> f64 {
    (1.0 - ty) * ((1.0 - tx) * v[c[0]] + tx * v[c[1]]) + ty * ((1.0 - tx) * v[c[2]] + tx * v[c[3]])
}

/// Compare a simulation with the design tile (periodic, repeated from the work origin; a non-periodic design
/// is placed once at the origin and cells beyond it are not assessed). An invalid design assesses nothing.
pub fn deviation(sim: &Simulation, design: &Heightfield, tool: &Shape) -> Deviation {
    let margin = 2.0 * tool.radius_mm() + sim.heightfield.pitch_mm;
    let mut dev = Deviation::unassessed(sim, margin);
    if design.check_invariants().is_err() || tool.validate().is_err() {
        return dev;
    }
    let Some(cells) = Interior::of(sim, margin) else {
        return dev;
    };
    let Some(win) = Window::around(design, sim, &cells, tool) else {
        return dev;
    };
    let acc = compare(sim, &win, &cells, &mut dev.map_um, &mut dev.unreachable);
    if acc.n > 0 {
        dev.record(&acc);
    }
    dev
}

/// The assessed cells: `i_lo..=i_hi` by `j_lo..=j_hi`.
struct Interior {
    i_lo: usize,
    i_hi: usize,
    j_lo: usize,
    j_hi: usize,
}

impl Interior {
    /// The cells at least `margin` from the stock's edge, None when there are none.
    fn of(sim: &Simulation, margin: f64) -> Option<Self> {
        let hf = &sim.heightfield;
        let p = hf.pitch_mm;
        let (i_lo, i_hi) = ((margin / p - 0.5).ceil() as usize, hf.nx as f64 - 0.5 - margin / p);
        let (j_lo, j_hi) = ((margin / p - 0.5).ceil() as usize, hf.ny as f64 - 0.5 - margin / p);
        if i_hi < i_lo as f64 || j_hi < j_lo as f64 {
            return None;
        }
        Some(Self {
            i_lo,
            i_hi: i_hi.floor() as usize,
            j_lo,
            j_hi: j_hi.floor() as usize,
        })
    }
}

impl Window {
    /// The design under the interior plus two tool radii (CL needs one, the opening another), with its
    /// opening: the whole tile when a periodic design's tile is no larger than that window, otherwise the
    /// window's samples (wrapped for a periodic design, clipped to a non-periodic one; None when nothing
    /// of it is left).
    fn around(design: &Heightfield, sim: &Simulation, cells: &Interior, tool: &Shape) -> Option<Self> {
        let (r, pd) = (tool.radius_mm(), design.pitch_mm);
        let [x_lo, y_lo] = sim.cell_xy(cells.i_lo, cells.j_lo);
        let [x_hi, y_hi] = sim.cell_xy(cells.i_hi, cells.j_hi);
        let pad = 2.0 * r + 2.0 * pd;
        let (mut k0, mut l0) = (((x_lo - pad) / pd).floor() as i64, ((y_lo - pad) / pd).floor() as i64);
        let (mut k1, mut l1) = (((x_hi + pad) / pd).ceil() as i64, ((y_hi + pad) / pd).ceil() as i64);
        let periodic_whole = design.periodic && (k1 - k0 + 1) * (l1 - l0 + 1) >= (design.nx * design.ny) as i64;
        if !design.periodic {
            k0 = k0.max(0);
            l0 = l0.max(0);
            k1 = k1.min(design.nx as i64 - 1);
            l1 = l1.min(design.ny as i64 - 1);
            if k1 < k0 || l1 < l0 {
                return None;
            }
        }
        let mut win = if periodic_whole {
            Window {
                nx: design.nx,
                ny: design.ny,
                k0: 0,
                l0: 0,
                periodic: true,
                pitch: pd,
                h: design.z_mm.clone(),
                open: vec![],
            }
        } else {
            let (wn, hn) = ((k1 - k0 + 1) as usize, (l1 - l0 + 1) as usize);
            let mut h = vec![0.0; wn * hn];
            for (l, row) in h.chunks_mut(wn).enumerate() {
                for (k, v) in row.iter_mut().enumerate() {
                    let (a, b) = (k as i64 + k0, l as i64 + l0);
                    *v = design.at(
                        a.rem_euclid(design.nx as i64) as usize,
                        b.rem_euclid(design.ny as i64) as usize,
                    );
                }
            }
            Window {
                nx: wn,
                ny: hn,
                k0,
                l0,
                periodic: false,
                pitch: pd,
                h,
                open: vec![],
            }
        };
        win.open = if win.periodic {
            crate::cut::morphology::opening_periodic(&win.h, win.nx, win.ny, pd, tool)
        } else {
            opening(&win.h, win.nx, win.ny, pd, false, tool)
        };
        Some(win)
    }
}

/// Running totals over assessed cells.
#[derive(Clone, Copy)]
struct Acc {
    n: usize,
    unreach: usize,
    over: Extreme,
    under: Extreme,
    over_r: Extreme,
    above_open: Extreme,
    ss: f64,
    nr: usize,
}

impl Acc {
    fn zero() -> Self {
        Self {
            n: 0,
            unreach: 0,
            over: Extreme::none(),
            under: Extreme::none(),
            over_r: Extreme::none(),
            above_open: Extreme::none(),
            ss: 0.0,
            nr: 0,
        }
    }

    fn merge(self, b: Self) -> Self {
        Self {
            n: self.n + b.n,
            unreach: self.unreach + b.unreach,
            over: self.over.max(b.over),
            under: self.under.max(b.under),
            over_r: self.over_r.max(b.over_r),
            above_open: self.above_open.max(b.above_open),
            ss: self.ss + b.ss,
            nr: self.nr + b.nr,
        }
    }
}

/// Fill the deviation map and reach flags over the interior (rows in parallel) and total them.
fn compare(sim: &Simulation, win: &Window, cells: &Interior, map_um: &mut [f32], unreachable: &mut [bool]) -> Acc {
    let hf = &sim.heightfield;
    let tol_mm = REACH_TOLERANCE_UM * 1e-3;
    let nx = hf.nx;
    map_um
        .par_chunks_mut(nx)
        .zip(unreachable.par_chunks_mut(nx))
        .enumerate()
        .filter(|(j, _)| (cells.j_lo..=cells.j_hi).contains(j))
        .map(|(j, (mrow, urow))| {
            let mut a = Acc::zero();
            for i in cells.i_lo..=cells.i_hi {
                let at = sim.cell_xy(i, j);
                let Some((c, tx, ty)) = win.corners(at[0], at[1]) else {
                    continue;
                };
                let zd = bilinear(&win.h, c, tx, ty);
                let zo = bilinear(&win.open, c, tx, ty);
                let unreachable = c.iter().any(|&k| win.open[k] - win.h[k] > tol_mm);
                let zs = hf.at(i, j);
                let d = (zs - zd) * 1e3;
                mrow[i] = d as f32;
                urow[i] = unreachable;
                a.n += 1;
                a.over.take(d, at);
                a.under.take(-d, at);
                a.above_open.take((zs - zo) * 1e3, at);
                if unreachable {
                    a.unreach += 1;
                } else {
                    a.over_r.take(d, at);
                    a.ss += d * d;
                    a.nr += 1;
                }
            }
            a
        })
        // merged in row order: the sums do not depend on how the rows were stolen
        .collect::<Vec<_>>()
        .into_iter()
        .fold(Acc::zero(), Acc::merge)
}

impl Deviation {
    /// Nothing assessed yet: an empty map over the simulation's grid, every statistic NaN.
    fn unassessed(sim: &Simulation, margin: f64) -> Self {
        let hf = &sim.heightfield;
        Self {
            nx: hf.nx,
            ny: hf.ny,
            pitch_mm: hf.pitch_mm,
            origin_mm: sim.origin_mm,
            map_um: vec![f32::NAN; hf.nx * hf.ny],
            unreachable: vec![false; hf.nx * hf.ny],
            interior_margin_mm: margin,
            interior_cells: 0,
            unreachable_cells: 0,
            unreachable_fraction: f64::NAN,
            reach_tolerance_um: REACH_TOLERANCE_UM,
            max_over_um: f64::NAN,
            max_over_at_mm: [f64::NAN; 2],
            max_under_um: f64::NAN,
            max_under_at_mm: [f64::NAN; 2],
            max_over_reachable_um: f64::NAN,
            max_over_reachable_at_mm: [f64::NAN; 2],
            max_above_opening_um: f64::NAN,
            max_above_opening_at_mm: [f64::NAN; 2],
            rms_reachable_um: f64::NAN,
        }
    }

    /// The statistics from the totals of a non-empty assessment.
    fn record(&mut self, acc: &Acc) {
        let fin = |e: Extreme| {
            if e.um.is_finite() {
                (e.um, e.at_mm)
            } else {
                (f64::NAN, [f64::NAN; 2])
            }
        };
        self.interior_cells = acc.n;
        self.unreachable_cells = acc.unreach;
        self.unreachable_fraction = acc.unreach as f64 / acc.n as f64;
        (self.max_over_um, self.max_over_at_mm) = fin(acc.over);
        (self.max_under_um, self.max_under_at_mm) = fin(acc.under);
        (self.max_over_reachable_um, self.max_over_reachable_at_mm) = fin(acc.over_r);
        (self.max_above_opening_um, self.max_above_opening_at_mm) = fin(acc.above_open);
        self.rms_reachable_um = if acc.nr > 0 {
            (acc.ss / acc.nr as f64).sqrt()
        } else {
            f64::NAN
        };
    }
}

impl Deviation {
    /// A false-colour map of simulated − design (µm) over the assessed cells, unreachable cells and the edge
    /// band grey; each pixel shows the cell of largest |deviation| in its block, so extremes stay visible, and
    /// the colours span the 0.1–99.9 percentiles of what is shown (values beyond are clamped). Returns the
    /// figure and the colour scale's range `[low, high]`, µm, for its caption.
    pub fn to_png(&self, title: &str, max_px: usize) -> (crate::base::plot::Canvas, [f64; 2]) {
        let f = self.nx.max(self.ny).div_ceil(max_px.max(1)).max(1);
        let (w, h) = ((self.nx / f).max(1), (self.ny / f).max(1));
        let mut v = vec![f64::NAN; w * h];
        for (k, out) in v.iter_mut().enumerate() {
            let (bi, bj) = (k % w, k / w);
            for j in bj * f..((bj + 1) * f).min(self.ny) {
                for i in bi * f..((bi + 1) * f).min(self.nx) {
                    let c = j * self.nx + i;
                    let d = self.map_um[c] as f64;
                    if self.unreachable[c] || !d.is_finite() {
                        continue;
                    }
                    if out.is_nan() || d.abs() > out.abs() {
                        *out = d;
                    }
                }
            }
        }
        // colour range: the 0.1 and 99.9 percentiles, so that one extreme cell does not flatten the map
        let mut fin: Vec<f64> = v.iter().copied().filter(|d| d.is_finite()).collect();
        fin.sort_by(f64::total_cmp);
        let range = match fin.len() {
            0 => [f64::NAN; 2],
            n if n > 10 => [fin[n / 1000], fin[n - 1 - n / 1000]],
            n => [fin[0], fin[n - 1]],
        };
        if fin.len() > 10 {
            v.iter_mut()
                .filter(|d| d.is_finite())
                .for_each(|d| *d = d.clamp(range[0], range[1]));
        }
        let x0 = self.origin_mm[0];
        let y0 = self.origin_mm[1];
        let cv = crate::base::plot::Heatmap {
            values: &v,
            nx: w,
            ny: h,
            x_range: (x0, x0 + (w * f) as f64 * self.pitch_mm),
            y_range: (y0, y0 + (h * f) as f64 * self.pitch_mm),
            title: title.to_string(),
            x_label: "x (mm)".into(),
            y_label: "y (mm)".into(),
            value_label: "µm".into(),
            scale: crate::base::plot::Scale::Linear,
            value_max: None,
            value_min: None,
            plot_px: 640,
            rgb: None,
        }
        .render();
        (cv, range)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A V-groove design: the ball reaches the flanks but not the bottom of the V; the unreachable band has
    /// the width of the ball's contact points on the two flanks.
    #[test]
    fn v_groove_bottom_is_unreachable_and_flanks_are_not() {
        let (pd, n) = (0.01, 400);
        let slope: f64 = 0.5;
        let mut design = Heightfield::flat(n, n, pd, true, 0.0);
        for j in 0..n {
            for i in 0..n {
                let x = (i as f64 + 0.5) * pd - 2.0;
                design.z_mm[j * n + i] = slope * x.abs() - 1.0;
            }
        }
        let tool = Shape::Ball { diameter_mm: 1.0 };
        let win_open = opening(&design.z_mm, n, n, pd, true, &tool);
        // contact of a ball of radius r on a flank of slope s sits at |x| = r s / sqrt(1 + s²) from the axis
        let half = 0.5 * slope / (1.0 + slope * slope).sqrt();
        for i in 0..n {
            let x = (i as f64 + 0.5) * pd - 2.0;
            let gap = win_open[200 * n + i] - design.z_mm[200 * n + i];
            if x.abs() < half - 2.0 * pd {
                assert!(gap > REACH_TOLERANCE_UM * 1e-3, "x {x}: gap {gap}");
            } else if x.abs() > half + 2.0 * pd && x.abs() < 1.5 {
                assert!(gap.abs() < 1e-4, "x {x}: gap {gap}");
            }
        }
    }
}
