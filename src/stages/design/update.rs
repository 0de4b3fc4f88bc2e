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

/// The aim corrected cell by cell (a Richardson–Lucy step through the scallop lobe `K`):
///
/// `A'(s) = A(s) · [ (K ⊛ r)(s) / (K ⊛ 1)(s) ]^γ`,  `r = T_obs / M` clamped to `[1/RATIO_LIMIT, RATIO_LIMIT]`,
///
/// with `T_obs` the target as observed (with the base lobe), `M` the round's as-milled model, both floored
/// at [`RATIO_FLOOR`] of `T_obs`'s peak so that empty cells do not divide; zero beyond `cone_tan`,
/// normalised. Where the model has too much mass (the fillets' slopes), the aim loses some; where too little
/// (a sharp peak the ball's fillets spread), it gains. The normalised convolution keeps the ratio's mean at the
/// grid's edges.
pub fn reweighted(
    aim: &SlopeGrid,
    observed: &SlopeGrid,
    model: &SlopeGrid,
    kernel: &crate::stages::ndf::Kernel,
    gain: f64,
    cone_tan: f64,
) -> SlopeGrid {
    let floor = RATIO_FLOOR * observed.density.iter().copied().fold(0.0, f64::max);
    let ratio = SlopeGrid {
        domain: aim.domain,
        density: observed
            .density
            .iter()
            .zip(&model.density)
            .map(|(t, m)| (t.max(floor) / m.max(floor)).clamp(1.0 / RATIO_LIMIT, RATIO_LIMIT))
            .collect(),
    };
    let ones = SlopeGrid {
        domain: aim.domain,
        density: vec![1.0; aim.density.len()],
    };
    let (kr, k1) = (kernel.convolve(&ratio), kernel.convolve(&ones));
    let d = aim.domain;
    let mut g = SlopeGrid::from_fn(d, |_, _| 0.0);
    for j in 0..d.ny {
        for i in 0..d.nx {
            let k = j * d.nx + i;
            if d.p_at(i).hypot(d.q_at(j)) > cone_tan || k1.density[k] <= 0.0 {
                continue;
            }
            g.density[k] = aim.density[k] * (kr.density[k] / k1.density[k]).powf(gain);
        }
    }
    g.normalise();
    g
}

/// Below this fraction of the observed target's peak, a cell's density counts as this floor in the ratio.
pub const RATIO_FLOOR: f64 = 1e-3;

/// The most one round may multiply or divide a cell of the aim by.
pub const RATIO_LIMIT: f64 = 2.0;

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

    /// A Richardson–Lucy step through a delta lobe is the plain ratio: where the model has 1.5 times the
    /// target's mass the aim loses that factor, elsewhere it keeps its shape; a model equal to the target
    /// leaves the aim as it is (the fixed point).
    #[test]
    fn the_shape_step_divides_out_the_model_s_excess() {
        let d = SlopeDomain::square(64, 1.0);
        let target = gauss(d, 0.2, 0.25);
        let delta = crate::stages::ndf::Kernel {
            values: vec![1.0],
            w: 1,
            h: 1,
            dp: d.dp(),
            dq: d.dq(),
            label: "delta".into(),
        };
        let same = reweighted(&target, &target, &target, &delta, 1.0, f64::INFINITY);
        for (a, b) in same.density.iter().zip(&target.density) {
            assert!((a - b).abs() <= 1e-12 * b.max(1e-300), "{a} vs {b}");
        }
        let mut model = target.clone();
        for j in 0..d.ny {
            for i in d.nx / 2..d.nx {
                model.density[j * d.nx + i] *= 1.5;
            }
        }
        let a = reweighted(&target, &target, &model, &delta, 1.0, f64::INFINITY);
        let floor = RATIO_FLOOR * target.density.iter().copied().fold(0.0, f64::max);
        for j in 0..d.ny {
            for i in 0..d.nx / 2 {
                let (l, r) = (j * d.nx + i, j * d.nx + d.nx - 1 - i);
                if target.density[r] < floor {
                    continue; // under the floor the ratio is the floor's, not 1/1.5
                }
                let want = target.density[r] / target.density[l] / 1.5;
                let got = a.density[r] / a.density[l];
                assert!((got / want - 1.0).abs() < 1e-9, "cell ({i}, {j}): {got} vs {want}");
            }
        }
    }
}
