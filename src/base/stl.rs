//! Triangle soups as binary STL, and the volume a closed one encloses: the output format shared by the exact
//! facet tile (`facets::stl`), a refined tile and the simulated cut (`heightfield_solid`). Coordinates in mm.

use crate::base::geometry::Vec3;
use crate::base::heightfield::Heightfield;

/// A triangle with its three vertices, counter-clockwise seen from outside.
pub type Triangle = [Vec3; 3];

/// Encode triangles as binary STL (f32, normals from the vertex order).
pub fn to_binary_stl(tris: &[Triangle], header: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(84 + 50 * tris.len());
    let mut h = [b' '; 80];
    for (d, s) in h.iter_mut().zip(header.bytes()) {
        *d = s;
    }
    out.extend_from_slice(&h);
    out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        let n = (t[1] - t[0]).cross(&(t[2] - t[0]));
        let n = if n.norm() > 0.0 { n.normalize() } else { n };
        for v in std::iter::once(&n).chain(t.iter()) {
            for c in [v.x, v.y, v.z] {
                out.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&0u16.to_le_bytes());
    }
    out
}

/// Signed volume enclosed by a closed, outward-oriented triangle mesh (divergence theorem).
pub fn volume(tris: &[Triangle]) -> f64 {
    tris.iter().map(|t| t[0].dot(&t[1].cross(&t[2]))).sum::<f64>() / 6.0
}

/// A heightfield as a closed solid: the top through every `stride`-th sample centre (the stride chosen so
/// that at most `max_side` samples lie along either side, the last row and column always kept), vertical
/// sides and a flat bottom `base_mm` below the lowest point. Sample `(i, j)` stands at
/// `origin + ((i + ½)·pitch, (j + ½)·pitch)`.
pub fn heightfield_solid(hf: &Heightfield, origin_mm: [f64; 2], max_side: usize, base_mm: f64) -> Vec<Triangle> {
    let f = hf.nx.max(hf.ny).div_ceil(max_side.max(2)).max(1);
    let is: Vec<usize> = (0..hf.nx).step_by(f).chain(std::iter::once(hf.nx - 1)).collect();
    let js: Vec<usize> = (0..hf.ny).step_by(f).chain(std::iter::once(hf.ny - 1)).collect();
    let dedup = |mut v: Vec<usize>| {
        v.dedup();
        v
    };
    let (is, js) = (dedup(is), dedup(js));
    let (lo, _) = hf.range();
    let zb = lo - base_mm.abs().max(1e-3);
    let p = hf.pitch_mm;
    let xy = |a: usize, b: usize| {
        (
            origin_mm[0] + (is[a] as f64 + 0.5) * p,
            origin_mm[1] + (js[b] as f64 + 0.5) * p,
        )
    };
    let top = |a: usize, b: usize| {
        let (x, y) = xy(a, b);
        Vec3::new(x, y, hf.at(is[a], js[b]))
    };
    let bot = |a: usize, b: usize| {
        let (x, y) = xy(a, b);
        Vec3::new(x, y, zb)
    };
    let (w, h) = (is.len(), js.len());
    let mut t = Vec::with_capacity(2 * (w - 1) * (h - 1) + 4 * (w + h) + 8);
    for b in 0..h.saturating_sub(1) {
        for a in 0..w.saturating_sub(1) {
            t.push([top(a, b), top(a + 1, b), top(a + 1, b + 1)]);
            t.push([top(a, b), top(a + 1, b + 1), top(a, b + 1)]);
        }
    }
    // the boundary, counter-clockwise seen from above
    let mut ring: Vec<(usize, usize)> = vec![];
    ring.extend((0..w).map(|a| (a, 0)));
    ring.extend((1..h).map(|b| (w - 1, b)));
    ring.extend((0..w - 1).rev().map(|a| (a, h - 1)));
    ring.extend((1..h - 1).rev().map(|b| (0, b)));
    for k in 0..ring.len() {
        let (p, q) = (ring[k], ring[(k + 1) % ring.len()]);
        // outward side wall: seen from outside, p→q runs left to right along the top
        t.push([bot(p.0, p.1), bot(q.0, q.1), top(q.0, q.1)]);
        t.push([bot(p.0, p.1), top(q.0, q.1), top(p.0, p.1)]);
    }
    // bottom: a fan from its centre, facing down
    let c = ring.iter().fold(Vec3::zeros(), |s, &(a, b)| s + bot(a, b)) / ring.len() as f64;
    for k in 0..ring.len() {
        let (p, q) = (ring[k], ring[(k + 1) % ring.len()]);
        t.push([c, bot(q.0, q.1), bot(p.0, p.1)]);
    }
    t.retain(|tri| (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).norm() > 0.0);
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The corner tetrahedron of the unit cube, faces outward.
    fn tetrahedron() -> Vec<Triangle> {
        let (o, x, y, z) = (Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z());
        vec![[o, y, x], [o, x, z], [o, z, y], [x, y, z]]
    }

    #[test]
    fn binary_stl_layout() {
        let tris = tetrahedron();
        let bytes = to_binary_stl(&tris, "brdfmill tile");
        assert_eq!(bytes.len(), 84 + 50 * tris.len());
        assert_eq!(&bytes[..13], b"brdfmill tile");
        assert!(bytes[13..80].iter().all(|b| *b == b' '));
        assert_eq!(
            u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize,
            tris.len()
        );
        // the first record: normal −z (from the vertex order), then the three vertices
        let f = |k: usize| f32::from_le_bytes(bytes[84 + 4 * k..88 + 4 * k].try_into().unwrap());
        assert_eq!([f(0), f(1), f(2)], [0.0, 0.0, -1.0]);
        assert_eq!([f(6), f(7), f(8)], [0.0, 1.0, 0.0]);
        assert_eq!(&bytes[132..134], &[0, 0]);
    }

    #[test]
    fn volume_of_a_tetrahedron() {
        assert!((volume(&tetrahedron()) - 1.0 / 6.0).abs() < 1e-15);
    }
}
