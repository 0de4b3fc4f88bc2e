//! Dropping collinear points from a cutter-location polyline within a stated tolerance, one-sided.
//!
//! A point may be dropped only if the chord that replaces it passes **above** it (never below: below would
//! gouge) by no more than `tol`. The tool then leaves at most `tol` of extra material where points were
//! dropped and never cuts deeper than the CL surface. Runs of exactly collinear points (the planar facets)
//! collapse to their end points whatever the tolerance.

use super::moves::P3;

/// Greedy one-sided simplification: the kept points, first and last always kept.
pub fn simplify(points: &[P3], tol: f64) -> Vec<P3> {
    if points.len() <= 2 {
        return points.to_vec();
    }
    let mut out = vec![points[0]];
    let mut a = 0;
    while a < points.len() - 1 {
        // extend b as far as every intermediate point is under the chord a→b within tol
        let mut b = a + 1;
        while b + 1 < points.len() && chord_ok(points, a, b + 1, tol) {
            b += 1;
        }
        out.push(points[b]);
        a = b;
    }
    out
}

/// True when every point strictly between `a` and `b` lies at most `tol` below the chord and not above it.
fn chord_ok(p: &[P3], a: usize, b: usize, tol: f64) -> bool {
    let (pa, pb) = (p[a], p[b]);
    let d = [pb[0] - pa[0], pb[1] - pa[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    if len2 == 0.0 {
        return false;
    }
    for q in &p[a + 1..b] {
        let t = ((q[0] - pa[0]) * d[0] + (q[1] - pa[1]) * d[1]) / len2;
        // horizontal distance from the chord's line
        let (cx, cy) = (pa[0] + t * d[0], pa[1] + t * d[1]);
        if (q[0] - cx).hypot(q[1] - cy) > 1e-9 || !(0.0..=1.0).contains(&t) {
            return false;
        }
        let z = pa[2] + t * (pb[2] - pa[2]);
        let above = z - q[2]; // chord height above the CL point
        if above < -1e-12 || above > tol {
            return false;
        }
    }
    true
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
