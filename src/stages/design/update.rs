//! The correction of the design's aim from one round's as-milled model (DESIGN.md §3.1).
//!
//! What the bit adds to a tile is mostly slope variance: the ball's fillets at the foot of every step
//! between facets and in every concave corner carry slopes the facets do not have, and the steps grow with
//! the facet slopes. So the aim is the target NDF `T` with its slopes scaled per axis,
//! `A(p, q) = T(p/cx, q/cy) / (cx·cy)`, and each round moves the scales by the model's variance ratio `ρ`
//! (the as-milled model's slope variance over the target's along that axis): first `c ← c · ρ^(−γ/2)`, then
//! by the secant through the last two rounds ([`next_scale`]), `γ` the gain. The facets are sampled and arranged once, from `T`; later rounds scale that arrangement's
//! slopes (`facets::rescaled`), so the order of the facets is kept, the heights and steps scale by `c`,
//! and the variance the bit adds by about `c²`: the iteration then reaches the fixed point
//! `c² (σ²_design + σ²_tool) = σ²_target` in a round or two. (Re-sampling and re-annealing each round
//! instead was measured to move the rms step between 13.6 and 26.9 µm from round to round on the default
//! job, and the variance ratio with it, so the loop chased the arrangement's noise.) The shape of `T`
//! within the cone is kept.

use crate::base::slope::SlopeGrid;

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

/// The next scales from the rounds so far (`(scale, variance ratio)` per round, newest last), per axis.
/// The first step is `c · ρ^(−gain/2)`, which assumes all the variance scales with `c²`. From the second on,
/// the last two rounds fit `ρ = α c² + β` (what scales, and what the bit adds whatever the slopes: the
/// scallops' and polish's share the lobe does not carry exactly, fillets fed by the other axis's steps) and
/// the secant step aims at `ρ = 1`, `c² = (1 − β)/α`, damped by the gain; it falls back to the first rule
/// when the fit is degenerate. Each step is limited to a factor of 1.5 either way.
pub fn next_scale(history: &[([f64; 2], [f64; 2])], gain: f64) -> [f64; 2] {
    let Some(&(scale, ratio)) = history.last() else {
        return [1.0, 1.0];
    };
    let prev = history.len().checked_sub(2).map(|k| history[k]);
    let axis = |a: usize| -> f64 {
        let (c, r) = (scale[a], ratio[a]);
        if !(r.is_finite() && r > 0.0) {
            return c;
        }
        let power = c * r.powf(-0.5 * gain);
        let secant = prev.and_then(|(ps, pr)| {
            let (c0, r0) = (ps[a], pr[a]);
            let dc2 = c * c - c0 * c0;
            if dc2.abs() < 1e-6 * c * c || !r0.is_finite() {
                return None;
            }
            let alpha = (r - r0) / dc2;
            let beta = r - alpha * c * c;
            let c2 = (1.0 - beta) / alpha;
            (alpha > 0.0 && c2 > 0.0).then(|| {
                let target = c2.sqrt();
                c + gain * (target - c)
            })
        });
        secant.unwrap_or(power).clamp(c / 1.5, c * 1.5)
    };
    [axis(0), axis(1)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::slope::SlopeDomain;

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
        let mut history = vec![];
        let mut scale = [1.0, 1.0];
        for _ in 0..3 {
            let r = model(scale[0]) / target_var;
            history.push((scale, [r, r]));
            scale = next_scale(&history, 1.0);
        }
        // the model is exactly α c² + β, so the secant lands on it at the third round
        let r = model(scale[0]) / target_var;
        assert!((r - 1.0).abs() < 1e-9, "variance ratio after 3 rounds {r}");
    }
}
