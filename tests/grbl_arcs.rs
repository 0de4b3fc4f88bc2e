//! The arcs the simulation cuts for a GRBL machine against the **real GRBL 1.1h firmware**'s step trace: GRBL
//! draws a `G2`/`G3` as straight chords of at most its `$12` sagitta, and the simulation must follow those
//! chords, not the arc (docs/MACHINE.md §3). The harness is `grbl_harness` (tests/grbl_firmware.rs).

mod grbl_harness;

use brdfmill::gcode::Dialect;
use brdfmill::stages::simulate::gcode::{parse_all, ParseOptions};
use grbl_harness::*;

/// Distance from `p` to the segment `a`–`b`, mm.
fn to_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let d: Vec<f64> = (0..3).map(|i| b[i] - a[i]).collect();
    let l2: f64 = d.iter().map(|v| v * v).sum();
    let t = if l2 > 0.0 {
        ((0..3).map(|i| (p[i] - a[i]) * d[i]).sum::<f64>() / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (0..3).map(|i| (p[i] - a[i] - t * d[i]).powi(2)).sum::<f64>().sqrt()
}

/// A quarter circle in XY (`G3`, r = 5 mm) and one in ZX (`G18 G2`), with `$12` = 0.05 mm so that the chords
/// stand well clear of the arc (sagitta ≈ 60 µm) against GRBL's 4 µm steps. Every sample of the firmware's
/// step trace lies within two steps of the simulation's path; every vertex of the simulation's chords is
/// passed within two steps (the same segmentation: a chord count off by one moves the vertices 0.26 mm);
/// and the trace departs from the true XY arc by the chords' sagitta, so this tells chords from arcs.
#[test]
fn the_simulation_cuts_grbl_arcs_as_the_firmware_draws_them() {
    let _one = one_at_a_time();
    let Some((kit, exe)) = kit_or_skip("grbl arcs") else {
        return;
    };
    let tol_mm = 0.05;
    let sim = Sim::start(&kit, &exe, &["$12=0.05"]);
    let text = "G21 G90 G94\nG0 X5 Y0 Z0\nG3 X0 Y5 I-5 J0 F1000\nG0 X10 Y5 Z0\nG18 G2 X15 Z-5 I0 K-5\nG17\n";
    let prog = sim.dir.path().join("arcs.nc");
    std::fs::write(&prog, text).unwrap();
    let j = sim.path("j.jsonl");
    let r = stream(&sim, &prog, &j, &[]);
    assert!(r.ok(), "{r:?}");
    sim.wait_at_rest();
    // the simulation's path, as a GRBL machine at $12 = 0.05 draws it
    let opt = ParseOptions {
        dialect: Dialect::Grbl,
        start_mm: [0.0; 3],
        arc_tolerance_mm: tol_mm,
        ..Default::default()
    };
    let motion = parse_all(&[text], &opt).unwrap();
    let segs: Vec<([f64; 3], [f64; 3])> = motion.segments.iter().map(|s| (s.from, s.to)).collect();
    // the firmware's: every step-trace sample, mm (GRBL's stock 250 steps/mm on each axis)
    let trace: Vec<[f64; 3]> = std::fs::read_to_string(&sim.trace)
        .unwrap()
        .lines()
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            match f.as_slice() {
                [k, _, x, y, z] if *k == "T" || *k == "B" => {
                    let v = |s: &str| s.parse::<f64>().unwrap() / 250.0;
                    Some([v(x), v(y), v(z)])
                }
                _ => None,
            }
        })
        .collect();
    assert!(trace.len() > 100, "{} trace samples", trace.len());
    let step = 1.0 / 250.0;
    let worst = trace
        .iter()
        .map(|p| {
            segs.iter()
                .map(|(a, b)| to_segment(*p, *a, *b))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    let far: Vec<_> = trace
        .iter()
        .filter(|p| {
            segs.iter()
                .map(|(a, b)| to_segment(**p, *a, *b))
                .fold(f64::INFINITY, f64::min)
                > 2.0 * step
        })
        .take(5)
        .collect();
    assert!(
        worst <= 2.0 * step,
        "a trace sample {worst} mm from the simulated path: {far:?} of {segs:?}"
    );
    let arc_vertices: Vec<[f64; 3]> = motion
        .segments
        .iter()
        .filter(|s| s.kind == brdfmill::stages::simulate::gcode::SegmentKind::Arc)
        .map(|s| s.to)
        .collect();
    assert!(arc_vertices.len() >= 8, "{arc_vertices:?}");
    for v in &arc_vertices {
        let near = trace
            .iter()
            .map(|p| (0..3).map(|i| (p[i] - v[i]).powi(2)).sum::<f64>().sqrt());
        let d = near.fold(f64::INFINITY, f64::min);
        assert!(d <= 2.0 * step, "the firmware passes {d} mm from the vertex {v:?}");
    }
    // the XY quarter: the trace falls inside the true circle by about the sagitta
    let inside = trace
        .iter()
        .filter(|p| p[2].abs() < 1e-9 && p[0] > 0.1 && p[1] > 0.1 && p[0] < 5.0 && p[1] < 5.0)
        .map(|p| 5.0 - p[0].hypot(p[1]))
        .fold(0.0, f64::max);
    println!("worst trace sample {worst:.4} mm from the chords; up to {inside:.4} mm inside the arc");
    assert!(inside > 0.04, "the trace follows the arc, not chords: {inside} mm");
}
