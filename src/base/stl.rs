//! Triangle soups as binary STL, and the volume a closed one encloses: the output format shared by the exact
//! facet tile (`facets::stl`) and the simulated cut (`simulate::solid`). Coordinates in mm.

use crate::base::geometry::Vec3;

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
