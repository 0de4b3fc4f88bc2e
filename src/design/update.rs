//! The correction of the design's aim from one round's as-milled model (DESIGN.md §3.1).
//!
//! What the bit adds to a tile is mostly slope variance: the ball's fillets at the foot of every step
//! between facets and in every concave corner carry slopes the facets do not have, and the steps grow with
//! the facet slopes. So the aim is the target NDF `T` with its slopes scaled per axis,
//! `A(p, q) = T(p/cx, q/cy) / (cx·cy)`, and each round moves the scales by the model's variance ratio,
//! `c ← c · ρ^(−γ/2)` with `ρ` the as-milled model's slope variance over the target's along that axis and
//! `γ` the gain. The facets are sampled and arranged once, from `T`; later rounds scale that arrangement's
//! slopes (`facets::rescaled`), so the order of the facets is kept, the heights and steps scale by `c`,
//! and the variance the bit adds by about `c²`: the iteration then reaches the fixed point
//! `c² (σ²_design + σ²_tool) = σ²_target` in a round or two. (Re-sampling and re-annealing each round
//! instead was measured to move the rms step between 13.6 and 26.9 µm from round to round on the default
//! job, and the variance ratio with it, so the loop chased the arrangement's noise.) The shape of `T`
//! within the cone is kept.

use crate::slope::SlopeGrid;

/// `T(p/cx, q/cy) / (cx·cy)` on `target`'s grid (bilinear), zero beyond `cone_tan`, normalised.
pub fn scaled(target: &SlopeGrid, scale: [f64; 2], cone_tan: f64) -> SlopeGrid {
    let [cx, cy] = scale;
    let mut g = SlopeGrid::from_fn(target.domain, |p, q| {
        if p.hypot(q) > cone_tan {
            0.0
        } else {
            target.sample(p / cx, q / cy) / (cx * cy)
        }
    });
    g.normalise();
    g
}

/// The next scales: `c · ρ^(−gain/2)` per axis, each step limited to a factor of 1.5 either way.
pub fn next_scale(scale: [f64; 2], cov_ratio: [f64; 2], gain: f64) -> [f64; 2] {
    let f = |c: f64, r: f64| {
        if r.is_finite() && r > 0.0 {
            c * r.powf(-0.5 * gain).clamp(1.0 / 1.5, 1.5)
        } else {
            c
        }
    };
    [f(scale[0], cov_ratio[0]), f(scale[1], cov_ratio[1])]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slope::SlopeDomain;

    fn gauss(d: SlopeDomain, sx: f64, sy: f64) -> SlopeGrid {
        let mut g = SlopeGrid::from_fn(d, |p, q| (-(p * p) / (2.0 * sx * sx) - q * q / (2.0 * sy * sy)).exp());
        g.normalise();
        g
    }

    #[test]
    fn scaling_a_gaussian_scales_its_standard_deviations() {
        let d = SlopeDomain::square(257, 1.5);
        let s = scaled(&gauss(d, 0.1, 0.15), [0.9, 1.2], f64::INFINITY).stats();
        assert!((s.cov[0][0] / (0.09f64 * 0.09) - 1.0).abs() < 0.01, "{:?}", s.cov);
        assert!((s.cov[1][1] / (0.18f64 * 0.18) - 1.0).abs() < 0.01, "{:?}", s.cov);
    }

    #[test]
    fn a_tool_that_adds_variance_is_answered_in_a_few_rounds() {
        // a model of the bit that adds a fixed variance (fillets) and 20% of the aim's own (steps): the
        // scales must reach σ²_model = σ²_target along both axes
        let (target_var, add) = (0.02, 0.003);
        let model = |c: f64| c * c * target_var * 1.2 + add;
        let mut scale = [1.0, 1.0];
        for _ in 0..6 {
            let r = model(scale[0]) / target_var;
            scale = next_scale(scale, [r, r], 1.0);
        }
        let r = model(scale[0]) / target_var;
        assert!((r - 1.0).abs() < 0.01, "variance ratio after 6 rounds {r}");
    }
}
