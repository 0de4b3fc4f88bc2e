//! Arc fitting of a finishing pass: runs of short blocks that lie on one circle in the pass's vertical plane
//! become one `G2`/`G3` in `G18` (passes along X) or `G19` (along Y), one-sided within the stated tolerance.
//!
//! Where the ball rolls over a convex facet edge its tip traces a circle of the ball's radius, and the
//! one-sided simplification ([`super::simplify`]) keeps every sample there (any chord passes below the
//! curve): those 5 µm blocks are the program's densest. Starting at a kept vertex `A`, the arc to a later
//! kept vertex `B` is the circle through `A` and `B` whose sagitta `σ` is the least that passes over every
//! raw CL point between them (`σ = max_k σ_k`, `σ_k` the sagitta of the circle through `A`, `B` and point
//! `k`: raising `σ` raises every interior point of an arc under a half turn). The arc is then quantised as
//! it will be written — `A` and `B` rounded like any coordinate (X/Y nearest, Z up), the centre an offset
//! from `A` on the resolution `q` — and accepted only if the arc a controller draws from those numbers (the
//! radius `|A − C|`, less the difference to `|B − C|`) stays within `[z_k, z_k + tol + q]` at every raw
//! point and above the straight blocks' chords midway between raw points, both ends lie on the same side of the centre's height (no vertical tangent inside: the arc is a
//! function of the pass coordinate) and it replaces at least [`MIN_BLOCKS`] blocks. The least sagitta's arc
//! touches a raw point, so a written centre whose radii to `A` and `B` differ at all passes below it there;
//! the arc is tried again with `σ` raised by `q/8`, `q/4` and `q/2` ([`SIGMA_RAISES`]) before it is given up
//! (without them a dome of a curved facet, or any gentle convex run, was written as one 5 µm line per CL point). Greedy: from `A`, ends
//! `MIN_BLOCKS·2^k` vertices on are probed and the farthest passing end is refined by bisection; else the
//! next line.

use super::simplify;
use crate::gcode::emit::quantize_point;
use crate::gcode::moves::{Arc, Plane, P3};

/// The fewest line blocks an arc must replace.
pub const MIN_BLOCKS: usize = 3;

/// The largest radius fitted, mm: GRBL's single-precision arithmetic places a centre 1 m away to about
/// 0.06 µm (2⁻²⁴ of it), well inside the machines' 1.25 µm step; a curved facet's dome is often 20–200 mm
/// (was 100 mm, which left the flattest domes as 5 µm lines).
pub const MAX_RADIUS_MM: f64 = 1000.0;

/// The most raw points one arc may span (bounds the O(n²) extension).
const MAX_SPAN: usize = 4000;

/// One block of a fitted pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Piece {
    /// A straight feed to the point.
    Line(P3),
    /// An arc (its feed is the caller's).
    Arc(Arc),
}

/// The pass plane of `raw` when it runs along X (`G18`) or Y (`G19`) at one height of the other axis.
pub fn pass_plane(raw: &[P3]) -> Option<Plane> {
    let (first, last) = (raw.first()?, raw.last()?);
    if raw.iter().all(|p| p[1] == first[1]) && first[0] != last[0] {
        Some(Plane::Zx)
    } else if raw.iter().all(|p| p[0] == first[0]) && first[1] != last[1] {
        Some(Plane::Yz)
    } else {
        None
    }
}

/// The blocks of the pass `raw` (CL points in cutting order, the first is where the tool is): lines between
/// the one-sided simplification's vertices, arcs where they replace at least [`MIN_BLOCKS`] of them (see
/// the module documentation), in `plane` when the pass lies in one; `q` is the machine's resolution.
pub fn fit(raw: &[P3], tol: f64, q: f64, plane: Option<Plane>) -> Vec<Piece> {
    let kept = simplify::kept(raw, tol);
    let Some(plane) = plane else {
        return kept.iter().skip(1).map(|&k| Piece::Line(raw[k])).collect();
    };
    let mut out = Vec::with_capacity(kept.len());
    let mut s = 0;
    while s + 1 < kept.len() {
        // probe ends MIN_BLOCKS·2^k blocks on (a short arc is mostly the rounding of its ends, a longer one
        // fits the curve), then bisect between the farthest that passes and the next that fails
        let last = (s..kept.len())
            .take_while(|&t| kept[t] - kept[s] <= MAX_SPAN)
            .last()
            .unwrap_or(s);
        let try_at = |t: usize| arc(raw, kept[s], kept[t], tol, q, plane).map(|a| (t, a));
        let mut best = None;
        let mut fail = None;
        let mut step = MIN_BLOCKS;
        while s + step <= last {
            match try_at(s + step) {
                Some(b) => best = Some(b),
                None if best.is_some() => {
                    fail = Some(s + step);
                    break;
                }
                None => {}
            }
            step *= 2;
        }
        if best.is_some() && fail.is_none() && last > best.map_or(0, |b| b.0) {
            match try_at(last) {
                Some(b) => best = Some(b),
                None => fail = Some(last),
            }
        }
        if let (Some((mut lo, _)), Some(mut hi)) = (best, fail) {
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                match try_at(mid) {
                    Some(b) => {
                        lo = mid;
                        best = Some(b);
                    }
                    None => hi = mid,
                }
            }
        }
        match best {
            Some((t, a)) => {
                out.push(Piece::Arc(a));
                s = t;
            }
            None => {
                out.push(Piece::Line(raw[kept[s + 1]]));
                s += 1;
            }
        }
    }
    out
}

/// The chord of a candidate arc in the pass plane: its ends as written (`a3`, `b3`, on the resolution) and
/// as `(t, z)` with `t` increasing along the pass (`a` at `t = 0`, `b`), its length `l`, unit direction `e`
/// and normal `nrm`; `h` the pass axis's index and `sgn` the pass's direction along it.
#[derive(Clone, Copy)]
struct Chord {
    h: usize,
    sgn: f64,
    a3: P3,
    b3: P3,
    a: [f64; 2],
    b: [f64; 2],
    l: f64,
    e: [f64; 2],
    nrm: [f64; 2],
}

impl Chord {
    /// The chord from `from` to `to` quantised on `q`, if it advances along the pass.
    fn new(from: P3, to: P3, q: f64, plane: Plane) -> Option<Self> {
        let h = if plane == Plane::Zx { 0 } else { 1 };
        let (a3, b3) = (quantize_point(from, q), quantize_point(to, q));
        let sgn = if b3[h] > a3[h] { 1.0 } else { -1.0 };
        let (a, b) = ([0.0, a3[2]], [sgn * (b3[h] - a3[h]), b3[2]]);
        let d = [b[0] - a[0], b[1] - a[1]];
        let l = d[0].hypot(d[1]);
        if l <= 0.0 || d[0] <= 0.0 {
            return None;
        }
        let e = [d[0] / l, d[1] / l];
        Some(Self {
            h,
            sgn,
            a3,
            b3,
            a,
            b,
            l,
            e,
            nrm: [-e[1], e[0]],
        })
    }
}

/// The quantised arc from `raw[ia]` to `raw[ib]` over the raw points between, if one passes.
fn arc(raw: &[P3], ia: usize, ib: usize, tol: f64, q: f64, plane: Plane) -> Option<Arc> {
    let chord = Chord::new(raw[ia], raw[ib], q, plane)?;
    let Chord {
        h,
        sgn,
        a3,
        a,
        l,
        e,
        nrm,
        ..
    } = chord;
    // least sagitta passing over every interior point
    let mut sig = f64::NEG_INFINITY;
    for p in &raw[ia + 1..ib] {
        let v = [sgn * (p[h] - a3[h]), p[2] - a[1]];
        let (xi, eta) = (v[0] * e[0] + v[1] * e[1], v[0] * nrm[0] + v[1] * nrm[1]);
        let s = if eta.abs() < 1e-15 {
            0.0
        } else {
            let cy = (xi * xi - xi * l + eta * eta) / (2.0 * eta);
            let r = (l * l / 4.0 + cy * cy).sqrt();
            if eta > 0.0 {
                cy + r
            } else {
                cy - r
            }
        };
        sig = sig.max(s);
        // σ only grows: past a half turn no arc passes, however the rest of the points lie
        if sig >= l / 2.0 {
            return None;
        }
    }
    if !sig.is_finite() || sig.abs() >= l / 2.0 {
        return None;
    }
    // The least sagitta's arc touches a raw point, so a written centre whose radii to A and B differ by any
    // `dr` would pass below it: the arc is also tried raised by fractions of the resolution (room the band
    // `[z_k, z_k + tol + q]` keeps above the points).
    SIGMA_RAISES
        .iter()
        .find_map(|&raise| quantised_arc(raw, (ia, ib), (tol, q), plane, &chord, sig + raise * q))
}

/// Raises of the least sagitta tried, in units of the resolution `q`.
const SIGMA_RAISES: [f64; 4] = [0.0, 0.125, 0.25, 0.5];

/// The arc of sagitta `sig` over `chord` (`raw[ia]` to `raw[ib]` quantised) with its centre on
/// the resolution `q`, if the arc a controller draws from those numbers passes over every raw point between
/// within the band `[z_k, z_k + tol + q]`.
fn quantised_arc(
    raw: &[P3],
    (ia, ib): (usize, usize),
    (tol, q): (f64, f64),
    plane: Plane,
    chord: &Chord,
    sig: f64,
) -> Option<Arc> {
    let Chord {
        h,
        sgn,
        a3,
        b3,
        a,
        b,
        l,
        nrm,
        ..
    } = *chord;
    if sig.abs() >= l / 2.0 {
        return None;
    }
    let r = (l * l / 4.0 + sig * sig) / (2.0 * sig.abs());
    if r > MAX_RADIUS_MM || sig.abs() < 1e-9 {
        return None;
    }
    let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
    let off = sig - sig.signum() * r;
    let c = [mid[0] + nrm[0] * off, mid[1] + nrm[1] * off];
    // the centre as written: an offset from A on the resolution; of the four grid points around the exact
    // centre, the first (by how well its radii to A and B agree) whose drawn arc passes
    let (ch, cz) = ((sgn * c[0]) / q, (c[1] - a3[2]) / q);
    let mut cands: Vec<(f64, P3)> = [ch.floor(), ch.ceil()]
        .into_iter()
        .flat_map(|i| [cz.floor(), cz.ceil()].map(|k| (i, k)))
        .map(|(i, k)| {
            let mut c3 = a3;
            c3[h] = a3[h] + i * q;
            c3[2] = a3[2] + k * q;
            let ct = [sgn * i * q, c3[2]];
            let dr = ((b[0] - ct[0]).hypot(b[1] - ct[1]) - (a[0] - ct[0]).hypot(a[1] - ct[1])).abs();
            (dr, c3)
        })
        .collect();
    cands.sort_by(|x, y| x.0.total_cmp(&y.0));
    let passes = |dr: f64, c3: P3| -> bool {
        let ct = [sgn * (c3[h] - a3[h]), c3[2]];
        let ra = (a[0] - ct[0]).hypot(a[1] - ct[1]);
        let cap = a[1] > ct[1];
        if dr > q || cap != (b[1] > ct[1]) || (a[1] - ct[1]).abs() < 1e-12 || (b[1] - ct[1]).abs() < 1e-12 {
            return false;
        }
        let drawn = |t: f64| {
            let w = ra * ra - (t - ct[0]).powi(2);
            (w >= 0.0).then(|| if cap { ct[1] + w.sqrt() } else { ct[1] - w.sqrt() })
        };
        let points_ok = raw[ia + 1..ib]
            .iter()
            .all(|p| drawn(sgn * (p[h] - a3[h])).is_some_and(|z| z - dr >= p[2] - 1e-9 && z <= p[2] + tol + q + 1e-9));
        // between samples, at least as high as the straight blocks would be (a tight cup sags below its
        // chords)
        points_ok
            && raw[ia..=ib].windows(2).all(|w| {
                let (t, z) = (sgn * ((w[0][h] + w[1][h]) / 2.0 - a3[h]), (w[0][2] + w[1][2]) / 2.0);
                drawn(t).is_some_and(|za| za - dr >= z - 1e-9)
            })
    };
    let c3 = cands.into_iter().find_map(|(dr, c3)| passes(dr, c3).then_some(c3))?;
    // counter-clockwise in the plane's (first, second) axes
    let (f, s, _) = plane.axes();
    let cross = (a3[f] - c3[f]) * (b3[s] - c3[s]) - (a3[s] - c3[s]) * (b3[f] - c3[f]);
    Some(Arc::ccw_in_plane(b3, c3, plane, cross > 0.0, 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ball of radius `r` rolling over the ridge between two planes of slope ±`m` (along x, at y = 0.3):
    /// the CL is two lines joined by an arc of radius r.
    fn ridge(n: usize, p: f64, r: f64, m: f64, reverse: bool) -> Vec<P3> {
        let x0 = n as f64 * p / 2.0;
        let mut pts: Vec<P3> = (0..n)
            .map(|i| {
                let x = (i as f64 + 0.5) * p - x0;
                // contact with the ridge line itself while |x| < r·sinθ, with a plane beyond
                let s = r * m / (1.0 + m * m).sqrt();
                let z = if x.abs() < s {
                    (r * r - x * x).sqrt() - r
                } else {
                    -m * x.abs() + r * (1.0 + m * m).sqrt() - r
                };
                [x + x0, 0.3, z - 0.2]
            })
            .collect();
        if reverse {
            pts.reverse();
        }
        pts
    }

    /// The z a controller draws at `x` for the pieces from `start`, every end rounded as the emitter writes
    /// it (lines by interpolation, arcs on their circle from the rounded start's radius).
    fn drawn(start: P3, pieces: &[Piece], x: f64, q: f64) -> f64 {
        let mut at = quantize_point(start, q);
        for pc in pieces {
            let to = quantize_point(
                match pc {
                    Piece::Line(p) => *p,
                    Piece::Arc(a) => a.to,
                },
                q,
            );
            let (lo, hi) = (at[0].min(to[0]), at[0].max(to[0]));
            if x >= lo - 1e-12 && x <= hi + 1e-12 {
                return match pc {
                    Piece::Line(_) => at[2] + (x - at[0]) / (to[0] - at[0]) * (to[2] - at[2]),
                    Piece::Arc(a) => {
                        let r = (at[0] - a.center[0]).hypot(at[2] - a.center[2]);
                        let w = (r * r - (x - a.center[0]).powi(2)).sqrt();
                        if at[2] > a.center[2] {
                            a.center[2] + w
                        } else {
                            a.center[2] - w
                        }
                    }
                };
            }
            at = to;
        }
        panic!("x {x} outside the pass");
    }

    #[test]
    fn a_ridge_becomes_lines_and_one_arc_never_below_the_points() {
        let (p, r, q, tol) = (0.005, 0.25, 0.001, 0.0005);
        for reverse in [false, true] {
            let raw = ridge(400, p, r, 0.6, reverse);
            let pieces = fit(&raw, tol, q, pass_plane(&raw));
            let arcs: Vec<&Arc> = pieces
                .iter()
                .filter_map(|pc| match pc {
                    Piece::Arc(a) => Some(a),
                    _ => None,
                })
                .collect();
            let lines_only = simplify::kept(&raw, tol).len() - 1;
            // on the 1 µm grid the rounded ends keep a short arc from being the ball's circle; the cap still
            // takes well under half the blocks
            assert!(
                !arcs.is_empty() && 2 * pieces.len() < lines_only,
                "{} pieces of {lines_only}",
                pieces.len()
            );
            for a in &arcs {
                assert_eq!(a.plane, Plane::Zx);
                // a cap (centre below) traversed in +x turns clockwise with X right, Z up: counter-clockwise in
                // (Z, X), so G3; a cup the other way
                let cap = a.to[2] > a.center[2];
                assert_eq!(a.cw, reverse == cap, "direction of {a:?}");
            }
            // rounding X to the nearest step moves a point along the slope (the toolpath lifts its CL points by
            // that, `lift_for_rounding`); here the ridge's slope is at most 0.6
            let along = 0.6 * q / 2.0;
            for pt in &raw[1..raw.len() - 1] {
                let z = drawn(raw[0], &pieces, pt[0], q);
                assert!(
                    z >= pt[2] - along - 1e-9,
                    "below the CL at x {}: {} < {}",
                    pt[0],
                    z,
                    pt[2]
                );
                assert!(
                    z <= pt[2] + tol + q + along + 1e-9,
                    "more than tol above at x {}",
                    pt[0]
                );
            }
        }
    }

    /// A curved facet's dome (a parabola of curvature κ, a circle to within `κ³x⁴/8`, well under a
    /// nanometre over its millimetre) on GRBL's 1.25 µm grid: one arc or a few, never a 5 µm line per CL
    /// point, and never below the points. The least sagitta's arc touches a point, so with any radius
    /// mismatch of the rounded centre it failed: this is what the raised sagittas are for.
    #[test]
    fn a_dome_becomes_a_few_arcs_on_a_coarse_grid() {
        let (p, q, tol) = (0.005, 0.00125, 0.000625);
        for (kappa, slope, reverse) in [(0.05, 0.0, false), (0.1, 0.1, true), (0.18, -0.15, false)] {
            let mut raw: Vec<P3> = (0..160)
                .map(|i| {
                    let x = i as f64 * p;
                    [1.0 + x, 0.3, -0.3 + slope * x - 0.5 * kappa * x * x]
                })
                .collect();
            if reverse {
                raw.reverse();
            }
            let pieces = fit(&raw, tol, q, pass_plane(&raw));
            assert!(pieces.len() <= 3, "κ {kappa}: {} pieces", pieces.len());
            let along = slope.abs().max(0.2) * q / 2.0;
            for pt in &raw[1..raw.len() - 1] {
                let z = drawn(raw[0], &pieces, pt[0], q);
                assert!(
                    z >= pt[2] - along - 1e-9,
                    "below the CL at x {}: {z} < {}",
                    pt[0],
                    pt[2]
                );
                assert!(
                    z <= pt[2] + tol + q + along + 1e-9,
                    "more than tol above at x {}",
                    pt[0]
                );
            }
        }
    }

    #[test]
    fn passes_off_the_axes_and_straight_runs_stay_lines() {
        let diag: Vec<P3> = (0..50).map(|i| [i as f64 * 0.01, i as f64 * 0.01, -0.1]).collect();
        assert_eq!(pass_plane(&diag), None);
        let line: Vec<P3> = (0..50)
            .map(|i| [0.2, i as f64 * 0.01, -0.1 - 0.01 * i as f64])
            .collect();
        assert_eq!(pass_plane(&line), Some(Plane::Yz));
        let pieces = fit(&line, 0.0005, 0.001, Some(Plane::Yz));
        assert_eq!(pieces, vec![Piece::Line(line[49])]);
        // a pass with no point inside the area, or one
        assert!(fit(&[], 0.0005, 0.001, None).is_empty() && fit(&line[..1], 0.0005, 0.001, None).is_empty());
        assert!(fit(&line[..1], 0.0005, 0.001, Some(Plane::Yz)).is_empty());
    }
}
