//! Tests of the wave-optics evaluators against closed forms and each other.

use super::*;

fn flat(n: usize, pitch_um: f64) -> OpticalSurface {
    OpticalSurface::new(&Heightfield::flat(n, n, pitch_um * 1e-3, true, 0.0)).unwrap()
}

#[test]
fn catmull_rom_reproduces_planes_and_their_gradient() {
    let mut hf = Heightfield::flat(16, 16, 0.002, false, 0.0);
    for j in 0..16 {
        for i in 0..16 {
            let (x, y) = ((i as f64 + 0.5) * 2.0, (j as f64 + 0.5) * 2.0);
            hf.z_mm[j * 16 + i] = (0.1 * x - 0.05 * y + 3.0) * 1e-3;
        }
    }
    let s = OpticalSurface::new(&hf).unwrap();
    let (h, hx, hy) = s.eval(13.37, 9.1);
    assert!((h - (0.1 * 13.37 - 0.05 * 9.1 + 3.0)).abs() < 1e-12);
    assert!((hx - 0.1).abs() < 1e-12 && (hy + 0.05).abs() < 1e-12);
}

#[test]
fn a_flat_mirror_peaks_at_the_kernel_spectrum_and_reflects_f() {
    let cfg = WaveConfig {
        sigma_um: 4.0,
        windows: 1,
        material: Some(crate::stages::brdf::PRESETS[0].ior),
        ..Default::default()
    };
    let wi = crate::base::geometry::spherical(0.3, 0.7);
    let s = fft_slice(&flat(64, 1.0), &wi, &cfg).unwrap();
    let c = s.m / 2;
    let fres = cfg.fresnel(wi.z);
    let peak = fres / (cfg.wavelength_um.powi(2)) * 4.0 * PI * cfg.sigma_um.powi(2);
    // the window is cut at 4σ: its integral falls short by e^{−8}, the peak by 2·e^{−8} = 0.07%
    let trunc = 1.0 - 2.0 * (-8f64).exp();
    let got = s.f[c * s.m + c];
    assert!((got - peak * trunc).abs() < 1e-5 * peak, "{got} vs {peak}");
    let max = s.f.iter().cloned().fold(0.0, f64::max);
    assert_eq!(max, s.f[c * s.m + c]);
    assert!((s.albedo() - fres).abs() < 1e-3 * fres, "{} vs {fres}", s.albedo());
}

#[test]
fn bad_settings_are_refused() {
    let s = flat(8, 1.0);
    let wi = Vec3::new(0.0, 0.0, 1.0);
    let bad = WaveConfig {
        wavelength_um: -1.0,
        ..Default::default()
    };
    assert!(fft_slice(&s, &wi, &bad).is_err());
    assert!(fft_slice(&s, &Vec3::new(0.0, 0.0, -1.0), &WaveConfig::default()).is_err());
    assert!(OpticalSurface::new(&Heightfield::flat(2, 2, 0.001, false, 0.0)).is_err());
}

/// A sinusoidal grating of period `d_um` and height amplitude `amp_um` along x, 160 µm square at
/// 0.25 µm, not periodic (the one window, at its centre, stays 4σ from the edges).
fn grating(d_um: f64, amp_um: f64) -> OpticalSurface {
    let (n, pitch) = (640, 0.25);
    let mut hf = Heightfield::flat(n, n, pitch * 1e-3, false, 0.0);
    for j in 0..n {
        for i in 0..n {
            let x = (i as f64 + 0.5) * pitch;
            hf.z_mm[j * n + i] = amp_um * 1e-3 * (2.0 * PI * x / d_um).sin();
        }
    }
    OpticalSurface::new(&hf).unwrap()
}

/// The number after `marker` in `text`.
fn number_after(text: &str, marker: &str) -> f64 {
    let rest = &text[text.find(marker).unwrap_or_else(|| panic!("no `{marker}` in {text}")) + marker.len()..];
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(rest.len());
    rest[..end]
        .parse()
        .unwrap_or_else(|e| panic!("`{marker}` in {text}: {e}"))
}

/// The diffraction warning's figures checked against a second method: the wave slice (FFT, Kirchhoff) of a
/// sinusoidal grating at normal incidence, where order `m` sits at `ψ̄x = sin θ = mλ/d`, with the same
/// σ = 10 µm coherence window (one window, M = 1024, slice samples 0.0039 apart in sin θ).
#[test]
fn diffraction_warning_agrees_with_the_wave_slice_of_a_grating() {
    let (lambda, sigma, lobe) = (0.55, 10.0, 10f64.to_radians());
    let cfg = WaveConfig {
        wavelength_um: lambda,
        sigma_um: sigma,
        windows: 1,
        ..Default::default()
    };
    // Height amplitude with phase excursion 2π·ξ3·a/λ = 1.435 rad at ξ3 = 2: J0 = J1 (Jacobi–Anger), so
    // orders 0 and ±1 are equally bright and a dip between them is the window's doing alone.
    let amp = 1.435 * lambda / (4.0 * PI);
    let slice = |d_um: f64| fft_slice(&grating(d_um, amp), &Vec3::new(0.0, 0.0, 1.0), &cfg).unwrap();
    // The row ψ̄y = 0 of the surface spectrum, and ψ̄x of each of its samples.
    let row = |s: &WaveSlice| -> (Vec<f64>, Vec<f64>) {
        let c = s.m / 2;
        (
            (0..s.m).map(|a| s.spectrum[c * s.m + a]).collect(),
            (0..s.m).map(|a| s.psi_bar(a, c).0).collect(),
        )
    };
    // Where the first order peaks: the largest sample within six of mλ/d.
    let first_order = |s: &WaveSlice, d_um: f64| -> f64 {
        let (r, x) = row(s);
        let k = (s.m as f64 / 2.0 + lambda / d_um / s.dpsi).round() as usize;
        let peak = (k - 6..=k + 6).max_by(|a, b| r[*a].total_cmp(&r[*b])).unwrap();
        x[peak]
    };

    // 10 µm: warned; the angle it states is where the slice's first order peaks (within half a sample).
    let w = diffraction_warning(0.010, lambda, lobe, sigma).unwrap();
    let s10 = slice(10.0);
    let theta1 = number_after(&w, "θ₁ = ").to_radians();
    let got = first_order(&s10, 10.0);
    assert!(
        (theta1.sin() - got).abs() <= s10.dpsi / 2.0 + 1e-4,
        "stated θ₁ = {}°, the slice's first order at sin θ = {got}: {w}",
        theta1.to_degrees()
    );
    // The orders it says fall inside the lobe are the slice's resolved peaks with 0 < sin θ < sin(lobe):
    // local maxima above the 4σ cut's sidelobes (≲ e^-8 in amplitude, 1e-7 of the specular peak).
    let stated = number_after(&w, "): ") as usize;
    let (r, x) = row(&s10);
    let top = r.iter().cloned().fold(0.0, f64::max);
    let peaks = (1..s10.m - 1)
        .filter(|&a| x[a] > s10.dpsi && x[a] < lobe.sin())
        .filter(|&a| r[a] > r[a - 1] && r[a] > r[a + 1] && r[a] > 1e-5 * top)
        .count();
    assert_eq!(peaks, stated, "{w}");

    // The stepover below which the first order leaves the lobe: 10% below it the slice's first order
    // is outside the lobe and there is no warning; 10% above, inside and warned.
    let edge = number_after(&w, "A stepover below ");
    for (d, outside) in [(0.9 * edge, true), (1.1 * edge, false)] {
        let sin1 = first_order(&slice(d), d);
        assert_eq!(sin1 > lobe.sin(), outside, "d = {d} µm: first order at sin θ = {sin1}");
        assert_eq!(
            diffraction_warning(d * 1e-3, lambda, lobe, sigma).is_some(),
            !outside,
            "d = {d} µm"
        );
    }

    // The stepover above which the orders blur: resolved means orders at least 4 spectral stds apart,
    // where two equal Gaussians dip to 2e^-2 = 0.27 of their peaks between them. At 0.7× the stated
    // value (5.7 stds) the slice dips below that between orders 0 and 1; at 2× (2 stds, where two
    // equal Gaussians no longer dip at all) it stays above, and no warning is given.
    let blur = number_after(&w, "one above ");
    let visibility = |d: f64| -> f64 {
        let s = slice(d);
        let (r, _) = row(&s);
        let (a0, a1) = (s.m / 2, (s.m as f64 / 2.0 + lambda / d / s.dpsi).round() as usize);
        let trough = r[a0..=a1].iter().cloned().fold(f64::INFINITY, f64::min);
        trough / r[a0].min(r[a1])
    };
    let boundary = 2.0 * (-2f64).exp();
    let (sharp, blurred) = (visibility(0.7 * blur), visibility(2.0 * blur));
    println!(
        "stated θ₁ {:.3}° (slice sin θ {got:.5}), {stated} orders inside ({peaks} peaks in the slice), lobe edge \
         {edge} µm, blur limit {blur} µm: trough/peak {sharp:.4} at {:.1} µm, {blurred:.4} at {:.1} µm",
        theta1.to_degrees(),
        0.7 * blur,
        2.0 * blur
    );
    assert!(sharp < boundary, "d = {} µm: trough/peak {sharp}", 0.7 * blur);
    assert!(blurred > boundary, "d = {} µm: trough/peak {blurred}", 2.0 * blur);
    assert!(diffraction_warning(2.0 * blur * 1e-3, lambda, lobe, sigma).is_none());
    // The warned 10 µm stepover lies between the two remedies it states.
    assert!(edge < 10.0 && 10.0 < blur, "{w}");
}
