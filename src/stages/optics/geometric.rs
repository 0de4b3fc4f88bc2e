//! Geometric optics of a heightfield: the microfacet BRDF its slope distribution implies.
//!
//! The slope distribution is [`crate::base::surface`]'s (Eq. 6, with the optional Gaussian pre-filter of
//! Dong et al. 2015). The BRDF is Eq. 5 with `D = P22 / cos⁴θ` looked up in the grid, Fresnel from the
//! material and the separable Smith masking computed from the same grid (as in `ndf::halfangle`).

use crate::base::geometry::{half_vector, normal_to_slope, Vec3};
use crate::base::slope::{SlopeGrid, SmithTable};
use crate::stages::brdf::{ConductorIor, Rgb};

/// A microfacet BRDF (Eq. 5) whose NDF is a slope grid.
pub struct MicrofacetBrdf {
    ndf: SlopeGrid,
    smith: SmithTable,
    /// Fresnel material; `None` is a perfect mirror.
    pub material: Option<ConductorIor>,
}

impl MicrofacetBrdf {
    /// Build from a (normalised) slope density.
    pub fn new(ndf: SlopeGrid, material: Option<ConductorIor>) -> Self {
        let smith = SmithTable::new(&ndf, 64, 32);
        Self { ndf, smith, material }
    }

    /// The slope density it was built from.
    pub fn ndf(&self) -> &SlopeGrid {
        &self.ndf
    }

    /// `D(wm) = P22(p, q) / cos⁴θm`.
    pub fn d(&self, wm: &Vec3) -> f64 {
        match normal_to_slope(wm) {
            Some((p, q)) => self.ndf.sample(p, q) / wm.z.powi(4),
            None => 0.0,
        }
    }

    /// `f(wi, wo)` in RGB, without the cosine.
    pub fn eval(&self, wi: &Vec3, wo: &Vec3) -> Rgb {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return [0.0; 3];
        }
        let Some(wh) = half_vector(wi, wo) else {
            return [0.0; 3];
        };
        let g = self.smith.g1(wi) * self.smith.g1(wo);
        let v = self.d(&wh) * g / (4.0 * wi.z * wo.z);
        let f = match &self.material {
            Some(m) => m.reflectance(wi.dot(&wh)),
            None => [1.0; 3],
        };
        f.map(|c| c * v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::SlopeDomain;
    use crate::base::surface::ndf_of_slopes;
    use crate::stages::brdf::{Family, Microfacet};
    use rand::{Rng, SeedableRng};

    #[test]
    fn gaussian_slopes_give_a_beckmann_ndf() {
        // Independent Gaussian slopes of variance α²/2 are the Beckmann distribution (P22 is their density).
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let sigma: f64 = 0.2;
        let normal = |rng: &mut rand_pcg::Pcg64Mcg| -> f64 {
            let (u, v): (f64, f64) = (rng.gen(), rng.gen());
            (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let s: Vec<(f64, f64)> = (0..400_000)
            .map(|_| (sigma * normal(&mut rng), sigma * normal(&mut rng)))
            .collect();
        let domain = SlopeDomain::square(64, 1.2);
        let (g, _) = ndf_of_slopes(&s, domain);
        let m = Microfacet::new(Family::Beckmann, sigma * 2f64.sqrt(), sigma * 2f64.sqrt()).unwrap();
        let mut exact = SlopeGrid::from_fn(domain, |p, q| m.p22(p, q));
        exact.normalise();
        let l1 = g.relative_l1(&exact);
        assert!(l1 < 0.05, "relative L1 {l1}");
        // and its BRDF is the Beckmann model's (up to the masking's quadrature)
        let brdf = MicrofacetBrdf::new(g, None);
        let analytic = crate::stages::brdf::Brdf::parse("beckmann:alpha=0.28284271247461906").unwrap();
        let (wi, wo) = (
            crate::base::geometry::spherical(0.3, 0.0),
            crate::base::geometry::spherical(0.35, 3.0),
        );
        let (a, b) = (brdf.eval(&wi, &wo)[0], analytic.eval(&wi, &wo)[0]);
        assert!((a - b).abs() < 0.05 * b, "{a} vs {b}");
    }
}
