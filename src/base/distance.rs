//! Distances and moments of sampled distributions: the one set of helpers behind the verification metrics,
//! the wave/geometric comparison and the slope-grid distances.
//!
//! - relative L1: `∑|aᵢ − bᵢ| / ∑|bᵢ|` (0 when equal; `b` is the reference);
//! - Pearson correlation of the values: `cov(a, b) / (σa σb)`;
//! - Jensen–Shannon divergence of the normalised histograms, in bits:
//!   `JS = ½ KL(p‖m) + ½ KL(q‖m)`, `m = (p + q)/2`, in [0, 1];
//! - the variance of a coordinate `x` under weights `d`: `∑ dᵢ (xᵢ − x̄)² / ∑ dᵢ`, `x̄ = ∑ dᵢ xᵢ / ∑ dᵢ`.

/// Relative L1 distance of `a` to the reference `b`: `∑|a − b| / ∑|b|`.
#[must_use]
pub fn relative_l1(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum();
    let den: f64 = b.iter().map(|y| y.abs()).sum();
    num / den.max(f64::MIN_POSITIVE)
}

/// Pearson correlation of two equally long arrays.
#[must_use]
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt().max(1e-300)
}

/// Jensen–Shannon divergence of two non-negative arrays (each normalised to unit sum), bits, in [0, 1].
///
/// A negative cell (rounding noise of an unclamped FFT convolution, −1e-17 beside a cell of 1e-2) is no mass
/// and counts as 0, in the sums and in the terms. A non-finite value in either array, an array with no mass or
/// arrays of unequal length give NaN, which fails every tolerance: before, such a NaN sum went through
/// `f64::max(NaN, 0)` and read as 0 bits, a perfect score.
#[must_use]
pub fn jensen_shannon(a: &[f64], b: &[f64]) -> f64 {
    if a.len() != b.len() || a.iter().chain(b).any(|x| !x.is_finite()) {
        return f64::NAN;
    }
    let mass = |x: &f64| if *x > 0.0 { *x } else { 0.0 };
    let (sa, sb) = (a.iter().map(mass).sum::<f64>(), b.iter().map(mass).sum::<f64>());
    if sa <= 0.0 || sb <= 0.0 {
        return f64::NAN;
    }
    let mut js = 0.0;
    for (x, y) in a.iter().zip(b) {
        let (p, q) = (mass(x) / sa, mass(y) / sb);
        let m = 0.5 * (p + q);
        if p > 0.0 {
            js += 0.5 * p * (p / m).log2();
        }
        if q > 0.0 {
            js += 0.5 * q * (q / m).log2();
        }
    }
    // each term is ≥ 0 up to rounding, and the sum ≤ 1 bit; clamp keeps NaN as NaN
    js.clamp(0.0, 1.0)
}

/// Variance of the coordinates `x` under the weights `d`.
#[must_use]
pub fn weighted_variance(x: &[f64], d: &[f64]) -> f64 {
    let t: f64 = d.iter().sum();
    let mean: f64 = x.iter().zip(d).map(|(x, d)| x * d).sum::<f64>() / t;
    x.iter().zip(d).map(|(x, d)| (x - mean).powi(2) * d).sum::<f64>() / t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_forms() {
        // disjoint supports: JS = 1 bit; identical: 0
        assert!((jensen_shannon(&[1.0, 0.0], &[0.0, 1.0]) - 1.0).abs() < 1e-12);
        assert!(jensen_shannon(&[0.3, 0.7], &[0.3, 0.7]).abs() < 1e-12);
        // a cell of rounding noise below zero is no mass: disjoint supports still give 1 bit, not NaN or 0
        assert!((jensen_shannon(&[1.0, -1e-17, 0.0], &[0.0, 1e-18, 1.0]) - 1.0).abs() < 1e-12);
        assert!((jensen_shannon(&[1.0, 0.0], &[-1e-17, 1.0]) - 1.0).abs() < 1e-12);
        // no mass, a NaN, or unequal lengths: NaN, which fails a tolerance `js ≤ t`
        assert!(jensen_shannon(&[0.0, -1.0], &[0.5, 0.5]).is_nan());
        assert!(jensen_shannon(&[f64::NAN, 1.0], &[0.5, 0.5]).is_nan());
        assert!(jensen_shannon(&[1.0], &[0.5, 0.5]).is_nan());
        // an affine image correlates perfectly, its negation anti-correlates
        let a = [1.0, 4.0, 2.0, 8.0];
        let b: Vec<f64> = a.iter().map(|x| 3.0 * x - 1.0).collect();
        let c: Vec<f64> = a.iter().map(|x| -x).collect();
        assert!((correlation(&a, &b) - 1.0).abs() < 1e-12);
        assert!((correlation(&a, &c) + 1.0).abs() < 1e-12);
        assert!((relative_l1(&[1.0, 1.0], &[1.0, 3.0]) - 0.5).abs() < 1e-15);
        // two equal masses at ±1: variance 1 whatever the total mass
        assert!((weighted_variance(&[-1.0, 0.0, 1.0], &[2.0, 0.0, 2.0]) - 1.0).abs() < 1e-15);
    }
}
