//! The simulation cuts what the declared machine cuts (issue "The machine in the loop"): each error of a
//! profile's `[accuracy]` against a closed form of what it does to a cut, independent of the code under test
//! (docs/MACHINE.md).
//!
//! - Runout: a spindle whose tip circles at `e = TIR/2` about its axis cuts with the envelope of the ball
//!   over that circle, so a straight groove of depth `d` has the ball's cross-section split by a flat of
//!   width `2e`: `z(y) = −d + r − √(r² − max(|y| − e, 0)²)`, and is wider by the TIR.
//! - Backlash `b` on X: with passes along X cut alternately forward and back, the table stands `b` behind on
//!   one direction relative to the other, so on a plane of slope `p` along X neighbouring passes' floors
//!   differ by `p·b`.
//! - Step grid: every target is reached on the motors' grid, so a groove commanded off the grid is cut on
//!   the nearest step (no point moves by more than half a step).

use brdfmill::cut::accuracy::Accuracy;
use brdfmill::cut::machine::Machine;
use brdfmill::stages::simulate::{self, Shape, SimulateConfig, Simulation};
use std::path::Path;

const R: f64 = 0.25;

fn machine(acc: Accuracy) -> Machine {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut m = Machine::load(&root.join("machines/linuxcnc-mill.toml")).unwrap();
    m.accuracy = Some(acc);
    m
}

fn cut(prog: &str, acc: Accuracy, pitch_um: f64, bounds: [f64; 4]) -> Simulation {
    let cfg = SimulateConfig {
        tool: Shape::Ball { diameter_mm: 2.0 * R },
        pitch_um,
        bounds_mm: Some(bounds),
        machine: Some(machine(acc)),
        ..Default::default()
    };
    simulate::run(prog, &cfg).unwrap()
}

/// The cells of the row nearest `x`, as (y, z).
fn column_at(s: &Simulation, x: f64) -> Vec<(f64, f64)> {
    let hf = &s.heightfield;
    let i = (0..hf.nx)
        .min_by(|&a, &b| {
            (s.cell_xy(a, 0)[0] - x)
                .abs()
                .total_cmp(&(s.cell_xy(b, 0)[0] - x).abs())
        })
        .unwrap();
    (0..hf.ny).map(|j| (s.cell_xy(i, j)[1], hf.at(i, j))).collect()
}

#[test]
fn a_groove_cut_with_runout_is_the_balls_split_by_the_runout_and_wider_by_it() {
    let d = 0.05;
    let prog = format!(
        "G21 G90 G17\nG0 Z1\nG0 X0 Y0\nG1 Z{} F100\nG1 X2 F500\nG0 Z1\nM30\n",
        -d
    );
    let bounds = [-0.5, -0.5, 2.5, 0.5];
    for tir_um in [0.0, 15.0, 40.0] {
        let e = tir_um * 1e-3 / 2.0;
        let acc = Accuracy {
            runout_um: tir_um,
            ..Accuracy::PERFECT
        };
        let s = cut(&prog, acc, 1.0, bounds);
        let mut worst: f64 = 0.0;
        let mut width = 0usize;
        for (y, z) in column_at(&s, 1.0) {
            let u = (y.abs() - e).max(0.0);
            let closed = if u < R {
                (-d + R - (R * R - u * u).sqrt()).min(0.0)
            } else {
                0.0
            };
            worst = worst.max((z - closed).abs());
            width += usize::from(z < -1e-9);
        }
        assert!(
            worst < 1e-8,
            "TIR {tir_um} µm: cross-section off the closed form by {worst} mm"
        );
        // the width at the stock top, on the 1 µm grid: 2(e + √(2rd − d²)) to within a cell either side
        let want = 2.0 * (e + (2.0 * R * d - d * d).sqrt()) / 1e-3;
        assert!(
            (width as f64 - want).abs() <= 2.0,
            "TIR {tir_um} µm: groove {width} µm wide, the closed form {want:.1} µm"
        );
    }
}

#[test]
fn zigzag_passes_with_backlash_leave_slope_times_backlash_between_them() {
    // a plane falling along X with slope p, cut by passes along X at 0.3 mm apart, alternately forward and
    // back (the passes are far enough apart that each pass's floor is its own)
    let p = 0.1;
    let (n, s) = (6, 0.3);
    let mut prog = String::from("G21 G90 G17\nG0 Z1\nG0 X0 Y0\n");
    for k in 0..n {
        let y = k as f64 * s;
        let (x0, x1) = if k % 2 == 0 { (0.0, 3.0) } else { (3.0, 0.0) };
        prog.push_str(&format!("G0 X{x0} Y{y:.3}\nG1 Z{:.6} F100\n", -0.1 - p * x0));
        prog.push_str(&format!("G1 X{x1} Z{:.6} F500\nG0 Z1\n", -0.1 - p * x1));
    }
    prog.push_str("M30\n");
    let bounds = [-0.5, -0.5, 3.5, (n - 1) as f64 * s + 0.5];
    for b_um in [0.0, 25.0, 50.0] {
        let acc = Accuracy {
            backlash_um: [b_um, 0.0, 0.0],
            ..Accuracy::PERFECT
        };
        let sim = cut(&prog, acc, 2.0, bounds);
        let col = column_at(&sim, 1.5);
        // each pass's floor: the lowest cell within half a stepover of its line
        let floors: Vec<f64> = (0..n)
            .map(|k| {
                let y = k as f64 * s;
                col.iter()
                    .filter(|(cy, _)| (cy - y).abs() < s / 2.0)
                    .map(|c| c.1)
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let want = p * b_um * 1e-3;
        for w in floors.windows(2) {
            let step = (w[0] - w[1]).abs();
            // the floor is sampled on a 2 µm grid across a ball's bottom: within r(1 − cos) of a cell
            assert!(
                (step - want).abs() < 1e-5,
                "backlash {b_um} µm: step {step} mm between passes, p·b = {want} mm (floors {floors:?})"
            );
        }
    }
}

#[test]
fn an_off_grid_groove_is_cut_on_the_nearest_step() {
    // a groove commanded at y = 0.1234567 mm: on a 1/800 mm grid it lies at the nearest step, 0.12375
    let y = 0.1234567;
    let prog = format!("G21 G90 G17\nG0 Z1\nG0 X0 Y{y}\nG1 Z-0.05 F100\nG1 X1 F500\nG0 Z1\nM30\n");
    let steps = 800.0;
    let acc = Accuracy {
        steps_per_mm: Some([steps; 3]),
        ..Accuracy::PERFECT
    };
    let sim = cut(&prog, acc, 0.25, [-0.3, -0.2, 1.3, 0.45]);
    // the groove's axis: the midpoint of the cells below a level on either side (its cross-section is
    // symmetric about the axis), interpolated linearly between cells
    let col = column_at(&sim, 0.5);
    let level = -0.02;
    let below: Vec<usize> = (0..col.len()).filter(|&j| col[j].1 < level).collect();
    let cross = |a: usize, b: usize| {
        let ((ya, za), (yb, zb)) = (col[a], col[b]);
        ya + (level - za) * (yb - ya) / (zb - za)
    };
    let (j0, j1) = (below[0], *below.last().unwrap());
    let (left, right) = (cross(j0 - 1, j0), cross(j1, j1 + 1));
    let axis = 0.5 * (left + right);
    let on_grid = (y * steps).round() / steps;
    assert!(
        (axis - on_grid).abs() < 5e-5,
        "groove axis {axis} mm, the nearest step {on_grid} mm"
    );
    assert!((axis - y).abs() <= 0.5 / steps + 5e-5, "moved {} mm", (axis - y).abs());
    assert!(
        (on_grid - y).abs() > 2e-4,
        "the test needs a groove visibly off the grid"
    );
}
