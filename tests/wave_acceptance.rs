//! Issue 7's wave-optics figures: FFT and Gabor evaluations agree, the wave BRDF of a surface smooth at the
//! wavelength scale approaches the geometric one, and a grating's peaks sit at sin θ = mλ/d. Each bound is
//! derived in a comment from the model (the window's angular resolution, Parseval, edge diffraction), not
//! taken from a measured value.

use brdfmill::base::geometry::{spherical, Vec3};
use brdfmill::base::heightfield::Heightfield;
use brdfmill::stages::optics::wave::{self, OpticalSurface, WaveConfig};
use std::f64::consts::PI;

/// A periodic raster-finish patch: ball-nose scallops of radius `r_um` and period `d_um` along x, with a
/// gentle waviness along y, sampled at `pitch_um` (as the simulated milled surface is).
fn scallops(n: usize, pitch_um: f64, d_um: f64, r_um: f64) -> Heightfield {
    let mut hf = Heightfield::flat(n, n, pitch_um * 1e-3, true, 0.0);
    let len = n as f64 * pitch_um;
    for j in 0..n {
        for i in 0..n {
            let (x, y) = ((i as f64 + 0.5) * pitch_um, (j as f64 + 0.5) * pitch_um);
            let u = x.rem_euclid(d_um) - d_um / 2.0;
            let z = -(r_um - (r_um * r_um - u * u).sqrt()) + 0.3 * (2.0 * std::f64::consts::PI * y / len).sin();
            hf.z_mm[j * n + i] = z * 1e-3;
        }
    }
    hf
}

#[test]
fn fft_and_gabor_agree_within_one_percent() {
    // 128 µm periodic patch at 1 µm, scallops 32 µm apart from a 100 µm ball (slopes up to ±0.16),
    // resampled to λ/4 = 0.1375 µm for the FFT; Gabor texels of λ/4 too (one kernel per optical texel)
    let surf = OpticalSurface::new(&scallops(128, 1.0, 32.0, 100.0)).unwrap();
    let cfg = WaveConfig {
        sigma_um: 5.0,
        windows: 2,
        ..Default::default()
    };
    let wi = spherical(0.2, 0.4);
    let slice = wave::fft_slice(&surf, &wi, &cfg).unwrap();
    let fine = wave::compare_fft_gabor(&surf, &slice, &cfg, cfg.sample(), 16).unwrap();
    let coarse = wave::compare_fft_gabor(&surf, &slice, &cfg, 0.5, 16).unwrap();
    println!("FFT vs Gabor relative L2 over 33² samples: texel λ/4 {fine:.5}, texel 0.5 µm {coarse:.5}");
    // the target
    assert!(fine < 0.01, "relative L2 {fine}");
    // The first-order expansion converges as O(l²): what it drops over a texel of side l is the curvature
    // term, a phase error ≈ (2π·ξ3/λ)·H''·l²/8 (≤ 0.007 rad here for H'' = 1/100 µm⁻¹ at l = 0.5 µm, so in
    // its linear range), and the box-to-Gaussian replacement of Eqs. 11–12 also errs at O(l²). The two
    // texel sizes' errors are then in the ratio (0.5/0.1375)² = 13.2; allow a factor 2 either way for the
    // O(l⁴) remainder and for the FFT's own error in `fine`.
    let law = (0.5 / cfg.sample()).powi(2);
    assert!(
        coarse / fine > law / 2.0 && coarse / fine < 2.0 * law,
        "{coarse} vs {fine}: ratio {} against the l² law's {law}",
        coarse / fine
    );
}

/// `∫_δ^∞ Δ²/(x²(Δ+x)²) dx`: the far-side tail of two edges `Δ` apart in frequency (partial fractions).
fn two_edge_tail(delta: f64, gap: f64) -> f64 {
    1.0 / delta + 1.0 / (gap + delta) - 2.0 / gap * (1.0 + gap / delta).ln()
}

/// `∫_δ^{Δ−δ} Δ²/(x²(Δ−x)²) dx`: the part of the same tails that falls between the two edges.
fn two_edge_inner(delta: f64, gap: f64) -> f64 {
    2.0 * (1.0 / delta - 1.0 / (gap - delta)) + 4.0 / gap * ((gap - delta) / delta).ln()
}

#[test]
fn a_surface_smooth_at_the_wavelength_scale_approaches_geometric_optics() {
    // heights of µm (≫ λ), radius of curvature 300 µm, scallops 100 µm apart (slopes up to ±0.169): the
    // geometric regime. σ = 5 µm windows do not resolve the 100 µm period (no diffraction orders); 17 per
    // axis, 23.5 µm apart, fall at 17 evenly spread phases of the scallop (the geometric histogram sees
    // every phase; the windows must too); Δ = λ/2 covers |ψ̄| < 1
    let (period, radius, len) = (100.0, 300.0, 400.0);
    let hf = scallops(400, 1.0, period, radius);
    let surf = OpticalSurface::new(&hf).unwrap();
    let cfg = WaveConfig {
        sigma_um: 5.0,
        windows: 17,
        sample_um: Some(0.275),
        ..Default::default()
    };
    let slice = wave::fft_slice(&surf, &Vec3::new(0.0, 0.0, 1.0), &cfg).unwrap();
    let (p, wx, wy) = wave::slope_marginals(&slice);
    // Against the geometric module's histogram of central-difference slopes (the figures docs/CLI.md quotes).
    let slopes = brdfmill::base::surface::slopes(&hf, 0.0, 1);
    let (gx, gy) = wave::geometric_marginals(&slopes, &p, &slice, cfg.sigma_um);
    let l1_geo = brdfmill::base::distance::relative_l1(&wx, &gx);
    let ratio =
        brdfmill::base::distance::weighted_variance(&p, &wx) / brdfmill::base::distance::weighted_variance(&p, &gx);
    let ratio_y =
        brdfmill::base::distance::weighted_variance(&p, &wy) / brdfmill::base::distance::weighted_variance(&p, &gy);
    println!("wave vs geometric slope marginal across the scallops: relative L1 {l1_geo:.4}, variance ratio {ratio:.4} (along them {ratio_y:.4})");

    // An independent prediction of the wave marginal from the surface alone. At normal incidence ξ3 = 2 and
    // a sample's slope is p = −ψ̄x/ξ3. Each window's field w·e^{−i2π ξ3 H/λ} has, by Parseval applied to its
    // derivative, a spectrum whose second moment in slope is the w²-weighted mean of H_x² plus the window's
    // own spread b² = (λ/(2√2·π·σ·ξ3))² (from ∫(∂x w)²/∫w² = 1/(2σ²)), exactly, whatever the surface. The
    // FFT's ξ2 factor, A0 − ψ̄·A/ψz = A0·ξ2(ψ̄) up to a term odd about the window centre, weights each slope
    // by |ξ2|² = (1 + ξ3·p²/ψz)², ψz = 1 + √(1 − ξ3²p²): 1.5% of the variance here, resolved below.
    let (lambda, sigma, xi3) = (cfg.wavelength_um, cfg.sigma_um, 2.0);
    let b = lambda / (2.0 * 2f64.sqrt() * PI * sigma * xi3);
    let d = cfg.sample();
    let half = (4.0 * sigma / d).ceil() as i64;
    let n_win = cfg.windows;
    let (mut sw, mut sp, mut sp2) = (0.0, 0.0, 0.0);
    let dp = p[1] - p[0];
    let mut pred = vec![0.0; p.len()];
    let reach = (6.0 * b / dp).ceil() as i64;
    for ky in 0..n_win {
        for kx in 0..n_win {
            // the windows of a periodic surface: a regular grid, (k + ½)·L/n
            let (xc, yc) = (
                (kx as f64 + 0.5) * len / n_win as f64,
                (ky as f64 + 0.5) * len / n_win as f64,
            );
            for bj in -half..=half {
                for ai in -half..=half {
                    let (dx, dy) = (ai as f64 * d, bj as f64 * d);
                    let r2 = dx * dx + dy * dy;
                    if r2 > 16.0 * sigma * sigma {
                        continue; // the window is cut at 4σ, as the FFT's is
                    }
                    let (_, hx, hy) = surf.eval(xc + dx, yc + dy);
                    let s2 = hx * hx + hy * hy;
                    let xi2 = 1.0 + xi3 * s2 / (1.0 + (1.0 - xi3 * xi3 * s2).sqrt());
                    let wgt = (-r2 / (sigma * sigma)).exp() * xi2 * xi2;
                    sw += wgt;
                    sp += wgt * hx;
                    sp2 += wgt * (hx * hx + b * b);
                    let k0 = ((hx - p[0]) / dp).round() as i64;
                    for k in (k0 - reach).max(0)..=(k0 + reach).min(p.len() as i64 - 1) {
                        let z = (p[k as usize] - hx) / b;
                        pred[k as usize] += wgt * (-0.5 * z * z).exp();
                    }
                }
            }
        }
    }
    let total: f64 = pred.iter().sum();
    pred.iter_mut().for_each(|v| *v /= total);
    let v_pred = sp2 / sw - (sp / sw).powi(2);
    let v_wave = brdfmill::base::distance::weighted_variance(&p, &wx);
    // Variance: what the identity leaves out is the odd ξ2 term (relative ≈ |ψ̄|·λ/(2π·ξ3·σ·ψz) ≈ 0.2%, and
    // odd, so it cancels in the second moment to first order), ξ2 taken at each sample's slope rather than
    // across its spread b (≈ 4b² = 1.5e-4), the 4σ cut (e^-8 = 3e-4) and the ψ̄ grid (1.6 samples per b:
    // the sampled moments of a Gaussian are exact to e^{−2π²(b/dp)²} ≈ 1e-21): together ≲ 0.1%. Require 0.5%.
    println!(
        "wave variance {v_wave:.6}, predicted {v_pred:.6} (ratio {:.5})",
        v_wave / v_pred
    );
    assert!(
        (v_wave / v_pred - 1.0).abs() < 0.005,
        "variance {v_wave} against {v_pred}"
    );

    // Shape: where the per-window prediction is exact and where it is not. For a phase quadratic over the
    // window (a circular arc: the third derivative 3u/r³ is at most 6e-6 µm⁻², negligible) the window's
    // spectrum is a Gaussian with exactly the predicted variance: the prediction is exact. At the cusps it
    // is not: the slope jumps from +a to −a, and a window with the cusp at c has its field cut at two edge
    // frequencies Δ = 2ξ3·a/λ apart, with the amplitude tail w(c)·Δ/(2π·x·(Δ ± x)) at a distance x from
    // either edge. Averaged over the windows' phases (E[w(c)²] = σ√π/P against a window's ∫w² = σ√π), the
    // fraction of the marginal beyond a distance δ outside the two edges is T(δ) = ∫_δ^∞ Δ²/(x²(Δ+x)²)dx
    // / (2π²P).
    let a = (period / 2.0) / (radius * radius - (period / 2.0f64).powi(2)).sqrt();
    let gap = 2.0 * xi3 * a / lambda;
    // At 8b beyond the edges the window's Gaussian core has e^-32 of its mass: the tail is the cusp's. The
    // endpoint law is accurate there to ≈ 1/(2π·σ·δ_u)² = 3%; the bicubic interpolation rounds the cusp
    // over about one 1 µm sample, which lowers a tail at δ_u by ≈ (π·1 µm·δ_u)²/3 = 10%; ξ2 weights these
    // steep slopes (p ≈ 0.22) ≈ 8% above the mean weight. Require ±20%.
    let delta_p = 8.0 * b;
    let delta_u = xi3 * delta_p / lambda;
    let law = two_edge_tail(delta_u, gap) / (2.0 * PI * PI * period);
    let beyond = |v: &[f64]| -> f64 {
        p.iter()
            .zip(v)
            .filter(|(x, _)| x.abs() > a + delta_p)
            .map(|(_, m)| m)
            .sum()
    };
    let (tail, tail_pred) = (beyond(&wx), beyond(&pred));
    println!(
        "beyond |p| = a + 8b = {:.4}: wave {tail:.5}, edge-diffraction law {law:.5} (ratio {:.3}), geometric \
         prediction {tail_pred:.1e}",
        a + delta_p,
        tail / law
    );
    assert!(
        (tail / law - 1.0).abs() < 0.2,
        "cusp tail {tail} against the edge law {law}"
    );
    // L1 to the prediction: the wave moves the cusp's tails (both sides of both edges) away from where the
    // prediction keeps them; within one window width b_u = 1/(2√2·πσ) of an edge the two share the
    // Gaussian core. So the L1 distance is at most twice the tail mass beyond b_u of the edges, outside
    // (T) and between them, over 4π²P.
    let b_u = 1.0 / (2.0 * 2f64.sqrt() * PI * sigma);
    let moved = (2.0 * two_edge_tail(b_u, gap) + two_edge_inner(b_u, gap)) / (4.0 * PI * PI * period);
    let l1 = brdfmill::base::distance::relative_l1(&wx, &pred);
    println!("wave vs prediction relative L1 {l1:.4} (bound {:.4})", 2.0 * moved);
    assert!(l1 < 2.0 * moved, "relative L1 {l1} against {}", 2.0 * moved);
}

#[test]
fn a_grating_diffracts_at_m_lambda_over_d() {
    // sinusoidal grating, period 5 µm, amplitude 0.02 µm, 10 periods, normal incidence
    let (n, pitch, d) = (200, 0.25, 5.0);
    let mut hf = Heightfield::flat(n, n, pitch * 1e-3, true, 0.0);
    for j in 0..n {
        for i in 0..n {
            let x = (i as f64 + 0.5) * pitch;
            hf.z_mm[j * n + i] = 0.02e-3 * (2.0 * std::f64::consts::PI * x / d).sin();
        }
    }
    let surf = OpticalSurface::new(&hf).unwrap();
    let cfg = WaveConfig {
        windows: 1,
        ..Default::default()
    };
    let s = wave::fft_slice(&surf, &Vec3::new(0.0, 0.0, 1.0), &cfg).unwrap();
    let (m, c) = (s.m, s.m / 2);
    let row: Vec<f64> = (0..m).map(|a| s.f[c * m + a]).collect();
    for order in [-2i32, -1, 1, 2] {
        let want = order as f64 * cfg.wavelength_um / d; // sin θ = ψ̄x at normal incidence
        let k = (c as f64 + want / s.dpsi).round() as usize;
        let peak = (k - 6..=k + 6).max_by(|a, b| row[*a].total_cmp(&row[*b])).unwrap();
        let got = s.psi_bar(peak, c).0;
        println!(
            "order {order}: peak at sin θ = {got:.5}, mλ/d = {want:.5} (sample {:.5})",
            s.dpsi
        );
        assert!((got - want).abs() <= s.dpsi, "order {order}: {got} vs {want}");
        // a real peak: far above the trough halfway to the next order
        let mid = (c as f64 + (order as f64 + 0.5) * cfg.wavelength_um / d / s.dpsi).round() as usize;
        assert!(row[peak] > 100.0 * row[mid], "order {order}");
    }
}
