//! Directions on the hemisphere, microfacet slopes, and the half/difference angle parameterisation
//! (Rusinkiewicz 1998) used by measured BRDFs.
//!
//! Directions are unit `Vector3<f64>` in the local shading frame (`z` = mean surface normal). `wi` points
//! toward the light, `wo` toward the viewer, `wm` is a microfacet normal and `wh = normalize(wi + wo)`.

use nalgebra::{Unit, Vector3};

/// A 3-vector; directions are expected to be unit length.
pub type Vec3 = Vector3<f64>;

/// Cosine of the polar angle of a unit direction.
#[inline]
pub fn cos_theta(w: &Vec3) -> f64 {
    w.z
}

/// Squared tangent of the polar angle (infinite at the horizon).
#[inline]
pub fn tan2_theta(w: &Vec3) -> f64 {
    let c2 = w.z * w.z;
    (1.0 - c2).max(0.0) / c2
}

/// `(cos φ, sin φ)` of a direction; `(1, 0)` at the pole where φ is undefined.
#[inline]
pub fn cos_sin_phi(w: &Vec3) -> (f64, f64) {
    let r = (w.x * w.x + w.y * w.y).sqrt();
    if r < 1e-300 {
        (1.0, 0.0)
    } else {
        (w.x / r, w.y / r)
    }
}

/// Unit direction from spherical angles (radians).
#[inline]
pub fn spherical(theta: f64, phi: f64) -> Vec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * cp, st * sp, ct)
}

/// The microfacet normal of the slope `(p, q)`: the plane `z = p·x + q·y` has normal `(-p, -q, 1)/‖·‖`.
#[inline]
pub fn slope_to_normal(p: f64, q: f64) -> Vec3 {
    Vec3::new(-p, -q, 1.0) / (1.0 + p * p + q * q).sqrt()
}

/// The slope `(p, q) = (-mx/mz, -my/mz)` of an upper-hemisphere normal; `None` at or below the horizon.
#[inline]
pub fn normal_to_slope(wm: &Vec3) -> Option<(f64, f64)> {
    (wm.z > 0.0).then(|| (-wm.x / wm.z, -wm.y / wm.z))
}

/// Half vector `normalize(wi + wo)`; `None` when the two directions are opposite.
#[inline]
pub fn half_vector(wi: &Vec3, wo: &Vec3) -> Option<Vec3> {
    Unit::try_new(wi + wo, 1e-12).map(|u| u.into_inner())
}

/// Mirror reflection of `w` about the unit normal `n`.
#[inline]
pub fn reflect(w: &Vec3, n: &Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

/// Half/difference angles `(θh, φh, θd, φd)` of a pair of directions (Rusinkiewicz 1998), radians.
///
/// `wd` is `wi` expressed in the frame where `wh` is the pole: rotate by `-φh` about z, then `-θh` about y.
pub fn to_half_diff(wi: &Vec3, wo: &Vec3) -> Option<(f64, f64, f64, f64)> {
    let wh = half_vector(wi, wo)?;
    let theta_h = wh.z.clamp(-1.0, 1.0).acos();
    let phi_h = wh.y.atan2(wh.x);
    let wd = rotate_y(&rotate_z(wi, -phi_h), -theta_h);
    let theta_d = wd.z.clamp(-1.0, 1.0).acos();
    let phi_d = wd.y.atan2(wd.x);
    Some((theta_h, phi_h, theta_d, phi_d))
}

/// Inverse of [`to_half_diff`]: the directions `(wi, wo)` of given half/difference angles.
pub fn from_half_diff(theta_h: f64, phi_h: f64, theta_d: f64, phi_d: f64) -> (Vec3, Vec3) {
    let wd = spherical(theta_d, phi_d);
    let wi = rotate_z(&rotate_y(&wd, theta_h), phi_h);
    let wh = spherical(theta_h, phi_h);
    let wo = reflect(&wi, &wh);
    (wi, wo)
}

/// Rotate about the z axis by `a` radians.
#[inline]
pub fn rotate_z(v: &Vec3, a: f64) -> Vec3 {
    let (s, c) = a.sin_cos();
    Vec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z)
}

/// Rotate about the y axis by `a` radians.
#[inline]
pub fn rotate_y(v: &Vec3, a: f64) -> Vec3 {
    let (s, c) = a.sin_cos();
    Vec3::new(c * v.x + s * v.z, v.y, -s * v.x + c * v.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn half_diff_round_trip(th in 0.0..1.5f64, ph in -3.1..3.1f64, td in 0.0..1.5f64, pd in -3.1..3.1f64) {
            let (wi, wo) = from_half_diff(th, ph, td, pd);
            prop_assert!((wi.norm() - 1.0).abs() < 1e-12);
            prop_assert!((wo.norm() - 1.0).abs() < 1e-12);
            let wh = half_vector(&wi, &wo).unwrap();
            prop_assert!((wh - spherical(th, ph)).norm() < 1e-9);
            let (th2, _, td2, _) = to_half_diff(&wi, &wo).unwrap();
            prop_assert!((th2 - th).abs() < 1e-9);
            prop_assert!((td2 - td).abs() < 1e-9);
        }

        #[test]
        fn slope_normal_round_trip(p in -5.0..5.0f64, q in -5.0..5.0f64) {
            let n = slope_to_normal(p, q);
            prop_assert!((n.norm() - 1.0).abs() < 1e-12);
            let (p2, q2) = normal_to_slope(&n).unwrap();
            prop_assert!((p2 - p).abs() < 1e-12 && (q2 - q).abs() < 1e-12);
        }
    }

    #[test]
    fn facet_plane_normal_is_perpendicular_to_its_tangents() {
        // The plane z = p x + q y contains (1, 0, p) and (0, 1, q).
        let (p, q) = (0.3, -0.7);
        let n = slope_to_normal(p, q);
        assert!(n.dot(&Vec3::new(1.0, 0.0, p)).abs() < 1e-15);
        assert!(n.dot(&Vec3::new(0.0, 1.0, q)).abs() < 1e-15);
    }
}
