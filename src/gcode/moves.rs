//! The machine-independent form of a program: a list of moves in work coordinates (mm, z = 0 the stock top),
//! which the checker, the time estimator and the G-code emitter all read.

use serde::{Deserialize, Serialize};

/// A point in work coordinates, mm.
pub type P3 = [f64; 3];

/// One step of a program.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Move {
    /// `G0` to a point.
    Rapid(P3),
    /// `G1` to a point at a feed, mm/min.
    Feed(P3, f64),
    /// Spindle on clockwise (`M3`) at rev/min.
    SpindleOn(f64),
    /// Spindle off (`M5`).
    SpindleOff,
    /// `G4` dwell, s.
    Dwell(f64),
    /// A comment line.
    Comment(&'static str),
    /// A tool change to the tool numbered `number` (a `kind` bit of `diameter_mm`), written per dialect by
    /// `crate::gcode::emit`: LinuxCNC `G53 G0 Z`, `T M6`, `G43 H`; GRBL a program of its own per tool
    /// (`crate::stages::toolpath::files`; in the joined text, an `M0` manual change). The move list
    /// around it already holds the `M5` and the retract before it, and the spindle start after it.
    ToolChange {
        /// Tool number in the machine's table (the `T`/`H` word).
        number: u32,
        /// Diameter, mm (for the operator's message).
        diameter_mm: f64,
        /// `ball`, `flat` or `bull` (for the operator's message).
        kind: &'static str,
    },
    /// Coolant on (`M7` mist, `M8` flood) or off (`M9`).
    Coolant(Coolant),
    /// `G2`/`G3` at a feed (mm/min): a circular arc in `plane` from the tool's position to `to` about
    /// `center` (whose off-plane coordinate is ignored), `cw` when clockwise as the standard has it
    /// ([`Arc::ccw_in_plane`]), less than half a turn. Both points lie on the machine's resolution, so the
    /// emitter writes them unrounded.
    Arc(Arc),
}

/// The plane of an arc: its two in-plane axes, in the order G-code names them (`G17` X→Y, `G18` Z→X,
/// `G19` Y→Z).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Plane {
    /// `G17`.
    Xy,
    /// `G18`.
    Zx,
    /// `G19`.
    Yz,
}

impl Plane {
    /// The in-plane axes `(first, second)` and the axis normal to the plane.
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Plane::Xy => (0, 1, 2),
            Plane::Zx => (2, 0, 1),
            Plane::Yz => (1, 2, 0),
        }
    }

    /// The plane a modal `G17`/`G18`/`G19` (as 17, 18, 19) selects; anything else is the default XY.
    pub fn from_g(g: u8) -> Plane {
        match g {
            18 => Plane::Zx,
            19 => Plane::Yz,
            _ => Plane::Xy,
        }
    }

    /// The G word selecting it.
    pub fn g(self) -> u8 {
        match self {
            Plane::Xy => 17,
            Plane::Zx => 18,
            Plane::Yz => 19,
        }
    }
}

/// A `G2`/`G3` arc (see [`Move::Arc`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Arc {
    /// End point, mm.
    pub to: P3,
    /// Centre, mm.
    pub center: P3,
    /// Plane.
    pub plane: Plane,
    /// `G2` (clockwise seen from the positive end of the plane's normal axis) rather than `G3`.
    pub cw: bool,
    /// Feed, mm/min.
    pub feed_mm_min: f64,
}

impl Arc {
    /// The arc from `from` to `to` about `center` in `plane`, turning counter-clockwise in the plane's
    /// (first, second) axes when `ccw`: `G3` is counter-clockwise in those axes for all three planes (for
    /// `G18` that is (Z, X), which is clockwise with X drawn right and Z up).
    pub fn ccw_in_plane(to: P3, center: P3, plane: Plane, ccw: bool, feed_mm_min: f64) -> Arc {
        Arc {
            to,
            center,
            plane,
            cw: !ccw,
            feed_mm_min,
        }
    }

    /// The centre of a radius-form arc (`G2`/`G3` with `R`) from `from` to `to` in `plane`, placed as GRBL
    /// 1.1's `gc_execute_line` places it: on the perpendicular bisector of the in-plane chord `(x, y)` of
    /// length `d`, at `h = √(r² − d²/4)` from its midpoint, i.e. the start plus
    /// `½(x − y·s, y + x·s)` with `s = ∓√(4r² − d²)/d` — right of the chord for `G2` (`cw`), left for `G3`:
    /// the short way round, at most half a turn; a negative `r` puts it on the other side, the long way. The
    /// centre's normal coordinate is the start's (a helix climbs along it). `None` when `4r² − d² < 0` (the
    /// chord is longer than the diameter: GRBL's `error:34`) or the chord has no length in the plane (GRBL
    /// refuses an end equal to the start with `error:33`, and would divide by zero for a helix straight
    /// along the normal).
    #[must_use]
    pub fn center_from_radius(from: P3, to: P3, plane: Plane, r_mm: f64, cw: bool) -> Option<P3> {
        let (a, b, _) = plane.axes();
        let (x, y) = (to[a] - from[a], to[b] - from[b]);
        let d = x.hypot(y);
        let h4 = 4.0 * r_mm * r_mm - x * x - y * y;
        if !(h4 >= 0.0 && d > 0.0) {
            return None;
        }
        let mut s = -h4.sqrt() / d;
        if !cw {
            s = -s;
        }
        if r_mm < 0.0 {
            s = -s;
        }
        let mut c = from;
        c[a] = from[a] + 0.5 * (x - y * s);
        c[b] = from[b] + 0.5 * (y + x * s);
        Some(c)
    }

    /// The start angle and the signed angular travel (rad, negative clockwise in the plane's axes) from
    /// `from`, as GRBL's `mc_arc` turns it: `atan2` of the radius vectors' cross and dot products, moved by a
    /// full turn when it points the wrong way or lies within [`ARC_ANGULAR_TRAVEL_EPSILON`] of zero — so an
    /// arc whose end is its start, to rounding, is a full circle.
    #[must_use]
    pub fn sweep(&self, from: P3) -> (f64, f64) {
        let (a, b, _) = self.plane.axes();
        let (u0, v0) = (from[a] - self.center[a], from[b] - self.center[b]);
        let (u1, v1) = (self.to[a] - self.center[a], self.to[b] - self.center[b]);
        let mut travel = (u0 * v1 - v0 * u1).atan2(u0 * u1 + v0 * v1);
        if self.cw {
            if travel >= -ARC_ANGULAR_TRAVEL_EPSILON {
                travel -= std::f64::consts::TAU;
            }
        } else if travel <= ARC_ANGULAR_TRAVEL_EPSILON {
            travel += std::f64::consts::TAU;
        }
        (v0.atan2(u0), travel)
    }

    /// The radius at `from`, mm (the one a controller draws the arc with).
    #[must_use]
    pub fn radius(&self, from: P3) -> f64 {
        let (a, b, _) = self.plane.axes();
        (from[a] - self.center[a]).hypot(from[b] - self.center[b])
    }

    /// The helical length from `from`, mm: `√((r·θ)² + Δn²)`.
    #[must_use]
    pub fn length_mm(&self, from: P3) -> f64 {
        let n = self.plane.axes().2;
        (self.radius(from) * self.sweep(from).1).hypot(self.to[n] - from[n])
    }

    /// The point a fraction `t` of the angular travel from `from` (the normal coordinate moving linearly);
    /// exactly `to` at `t = 1`.
    #[must_use]
    pub fn point_at(&self, from: P3, t: f64) -> P3 {
        if t >= 1.0 {
            return self.to;
        }
        let (a, b, n) = self.plane.axes();
        let (t0, travel) = self.sweep(from);
        let r = self.radius(from);
        let ang = t0 + travel * t;
        let mut p = [0.0; 3];
        p[a] = self.center[a] + r * ang.cos();
        p[b] = self.center[b] + r * ang.sin();
        p[n] = from[n] + (self.to[n] - from[n]) * t;
        p
    }

    /// Where `p` lies along the arc from `from`: the fraction of the angular travel at `p`'s angle and the
    /// arc's point there (`None` outside the travel). The caller judges the distance from `p` to it.
    #[must_use]
    pub fn project(&self, from: P3, p: P3) -> Option<(f64, P3)> {
        let (a, b, _) = self.plane.axes();
        let (t0, travel) = self.sweep(from);
        let ang = (p[b] - self.center[b]).atan2(p[a] - self.center[a]);
        // the angle from the start in the direction of travel, in [0, 2π)
        let mut d = (ang - t0).rem_euclid(std::f64::consts::TAU);
        if travel < 0.0 {
            d = (std::f64::consts::TAU - d).rem_euclid(std::f64::consts::TAU);
        }
        let t = d / travel.abs();
        (t <= 1.0).then(|| (t, self.point_at(from, t)))
    }

    /// How many chords GRBL's `mc_arc` runs the arc from `from` with, for its arc tolerance `tol_mm` (`$12`):
    /// `⌊|θ·r/2| / √(tol·(2r − tol))⌋`, 0 meaning one straight move to the end (GRBL counts in 16 bits, so
    /// at most 65535).
    #[must_use]
    pub fn grbl_chords(&self, from: P3, tol_mm: f64) -> usize {
        let r = self.radius(from);
        let per = (tol_mm * (2.0 * r - tol_mm)).sqrt();
        if per > 0.0 {
            ((0.5 * self.sweep(from).1 * r).abs() / per)
                .floor()
                .min(f64::from(u16::MAX)) as usize
        } else {
            0
        }
    }

    /// Points along the arc from `from`, chords at most `tol_mm` from it, ending exactly at `to`. The radius
    /// is that of `from` (as a controller draws it); the helical coordinate (normal to the plane) moves
    /// linearly.
    pub fn points(&self, from: P3, tol_mm: f64) -> Vec<P3> {
        let r = self.radius(from);
        let (t0, travel) = self.sweep(from);
        // chord of angle φ misses the arc by r(1 − cos(φ/2))
        let step = if r > tol_mm && tol_mm > 0.0 {
            2.0 * (1.0 - tol_mm / r).acos()
        } else {
            std::f64::consts::FRAC_PI_4
        };
        let k = (travel.abs() / step.max(1e-6)).ceil().clamp(1.0, 1e5) as usize;
        let (a, b, n) = self.plane.axes();
        let mut out = Vec::with_capacity(k);
        for i in 1..k {
            let t = t0 + travel * i as f64 / k as f64;
            let mut p = [0.0; 3];
            p[a] = self.center[a] + r * t.cos();
            p[b] = self.center[b] + r * t.sin();
            p[n] = from[n] + (self.to[n] - from[n]) * i as f64 / k as f64;
            out.push(p);
        }
        out.push(self.to);
        out
    }
}

/// GRBL's `ARC_ANGULAR_TRAVEL_EPSILON` (rad): an arc turning less than this is taken as a full circle.
pub const ARC_ANGULAR_TRAVEL_EPSILON: f64 = 5e-7;

/// Chord tolerance at which [`expand_arcs`] replaces arcs, mm (0.1 µm).
pub const CHORD_TOL_MM: f64 = 1e-4;

/// The moves with every arc replaced by feed moves along its chords ([`CHORD_TOL_MM`]): what the checks,
/// lengths and extents read.
pub fn expand_arcs(moves: &[Move], start: P3) -> std::borrow::Cow<'_, [Move]> {
    if !moves.iter().any(|m| matches!(m, Move::Arc(_))) {
        return std::borrow::Cow::Borrowed(moves);
    }
    std::borrow::Cow::Owned(chords(moves, start).into_iter().map(|(_, m)| m).collect())
}

/// The moves with every arc replaced by feed moves along its chords ([`CHORD_TOL_MM`]), each tagged with the
/// index of the move it came from (an arc's chords share theirs: one block).
pub fn chords(moves: &[Move], start: P3) -> Vec<(usize, Move)> {
    let mut out = Vec::with_capacity(moves.len() * 2);
    let mut at = start;
    for (k, m) in moves.iter().enumerate() {
        match *m {
            Move::Arc(arc) => {
                out.extend(
                    arc.points(at, CHORD_TOL_MM)
                        .into_iter()
                        .map(|p| (k, Move::Feed(p, arc.feed_mm_min))),
                );
                at = arc.to;
            }
            Move::Rapid(p) | Move::Feed(p, _) => {
                out.push((k, *m));
                at = p;
            }
            _ => out.push((k, *m)),
        }
    }
    out
}

/// Coolant commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Coolant {
    /// `M9`.
    Off,
    /// `M7`.
    Mist,
    /// `M8`.
    Flood,
}

/// Path length split by kind, mm.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Lengths {
    /// Cutting (G1) length.
    pub feed_mm: f64,
    /// Rapid (G0) length.
    pub rapid_mm: f64,
}

/// Lengths of a move list starting from `start`.
pub fn lengths(moves: &[Move], start: P3) -> Lengths {
    let mut at = start;
    let mut l = Lengths::default();
    for m in expand_arcs(moves, start).iter() {
        match *m {
            Move::Rapid(p) => {
                l.rapid_mm += dist(at, p);
                at = p;
            }
            Move::Feed(p, _) => {
                l.feed_mm += dist(at, p);
                at = p;
            }
            _ => {}
        }
    }
    l
}

/// Euclidean distance.
#[inline]
pub fn dist(a: P3, b: P3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Bounding box `(min, max)` of all motion end points (and `start`), arcs by their chords' ends.
pub fn bounds(moves: &[Move], start: P3) -> (P3, P3) {
    let mut lo = start;
    let mut hi = start;
    for m in expand_arcs(moves, start).iter() {
        if let Move::Rapid(p) | Move::Feed(p, _) = m {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

    fn quarter(cw: bool) -> Arc {
        Arc {
            to: [0.0, 1.0, 1.0],
            center: [0.0; 3],
            plane: Plane::Xy,
            cw,
            feed_mm_min: 100.0,
        }
    }

    #[test]
    fn sweep_length_and_projection_follow_the_circle() {
        let from = [1.0, 0.0, 0.0];
        let (t0, ccw) = quarter(false).sweep(from);
        assert!(t0.abs() < 1e-15 && (ccw - FRAC_PI_2).abs() < 1e-12);
        let (_, cw) = quarter(true).sweep(from);
        assert!((cw + 3.0 * FRAC_PI_2).abs() < 1e-12, "the long way round: {cw}");
        // a helix: √((r·θ)² + Δz²)
        assert!((quarter(false).length_mm(from) - FRAC_PI_2.hypot(1.0)).abs() < 1e-12);
        // the point at 45° is halfway along the counter-clockwise quarter, and Z has risen halfway
        let p = [FRAC_PI_4.cos(), FRAC_PI_4.sin(), 0.3];
        let (t, q) = quarter(false).project(from, p).unwrap();
        assert!((t - 0.5).abs() < 1e-12 && (q[2] - 0.5).abs() < 1e-12, "{t} {q:?}");
        // clockwise the arc runs through the other three quarters: 45° is not on it, 225° is
        assert!(quarter(true).project(from, p).is_none());
        let (t, _) = quarter(true).project(from, [-p[0], -p[1], 0.0]).unwrap();
        assert!((t - (3.0 * PI / 4.0) / (3.0 * FRAC_PI_2)).abs() < 1e-12, "{t}");
        // an arc ending where it starts is a full turn, as GRBL draws it
        let full = Arc {
            to: from,
            ..quarter(false)
        };
        assert!((full.sweep(from).1 - TAU).abs() < 1e-12);
        assert!(full.point_at(from, 0.5)[0] + 1.0 < 1e-12);
    }

    /// The radius form against circles whose centres are known: each centre lies at `|r|` from both ends,
    /// on the side the direction and sign of `r` call for (the sweep is then at most, or at least, half a
    /// turn), in every plane; chords longer than the diameter have none.
    #[test]
    fn radius_form_centres_lie_on_the_side_its_direction_and_sign_call_for() {
        // the unit circle about (0, 0) in each plane, from angle 0 to 90°: short way G3 with R1, G2 with R-1
        for plane in [Plane::Xy, Plane::Zx, Plane::Yz] {
            let (a, b, n) = plane.axes();
            let mut from = [0.0; 3];
            from[a] = 1.0;
            let mut to = [0.0; 3];
            to[b] = 1.0;
            to[n] = 0.7;
            let c = Arc::center_from_radius(from, to, plane, 1.0, false).unwrap();
            assert!(
                c[a].abs() < 1e-15 && c[b].abs() < 1e-15 && c[n] == 0.0,
                "{plane:?} {c:?}"
            );
            let arc = Arc::ccw_in_plane(to, c, plane, true, 1.0);
            assert!((arc.sweep(from).1 - FRAC_PI_2).abs() < 1e-12);
            // the same centre, the long way clockwise: three quarters of a turn
            let c = Arc::center_from_radius(from, to, plane, -1.0, true).unwrap();
            assert!(c[a].abs() < 1e-15 && c[b].abs() < 1e-15, "{plane:?} {c:?}");
            let arc = Arc::ccw_in_plane(to, c, plane, false, 1.0);
            assert!((arc.sweep(from).1 + 3.0 * FRAC_PI_2).abs() < 1e-12);
            // G2 the short way and G3 the long way have the centre at (1, 1), across the chord
            for (r, cw) in [(1.0, true), (-1.0, false)] {
                let c = Arc::center_from_radius(from, to, plane, r, cw).unwrap();
                assert!(
                    (c[a] - 1.0).abs() < 1e-15 && (c[b] - 1.0).abs() < 1e-15,
                    "{plane:?} {c:?}"
                );
                let arc = Arc {
                    to,
                    center: c,
                    plane,
                    cw,
                    feed_mm_min: 1.0,
                };
                let want = if r > 0.0 { FRAC_PI_2 } else { 3.0 * FRAC_PI_2 };
                assert!((arc.sweep(from).1.abs() - want).abs() < 1e-12, "{plane:?} {r} {cw}");
            }
        }
        // a half turn: the centre is the chord's midpoint whichever the sign
        let (from, to) = ([0.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
        for r in [1.0, -1.0] {
            let c = Arc::center_from_radius(from, to, Plane::Xy, r, true).unwrap();
            assert!((c[0] - 1.0).abs() < 1e-15 && c[1].abs() < 1e-15);
        }
        // a 3-4-5 chord: d = 5, r = 2.5 + ε has its centre near the midpoint; r < d/2 has none
        assert!(Arc::center_from_radius(from, [3.0, 4.0, 0.0], Plane::Xy, 2.4999, false).is_none());
        assert!(Arc::center_from_radius(from, [0.0, 0.0, 1.0], Plane::Xy, 1.0, false).is_none());
        assert!(Arc::center_from_radius(from, to, Plane::Xy, f64::NAN, false).is_none());
    }
}
