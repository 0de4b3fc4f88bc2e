use super::*;

/// A surface with features at several scales: Gaussian bumps and pits at seeded places, and a fine ripple.
fn surface(x: f64, y: f64) -> f64 {
    seeded(7, x, y)
}

fn seeded(seed: u64, x: f64, y: f64) -> f64 {
    let mut s = 0.0;
    let mut state = seed;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..60 {
        let (cx, cy, w, a) = (rnd() * 3.0, rnd() * 3.0, 0.05 + 0.2 * rnd(), (rnd() - 0.5) * 0.06);
        s += a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * w * w)).exp();
    }
    s + 0.001 * (x * 40.0).sin() * (y * 31.0).cos()
}

fn grid(nx: usize, ny: usize, p: f64, f: impl Fn(f64, f64) -> Option<f64> + Sync) -> Grid {
    let cells: Vec<Option<f64>> = (0..nx * ny)
        .map(|k| f(((k % nx) as f64 + 0.5) * p, ((k / nx) as f64 + 0.5) * p))
        .collect();
    Grid {
        nx,
        ny,
        pitch_mm: p,
        z: cells.iter().map(|c| c.unwrap_or(0.0)).collect(),
        valid: cells.iter().map(Option::is_some).collect(),
    }
}

/// The simulation: 3 mm square at 10 µm.
fn sim() -> Grid {
    grid(300, 300, 0.01, |x, y| Some(surface(x, y)))
}

/// A scan of the same surface at `pitch`, `n × n` points, seeing sim point `x` at
/// `R(φ)(x − c_sim) + c_scan + t` (the pose's convention, written out here), tilted by `(gx, gy)` in its own
/// frame, missing where it falls off the simulated part.
fn scan(n: usize, pitch: f64, phi_deg: f64, t: [f64; 2], tilt: [f64; 2], noise_um: f64) -> Grid {
    let (c, s) = (phi_deg.to_radians().cos(), phi_deg.to_radians().sin());
    let cc = 0.5 * n as f64 * pitch;
    let mut state = 11u64;
    let mut gauss = move || {
        let mut u = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (-2.0 * u().ln()).sqrt() * (std::f64::consts::TAU * u()).cos()
    };
    let noise: Vec<f64> = (0..n * n).map(|_| gauss() * noise_um * 1e-3).collect();
    grid(n, n, pitch, |xs, ys| {
        // invert: x = R(−φ)(X − c_scan − t) + c_sim
        let (dx, dy) = (xs - cc - t[0], ys - cc - t[1]);
        let (x, y) = (c * dx + s * dy + 1.5, -s * dx + c * dy + 1.5);
        if !(0.0..3.0).contains(&x) || !(0.0..3.0).contains(&y) {
            return None;
        }
        let k = ((ys / pitch) as usize) * n + (xs / pitch) as usize;
        Some(surface(x, y) + tilt[0] * xs + tilt[1] * ys + 0.2 + noise[k])
    })
}

#[test]
fn a_turned_shifted_tilted_noisy_scan_registers_to_the_pose_that_made_it() {
    let sim = sim();
    let tilt = 0.5f64.to_radians().tan();
    for (phi, t) in [
        (0.0, [0.0, 0.0]),
        (93.0, [0.4, -0.3]),
        (-87.5, [-0.7, 0.2]),
        (181.0, [0.1, 0.9]),
    ] {
        let sc = scan(400, 0.01, phi, t, [tilt * 0.6, tilt * 0.8], 0.2);
        let r = register(&sim, &sc, 0.02).expect("registers");
        assert!(!r.pose.mirrored, "a scan as made is not read mirrored");
        let err_phi = (r.pose.rotation_deg() - phi + 540.0).rem_euclid(360.0) - 180.0;
        assert!(err_phi.abs() < 0.02, "rotation {} for {phi}", r.pose.rotation_deg());
        for a in 0..2 {
            assert!(
                (r.pose.shift_mm[a] - t[a]).abs() < 2e-3,
                "shift {:?} for {t:?}",
                r.pose.shift_mm
            );
        }
        assert!((r.tilt_deg - 0.5).abs() < 0.01, "tilt {}", r.tilt_deg);
        // what is left is the scan's noise (0.2 µm) and bilinear reading of the surface's curvature
        assert!(r.residual_rms_um < 0.4, "residual {} µm at {phi}°", r.residual_rms_um);
        assert!(r.correlation > 0.999, "correlation {}", r.correlation);
        assert!(r.slope_correlation > 0.99, "slopes agree {}", r.slope_correlation);
        // the share of simulation points whose scan point has four measured scan points around it
        let (c, s) = (phi.to_radians().cos(), phi.to_radians().sin());
        let inside = (0..300 * 300)
            .filter(|k| {
                let (dx, dy) = (
                    (k % 300) as f64 * 0.01 + 0.005 - 1.5,
                    (k / 300) as f64 * 0.01 + 0.005 - 1.5,
                );
                let q = [c * dx - s * dy + 2.0 + t[0], s * dx + c * dy + 2.0 + t[1]];
                let (u, v) = (q[0] / 0.01 - 0.5, q[1] / 0.01 - 0.5);
                if !(u >= 0.0 && v >= 0.0 && u < 399.0 && v < 399.0) {
                    return false;
                }
                let (i, j) = (u as usize, v as usize);
                [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
                    .iter()
                    .all(|&(i, j)| sc.valid[j * 400 + i])
            })
            .count() as f64
            / 90_000.0;
        // (a scan point on a grid line counts or not by the last bit of the pose: one row either way)
        assert!(
            (r.coverage - inside).abs() < 0.01,
            "coverage {} of {inside}",
            r.coverage
        );
    }
}

#[test]
fn a_scan_of_a_far_corner_of_the_part_registers() {
    // a quarter of the part's side, off centre by more than half the part: the translation at the
    // correlation's peak is far from zero and negative
    let sim = sim();
    for (phi, corner) in [(0.0, [2.55, 2.55]), (-90.0, [0.45, 2.55]), (2.0, [2.55, 0.45])] {
        // the scan's centre sees the part's point `corner`: t = −R(φ)(corner − c_sim), c_sim = 1.5
        let (c, s) = (f64::to_radians(phi).cos(), f64::to_radians(phi).sin());
        let v = [corner[0] - 1.5, corner[1] - 1.5];
        let t = [-(c * v[0] - s * v[1]), -(s * v[0] + c * v[1])];
        let sc = scan(80, 0.01, phi, t, [0.0, 0.0], 0.0);
        let r = register(&sim, &sc, 0.02).expect("registers");
        let err_phi = (r.pose.rotation_deg() - phi + 540.0).rem_euclid(360.0) - 180.0;
        assert!(err_phi.abs() < 0.05, "rotation {} for {phi}", r.pose.rotation_deg());
        assert!(
            r.residual_rms_um < 0.5,
            "residual {} µm at {phi}°, {t:?}",
            r.residual_rms_um
        );
        assert!(r.slope_correlation > 0.99, "slopes agree {}", r.slope_correlation);
    }
}

#[test]
fn a_scan_whose_rows_run_the_other_way_registers_mirrored() {
    // an instrument that counts rows from the other edge: the scan made as above, its rows reversed;
    // registration reads it mirrored and finds what it finds for the scan as made, and the pose that made it
    let sim = sim();
    let tilt = 0.5f64.to_radians().tan();
    for (n, phi, t) in [
        (400, 93.0, [0.4, -0.3]),
        (400, -2.0, [0.0, 0.0]),
        (120, 0.0, [0.9, 0.9]),
    ] {
        let sc = scan(n, 0.01, phi, t, [tilt * 0.6, 0.0], 0.2);
        let (r0, r) = (
            register(&sim, &sc, 0.02).expect("registers"),
            register(&sim, &sc.mirrored(), 0.02).expect("registers"),
        );
        assert!(r.pose.mirrored && !r0.pose.mirrored, "read mirrored at {phi}°");
        let err_phi = (r.pose.rotation_deg() - phi + 540.0).rem_euclid(360.0) - 180.0;
        assert!(err_phi.abs() < 0.05, "rotation {} for {phi}", r.pose.rotation_deg());
        assert!(
            (0..2).all(|a| (r.pose.shift_mm[a] - t[a]).abs() < 2e-3),
            "shift {:?} for {t:?}",
            r.pose.shift_mm
        );
        assert!(r.residual_rms_um < 0.5, "residual {} µm", r.residual_rms_um);
        for (what, a, b) in [
            ("residual", r.residual_rms_um, r0.residual_rms_um),
            ("slope agreement", r.slope_correlation, r0.slope_correlation),
            ("coverage", r.coverage, r0.coverage),
        ] {
            assert!(
                (a - b).abs() < 1e-3 * b.abs().max(1.0),
                "{what}: {a} mirrored, {b} as made ({n} points at {phi}°)"
            );
        }
    }
}

#[test]
fn a_scan_far_larger_than_the_part_is_refused() {
    let sim = sim();
    let big = grid(700, 700, 0.01, |x, y| Some(surface(x, y)));
    assert!(matches!(
        register(&sim, &big, 0.02),
        Err(RegisterError::TooLarge { .. })
    ));
}

#[test]
fn a_scan_at_another_pitch_is_read_onto_the_simulations() {
    let sim = sim();
    let sc = scan(260, 0.015, 2.0, [0.05, 0.1], [0.0, 0.0], 0.0);
    let r = register(&sim, &sc, 0.02).expect("registers");
    assert!(
        (r.pose.rotation_deg() - 2.0).abs() < 0.05,
        "rotation {}",
        r.pose.rotation_deg()
    );
    assert!(r.residual_rms_um < 1.0, "residual {} µm", r.residual_rms_um);
}

#[test]
fn another_surface_correlates_poorly() {
    let sim = sim();
    // the same kind of surface from another seed: another part
    let other = grid(300, 300, 0.01, |x, y| Some(seeded(8, x, y)));
    let r = register(&sim, &other, 0.02).expect("some pose");
    let own = register(&sim, &scan(300, 0.01, 0.0, [0.0; 2], [0.0; 2], 0.0), 0.02).expect("registers");
    assert!(own.correlation > 0.999 && own.slope_correlation > 0.999);
    assert!(r.correlation < 0.8, "a different surface correlates {}", r.correlation);
    assert!(r.slope_correlation < 0.5, "its slopes agree {}", r.slope_correlation);
    assert!(r.residual_rms_um > 5.0, "residual {}", r.residual_rms_um);
}

#[test]
fn a_scan_of_a_few_points_is_refused() {
    let sim = sim();
    let tiny = grid(10, 10, 0.01, |x, y| Some(surface(x, y)));
    assert!(matches!(
        register(&sim, &tiny, 0.02),
        Err(RegisterError::TooSmall { .. })
    ));
}

#[test]
fn a_part_in_flat_stock_registers_in_a_frame_of_flat_stock() {
    // the cut in the middle of a flat top, scanned with more flat top around it and a tilt: flat against flat
    // correlates as rounding, which must not win
    let part = |x: f64, y: f64| {
        if (0.75..2.25).contains(&x) && (0.75..2.25).contains(&y) {
            surface(x, y)
        } else {
            0.0
        }
    };
    let sim = grid(300, 300, 0.01, |x, y| Some(part(x, y)));
    let (t, tilt) = ([0.6, -0.4], 0.3f64.to_radians().tan());
    // X = x − c_sim + c_scan + t, c_sim = 1.5, c_scan = 2.0
    let sc = grid(400, 400, 0.01, |xs, ys| {
        let (x, y) = (xs - 2.0 - t[0] + 1.5, ys - 2.0 - t[1] + 1.5);
        Some(part(x, y) + tilt * xs)
    });
    let r = register(&sim, &sc, 0.02).expect("registers");
    let err_phi = (r.pose.rotation_deg() + 540.0).rem_euclid(360.0) - 180.0;
    assert!(err_phi.abs() < 0.02, "rotation {}", r.pose.rotation_deg());
    assert!(
        (r.pose.shift_mm[0] - t[0]).abs() < 2e-3 && (r.pose.shift_mm[1] - t[1]).abs() < 2e-3,
        "shift {:?}",
        r.pose.shift_mm
    );
    assert!((r.tilt_deg - 0.3).abs() < 0.01, "tilt {}", r.tilt_deg);
}
