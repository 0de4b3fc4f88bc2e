//! The lowest point of a bit swept along one straight segment, above a point `(x, y)`: the height the
//! segment leaves the stock at, `stock = min(stock, sweep)` (DESIGN.md §5).
//!
//! The tip moves from `A` to `B`, `P(t) = A + t (B − A)`, `t ∈ [0, 1]`. The bit's underside at horizontal
//! distance `ρ` from its axis stands `prof(ρ)` above the tip (the bit continues upward as a cylinder, so a
//! heightfield sees only its underside). Above `(x, y)` the sweep leaves
//!
//! `f(t) = z(t) + prof(ρ(t))`, minimised over the `t` with `ρ(t) ≤ R`,
//!
//! where, with `L = |B − A|_xy`, `t_p` the parameter of the foot of the perpendicular from `(x, y)` to the
//! segment's line and `h` the distance to that line, `ρ(t)² = h² + L² (t − t_p)²`. `ρ` is convex in `t` and
//! `prof` convex and non-decreasing, so `f` is convex: its minimum over an interval is its stationary point
//! clamped to the interval.
//!
//! - **Ball** (radius `r`, `prof = r − sqrt(r² − ρ²)`), the capsule. With `R'² = r² − h²` and `dz = z_B − z_A`,
//!   `f'(t) = 0` at `t* = t_p − dz R' / (L sqrt(L² + dz²))`, where `f(t*) = z(t_p) + r − R' sqrt(L² + dz²) / L`.
//!   Closed form: `f(clamp(t*, 0, 1))`; a clamped `t*` is the lowest point of an end sphere.
//! - **Flat** (radius `R`, `prof = 0`): `f = z(t)` on the interval `|t − t_p| ≤ sqrt(R² − h²) / L`, clipped to
//!   `[0, 1]`; the minimum is its lower end (endpoints ordered so that `dz ≥ 0`). Closed form.
//! - **Bull** (radius `R`, corner radius `rc`, flat of radius `R0 = R − rc`, `prof = rc − sqrt(rc² − (ρ −
//!   R0)²)` beyond `R0`): no practical closed form (the stationary point solves a quartic). `f` is convex,
//!   so Newton's method on `f'`, safeguarded by bisection on its sign, from the stationary point of the
//!   ball of radius `rc` at the distance `h − R0` (near the bull's for a thin flat such as a runout's), with
//!   certified lower bounds (tangents of the convex `f`), stopped when a bound is within
//!   [`BULL_TOLERANCE_MM`] of the best value found; the value returned is the best found, never below the
//!   true minimum and at most that tolerance above it. Before solving, a closed-form lower bound (the ball of
//!   radius `rc` at the distance to the flat's bounding square, `Sweep::bull_floor`) and the ends of the
//!   interval are worked out for a block of cells at once, with vector instructions; only cells the bound
//!   says the sweep may lower, with the minimum inside the interval, are solved.
//!
//! A segment whose horizontal length is below [`VERTICAL_MM`] is taken as vertical (a plunge or a retract):
//! the lowest point is then the lower end's.

use crate::cut::tool::Shape;
use crate::gcode::moves::P3;
use serde::{Deserialize, Serialize};

/// What a linear segment of the swept path comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentKind {
    /// `G0`.
    Rapid,
    /// `G1`.
    Feed,
    /// A chord of a `G2`/`G3` arc.
    Arc,
}

/// One straight piece of the tool-tip path, mm, in work coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Start of the tip.
    pub from: P3,
    /// End of the tip.
    pub to: P3,
    /// Where it comes from.
    pub kind: SegmentKind,
    /// The program line, from 1.
    pub line: u32,
    /// The tool in the spindle (the number of the last `T… M6`; 0 before any).
    #[serde(default)]
    pub tool: u32,
    /// The programmed feed, mm/min (0 for a rapid).
    #[serde(default)]
    pub feed_mm_min: f64,
}

/// Horizontal length below which a segment counts as vertical, mm (0.1 nm).
pub const VERTICAL_MM: f64 = 1e-7;

/// Largest amount by which a bull-nose sweep height may exceed the exact minimum, mm (1 pm).
pub const BULL_TOLERANCE_MM: f64 = 1e-9;

/// What the bull's floor (`Sweep::bull_floor`, the row's lower bound of its sweep) stands below its closed
/// form, mm (20 pm): the rounding of its square roots near the rim, so that a cell it skips is one the exact
/// minimum would not lower by more than a hair.
pub const BULL_FLOOR_SLACK_MM: f64 = 2e-8;

/// A cell counts as lowered by a segment (for the report of rapids that cut) only when by more than this, mm
/// (1 nm): a retract from the bottom of a cut re-sweeps the end sphere the cut already left, up to rounding.
pub const LOWERED_MM: f64 = 1e-6;

/// A segment cuts (for the figures of time spent feeding through air) only when it lowers some cell by more
/// than this when it runs, mm (1 µm): above the simplification tolerance, so that retracing a surface along
/// slightly different chords is not cutting.
pub const CUT_MM: f64 = 1e-3;

/// One segment prepared for sweeping: endpoints ordered so that `dz ≥ 0`, constants of the closed forms.
#[derive(Clone, Copy, Debug)]
pub struct Sweep {
    bit: Shape,
    ax: f64,
    ay: f64,
    az: f64,
    dx: f64,
    dy: f64,
    dz: f64,
    /// `1 / L²` (0 for a vertical segment).
    inv_l2: f64,
    /// `1 / L` (0 for a vertical segment).
    inv_l: f64,
    /// Ball: `dz / (L sqrt(L² + dz²))`.
    c1: f64,
    r: f64,
    r2: f64,
}

impl Sweep {
    /// Prepare the sweep of `bit` with its tip from `a` to `b` (mm).
    pub fn new(bit: Shape, a: P3, b: P3) -> Self {
        // The swept solid does not depend on the direction of travel: order so that z rises.
        let (a, b) = if b[2] < a[2] { (b, a) } else { (a, b) };
        let (mut dx, mut dy, dz) = (b[0] - a[0], b[1] - a[1], b[2] - a[2]);
        let mut l2 = dx * dx + dy * dy;
        if l2 < VERTICAL_MM * VERTICAL_MM {
            (dx, dy, l2) = (0.0, 0.0, 0.0);
        }
        let (inv_l2, inv_l, c1) = if l2 > 0.0 {
            let l = l2.sqrt();
            (1.0 / l2, 1.0 / l, dz / (l * (l2 + dz * dz).sqrt()))
        } else {
            (0.0, 0.0, 0.0)
        };
        let r = bit.radius_mm();
        Self {
            bit,
            ax: a[0],
            ay: a[1],
            az: a[2],
            dx,
            dy,
            dz,
            inv_l2,
            inv_l,
            c1,
            r,
            r2: r * r,
        }
    }

    /// The lowest tip height along the segment, mm: no point of the sweep is lower.
    pub fn z_min(&self) -> f64 {
        self.az
    }

    /// A lower bound of the sweep over the cells of row `y` from `x_lo` to `x_hi`: the lowest tip plus the
    /// profile at their distance from the segment's bounding box (`+∞` beyond the radius).
    #[inline(always)]
    pub fn floor(&self, x_lo: f64, x_hi: f64, y: f64) -> f64 {
        let (bx, by) = (self.ax + self.dx, self.ay + self.dy);
        let dy = (self.ay.min(by) - y).max(y - self.ay.max(by)).max(0.0);
        let dx = (self.ax.min(bx) - x_hi).max(x_lo - self.ax.max(bx)).max(0.0);
        // (from the squared distance: a ball's profile then takes one square root, not two)
        let d2 = dx * dx + dy * dy;
        if d2 > self.r2 {
            f64::INFINITY
        } else {
            self.az + self.bit.profile_sq(d2)
        }
    }

    /// `(x_min, y_min, x_max, y_max)` of the swept footprint, mm.
    pub fn footprint(&self) -> [f64; 4] {
        let (bx, by) = (self.ax + self.dx, self.ay + self.dy);
        [
            self.ax.min(bx) - self.r,
            self.ay.min(by) - self.r,
            self.ax.max(bx) + self.r,
            self.ay.max(by) + self.r,
        ]
    }

    /// The x interval of the footprint (points within the bit's radius of the segment) on the line at `y`,
    /// widened by a hair so that points on its rim are inside; None when the line misses it.
    #[inline(always)]
    pub fn row_span(&self, y: f64) -> Option<(f64, f64)> {
        let (r, r2) = (self.r, self.r2);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        // the end discs
        for (cx, cy) in [(self.ax, self.ay), (self.ax + self.dx, self.ay + self.dy)] {
            let d2 = r2 - (y - cy) * (y - cy);
            if d2 >= 0.0 {
                let w = d2.sqrt();
                lo = lo.min(cx - w);
                hi = hi.max(cx + w);
            }
        }
        // the band: |cross| ≤ r L and 0 ≤ projection ≤ L², both linear in x
        if self.inv_l2 > 0.0 {
            let ey = y - self.ay;
            let l = 1.0 / self.inv_l;
            // cross(x) = (x − ax) dy − ey dx ∈ [−rL, rL]; proj(x) = (x − ax) dx + ey dy ∈ [0, L²]
            let mut a = f64::NEG_INFINITY;
            let mut b = f64::INFINITY;
            for (k, c, clo, chi) in [
                (self.dy, -ey * self.dx, -r * l, r * l),
                (self.dx, ey * self.dy, 0.0, l * l),
            ] {
                if k.abs() < 1e-300 {
                    if c < clo || c > chi {
                        a = f64::INFINITY;
                    }
                } else {
                    let (u, v) = ((clo - c) / k, (chi - c) / k);
                    a = a.max(u.min(v));
                    b = b.min(u.max(v));
                }
            }
            if a <= b {
                lo = lo.min(self.ax + a);
                hi = hi.max(self.ax + b);
            }
        }
        (lo <= hi).then(|| {
            let e = 1e-9 * (1.0 + r);
            (lo - e, hi + e)
        })
    }

    /// The height the sweep leaves above `(x, y)`, mm; `+∞` when the bit does not pass over it (the tests'
    /// pointwise form of [`Sweep::row`]).
    #[cfg(test)]
    pub fn lowest(&self, x: f64, y: f64) -> f64 {
        let mut z = [f64::INFINITY];
        self.row(y, x, 0.0, &mut z);
        z[0]
    }

    /// `row[i] = min(row[i], sweep at (x0 + i·pitch, y))` for every cell of a row; returns the number of cells
    /// the footprint covers and the most any cell was lowered, mm (0 when none was).
    #[inline(always)]
    pub fn row(&self, y: f64, x0: f64, pitch: f64, row: &mut [f64]) -> (usize, f64) {
        assert!(i32::try_from(row.len()).is_ok(), "a row of {} cells", row.len());
        let ey = y - self.ay;
        let ex0 = x0 - self.ax;
        let (dx, dy, dz, az, r, r2) = (self.dx, self.dy, self.dz, self.az, self.r, self.r2);
        let (inv_l2, inv_l, c1) = (self.inv_l2, self.inv_l, self.c1);
        let (ey2, eyd) = (ey * ey, ey * dy);
        // cells on the rim count as covered, within the drop-cutter's relative 1e-12 (`cut::dropcutter`):
        // the two must agree there, or a tip the drop-cutter holds up by a rim cell never lowers that cell
        let rim = r2 * 1e-12;
        let mut hits = 0;
        let mut drop = 0.0f64;
        match self.bit {
            // (selects and non-short-circuit `&`, with the column counted in `i32` and the reductions kept
            // per lane, so that the loops compile to vector instructions)
            Shape::Ball { .. } => {
                (hits, drop) = lanes(row, |i| {
                    let ex = ex0 + f64::from(i) * pitch;
                    let ed = ex * dx + eyd;
                    let tp = ed * inv_l2;
                    let rp2 = r2 - (ex * ex + ey2 - ed * tp);
                    let rp = rp2.max(0.0).sqrt();
                    let t = (tp - rp * c1).clamp(0.0, 1.0);
                    let (fx, fy) = (ex - t * dx, ey - t * dy);
                    let s = r2 - (fx * fx + fy * fy);
                    let z = az + t * dz + r - s.max(0.0).sqrt();
                    let inside = (rp2 >= -rim) & (s >= -rim);
                    (z, inside)
                });
            }
            Shape::Flat { .. } => {
                (hits, drop) = lanes(row, |i| {
                    let ex = ex0 + f64::from(i) * pitch;
                    let ed = ex * dx + eyd;
                    let tp = ed * inv_l2;
                    let rp2 = r2 - (ex * ex + ey2 - ed * tp);
                    let w = rp2.max(0.0).sqrt() * inv_l;
                    let t = (tp - w).max(0.0);
                    let inside = (rp2 >= -rim) & (t <= (tp + w).min(1.0));
                    (az + t * dz, inside)
                });
            }
            Shape::Bull { .. } => {
                // two passes over each block of cells: without branches, the interval of `t` over which the
                // bit covers the cell, the floor of the sweep there and `f` at the interval's ends; then the
                // solve, only where the floor is below the cell (most of a dense raster's neighbouring passes
                // it cannot lower) and the minimum is not at an end
                let l2 = self.l2();
                let mut base = 0i32;
                for chunk in row.chunks_mut(LANES) {
                    let n = chunk.len();
                    let mut cells = [f64::INFINITY; LANES];
                    cells[..n].copy_from_slice(chunk);
                    let mut at = [[0.0f64; 2]; LANES];
                    let mut ends = [[0.0f64; 6]; LANES];
                    let mut need = [false; LANES];
                    for l in 0..LANES {
                        let ex = ex0 + f64::from(base + l as i32) * pitch;
                        let ed = ex * dx + eyd;
                        let tp = ed * inv_l2;
                        let h2 = (ex * ex + ey2 - ed * tp).max(0.0);
                        let rp2 = r2 - h2;
                        let w = rp2.max(0.0).sqrt() * inv_l;
                        let (lo, hi) = ((tp - w).max(0.0), (tp + w).min(1.0));
                        let inside = (rp2 >= 0.0) & (lo <= hi) & (l < n);
                        hits += inside as usize;
                        need[l] = inside & (self.bull_floor(h2, tp, lo, hi) < cells[l]);
                        let ((fa, da, _), (fb, db, _)) =
                            (self.bull_eval(h2, tp, l2, lo), self.bull_eval(h2, tp, l2, hi));
                        at[l] = [h2, tp];
                        ends[l] = [lo, fa, da, hi, fb, db];
                    }
                    for (l, cell) in chunk.iter_mut().enumerate() {
                        if need[l] {
                            let [h2, tp] = at[l];
                            let z = match Sweep::bull_at_ends(ends[l]) {
                                Ok(z) => z,
                                Err(e) => self.bull_interior(h2, tp, e),
                            };
                            drop = drop.max(*cell - z);
                            if z < *cell {
                                *cell = z;
                            }
                        }
                    }
                    base += LANES as i32;
                }
            }
        }
        (hits, drop)
    }

    /// A lower bound of the bull's sweep (the minimum of `f`, [`Sweep::bull_interior`]) in closed form, less
    /// [`BULL_FLOOR_SLACK_MM`].
    ///
    /// The bull is the ball of radius `rc` widened by the flat's disc of radius `R0`, so with `v = (h, L u)`
    /// the point's offset from the tip in the segment's frame, `ρ − R0 = |v| − R0` is its distance to that
    /// disc, at least its distance to the square `[−R0, R0]²` around it:
    /// `ρ − R0 ≥ √(h'² + (L|u| − R0)₊²)` with `h' = (h − R0)₊`. As `prof` is non-decreasing,
    /// `f(t) ≥ z(t) + prof_rc(√(h'² + (L|u| − R0)₊²))`: for `|u| ≤ w0 = R0/L` a constant profile over a
    /// rising `z` (least at the band's low end), for `u ≤ −w0` the ball of radius `rc` at distance `h'` from
    /// a segment whose foot is `t_p − w0` (its closed form, [`Sweep::row`]'s ball arm), and for `u ≥ w0` no
    /// lower than the band's high end (`z` rises and the ball's stationary point is behind it). Where the
    /// ball's closed form lands outside its radius the weaker `z(lo) + prof_rc(h')` stands in. Near the
    /// rim the square roots of small differences round by a few picometres (5 pm at most over the default
    /// job), hence the slack.
    #[inline(always)]
    fn bull_floor(&self, h2: f64, tp: f64, lo: f64, hi: f64) -> f64 {
        let (r0, rc) = self.bull_radii();
        let (az, dz) = (self.az, self.dz);
        let hp = (h2.sqrt() - r0).max(0.0);
        let rp = (rc * rc - hp * hp).max(0.0).sqrt();
        // `ρ(t) ≥ h` and `prof` is non-decreasing: `f ≥ z(lo) + prof(h)`, all a vertical segment has
        let weak = az + lo * dz + rc - rp;
        // (selects throughout, so that the row's first pass compiles to vector instructions; what a select
        // discards may be NaN)
        let l = 1.0 / self.inv_l;
        let w0 = r0 * self.inv_l;
        // the ball of radius `rc` at distance `h'` from a segment whose foot is `foot`, with its tip at `t`, where
        // `apply` (`+∞` elsewhere); `weak` where that lands outside its radius
        let ball = |apply: bool, t: f64, foot: f64| {
            let e = l * (t - foot);
            let q = rp * rp - e * e;
            match (apply, q >= 0.0) {
                (true, true) => az + t * dz + rc - q.sqrt(),
                (true, false) => weak,
                (false, _) => f64::INFINITY,
            }
        };
        // the band |u| ≤ w0 and beyond it
        let tm = (tp - w0).max(lo);
        let band = if tm <= hi {
            az + tm * dz + rc - rp
        } else {
            f64::INFINITY
        };
        // the ball behind the band
        let tl = (tp - w0).min(hi);
        let behind = ball(lo <= tl, (tp - w0 - rp * self.c1).max(lo).min(tl), tp - w0);
        // the band wholly before the interval: the ball ahead of it, from `lo`
        let before = ball(tp + w0 < lo, lo, tp + w0);
        let sloped = band.min(behind).min(before).max(weak);
        (if self.inv_l > 0.0 { sloped } else { weak }) - BULL_FLOOR_SLACK_MM
    }

    /// `(f, f', f'')` of the bull's `f(t) = z(t) + prof(ρ(t))` at `t`, `l2 = L²`.
    ///
    /// With `s = ρ − R0 > 0` and `q = rc² − s²`: `prof' = s / √q`, `prof'' = rc² / q^{3/2}`;
    /// `ρ' = L²(t − t_p)/ρ`, `ρ'' = L² h² / ρ³`; `f' = dz + prof'·ρ'`, `f'' = prof''·ρ'² + prof'·ρ''` (both 0 on
    /// the flat, `s ≤ 0`).
    #[inline(always)]
    fn bull_eval(&self, h2: f64, tp: f64, l2: f64, t: f64) -> (f64, f64, f64) {
        let (r0, rc) = self.bull_radii();
        let rc2 = rc * rc;
        let u = t - tp;
        let rho = (h2 + l2 * u * u).sqrt();
        let z = self.az + t * self.dz;
        let s = rho - r0;
        let q = (rc2 - s * s).max(0.0);
        let sq = q.sqrt();
        // at the rim (`q = 0`, `s > 0`) both are +∞, as the profile stands vertical there
        let (p0, p1) = (rc - sq, s / sq);
        let p2 = rc2 / (q * sq);
        let on = rho > 0.0;
        let (r1, r2) = (
            if on { l2 * u / rho } else { 0.0 },
            if on { l2 * h2 / (rho * rho * rho) } else { 0.0 },
        );
        // 0·∞ at a tangent point of the rim: the slope there is that of z alone
        let d1 = self.dz + if r1 == 0.0 { 0.0 } else { p1 * r1 };
        let d2 = p2 * r1 * r1 + if r2 == 0.0 { 0.0 } else { p1 * r2 };
        let flat = s <= 0.0;
        (
            if flat { z } else { z + p0 },
            if flat { self.dz } else { d1 },
            if flat { 0.0 } else { d2 },
        )
    }

    /// `(R0, rc)`: the bull's flat radius and corner radius, mm.
    #[inline(always)]
    fn bull_radii(&self) -> (f64, f64) {
        let Shape::Bull {
            corner_radius_mm: rc, ..
        } = self.bit
        else {
            unreachable!("a bull's sweep with a {:?}", self.bit)
        };
        (self.r - rc, rc)
    }

    /// `L²` (0 for a vertical segment).
    #[inline(always)]
    fn l2(&self) -> f64 {
        if self.inv_l2 > 0.0 {
            1.0 / self.inv_l2
        } else {
            0.0
        }
    }

    /// The minimum of the convex `f` over `[lo, hi]` when it lies at an end (`f' ≥ 0` at `lo`, or `≤ 0` at
    /// `hi`), from the ends' `e = [lo, f(lo), f'(lo), hi, f(hi), f'(hi)]`; otherwise `e`, a bracket of it.
    #[inline(always)]
    fn bull_at_ends(e: [f64; 6]) -> Result<f64, [f64; 6]> {
        let [lo, fa, da, hi, fb, db] = e;
        if hi - lo <= 0.0 || da >= 0.0 {
            return Ok(fa);
        }
        if db <= 0.0 {
            return Ok(fb);
        }
        Err(e)
    }

    /// The first Newton point: the stationary point of the ball of radius `rc` at the distance `h − R0` (the
    /// bull is that ball widened by `R0`, so its minimum lies near there), or the bracket's middle.
    #[inline(always)]
    fn bull_start(&self, h2: f64, tp: f64, a: f64, b: f64) -> f64 {
        let (r0, rc) = self.bull_radii();
        let hs = (h2.sqrt() - r0).max(0.0);
        let t = tp - (rc * rc - hs * hs).max(0.0).sqrt() * self.c1;
        if t > a && t < b {
            t
        } else {
            0.5 * (a + b)
        }
    }

    /// Minimum of the convex `f(t) = z(t) + prof(ρ(t))` inside the bracket `e` of [`Sweep::bull_at_ends`]: Newton's
    /// method on `f'` from [`Sweep::bull_start`], safeguarded by the bracket `[a, b]` on the sign of `f'` (a
    /// step that leaves it, or does not halve it twice running, is a bisection). Certified by two lower bounds
    /// of the convex `f` ([`bull_certified`]); the value returned is the best found, never below the true
    /// minimum and at most [`BULL_TOLERANCE_MM`] above it.
    fn bull_interior(&self, h2: f64, tp: f64, e: [f64; 6]) -> f64 {
        let l2 = self.l2();
        let [mut a, mut fa, mut da, mut b, mut fb, mut db] = e;
        let mut best = fa.min(fb);
        let mut t = self.bull_start(h2, tp, a, b);
        let mut slow = 0;
        for _ in 0..200 {
            let (ft, dt, d2t) = self.bull_eval(h2, tp, l2, t);
            best = best.min(ft);
            if dt == 0.0 {
                break;
            }
            let w = b - a;
            if dt < 0.0 {
                (a, fa, da) = (t, ft, dt);
            } else {
                (b, fb, db) = (t, ft, dt);
            }
            if bull_certified(best, [a, fa, da, b, fb, db], ft, dt) {
                break;
            }
            slow = if b - a > 0.5 * w { slow + 1 } else { 0 };
            let newton = t - dt / d2t;
            t = if slow < 2 && newton > a && newton < b {
                newton
            } else {
                slow = 0;
                0.5 * (a + b)
            };
        }
        best
    }
}

/// Whether `best` (the least `f` found) is within [`BULL_TOLERANCE_MM`] of the minimum of the convex `f`, by two
/// lower bounds: the tangent at the last point `(t, f, f')`, `f − |f'|·(b − a)`, and the meeting point of the
/// tangents at the bracket's ends `e = [a, f(a), f'(a), b, f(b), f'(b)]`; or the bracket is a point.
#[inline(always)]
fn bull_certified(best: f64, e: [f64; 6], ft: f64, dt: f64) -> bool {
    let [a, fa, da, b, fb, db] = e;
    let at_t = ft - dt.abs() * (b - a);
    let ends = if da.is_finite() & db.is_finite() & (db > da) {
        let x = (fb - fa + da * a - db * b) / (da - db);
        fa + da * (x - a)
    } else {
        f64::NEG_INFINITY
    };
    (best - at_t.max(ends) <= BULL_TOLERANCE_MM) | (b - a <= 1e-15)
}

/// Cells [`lanes`] takes at a time: a vector register's worth or two, so that the per-lane reductions
/// stay in registers.
const LANES: usize = 8;

/// `row[i] = min(row[i], z)` where `(z, inside) = cell(i)` and the cell is inside the footprint; returns
/// the cells inside and the most any was lowered, mm (0 when none was). The count and the largest drop are
/// kept per lane and reduced at the end (a running maximum carried from cell to cell would keep the loop
/// scalar); the result is the same, the maximum being exact.
#[inline(always)]
fn lanes(row: &mut [f64], cell: impl Fn(i32) -> (f64, bool)) -> (usize, f64) {
    let mut hits = [0usize; LANES];
    let mut drop = [0.0f64; LANES];
    let mut chunks = row.chunks_exact_mut(LANES);
    let mut base = 0i32;
    for chunk in &mut chunks {
        for l in 0..LANES {
            let c = chunk[l];
            let (z, inside) = cell(base + l as i32);
            hits[l] += inside as usize;
            let d = if inside { c - z } else { 0.0 };
            drop[l] = if d > drop[l] { d } else { drop[l] };
            chunk[l] = if inside & (z < c) { z } else { c };
        }
        base += LANES as i32;
    }
    for (l, c) in chunks.into_remainder().iter_mut().enumerate() {
        let (z, inside) = cell(base + l as i32);
        hits[l] += inside as usize;
        let d = if inside { *c - z } else { 0.0 };
        drop[l] = if d > drop[l] { d } else { drop[l] };
        *c = if inside & (z < *c) { z } else { *c };
    }
    (
        hits.iter().sum(),
        drop.iter().fold(0.0, |m, &d| if d > m { d } else { m }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The slow reference: the bit placed at `n + 1` evenly spaced positions along the segment.
    fn sampled(bit: Shape, a: P3, b: P3, x: f64, y: f64, n: usize) -> f64 {
        let r = bit.radius_mm();
        let mut best = f64::INFINITY;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let p = [
                a[0] + t * (b[0] - a[0]),
                a[1] + t * (b[1] - a[1]),
                a[2] + t * (b[2] - a[2]),
            ];
            let rho = ((x - p[0]).powi(2) + (y - p[1]).powi(2)).sqrt();
            if rho <= r {
                best = best.min(p[2] + bit.profile(rho));
            }
        }
        best
    }

    /// `(h², t_p, lo, hi)` of a bull's sweep above `(x, y)` as [`Sweep::row`] works them out; None when
    /// the bit does not pass over the point.
    fn bull_interval(s: &Sweep, x: f64, y: f64) -> Option<(f64, f64, f64, f64)> {
        let (ex, ey) = (x - s.ax, y - s.ay);
        let ed = ex * s.dx + ey * s.dy;
        let tp = ed * s.inv_l2;
        let h2 = (ex * ex + ey * ey - ed * tp).max(0.0);
        let rp2 = s.r2 - h2;
        if rp2 < 0.0 {
            return None;
        }
        let w = rp2.sqrt() * s.inv_l;
        let (lo, hi) = ((tp - w).max(0.0), (tp + w).min(1.0));
        (lo <= hi).then_some((h2, tp, lo, hi))
    }

    /// Along a level segment the bull's minimum over the band `|u| ≤ R0/L` is its profile at the distance
    /// `h`, `z + prof(h)` (the tip passes straight by): the floor is exact there, not merely below.
    #[test]
    fn bull_floor_is_exact_beside_a_level_segment() {
        let bit = Shape::Bull {
            diameter_mm: 0.515,
            corner_radius_mm: 0.25,
        };
        let s = Sweep::new(bit, [0.0, 0.0, -0.3], [1.0, 0.0, -0.3]);
        for h in [0.0, 0.005, 0.0075, 0.1, 0.2, 0.25] {
            let (h2, tp, lo, hi) = bull_interval(&s, 0.5, h).expect("covered");
            let want = -0.3 + bit.profile(h);
            let floor = s.bull_floor(h2, tp, lo, hi);
            assert!(
                (floor - want).abs() <= 2.0 * BULL_FLOOR_SLACK_MM,
                "h {h}: floor {floor}, z + prof(h) {want}"
            );
            assert!((s.lowest(0.5, h) - want).abs() <= BULL_TOLERANCE_MM);
        }
    }

    fn bits() -> impl Strategy<Value = Shape> {
        prop_oneof![
            (0.05..2.0f64).prop_map(|r| Shape::Ball { diameter_mm: 2.0 * r }),
            (0.05..2.0f64).prop_map(|r| Shape::Flat { diameter_mm: 2.0 * r }),
            (0.1..2.0f64, 0.05..1.0f64).prop_map(|(r, f)| Shape::Bull {
                diameter_mm: 2.0 * r,
                corner_radius_mm: r * f
            }),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        /// The closed forms are never above dense sampling (they are the exact minimum) and within the
        /// sampling's own resolution of it.
        #[test]
        fn closed_form_matches_dense_sampling(
            bit in bits(),
            a in prop::array::uniform3(-1.0..1.0f64),
            b in prop::array::uniform3(-1.0..1.0f64),
            q in prop::array::uniform2(-2.0..2.0f64),
            vertical in prop::bool::weighted(0.1),
        ) {
            let b = if vertical { [a[0], a[1], b[2]] } else { b };
            let s = Sweep::new(bit, a, b);
            let exact = s.lowest(q[0], q[1]);
            let n = 20_000;
            let dense = sampled(bit, a, b, q[0], q[1], n);
            if dense.is_finite() {
                // exact for ball and flat; the bull's bisection stops within its stated tolerance
                let slack = if matches!(bit, Shape::Bull { .. }) { BULL_TOLERANCE_MM } else { 1e-12 };
                prop_assert!(exact <= dense + slack, "{bit:?} {a:?} {b:?} {q:?}: {exact} above sampled {dense}");
                // between samples the bit moves by |AB|/n; the sweep height changes by at most that times
                // the steepest slope met, bounded here by sampling twice as finely
                let finer = sampled(bit, a, b, q[0], q[1], 2 * n);
                prop_assert!(exact <= finer + slack);
                prop_assert!(dense - exact <= 2.0 * (dense - finer).max(0.0) + 2e-4,
                    "{bit:?}: exact {exact} dense {dense} finer {finer}");
            }
            // the footprint interval contains every covered point of the row
            if exact.is_finite() {
                let (lo, hi) = s.row_span(q[1]).expect("covered point outside the row span");
                prop_assert!(lo <= q[0] && q[0] <= hi);
            }
        }

        /// The bull's closed-form floor is never above the minimum, which dense sampling bounds from above
        /// (an independent truth: the bit placed along the segment), so a cell it lets the row skip is one
        /// the sweep would not lower; and a cell a hair above the minimum is still lowered to it.
        #[test]
        fn bull_floor_is_below_the_sampled_minimum(
            r in 0.1..2.0f64,
            flat in 0.0..0.3f64,
            a in prop::array::uniform3(-1.0..1.0f64),
            b in prop::array::uniform3(-1.0..1.0f64),
            q in prop::array::uniform2(-2.0..2.0f64),
        ) {
            let bit = Shape::Bull { diameter_mm: 2.0 * r, corner_radius_mm: r * (1.0 - flat) };
            let s = Sweep::new(bit, a, b);
            if let Some((h2, tp, lo, hi)) = bull_interval(&s, q[0], q[1]) {
                let floor = s.bull_floor(h2, tp, lo, hi);
                let dense = sampled(bit, a, b, q[0], q[1], 20_000);
                prop_assert!(floor <= dense, "{bit:?} {a:?} {b:?} {q:?}: floor {floor} above sampled {dense}");
                let exact = s.lowest(q[0], q[1]);
                prop_assert!(floor <= exact, "floor {floor} above the solved minimum {exact}");
                for above in [1e-7, 1e-4] {
                    let mut cell = [exact + above];
                    s.row(q[1], q[0], 0.0, &mut cell);
                    prop_assert!(
                        cell[0] <= exact + BULL_TOLERANCE_MM,
                        "a cell {above} mm above the minimum was skipped"
                    );
                }
            }
        }

        /// A point the row span excludes is not covered.
        #[test]
        fn row_span_is_tight(
            bit in bits(),
            a in prop::array::uniform3(-1.0..1.0f64),
            b in prop::array::uniform3(-1.0..1.0f64),
            y in -2.0..2.0f64,
        ) {
            let s = Sweep::new(bit, a, b);
            if let Some((lo, hi)) = s.row_span(y) {
                prop_assert!(s.lowest(lo - 1e-6, y).is_infinite() && s.lowest(hi + 1e-6, y).is_infinite());
                prop_assert!(s.lowest(0.5 * (lo + hi), y).is_finite());
            } else {
                for x in [-3.0, -1.0, 0.0, 1.0, 3.0] {
                    prop_assert!(s.lowest(x, y).is_infinite());
                }
            }
        }
    }

    #[test]
    fn ball_closed_form_on_the_capsule_axis() {
        // Horizontal segment: the cross-section is the circle z = z0 + r − sqrt(r² − d²).
        let s = Sweep::new(Shape::Ball { diameter_mm: 1.0 }, [0.0, 0.0, -0.2], [2.0, 0.0, -0.2]);
        for d in [0.0, 0.1, 0.3, 0.49] {
            let z = s.lowest(1.0, d);
            assert!((z - (-0.2 + 0.5 - (0.25f64 - d * d).sqrt())).abs() < 1e-15, "{d}: {z}");
        }
        // Sloped segment seen in the middle: the capsule's cross-section perpendicular to the axis is a
        // circle, so the lowest point is r·sqrt(1 + m²) − r below the axis line's tip height (m the slope).
        let m: f64 = 0.4;
        let s = Sweep::new(Shape::Ball { diameter_mm: 1.0 }, [0.0, 0.0, 0.0], [2.0, 0.0, 2.0 * m]);
        let z = s.lowest(1.0, 0.0);
        let expect = m - (0.5 * (1.0 + m * m).sqrt() - 0.5);
        assert!((z - expect).abs() < 1e-14, "{z} vs {expect}");
    }

    #[test]
    fn flat_leaves_a_flat_floor_and_bull_sits_between() {
        let (a, b) = ([0.0, 0.0, -0.1], [1.0, 0.3, -0.1]);
        let flat = Sweep::new(Shape::Flat { diameter_mm: 1.0 }, a, b);
        let bull = Sweep::new(
            Shape::Bull {
                diameter_mm: 1.0,
                corner_radius_mm: 0.2,
            },
            a,
            b,
        );
        let ball = Sweep::new(Shape::Ball { diameter_mm: 1.0 }, a, b);
        for (x, y) in [(0.5, 0.15), (0.2, 0.4), (0.9, -0.1), (-0.3, 0.1)] {
            let (f, u, l) = (flat.lowest(x, y), bull.lowest(x, y), ball.lowest(x, y));
            assert_eq!(f, -0.1);
            assert!(f <= u && u <= l + 1e-15, "{f} {u} {l}");
        }
    }
}
