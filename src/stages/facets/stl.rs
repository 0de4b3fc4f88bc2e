//! The exact faceted solid of one tile, as triangles for [`crate::base::stl`]: every facet's planar top, the vertical walls where
//! neighbouring facet planes do not meet, the four outer sides and a flat bottom.
//!
//! The mesh is closed: wherever several faces meet along a vertical line (a facet corner), every face's
//! side is split at all the heights that occur there, and where two facet planes cross along an edge the
//! crossing point is a vertex of both tops and of the wall. Each planar polygon is triangulated as a fan from
//! its centroid and oriented by its outward normal. Coordinates in mm, z = 0 the stock top.

use super::Arrangement;
use crate::base::geometry::Vec3;
use crate::base::stl::Triangle;

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
    let tile = Tile::new(a, z_mm, facet_mm, base_mm);
    let mut b = Builder { tris: vec![] };
    let crossings = tile.interior_walls(&mut b);
    tile.tops(&mut b, &crossings);
    tile.outer_sides(&mut b);
    tile.bottom(&mut b);
    b.tris
}

/// Which way a wall between two facets faces: [`Axis::X`] walls stand on a line `x = const` between a
/// facet and its right neighbour, [`Axis::Y`] walls on `y = const` between a facet and the one above.
#[derive(Clone, Copy)]
enum Axis {
    X,
    Y,
}

impl Axis {
    /// `(x, y)` of a point given by its coordinate `across` the wall's line (the line's own position) and
    /// `along` it; the same for corner indices.
    fn xy<T>(self, across: T, along: T) -> (T, T) {
        match self {
            Axis::X => (across, along),
            Axis::Y => (along, across),
        }
    }
}

/// The crossing points that walls put on facet edges.
struct Crossings {
    /// `right[k]`: the crossing y on the right edge of facet k.
    right: Vec<Option<f64>>,
    /// `top[k]`: the crossing x on the top edge of facet k.
    top: Vec<Option<f64>>,
}

/// A tile's facet planes and, at every corner point, the heights that occur there.
struct Tile<'a> {
    a: &'a Arrangement,
    z_mm: &'a [f64],
    f: f64,
    base_mm: f64,
    /// Sorted distinct heights at every corner point `(cx, cy)`, row-major over `(w + 1) × (h + 1)`.
    corner: Vec<Vec<f64>>,
}

impl<'a> Tile<'a> {
    fn new(a: &'a Arrangement, z_mm: &'a [f64], f: f64, base_mm: f64) -> Self {
        let mut tile = Self {
            a,
            z_mm,
            f,
            base_mm,
            corner: vec![],
        };
        let (w, h) = (a.w, a.h);
        let mut corner: Vec<Vec<f64>> = vec![vec![]; (w + 1) * (h + 1)];
        for cy in 0..=h {
            for cx in 0..=w {
                let (x, y) = (cx as f64 * f, cy as f64 * f);
                let list = &mut corner[cy * (w + 1) + cx];
                for (dx, dy) in [(0isize, 0isize), (-1, 0), (0, -1), (-1, -1)] {
                    let (fx, fy) = (cx as isize + dx, cy as isize + dy);
                    if fx >= 0 && fy >= 0 && (fx as usize) < w && (fy as usize) < h {
                        list.push(tile.plane(fy as usize * w + fx as usize, x, y));
                    }
                }
                if cx == 0 || cy == 0 || cx == w || cy == h {
                    list.push(base_mm);
                }
                list.sort_by(f64::total_cmp);
                list.dedup_by(|p, q| (*p - *q).abs() <= EPS);
            }
        }
        tile.corner = corner;
        tile
    }

    /// Height of facet k's plane at (x, y).
    fn plane(&self, k: usize, x: f64, y: f64) -> f64 {
        let (w, f) = (self.a.w, self.f);
        let (fx, fy) = ((k % w) as f64, (k / w) as f64);
        self.z_mm[k] + self.a.p[k] * (x - (fx + 0.5) * f) + self.a.q[k] * (y - (fy + 0.5) * f)
    }

    /// A vertical side at corner (cx, cy) spanning [lo, hi], as the ascending heights of its points: `lo`,
    /// every corner height strictly between, and `hi` unless it coincides with `lo`.
    fn side(&self, cx: usize, cy: usize, lo: f64, hi: f64) -> Vec<f64> {
        let mut v = vec![lo];
        v.extend(
            self.corner[cy * (self.a.w + 1) + cx]
                .iter()
                .copied()
                .filter(|v| *v > lo + EPS && *v < hi - EPS),
        );
        if hi > lo + EPS {
            v.push(hi);
        }
        v
    }

    /// Interior walls, facet by facet (its right wall, then its top wall), and the crossing points they put
    /// on facet edges.
    fn interior_walls(&self, b: &mut Builder) -> Crossings {
        let (w, h) = (self.a.w, self.a.h);
        let mut c = Crossings {
            right: vec![None; w * h],
            top: vec![None; w * h],
        };
        for fy in 0..h {
            for fx in 0..w {
                let k = fy * w + fx;
                if fx + 1 < w {
                    c.right[k] = self.wall(b, Axis::X, k, k + 1, fx + 1, fy);
                }
                if fy + 1 < h {
                    c.top[k] = self.wall(b, Axis::Y, k, k + w, fy + 1, fx);
                }
            }
        }
        c
    }

    /// The wall between facet `k` and its neighbour `n` on the grid line `across` (in corner indices) of
    /// `axis`, over the cell `along` the line: split where the two planes cross (the crossing, along the
    /// line, is returned), each part facing away from the higher plane.
    fn wall(&self, b: &mut Builder, axis: Axis, k: usize, n: usize, across: usize, along: usize) -> Option<f64> {
        let f = self.f;
        let c = across as f64 * f;
        let (s0, s1) = (along as f64 * f, (along + 1) as f64 * f);
        let height = |m: usize, s: f64| {
            let (x, y) = axis.xy(c, s);
            self.plane(m, x, y)
        };
        let t = crossing(height(k, s0), height(k, s1), height(n, s0), height(n, s1));
        let cross = t.map(|t| s0 + t * (s1 - s0));
        let mut cuts = vec![(s0, Some(along)), (s1, Some(along + 1))];
        if let Some(sc) = cross {
            cuts.insert(1, (sc, None));
        }
        for seg in cuts.windows(2) {
            let ((sa, ca), (sb, cb)) = (seg[0], seg[1]);
            let (ka, kb, na, nb) = (height(k, sa), height(k, sb), height(n, sa), height(n, sb));
            if (ka - na).abs() <= EPS && (kb - nb).abs() <= EPS {
                continue;
            }
            let k_high = (ka - na) + (kb - nb) > 0.0;
            let end = |corner: Option<usize>, zk: f64, zn: f64| match corner {
                Some(ci) => {
                    let (cx, cy) = axis.xy(across, ci);
                    self.side(cx, cy, zk.min(zn), zk.max(zn))
                }
                None => vec![zk],
            };
            let point = |s: f64, z: f64| {
                let (x, y) = axis.xy(c, s);
                Vec3::new(x, y, z)
            };
            let mut poly: Vec<Vec3> = end(ca, ka, na).iter().map(|z| point(sa, *z)).collect();
            poly.extend(end(cb, kb, nb).iter().rev().map(|z| point(sb, *z)));
            let sign = if k_high { 1.0 } else { -1.0 };
            let (nx, ny) = axis.xy(sign, 0.0);
            b.polygon(&poly, Vec3::new(nx, ny, 0.0));
        }
        cross
    }

    /// Facet tops, with crossing points on their edges.
    fn tops(&self, b: &mut Builder, cross: &Crossings) {
        let (w, h, f) = (self.a.w, self.a.h, self.f);
        for fy in 0..h {
            for fx in 0..w {
                let k = fy * w + fx;
                let (x0, x1, y0, y1) = (fx as f64 * f, (fx + 1) as f64 * f, fy as f64 * f, (fy + 1) as f64 * f);
                let mut pts: Vec<(f64, f64)> = vec![(x0, y0)];
                if fy > 0 {
                    if let Some(xc) = cross.top[k - w] {
                        pts.push((xc, y0));
                    }
                }
                pts.push((x1, y0));
                if let Some(yc) = cross.right[k] {
                    pts.push((x1, yc));
                }
                pts.push((x1, y1));
                if let Some(xc) = cross.top[k] {
                    pts.push((xc, y1));
                }
                pts.push((x0, y1));
                if fx > 0 {
                    if let Some(yc) = cross.right[k - 1] {
                        pts.push((x0, yc));
                    }
                }
                let poly: Vec<Vec3> = pts
                    .iter()
                    .map(|(x, y)| Vec3::new(*x, *y, self.plane(k, *x, *y)))
                    .collect();
                b.polygon(&poly, Vec3::z());
            }
        }
    }

    /// Outer sides: one polygon per facet edge on the boundary.
    fn outer_sides(&self, b: &mut Builder) {
        let (w, h, f) = (self.a.w, self.a.h, self.f);
        let mut outer =
            |k: usize, (xa, ya): (f64, f64), (xb, yb): (f64, f64), ca: (usize, usize), cb: (usize, usize), n: Vec3| {
                let sa = self.side(ca.0, ca.1, self.base_mm, self.plane(k, xa, ya));
                let sb = self.side(cb.0, cb.1, self.base_mm, self.plane(k, xb, yb));
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
    }

    /// Bottom: every boundary corner at the base height.
    fn bottom(&self, b: &mut Builder) {
        let (w, h, f, base) = (self.a.w, self.a.h, self.f, self.base_mm);
        let (wf, hf) = (w as f64 * f, h as f64 * f);
        let mut ring: Vec<Vec3> = vec![];
        ring.extend((0..=w).map(|cx| Vec3::new(cx as f64 * f, 0.0, base)));
        ring.extend((1..=h).map(|cy| Vec3::new(wf, cy as f64 * f, base)));
        ring.extend((0..w).rev().map(|cx| Vec3::new(cx as f64 * f, hf, base)));
        ring.extend((1..h).rev().map(|cy| Vec3::new(0.0, cy as f64 * f, base)));
        b.polygon(&ring, -Vec3::z());
    }
}

/// Crossing parameter t in (0, 1) where two linear profiles a0→a1 and b0→b1 cross, if strictly inside.
fn crossing(a0: f64, a1: f64, b0: f64, b1: f64) -> Option<f64> {
    let (d0, d1) = (a0 - b0, a1 - b1);
    (d0.abs() > EPS && d1.abs() > EPS && (d0 > 0.0) != (d1 > 0.0)).then(|| d0 / (d0 - d1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::stl::{to_binary_stl, volume};
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
