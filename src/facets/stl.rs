//! The exact faceted solid of one tile, as triangles for [`crate::stl`]: every facet's planar top, the vertical walls where
//! neighbouring facet planes do not meet, the four outer sides and a flat bottom.
//!
//! The mesh is closed: wherever several faces meet along a vertical line (a facet corner), every face's
//! side is split at all the heights that occur there, and where two facet planes cross along an edge the
//! crossing point is a vertex of both tops and of the wall. Each planar polygon is triangulated as a fan from
//! its centroid and oriented by its outward normal. Coordinates in mm, z = 0 the stock top.

use super::Arrangement;
use crate::geometry::Vec3;
use crate::stl::Triangle;

const EPS: f64 = 1e-9;

struct Builder {
    tris: Vec<Triangle>,
}

impl Builder {
    /// Fan-triangulate a planar polygon from its centroid, oriented by `outward`.
    fn polygon(&mut self, poly: &[Vec3], outward: Vec3) {
        let mut pts: Vec<Vec3> = Vec::with_capacity(poly.len());
        for p in poly {
            if pts.last().is_none_or(|l: &Vec3| (l - p).norm() > EPS) {
                pts.push(*p);
            }
        }
        while pts.len() > 1 && (pts[0] - pts[pts.len() - 1]).norm() <= EPS {
            pts.pop();
        }
        if pts.len() < 3 {
            return;
        }
        let c = pts.iter().fold(Vec3::zeros(), |a, p| a + p) / pts.len() as f64;
        for k in 0..pts.len() {
            let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
            let n = (a - c).cross(&(b - c));
            if n.norm() < 1e-18 {
                continue;
            }
            self.tris
                .push(if n.dot(&outward) >= 0.0 { [c, a, b] } else { [c, b, a] });
        }
    }
}

/// The closed faceted solid of a tile: `z_mm` facet-centre heights (row-major), `base_mm` the bottom.
pub fn tile_solid(a: &Arrangement, z_mm: &[f64], facet_mm: f64, base_mm: f64) -> Vec<Triangle> {
    let (w, h, f) = (a.w, a.h, facet_mm);
    // height of facet k's plane at (x, y)
    let plane = |k: usize, x: f64, y: f64| -> f64 {
        let (fx, fy) = ((k % w) as f64, (k / w) as f64);
        z_mm[k] + a.p[k] * (x - (fx + 0.5) * f) + a.q[k] * (y - (fy + 0.5) * f)
    };
    // sorted distinct heights at every corner point (cx, cy)
    let mut corner: Vec<Vec<f64>> = vec![vec![]; (w + 1) * (h + 1)];
    for cy in 0..=h {
        for cx in 0..=w {
            let (x, y) = (cx as f64 * f, cy as f64 * f);
            let list = &mut corner[cy * (w + 1) + cx];
            for (dx, dy) in [(0isize, 0isize), (-1, 0), (0, -1), (-1, -1)] {
                let (fx, fy) = (cx as isize + dx, cy as isize + dy);
                if fx >= 0 && fy >= 0 && (fx as usize) < w && (fy as usize) < h {
                    list.push(plane(fy as usize * w + fx as usize, x, y));
                }
            }
            if cx == 0 || cy == 0 || cx == w || cy == h {
                list.push(base_mm);
            }
            list.sort_by(f64::total_cmp);
            list.dedup_by(|p, q| (*p - *q).abs() <= EPS);
        }
    }
    let heights_between = |cx: usize, cy: usize, lo: f64, hi: f64| -> Vec<f64> {
        corner[cy * (w + 1) + cx]
            .iter()
            .copied()
            .filter(|v| *v > lo + EPS && *v < hi - EPS)
            .collect()
    };
    let mut b = Builder { tris: vec![] };
    // A vertical side at corner (cx, cy) spanning [lo, hi], as ascending points at (x, y).
    let side = |cx: usize, cy: usize, lo: f64, hi: f64| -> Vec<f64> {
        let mut v = vec![lo];
        v.extend(heights_between(cx, cy, lo, hi));
        if hi > lo + EPS {
            v.push(hi);
        }
        v
    };

    // crossing parameter t in (0, 1) where two linear profiles a0→a1 and b0→b1 cross, if strictly inside
    let crossing = |a0: f64, a1: f64, b0: f64, b1: f64| -> Option<f64> {
        let (d0, d1) = (a0 - b0, a1 - b1);
        (d0.abs() > EPS && d1.abs() > EPS && (d0 > 0.0) != (d1 > 0.0)).then(|| d0 / (d0 - d1))
    };

    // Interior walls and the crossing points they put on facet edges.
    // crossings_x[k]: crossing y on the right edge of facet k; crossings_y[k]: crossing x on its top edge.
    let mut cross_right: Vec<Option<f64>> = vec![None; w * h];
    let mut cross_top: Vec<Option<f64>> = vec![None; w * h];
    for fy in 0..h {
        for fx in 0..w {
            let k = fy * w + fx;
            // x-edge with the right neighbour
            if fx + 1 < w {
                let r = k + 1;
                let x = (fx + 1) as f64 * f;
                let (y0, y1) = (fy as f64 * f, (fy + 1) as f64 * f);
                let (l0, l1, r0, r1) = (plane(k, x, y0), plane(k, x, y1), plane(r, x, y0), plane(r, x, y1));
                let t = crossing(l0, l1, r0, r1);
                cross_right[k] = t.map(|t| y0 + t * (y1 - y0));
                let mut cuts = vec![(y0, Some(fy)), (y1, Some(fy + 1))];
                if let Some(yc) = cross_right[k] {
                    cuts.insert(1, (yc, None));
                }
                for seg in cuts.windows(2) {
                    let ((ya, ca), (yb, cb)) = (seg[0], seg[1]);
                    let (la, lb, ra, rb) = (plane(k, x, ya), plane(k, x, yb), plane(r, x, ya), plane(r, x, yb));
                    let left_high = (la - ra) + (lb - rb) > 0.0;
                    if (la - ra).abs() <= EPS && (lb - rb).abs() <= EPS {
                        continue;
                    }
                    let sa = match ca {
                        Some(cy) => side(fx + 1, cy, la.min(ra), la.max(ra)),
                        None => vec![la],
                    };
                    let sb = match cb {
                        Some(cy) => side(fx + 1, cy, lb.min(rb), lb.max(rb)),
                        None => vec![lb],
                    };
                    let mut poly: Vec<Vec3> = sa.iter().map(|z| Vec3::new(x, ya, *z)).collect();
                    poly.extend(sb.iter().rev().map(|z| Vec3::new(x, yb, *z)));
                    b.polygon(&poly, Vec3::new(if left_high { 1.0 } else { -1.0 }, 0.0, 0.0));
                }
            }
            // y-edge with the upper neighbour
            if fy + 1 < h {
                let u = k + w;
                let y = (fy + 1) as f64 * f;
                let (x0, x1) = (fx as f64 * f, (fx + 1) as f64 * f);
                let (l0, l1, u0, u1) = (plane(k, x0, y), plane(k, x1, y), plane(u, x0, y), plane(u, x1, y));
                let t = crossing(l0, l1, u0, u1);
                cross_top[k] = t.map(|t| x0 + t * (x1 - x0));
                let mut cuts = vec![(x0, Some(fx)), (x1, Some(fx + 1))];
                if let Some(xc) = cross_top[k] {
                    cuts.insert(1, (xc, None));
                }
                for seg in cuts.windows(2) {
                    let ((xa, ca), (xb, cb)) = (seg[0], seg[1]);
                    let (la, lb, ua, ub) = (plane(k, xa, y), plane(k, xb, y), plane(u, xa, y), plane(u, xb, y));
                    if (la - ua).abs() <= EPS && (lb - ub).abs() <= EPS {
                        continue;
                    }
                    let low_high = (la - ua) + (lb - ub) > 0.0;
                    let sa = match ca {
                        Some(cx) => side(cx, fy + 1, la.min(ua), la.max(ua)),
                        None => vec![la],
                    };
                    let sb = match cb {
                        Some(cx) => side(cx, fy + 1, lb.min(ub), lb.max(ub)),
                        None => vec![lb],
                    };
                    let mut poly: Vec<Vec3> = sa.iter().map(|z| Vec3::new(xa, y, *z)).collect();
                    poly.extend(sb.iter().rev().map(|z| Vec3::new(xb, y, *z)));
                    b.polygon(&poly, Vec3::new(0.0, if low_high { 1.0 } else { -1.0 }, 0.0));
                }
            }
        }
    }

    // Facet tops, with crossing points on their edges.
    for fy in 0..h {
        for fx in 0..w {
            let k = fy * w + fx;
            let (x0, x1, y0, y1) = (fx as f64 * f, (fx + 1) as f64 * f, fy as f64 * f, (fy + 1) as f64 * f);
            let mut pts: Vec<(f64, f64)> = vec![(x0, y0)];
            if fy > 0 {
                if let Some(xc) = cross_top[k - w] {
                    pts.push((xc, y0));
                }
            }
            pts.push((x1, y0));
            if let Some(yc) = cross_right[k] {
                pts.push((x1, yc));
            }
            pts.push((x1, y1));
            if let Some(xc) = cross_top[k] {
                pts.push((xc, y1));
            }
            pts.push((x0, y1));
            if fx > 0 {
                if let Some(yc) = cross_right[k - 1] {
                    pts.push((x0, yc));
                }
            }
            let poly: Vec<Vec3> = pts.iter().map(|(x, y)| Vec3::new(*x, *y, plane(k, *x, *y))).collect();
            b.polygon(&poly, Vec3::z());
        }
    }

    // Outer sides: one polygon per facet edge on the boundary.
    let mut outer =
        |k: usize, (xa, ya): (f64, f64), (xb, yb): (f64, f64), ca: (usize, usize), cb: (usize, usize), n: Vec3| {
            let sa = side(ca.0, ca.1, base_mm, plane(k, xa, ya));
            let sb = side(cb.0, cb.1, base_mm, plane(k, xb, yb));
            let mut poly: Vec<Vec3> = sa.iter().map(|z| Vec3::new(xa, ya, *z)).collect();
            poly.extend(sb.iter().rev().map(|z| Vec3::new(xb, yb, *z)));
            b.polygon(&poly, n);
        };
    let (wf, hf) = (w as f64 * f, h as f64 * f);
    for fy in 0..h {
        let (y0, y1) = (fy as f64 * f, (fy + 1) as f64 * f);
        outer(fy * w, (0.0, y0), (0.0, y1), (0, fy), (0, fy + 1), -Vec3::x());
        outer(fy * w + w - 1, (wf, y0), (wf, y1), (w, fy), (w, fy + 1), Vec3::x());
    }
    for fx in 0..w {
        let (x0, x1) = (fx as f64 * f, (fx + 1) as f64 * f);
        outer(fx, (x0, 0.0), (x1, 0.0), (fx, 0), (fx + 1, 0), -Vec3::y());
        outer((h - 1) * w + fx, (x0, hf), (x1, hf), (fx, h), (fx + 1, h), Vec3::y());
    }
    // Bottom: every boundary corner at the base height.
    let mut ring: Vec<Vec3> = vec![];
    ring.extend((0..=w).map(|cx| Vec3::new(cx as f64 * f, 0.0, base_mm)));
    ring.extend((1..=h).map(|cy| Vec3::new(wf, cy as f64 * f, base_mm)));
    ring.extend((0..w).rev().map(|cx| Vec3::new(cx as f64 * f, hf, base_mm)));
    ring.extend((1..h).rev().map(|cy| Vec3::new(0.0, cy as f64 * f, base_mm)));
    b.polygon(&ring, -Vec3::z());
    b.tris
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stl::{to_binary_stl, volume};
    use rand::{Rng, SeedableRng};
    use std::collections::HashMap;

    type Key = (i64, i64, i64);

    fn random_tile(w: usize, h: usize, seed: u64) -> (Arrangement, Vec<f64>) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let s: Vec<(f64, f64)> = (0..w * h)
            .map(|_| (rng.gen_range(-0.6..0.6), rng.gen_range(-0.6..0.6)))
            .collect();
        let a = Arrangement::new(w, h, &s, 0.0);
        let z: Vec<f64> = (0..w * h).map(|_| rng.gen_range(-0.5..0.0)).collect();
        (a, z)
    }

    #[test]
    fn solid_is_closed_and_has_the_right_volume() {
        for (w, h, seed) in [(1, 1, 1), (2, 3, 2), (5, 4, 3), (8, 8, 4)] {
            let (a, z) = random_tile(w, h, seed);
            let (f, base) = (0.8, -2.0);
            let tris = tile_solid(&a, &z, f, base);
            // Closed and consistently oriented: every directed edge is matched by its reverse.
            let key = |v: &Vec3| {
                (
                    (v.x * 1e7).round() as i64,
                    (v.y * 1e7).round() as i64,
                    (v.z * 1e7).round() as i64,
                )
            };
            let mut edges: HashMap<(Key, Key), i64> = HashMap::new();
            for t in &tris {
                for k in 0..3 {
                    let (a, b) = (key(&t[k]), key(&t[(k + 1) % 3]));
                    *edges.entry((a, b)).or_default() += 1;
                    *edges.entry((b, a)).or_default() -= 1;
                }
            }
            let open = edges.values().filter(|c| **c != 0).count();
            assert_eq!(open, 0, "{w}×{h}: {open} unmatched directed edges");
            // Volume: each facet column contributes area × (centre height − base).
            let expect: f64 = z.iter().map(|zc| f * f * (zc - base)).sum();
            let v = volume(&tris);
            assert!((v - expect).abs() < 1e-9 * expect, "{w}×{h}: volume {v} vs {expect}");
        }
    }

    /// The exact bytes (and the f64 vertices) of fixed tiles, hashed: construction changes that alter the
    /// output in any bit show up here.
    #[test]
    fn tile_solid_output_is_unchanged() {
        use md5::{Digest, Md5};
        let mut md5 = Md5::new();
        for (w, h, seed) in [(1, 1, 1), (2, 3, 2), (5, 4, 3), (8, 8, 4), (3, 7, 11)] {
            let (a, z) = random_tile(w, h, seed);
            let tris = tile_solid(&a, &z, 0.8, -2.0);
            md5.update(to_binary_stl(&tris, "golden"));
            for t in &tris {
                for v in t {
                    for c in [v.x, v.y, v.z] {
                        md5.update(c.to_bits().to_le_bytes());
                    }
                }
            }
        }
        let got: String = md5.finalize().iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(got, "1cdea4e36495b1831583c0ab37ab71a1");
    }
}
