//! The simulation's acceptance figures (issue "Cut simulation"): grooves of the exact cross-section for
//! straight, diagonal, sloped and arc moves of a ball, a flat floor for a flat bit, and the toolpath stage's
//! finishing program reproducing the design within scallop plus tolerance wherever the bit can reach.

use brdfmill::cut::machine::Machine;
use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::facets::{self, FacetsConfig};
use brdfmill::stages::ndf::{self, NdfConfig};
use brdfmill::stages::simulate::{self, Shape, SimulateConfig, Simulation};
use brdfmill::stages::toolpath::{self, ToolpathConfig};
use std::path::Path;

const R: f64 = 0.5;

fn sim(prog: &str, tool: Shape, pitch_um: f64) -> Simulation {
    let cfg = SimulateConfig {
        tool,
        pitch_um,
        ..Default::default()
    };
    simulate::run(prog, &cfg).unwrap()
}

/// Independent reference for a ball swept along a 3D segment: golden-section minimisation over the segment
/// parameter of the ball's underside above the point (convex in t).
fn capsule_reference(a: [f64; 3], b: [f64; 3], x: f64, y: f64) -> f64 {
    let f = |t: f64| {
        let p = [
            a[0] + t * (b[0] - a[0]),
            a[1] + t * (b[1] - a[1]),
            a[2] + t * (b[2] - a[2]),
        ];
        let d2 = (x - p[0]).powi(2) + (y - p[1]).powi(2);
        if d2 > R * R {
            f64::INFINITY
        } else {
            p[2] + R - (R * R - d2).sqrt()
        }
    };
    // the domain where the ball covers (x, y): an interval; find it by dense scan, then golden section
    let n = 2000;
    let ks: Vec<usize> = (0..=n).filter(|k| f(*k as f64 / n as f64).is_finite()).collect();
    if ks.is_empty() {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = (
        (ks[0] as f64 - 1.0).max(0.0) / n as f64,
        (ks[ks.len() - 1] as f64 + 1.0).min(n as f64) / n as f64,
    );
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..200 {
        let (c, d) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if f(c) <= f(d) {
            hi = d;
        } else {
            lo = c;
        }
    }
    f(0.5 * (lo + hi)).min(f(0.0)).min(f(1.0))
}

/// Largest |simulated − reference| over the cells whose centre projects inside the segment, away from its
/// ends by one radius, and the groove's width measured on the grid at the stock top.
fn groove_error(s: &Simulation, a: [f64; 3], b: [f64; 3]) -> (f64, usize) {
    let hf = &s.heightfield;
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l = (dx * dx + dy * dy).sqrt();
    let mut worst: f64 = 0.0;
    let mut n = 0;
    for j in 0..hf.ny {
        for i in 0..hf.nx {
            let [x, y] = s.cell_xy(i, j);
            let t = ((x - a[0]) * dx + (y - a[1]) * dy) / (l * l);
            if t * l < R || (1.0 - t) * l < R {
                continue;
            }
            let r = capsule_reference(a, b, x, y).min(0.0);
            worst = worst.max((hf.at(i, j) - r).abs());
            n += 1;
        }
    }
    (worst, n)
}

#[test]
fn ball_grooves_have_the_exact_cross_section() {
    let ball = Shape::Ball { diameter_mm: 2.0 * R };
    for (what, a, b) in [
        ("straight", [0.0, 0.0, -0.2], [3.0, 0.0, -0.2]),
        ("diagonal", [0.0, 0.0, -0.2], [2.3, 1.7, -0.2]),
        ("sloped", [0.0, 0.0, -0.05], [2.5, 1.0, -0.35]),
    ] {
        let prog = format!(
            "G21 G90\nG0 X{} Y{} Z1\nG1 Z{} F200\nX{} Y{} Z{}\nG0 Z1\nM2\n",
            a[0], a[1], a[2], b[0], b[1], b[2]
        );
        let s = sim(&prog, ball, 5.0);
        let (err, n) = groove_error(&s, a, b);
        println!("{what}: {n} cells, largest error {err:.2e} mm");
        assert!(n > 10_000, "{what}: {n} cells checked");
        assert!(err < 1e-9, "{what}: error {err} mm");
    }
    // width at the stock top of the straight groove: 2 sqrt(r² − (r − d)²), within one pitch
    let s = sim("G0 X0 Y0 Z1\nG1 Z-0.2 F200\nX3\nG0 Z1\n", ball, 5.0);
    let hf = &s.heightfield;
    let i = (1.5 - s.origin_mm[0]) / hf.pitch_mm;
    let cut: usize = (0..hf.ny).filter(|&j| hf.at(i as usize, j) < -1e-12).count();
    let width = cut as f64 * hf.pitch_mm;
    let exact = 2.0 * (R * R - (R - 0.2f64).powi(2)).sqrt();
    println!("straight groove width {width:.4} mm, exact {exact:.4} mm");
    assert!((width - exact).abs() <= hf.pitch_mm, "{width} vs {exact}");
}

#[test]
fn arc_groove_is_a_torus_within_the_arc_tolerance() {
    // a half circle of radius 2 about (0, 0) at depth 0.2: the exact sweep is a torus, z = −0.2 + r −
    // sqrt(r² − (ρ − 2)²); the chords lie within the sagitta tolerance inside the circle, so the radial
    // distance implied by the simulated height is off by at most that tolerance.
    let tol_um = 0.1;
    let cfg = SimulateConfig {
        tool: Shape::Ball { diameter_mm: 2.0 * R },
        pitch_um: 5.0,
        arc_tolerance_um: tol_um,
        ..Default::default()
    };
    let s = simulate::run("G0 X2 Y0 Z1\nG1 Z-0.2 F200\nG3 X-2 Y0 I-2 J0\nG0 Z1\n", &cfg).unwrap();
    let hf = &s.heightfield;
    let (mut worst, mut n) = (0.0f64, 0);
    for j in 0..hf.ny {
        for i in 0..hf.nx {
            let [x, y] = s.cell_xy(i, j);
            let rho = (x * x + y * y).sqrt();
            let d = (rho - 2.0).abs();
            if y < R || d > 0.39 {
                continue; // away from the ends; inside the groove (half-width 0.4 mm at the top)
            }
            let z = hf.at(i, j);
            // the radial offset implied by the height
            let implied = (R * R - (z + 0.2 - R).powi(2)).max(0.0).sqrt();
            worst = worst.max((implied - d).abs());
            n += 1;
        }
    }
    println!(
        "arc: {n} cells, largest radial error {:.4} µm (tolerance {tol_um} µm)",
        worst * 1e3
    );
    assert!(n > 10_000);
    assert!(worst <= tol_um * 1e-3 + 1e-9, "radial error {worst} mm");
    assert_eq!(s.stats.arcs, 1);
}

#[test]
fn flat_bit_leaves_a_flat_floor_and_bull_its_corner() {
    let prog = "G0 X0 Y0 Z1\nG1 Z-0.1 F200\nX3 Y1\nG0 Z1\n";
    let (a, b) = ([0.0, 0.0], [3.0, 1.0]);
    let dist = |x: f64, y: f64| {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let t = (((x - a[0]) * dx + (y - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        ((x - a[0] - t * dx).powi(2) + (y - a[1] - t * dy).powi(2)).sqrt()
    };
    let flat = sim(prog, Shape::Flat { diameter_mm: 1.0 }, 5.0);
    let bull = sim(
        prog,
        Shape::Bull {
            diameter_mm: 1.0,
            corner_radius_mm: 0.2,
        },
        5.0,
    );
    let (mut floor, mut worst_bull) = (0, 0.0f64);
    for j in 0..flat.heightfield.ny {
        for i in 0..flat.heightfield.nx {
            let [x, y] = flat.cell_xy(i, j);
            let d = dist(x, y);
            let z = flat.heightfield.at(i, j);
            if d < 0.5 - 1e-9 {
                assert_eq!(z, -0.1, "flat floor at ({x}, {y})");
                floor += 1;
            } else if d > 0.5 + 1e-9 {
                assert_eq!(z, 0.0, "outside the flat bit's reach at ({x}, {y})");
            }
            // bull: flat within 0.3 of the path, the corner's circle beyond
            let zb = bull.heightfield.at(i, j);
            let expect = if d <= 0.3 {
                -0.1
            } else if d < 0.5 {
                (-0.1 + 0.2 - (0.04 - (d - 0.3).powi(2)).sqrt()).min(0.0)
            } else {
                0.0
            };
            worst_bull = worst_bull.max((zb - expect).abs());
        }
    }
    println!("flat floor cells {floor}; bull largest error {worst_bull:.2e} mm");
    assert!(floor > 50_000);
    assert!(worst_bull < 2e-9, "bull error {worst_bull}");
}

#[test]
fn finishing_program_reproduces_the_design_where_the_bit_reaches() {
    // A small design: 4×4 facets of 1 mm at 10 µm, cut over a 3×3 mm area with a 1 mm ball, scallop 1 µm.
    let n = ndf::run(&NdfConfig::default(), &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
    let fcfg = FacetsConfig {
        facets_x: 4,
        facets_y: 4,
        test_permutations: 19,
        ..Default::default()
    };
    let tile = facets::run(&fcfg, &n.target).unwrap().heightfield;
    let machine = Machine::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/linuxcnc-mill.toml")).unwrap();
    let tcfg = ToolpathConfig {
        tool: "ball1".into(),
        area_mm: [3.0, 3.0],
        scallop_um: 1.0,
        tolerance_um: 0.5,
        ..Default::default()
    };
    let prog = toolpath::run(&tcfg, &tile, &machine).unwrap();
    let tool = Shape::Ball { diameter_mm: 1.0 };
    let s = simulate::run(
        &prog.gcode,
        &SimulateConfig {
            tool,
            pitch_um: 5.0,
            ..Default::default()
        },
    )
    .unwrap();
    let d = simulate::deviation(&s, &tile, &tool);
    println!(
        "{} lines simulated ({:.3e} cells swept); interior {} cells, unreachable {:.1}%",
        prog.summary.lines,
        s.stats.swept_cells as f64,
        d.interior_cells,
        100.0 * d.unreachable_fraction
    );
    println!(
        "over {:.3} µm at {:?}; over where reachable {:.3} µm at {:?}; under {:.3} µm at {:?}; above the opening \
         {:.3} µm at {:?}; rms reachable {:.3} µm",
        d.max_over_um,
        d.max_over_at_mm,
        d.max_over_reachable_um,
        d.max_over_reachable_at_mm,
        d.max_under_um,
        d.max_under_at_mm,
        d.max_above_opening_um,
        d.max_above_opening_at_mm,
        d.rms_reachable_um
    );
    let scallop = prog.summary.scallop_um;
    assert!(d.interior_cells > 50_000);
    // never below the design beyond the G-code's rounding (0.05 µm per axis) and the sampling of the
    // design between its samples
    assert!(d.max_under_um < 0.2, "gouge {} µm", d.max_under_um);
    // the concave facet edges narrower than the ball are found, and they are a minority
    assert!(d.unreachable_fraction > 0.01 && d.unreachable_fraction < 0.6);
    // Next to an unreachable valley the raster's cusps are not the flat scallop: the bit in the valley is
    // held by both flanks, and passes beside the valley's axis stand higher. Report the largest height over
    // the design as a function of the distance from unreachable cells.
    let (nx, ny) = (d.nx, d.ny);
    let near = |k: usize| -> Vec<bool> {
        // unreachable mask dilated by a square of half-width k cells (separable)
        let mut a = vec![false; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                a[j * nx + i] = (i.saturating_sub(k)..(i + k + 1).min(nx)).any(|ii| d.unreachable[j * nx + ii]);
            }
        }
        let mut b = vec![false; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                b[j * nx + i] = (j.saturating_sub(k)..(j + k + 1).min(ny)).any(|jj| a[jj * nx + i]);
            }
        }
        b
    };
    let mut away = vec![];
    for k in [0usize, 4, 8, 16, 32] {
        let m = near(k);
        let worst = d
            .map_um
            .iter()
            .zip(&m)
            .filter(|(v, n)| v.is_finite() && !**n)
            .map(|(v, _)| *v as f64)
            .fold(f64::NEG_INFINITY, f64::max);
        println!(
            "  reachable cells at least {} µm from unreachable ones: largest over {worst:.3} µm",
            k as f64 * 5.0
        );
        away.push(worst);
    }
    // Where the bit reaches, 40 µm or more from an unreachable cell: within the scallop plus the
    // simplification tolerance, plus 0.1 µm for the G-code's rounding and the design's sampling.
    let bound = scallop + tcfg.tolerance_um + 0.1;
    assert!(
        away[2] <= bound,
        "{} µm over, 40 µm from unreachable cells (bound {bound})",
        away[2]
    );
    // closer to the valleys the cusps grow, but stay within a few scallops
    assert!(
        d.max_over_reachable_um <= 3.0 * bound,
        "{} µm over where reachable",
        d.max_over_reachable_um
    );
    assert!(d.rms_reachable_um <= scallop + tcfg.tolerance_um);
}
