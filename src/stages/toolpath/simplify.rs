//! Dropping collinear points from a cutter-location polyline within a stated tolerance, one-sided.
//!
//! A point may be dropped only if the chord that replaces it passes **above** it (never below: below would
//! gouge) by no more than `tol`. The tool then leaves at most `tol` of extra material where points were
//! dropped and never cuts deeper than the CL surface. Runs of exactly collinear points (the planar facets)
//! collapse to their end points whatever the tolerance.

use crate::gcode::moves::P3;

/// Greedy one-sided simplification: the kept points, first and last always kept. O(n): while a chord from
/// the last kept point `a` is extended, the interval of chord slopes that keeps every point passed within
/// `[0, tol]` below the chord is narrowed point by point; the chord to `b` is allowed while its slope lies in
/// the interval and `b` is on the same straight line in x, y.
pub fn simplify(points: &[P3], tol: f64) -> Vec<P3> {
    kept(points, tol).into_iter().map(|k| points[k]).collect()
}

/// The indices of the points [`simplify`] keeps, increasing, first and last included.
pub fn kept(points: &[P3], tol: f64) -> Vec<usize> {
    if points.len() <= 2 {
        return (0..points.len()).collect();
    }
    let mut out = vec![0];
    let mut a = 0;
    while a < points.len() - 1 {
        let pa = points[a];
        let d = [points[a + 1][0] - pa[0], points[a + 1][1] - pa[1]];
        let len = d[0].hypot(d[1]);
        let mut b = a + 1;
        if len > 0.0 {
            let dir = [d[0] / len, d[1] / len];
            let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
            let mut last_u = 0.0;
            while b + 1 < points.len() {
                // the point b would now be passed over: it constrains the chord slope
                let q = points[b];
                let (u, off) = along(pa, dir, q);
                if off > 1e-9 || u <= last_u {
                    break;
                }
                last_u = u;
                lo = lo.max((q[2] - pa[2]) / u - 1e-12 / u);
                hi = hi.min((q[2] + tol - pa[2]) / u + 1e-12 / u);
                let c = points[b + 1];
                let (uc, offc) = along(pa, dir, c);
                if offc > 1e-9 || uc <= u {
                    break;
                }
                let m = (c[2] - pa[2]) / uc;
                if m < lo || m > hi {
                    break;
                }
                b += 1;
            }
        }
        out.push(b);
        a = b;
    }
    out
}

/// Distance of `q` along the line from `a` in direction `dir` (x, y), and its distance off that line.
#[inline]
fn along(a: P3, dir: [f64; 2], q: P3) -> (f64, f64) {
    let (dx, dy) = (q[0] - a[0], q[1] - a[1]);
    (dx * dir[0] + dy * dir[1], (dx * dir[1] - dy * dir[0]).abs())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn collinear_runs_collapse() {
        let pts: Vec<P3> = (0..100)
            .map(|i| [i as f64 * 0.01, 0.0, -0.2 + 0.3 * i as f64 * 0.01])
            .collect();
        assert_eq!(simplify(&pts, 0.0).len(), 2);
    }

    proptest! {
        #[test]
        fn chords_never_go_below_and_stay_within_tol(zs in proptest::collection::vec(-1.0..0.0f64, 3..80), tol in 0.0..0.05f64) {
            let pts: Vec<P3> = zs.iter().enumerate().map(|(i, z)| [i as f64 * 0.01, 0.5, *z]).collect();
            let kept = simplify(&pts, tol);
            prop_assert_eq!(kept[0], pts[0]);
            prop_assert_eq!(*kept.last().unwrap(), *pts.last().unwrap());
            for q in &pts {
                let k = kept.iter().position(|p| p[0] >= q[0] - 1e-12).unwrap();
                let z = if kept[k][0] <= q[0] + 1e-12 { kept[k][2] } else {
                    let (a, b) = (kept[k - 1], kept[k]);
                    a[2] + (q[0] - a[0]) / (b[0] - a[0]) * (b[2] - a[2])
                };
                prop_assert!(z >= q[2] - 1e-9, "gouge at x {}", q[0]);
                prop_assert!(z <= q[2] + tol + 1e-9, "leaves more than tol at x {}", q[0]);
            }
        }
    }
}
