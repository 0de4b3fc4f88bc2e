//! `brdfmill calibrate`: the coupon program and its sheet for every shipped profile; the sheet's readings
//! checked against an independent truth (the coupon cut by the simulator on a machine with known backlash,
//! runout and scale errors, its walls measured on the simulated heightfield); LinuxCNC's own interpreter
//! accepts the LinuxCNC coupon; the GRBL coupon streams to the virtual GRBL 1.1h controller.

use brdfmill::apps::calibrate::{self, CalibrateConfig, Coupon, CouponSpec};
use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig};
use brdfmill::apps::stream::program::Program;
use brdfmill::apps::stream::serial::{Link, SerialLink};
use brdfmill::apps::stream::session::{self, Config, Mode, Outcome, Silent};
use brdfmill::cut::machine::{Accuracy, Dialect, Machine, Stock};
use brdfmill::stages::simulate::{self, gcode, SimulateConfig, Simulation};
use std::path::Path;
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

const PROFILES: [&str; 3] = ["grbl-3018", "grbl-router-6040", "linuxcnc-mill"];

fn machine(name: &str) -> Machine {
    Machine::find(name, Path::new("")).unwrap().1
}

fn coupon(m: &Machine) -> Coupon {
    calibrate::coupon(m, &CalibrateConfig::default()).unwrap_or_else(|e| panic!("{}: {e}", m.name))
}

#[test]
fn every_shipped_profile_gets_a_program_and_a_sheet_that_names_the_keys() {
    for name in PROFILES {
        let m = machine(name);
        let c = coupon(&m);
        let dir = tempfile::tempdir().unwrap();
        let written = c.write(dir.path()).unwrap();
        let linuxcnc = m.dialect == Dialect::Linuxcnc;
        assert_eq!(written.len(), if linuxcnc { 4 } else { 3 }, "{name}: {written:?}");
        for f in ["calibrate.nc", "calibrate.md", "calibrate.json"] {
            assert!(dir.path().join(f).is_file(), "{name}: {f}");
        }
        assert_eq!(dir.path().join("tool.tbl").is_file(), linuxcnc, "{name}");
        let sheet = std::fs::read_to_string(dir.path().join("calibrate.md")).unwrap();
        for key in ["accuracy.backlash_um", "accuracy.runout_um", "accuracy.steps_per_mm"] {
            assert!(sheet.contains(key), "{name}: the sheet does not name {key}");
        }
        let controller = if linuxcnc {
            ["SCALE", "[JOINT_0]"]
        } else {
            ["$100", "$101"]
        };
        assert!(controller.iter().all(|k| sheet.contains(k)), "{name}: {controller:?}");
        assert!(sheet.contains("50 x 30 mm") && sheet.contains("front-left corner") && sheet.contains("Z0"));
        assert!(!sheet.contains('{'), "{name}: a field left unfilled:\n{sheet}");
        // the dimensions: on the block, lands equal, the longest span at least 30 mm
        let spec: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("calibrate.json")).unwrap()).unwrap();
        assert_eq!(spec["format"], "brdfmill-calibrate");
        let s = &c.spec;
        for f in [&s.x, &s.y] {
            assert_eq!(f.lands_mm[0], f.lands_mm[1], "{name} {}", f.axis);
            assert!(f.lands_mm[0] >= calibrate::MIN_LAND_MM);
        }
        assert!(s.x.pitch_mm >= 30.0, "{name}: P_x = {}", s.x.pitch_mm);
        assert!(s.depth_mm <= 1.0 && s.stock_mm[0] <= 50.0 && s.stock_mm[1] <= 30.0);
        assert_eq!(s.tool.kind, "flat", "{name}: the default tool is a flat end mill");
        // the program: spindle and dwell before the first cut, comments safe, ends with M30
        let g = &c.gcode;
        assert!(
            g.contains("M3 S") && g.contains("G4 P") && g.trim_end().ends_with("M30"),
            "{name}"
        );
        assert!(g.lines().all(|l| l.len() < 80), "{name}: a line beyond GRBL's buffer");
        assert!(
            g.contains(&format!("T{} M6", s.tool.number)) == linuxcnc,
            "{name}: tool change"
        );
        let first_cut = g.find("G1 ").unwrap();
        assert!(
            g[..first_cut].contains("M3 S") && g[..first_cut].contains("G4 P"),
            "{name}"
        );
        assert!(
            s.estimated_s > 5.0 && s.estimated_s < 600.0,
            "{name}: {} s",
            s.estimated_s
        );
        println!("{name}: {} s, {} blocks", s.estimated_s, s.blocks);
    }
}

#[test]
fn tools_that_cannot_cut_it_are_refused_by_name() {
    let m = machine("grbl-3018");
    let with = |id: &str, stock| CalibrateConfig {
        tool: Some(id.into()),
        stock,
        ..Default::default()
    };
    // a 1 mm ball leaves 0.5 mm of vertical wall; in aluminium its depth of cut needs several levels
    let c = calibrate::coupon(&m, &with("ball1", Stock::Aluminium)).unwrap();
    assert_eq!(c.spec.levels, 10);
    let e = calibrate::coupon(&m, &with("ball2", Stock::Wax))
        .unwrap_err()
        .to_string();
    assert!(e.contains("ball2") && e.contains("vertical wall"), "{e}");
    let e = calibrate::coupon(&m, &with("nope", Stock::Wax))
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope") && e.contains("flat3"), "{e}");
    assert_eq!(calibrate::default_tool(&m).unwrap().id, "flat3");
    // the layout: equal lands on the block, border kept; a tool too wide for the short side refused
    for d in [0.5, 3.175, 6.0] {
        for len in calibrate::STOCK_MM {
            let c = calibrate::centres(len, d, 1.0 / 800.0).unwrap();
            assert_eq!(c[1] - c[0], c[2] - c[1]);
            assert!(c[0] - d / 2.0 >= calibrate::BORDER_MM && c[2] + d / 2.0 <= len - calibrate::BORDER_MM);
        }
    }
    assert!(calibrate::centres(30.0, 8.0, 1e-3).is_none());
}

/// Text from the profile reaches the program only as a comment and the sheet only as text: a name that
/// holds a block or a sheet field is written as it is, never read as either.
#[test]
fn profile_text_stays_text() {
    let mut m = machine("grbl-3018");
    m.name = "evil {d} (x)\nG0 Z-40".into();
    let c = coupon(&m);
    assert!(c.sheet.contains("evil {d} (x)"), "{}", c.sheet.lines().next().unwrap());
    assert!(!c.gcode.lines().any(|l| l.starts_with("G0 Z-40")), "{}", c.gcode);
    assert!(c.gcode.lines().next().unwrap().starts_with('('));
}

#[test]
fn the_binary_writes_the_coupon_and_refuses_a_bad_stock() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let o = Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(["calibrate", "--machine", "linuxcnc-mill", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}{}", String::from_utf8_lossy(&o.stderr));
    for f in ["calibrate.nc", "calibrate.md", "calibrate.json", "tool.tbl"] {
        assert!(out.join(f).is_file(), "{f}: {text}");
    }
    assert!(text.contains("flat6") && text.contains("estimated"), "{text}");
    let table = std::fs::read_to_string(out.join("tool.tbl")).unwrap();
    assert!(table.lines().any(|l| l.starts_with("T3 P3 D6 Z0 ;flat6")), "{table}");
    let o = Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(["calibrate", "--machine", "grbl-3018", "--stock", "steel", "--out"])
        .arg(dir.path().join("bad"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--stock") && err.contains("steel"), "{err}");
    assert!(
        !dir.path().join("bad").exists(),
        "nothing written for a refused command"
    );
}

// ---- the readings against the simulator -------------------------------------------------------------

/// Grid pitch of the simulated cut, mm: every reading is asserted within two of it.
const PITCH_MM: f64 = 0.005;

/// The walls `[left, right]` of each run of cells cut deeper than half the slot depth along a line through
/// the simulated strip (`axis` 0: a row along X, 1: a column along Y), mm.
fn slots_along(sim: &Simulation, axis: usize, depth: f64) -> Vec<[f64; 2]> {
    let hf = &sim.heightfield;
    let (n, mid) = if axis == 0 {
        (hf.nx, hf.ny / 2)
    } else {
        (hf.ny, hf.nx / 2)
    };
    let cut = |i: usize| {
        let z = if axis == 0 { hf.at(i, mid) } else { hf.at(mid, i) };
        z < -depth / 2.0
    };
    let at = |i: usize| {
        let xy = if axis == 0 {
            sim.cell_xy(i, mid)
        } else {
            sim.cell_xy(mid, i)
        };
        xy[axis]
    };
    let mut runs = vec![];
    let mut start = None;
    for i in 0..=n {
        match (start, i < n && cut(i)) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                runs.push([at(s) - hf.pitch_mm / 2.0, at(i - 1) + hf.pitch_mm / 2.0]);
                start = None;
            }
            _ => {}
        }
    }
    runs
}

/// What the sheet reads off one axis: `(backlash µm, mean slot width mm, L = (O + I)/2 mm)`.
fn read_axis(walls: &[[f64; 2]]) -> (f64, f64, f64) {
    assert_eq!(walls.len(), 3, "three slots: {walls:?}");
    let (a, b, c) = (walls[0], walls[1], walls[2]);
    let (land_a, land_b) = (b[0] - a[1], c[0] - b[1]);
    let (inner, outer) = (c[0] - a[1], c[1] - a[0]);
    let s = walls.iter().map(|w| w[1] - w[0]).sum::<f64>() / 3.0;
    (1000.0 * (land_a - land_b) / 2.0, s, (outer + inner) / 2.0)
}

/// Cut `motion` (the coupon as read, possibly with its coordinates changed) on `m` over a thin strip
/// through the middle of island column/row A of each axis, and read both axes.
fn cut_and_read(m: &Machine, spec: &CouponSpec, motion: &gcode::Motion) -> [(f64, f64, f64); 2] {
    let tool = m.tool(&spec.tool.id).unwrap().shape;
    let mid = |f: &calibrate::AxisFeatures| (f.centres_mm[0] + f.centres_mm[1]) / 2.0;
    let (row_y, col_x) = (mid(&spec.y), mid(&spec.x));
    let strips = [
        [-2.0, row_y - 0.02, calibrate::STOCK_MM[0] + 2.0, row_y + 0.02],
        [col_x - 0.02, -2.0, col_x + 0.02, calibrate::STOCK_MM[1] + 2.0],
    ];
    [0, 1].map(|k| {
        let cfg = SimulateConfig {
            tool,
            tools: simulate::tool_table(m),
            pitch_um: PITCH_MM * 1000.0,
            bounds_mm: Some(strips[k]),
            machine: Some(m.clone()),
            ..Default::default()
        };
        let sim = simulate::simulate(motion, &cfg).unwrap();
        assert_eq!(sim.stats.rapid_cuts, 0, "a rapid cut the stock");
        read_axis(&slots_along(&sim, k, spec.depth_mm))
    })
}

/// `m` with these errors declared (the simulator cuts as they say).
fn with_errors(m: &Machine, backlash_um: [f64; 3], runout_um: f64) -> Machine {
    let mut m = m.clone();
    m.accuracy = Some(Accuracy {
        backlash_um,
        runout_um,
        ..m.accuracy()
    });
    m
}

/// The sheet's formulas recover the backlash and runout the simulated machine has, for each shipped
/// profile; on a perfect machine they read zero and the commanded dimensions.
#[test]
fn the_sheet_reads_back_the_backlash_and_runout_the_simulated_machine_has() {
    for name in PROFILES {
        let shipped = machine(name);
        let c = coupon(&shipped);
        let opt = simulate::parse_options(&SimulateConfig {
            machine: Some(shipped.clone()),
            ..Default::default()
        });
        let motion = gcode::parse(&c.gcode, &opt).unwrap();
        let d = c.spec.tool.diameter_mm;
        for (backlash, runout) in [([0.0, 0.0, 0.0], 0.0), ([80.0, 50.0, 0.0], 40.0)] {
            let m = with_errors(&shipped, backlash, runout);
            let read = cut_and_read(&m, &c.spec, &motion);
            for (k, f) in [&c.spec.x, &c.spec.y].into_iter().enumerate() {
                let (b, s, l) = read[k];
                println!("{name} {}: backlash {b:.2} um, slot {s:.4} mm, L {l:.4} mm", f.axis);
                let tol = 2.0 * PITCH_MM;
                assert!(
                    (b - backlash[k]).abs() <= 1000.0 * tol,
                    "{name} {}: backlash {b} um",
                    f.axis
                );
                assert!((s - (d + runout * 1e-3)).abs() <= tol, "{name} {}: slot {s} mm", f.axis);
                assert!(
                    (l - f.pitch_mm).abs() <= tol,
                    "{name} {}: L {l} against P {}",
                    f.axis,
                    f.pitch_mm
                );
            }
        }
    }
}

/// A wrong scale (the controller's steps/mm off by a factor) is read back by `steps_old · P / L`: the
/// coupon's commanded coordinates are scaled as the wrong steps would move the machine, with backlash and
/// runout present, and the new steps/mm come out within two grid pitches over P.
#[test]
fn the_sheet_reads_back_a_wrong_scale() {
    let shipped = machine("grbl-3018");
    let c = coupon(&shipped);
    let m = with_errors(&shipped, [30.0, 60.0, 0.0], 20.0);
    let opt = simulate::parse_options(&SimulateConfig {
        machine: Some(m.clone()),
        ..Default::default()
    });
    let mut motion = gcode::parse(&c.gcode, &opt).unwrap();
    // travel per commanded mm: the true steps/mm are steps_old / k
    let k = [1.004, 0.997];
    for s in &mut motion.segments {
        for p in [&mut s.from, &mut s.to] {
            p[0] *= k[0];
            p[1] *= k[1];
        }
    }
    let old = shipped.accuracy().steps_per_mm.unwrap();
    let read = cut_and_read(&m, &c.spec, &motion);
    for (a, f) in [&c.spec.x, &c.spec.y].into_iter().enumerate() {
        let (b, _, l) = read[a];
        let new = old[a] * f.pitch_mm / l;
        let truth = old[a] / k[a];
        println!(
            "{}: steps/mm read {new:.3}, true {truth:.3}; backlash {b:.1} um",
            f.axis
        );
        assert!(
            (new - truth).abs() <= truth * 2.0 * PITCH_MM / f.pitch_mm,
            "{}: {new} against {truth}",
            f.axis
        );
        assert!(
            (b - m.accuracy().backlash_um[a]).abs() <= 2000.0 * PITCH_MM,
            "{}: {b}",
            f.axis
        );
    }
}

// ---- peers: LinuxCNC's interpreter, the virtual GRBL controller --------------------------------------

/// LinuxCNC's standalone interpreter `rs274` (Debian package linuxcnc-uspace), as the toolpath acceptance
/// tests use it: `#[ignore]`d, so that plain `cargo test` reports it as ignored; with `--ignored` it fails
/// when rs274 is missing.
fn require_rs274() {
    let found = Command::new("rs274")
        .arg("-h")
        .stdin(std::process::Stdio::null())
        .output()
        .is_ok();
    assert!(
        found,
        "rs274 is required by this test but not installed (apt-get install linuxcnc-uspace)"
    );
}

#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn rs274_accepts_the_linuxcnc_coupon_with_its_tool_table() {
    require_rs274();
    let c = coupon(&machine("linuxcnc-mill"));
    let dir = tempfile::tempdir().unwrap();
    c.write(dir.path()).unwrap();
    let (prog, canon) = (dir.path().join("calibrate.nc"), dir.path().join("p.canon"));
    let out = Command::new("rs274")
        .arg("-t")
        .arg(dir.path().join("tool.tbl"))
        .arg("-g")
        .arg(&prog)
        .arg(&canon)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let canon = std::fs::read_to_string(&canon).unwrap_or_default();
    assert!(
        out.status.success() && canon.contains("PROGRAM_END") && !text.to_lowercase().contains("error"),
        "rs274 exit {:?}: {text}",
        out.status.code()
    );
    // the tool change read the table: tool 3 of 6 mm is in the spindle
    assert!(
        canon.contains("CHANGE_TOOL(3)") || canon.contains("CHANGE_TOOL(1)"),
        "{canon}"
    );
    assert!(
        canon.lines().filter(|l| l.contains("STRAIGHT_FEED")).count() >= 12,
        "{canon}"
    );
}

/// A link that keeps every byte read from the controller once the first program line is written.
struct Recording {
    inner: SerialLink,
    first_line: Vec<u8>,
    streaming: bool,
    received: Vec<u8>,
}

impl Link for Recording {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.streaming |= bytes == self.first_line.as_slice();
        self.inner.write_all(bytes)
    }
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        let n = self.inner.read(buf, timeout)?;
        if self.streaming {
            self.received.extend_from_slice(&buf[..n]);
        }
        Ok(n)
    }
    fn name(&self) -> &str {
        self.inner.name()
    }
}

/// Each GRBL coupon streams to the virtual GRBL 1.1h controller on a pseudo-terminal: completed, one `ok`
/// per line and no `error:`, every line once and in order, no receive-buffer overflow.
#[test]
fn the_grbl_coupons_stream_to_the_virtual_controller() {
    for name in ["grbl-3018", "grbl-router-6040"] {
        let c = coupon(&machine(name));
        let dir = tempfile::tempdir().unwrap();
        c.write(dir.path()).unwrap();
        let prog = Program::read(&dir.path().join("calibrate.nc"), true).unwrap();
        let baud = 1_000_000;
        let emu = Emulator::start(EmulatorConfig {
            baud,
            time_scale: 1000.0,
            ..EmulatorConfig::default()
        })
        .expect("pseudo-terminal");
        let mut link = Recording {
            inner: SerialLink::open(&emu.port_path().unwrap(), baud).unwrap(),
            first_line: format!("{}\n", prog.sendable().next().unwrap().wire_text(true)).into_bytes(),
            streaming: false,
            received: Vec::new(),
        };
        let cfg = Config {
            spindle_dwell_s: 0.1,
            ..Config::default()
        };
        let journal = dir.path().join("calibrate.nc.journal.jsonl");
        let outcome = session::run(
            &mut link,
            &prog,
            &cfg,
            &journal,
            Mode::Fresh,
            &mut Silent,
            &AtomicBool::new(false),
        )
        .unwrap();
        assert!(matches!(outcome, Outcome::Completed(_)), "{name}: {outcome:?}");
        let log = emu.log();
        assert_eq!(log.rx_overflows, 0, "{name}");
        let answers = String::from_utf8_lossy(&link.received);
        let errors: Vec<&str> = answers.lines().filter(|l| l.trim().starts_with("error:")).collect();
        assert!(errors.is_empty(), "{name}: {errors:?}");
        let oks = answers.lines().filter(|l| l.trim() == "ok").count();
        assert_eq!(oks, prog.sendable().count(), "{name}: one ok per line");
        let sent: Vec<String> = prog.sendable().map(|l| l.wire_text(true)).collect();
        assert!(
            log.received.ends_with(&sent),
            "{name}: every line arrived once, in order"
        );
        assert!(!log.executed.is_empty(), "{name}: motion executed");
    }
}
