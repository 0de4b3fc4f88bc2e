//! Microfacet distributions: Beckmann, GGX (Trowbridge–Reitz) and Blinn–Phong, with Smith masking.
//!
//! Notation follows pbrt-v4 and Mitsuba 3: `d(wm)` is the NDF normalised by projected area
//! (`∫ D(wm) cosθm dω = 1`), `lambda(w)` is Smith's Λ, `g1(w, wm) = 1/(1 + Λ(w))` on the visible side, and
//! the shadowing–masking term is the **separable** Smith form `G = G1(wi) G1(wo)`, as in Mitsuba 3's
//! `MicrofacetDistribution::G`, so that values agree with its `roughconductor`. Beckmann's Λ is the exact
//! erf form (Mitsuba uses a rational fit that is about 0.6% off at grazing angles).

use crate::base::geometry::{cos_sin_phi, tan2_theta, Vec3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The family of a microfacet distribution (the shape of its slope density).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Family {
    /// Gaussian slopes (Beckmann 1963).
    Beckmann,
    /// Trowbridge–Reitz / GGX (Walter et al. 2007).
    Ggx,
}

/// An anisotropic microfacet distribution with roughness `αx`, `αy` along the frame's x and y axes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Microfacet {
    /// Beckmann or GGX.
    pub shape: Family,
    /// Roughness along x (dimensionless; the slope standard deviation along x is `αx/√2` for Beckmann).
    pub alpha_x: f64,
    /// Roughness along y.
    pub alpha_y: f64,
}

impl Microfacet {
    /// A distribution; `None` unless both roughnesses are finite and positive.
    pub fn new(shape: Family, alpha_x: f64, alpha_y: f64) -> Option<Self> {
        let ok = |a: f64| a.is_finite() && a > 0.0;
        (ok(alpha_x) && ok(alpha_y)).then_some(Self {
            shape,
            alpha_x,
            alpha_y,
        })
    }

    /// The Blinn–Phong lobe `cosⁿθ` expressed as its Beckmann equivalent `α = √(2/(n+2))`
    /// (Walter et al. 2007, Eq. 30), which is how it gets a Smith masking term.
    pub fn blinn_equivalent_alpha(n: f64) -> f64 {
        (2.0 / (n + 2.0)).sqrt()
    }

    /// `tan²θ · (cos²φ/αx² + sin²φ/αy²)` — the squared "stretched" slope of a direction.
    #[inline]
    fn stretched_tan2(&self, w: &Vec3) -> f64 {
        let (c, s) = cos_sin_phi(w);
        tan2_theta(w) * (c * c / (self.alpha_x * self.alpha_x) + s * s / (self.alpha_y * self.alpha_y))
    }

    /// The NDF `D(wm)`, normalised so that `∫ D(wm) cosθm dω = 1`; zero below the horizon.
    pub fn d(&self, wm: &Vec3) -> f64 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        let cos4 = wm.z.powi(4);
        let e = self.stretched_tan2(wm);
        let norm = PI * self.alpha_x * self.alpha_y * cos4;
        match self.shape {
            Family::Beckmann => (-e).exp() / norm,
            Family::Ggx => 1.0 / (norm * (1.0 + e) * (1.0 + e)),
        }
    }

    /// The slope density `P22(p, q) = D(wm) cos⁴θm` in closed form.
    pub fn p22(&self, p: f64, q: f64) -> f64 {
        let e = (p / self.alpha_x).powi(2) + (q / self.alpha_y).powi(2);
        let norm = PI * self.alpha_x * self.alpha_y;
        match self.shape {
            Family::Beckmann => (-e).exp() / norm,
            Family::Ggx => 1.0 / (norm * (1.0 + e) * (1.0 + e)),
        }
    }

    /// Projected roughness `α(φ) = √(cos²φ αx² + sin²φ αy²)` toward a direction.
    #[inline]
    fn alpha_along(&self, w: &Vec3) -> f64 {
        let (c, s) = cos_sin_phi(w);
        (c * c * self.alpha_x * self.alpha_x + s * s * self.alpha_y * self.alpha_y).sqrt()
    }

    /// Smith's `Λ(w)`: GGX `(√(1 + α²tan²θ) − 1)/2`; Beckmann, exact, with `a = 1/(α tanθ)`:
    /// `Λ = (erf(a) − 1)/2 + exp(−a²)/(2a√π)`.
    pub fn lambda(&self, w: &Vec3) -> f64 {
        if w.z <= 0.0 {
            return f64::INFINITY;
        }
        let t2 = tan2_theta(w);
        if t2 == 0.0 {
            return 0.0;
        }
        let alpha = self.alpha_along(w);
        match self.shape {
            Family::Ggx => ((1.0 + alpha * alpha * t2).sqrt() - 1.0) / 2.0,
            Family::Beckmann => {
                let a = 1.0 / (alpha * t2.sqrt());
                (libm::erf(a) - 1.0) / 2.0 + (-a * a).exp() / (2.0 * a * PI.sqrt())
            }
        }
    }

    /// Smith's monodirectional masking `G1(w, wm) = 1/(1 + Λ(w))`, zero when `w` sees the back of `wm`.
    pub fn g1(&self, w: &Vec3, wm: &Vec3) -> f64 {
        if w.dot(wm) * w.z <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + self.lambda(w))
    }

    /// Separable shadowing–masking `G(wi, wo, wm) = G1(wi, wm) · G1(wo, wm)`.
    pub fn g(&self, wi: &Vec3, wo: &Vec3, wm: &Vec3) -> f64 {
        self.g1(wi, wm) * self.g1(wo, wm)
    }
}

/// The normalised Blinn–Phong NDF `D(wm) = (n + 2)/(2π) · cosⁿθm` (projected-area normalised).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlinnPhong {
    /// The exponent n (> 0).
    pub exponent: f64,
}

impl BlinnPhong {
    /// The NDF.
    pub fn d(&self, wm: &Vec3) -> f64 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        (self.exponent + 2.0) / (2.0 * PI) * wm.z.powf(self.exponent)
    }

    /// The Beckmann distribution with the equivalent roughness, which supplies Smith's Λ.
    pub fn smith_proxy(&self) -> Microfacet {
        let a = Microfacet::blinn_equivalent_alpha(self.exponent);
        Microfacet {
            shape: Family::Beckmann,
            alpha_x: a,
            alpha_y: a,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::geometry::{slope_to_normal, spherical};
    use proptest::prelude::*;

    /// `∫ D(wm) cosθm dω` by midpoint quadrature in (θ, φ) with `dω = sinθ dθ dφ`.
    fn projected_integral(d: impl Fn(&Vec3) -> f64) -> f64 {
        let (nt, np) = (2000, 256);
        let mut acc = 0.0;
        for it in 0..nt {
            let th = (it as f64 + 0.5) / nt as f64 * PI / 2.0;
            for ip in 0..np {
                let ph = (ip as f64 + 0.5) / np as f64 * 2.0 * PI;
                acc += d(&spherical(th, ph)) * th.cos() * th.sin();
            }
        }
        acc * (PI / 2.0 / nt as f64) * (2.0 * PI / np as f64)
    }

    #[test]
    fn ndfs_are_normalised_by_projected_area() {
        for shape in [Family::Beckmann, Family::Ggx] {
            for (ax, ay) in [(0.1, 0.1), (0.3, 0.3), (0.1, 0.3), (0.6, 0.25)] {
                let m = Microfacet::new(shape, ax, ay).unwrap();
                let i = projected_integral(|w| m.d(w));
                assert!((i - 1.0).abs() < 1e-3, "{shape:?} {ax} {ay}: {i}");
            }
        }
        for n in [10.0, 200.0] {
            let b = BlinnPhong { exponent: n };
            let i = projected_integral(|w| b.d(w));
            assert!((i - 1.0).abs() < 1e-3, "blinn {n}: {i}");
        }
    }

    #[test]
    fn smith_lambda_satisfies_the_projected_area_identity() {
        // ∫ ⟨w, m⟩ D(m) dm = cosθ (the signed projected area of the microsurface equals the macrosurface's),
        // and ∫ ⟨w, m⟩⁺ D(m) dm = cosθ (1 + Λ(w)).
        for shape in [Family::Beckmann, Family::Ggx] {
            let m = Microfacet::new(shape, 0.5, 0.2).unwrap();
            for (th, ph) in [(0.5, 0.3), (1.1, 1.9), (1.35, -0.4)] {
                let w = spherical(th, ph);
                let pos = projected_integral(|wm| m.d(wm) * w.dot(wm).max(0.0) / wm.z);
                let expect = w.z * (1.0 + m.lambda(&w));
                assert!(
                    (pos - expect).abs() < 2e-3 * expect,
                    "{shape:?} θ={th}: {pos} vs {expect}"
                );
            }
        }
    }

    proptest! {
        #[test]
        fn p22_is_d_times_cos4(p in -3.0..3.0f64, q in -3.0..3.0f64, ax in 0.05..1.0f64, ay in 0.05..1.0f64) {
            for shape in [Family::Beckmann, Family::Ggx] {
                let m = Microfacet::new(shape, ax, ay).unwrap();
                let wm = slope_to_normal(p, q);
                let a = m.p22(p, q);
                let b = m.d(&wm) * wm.z.powi(4);
                prop_assert!((a - b).abs() <= 1e-10 * a.max(1e-300));
            }
        }

        #[test]
        fn masking_is_a_fraction(th in 0.0..1.55f64, ph in -3.1..3.1f64, ax in 0.05..1.0f64, ay in 0.05..1.0f64) {
            for shape in [Family::Beckmann, Family::Ggx] {
                let m = Microfacet::new(shape, ax, ay).unwrap();
                let w = spherical(th, ph);
                let g = m.g1(&w, &Vec3::z());
                prop_assert!((0.0..=1.0).contains(&g));
            }
        }
    }

    #[test]
    fn invalid_roughness_is_refused() {
        assert!(Microfacet::new(Family::Ggx, 0.0, 0.1).is_none());
        assert!(Microfacet::new(Family::Beckmann, f64::NAN, 0.1).is_none());
        assert!(Microfacet::new(Family::Beckmann, -0.2, 0.1).is_none());
    }
}
