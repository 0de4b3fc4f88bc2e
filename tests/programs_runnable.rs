//! Issue 35: programs a machinist can run as written. A job with a roughing tool on each shipped profile:
//! GRBL gets one program per tool with no pause or tool-change word (GRBL accepts no jog during a hold, so a
//! pause could not be used to re-zero), and the programs read one after another cut exactly what the joined
//! job does; LinuxCNC retracts in machine coordinates before every `M6`, and `rs274` accepts every program
//! with the tool table written beside it. The run-time estimate is re-checked against a planner limited to
//! GRBL's block buffer, and an over-long job is refused naming what takes the time.

use brdfmill::base::heightfield::Heightfield;
use brdfmill::cut::machine::Machine;
use brdfmill::gcode::Dialect;
use brdfmill::stages::simulate::{self, gcode::ParseOptions, Shape, SimulateConfig};
use brdfmill::stages::toolpath::{self, ToolpathConfig};
use std::path::Path;

mod planner;
use planner::planner_with_buffer;

fn machine(name: &str) -> Machine {
    Machine::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("machines").join(name)).unwrap()
}

/// A periodic round pocket `depth` deep, 6 mm across (deeper than one cut: roughing layers and
/// intermediate levels).
fn pocket(depth: f64) -> Heightfield {
    let (n, p) = (300, 0.02);
    let mut hf = Heightfield::flat(n, n, p, true, 0.0);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = ((i as f64 + 0.5) * p - 3.0, (j as f64 + 0.5) * p - 3.0);
            let t = ((2.7 - (x * x + y * y).sqrt()) / 1.2).clamp(0.0, 1.0);
            hf.z_mm[j * n + i] = -depth * t;
        }
    }
    hf
}

/// Each shipped profile with a roughing tool other than the finishing `ball1`.
const SETUPS: [(&str, &str); 3] = [
    ("grbl-3018.toml", "flat3"),
    ("grbl-router-6040.toml", "ball3"),
    ("linuxcnc-mill.toml", "ball2"),
];

fn program(profile: &str, rough: &str, cfg: ToolpathConfig) -> toolpath::Toolpath {
    let cfg = ToolpathConfig {
        tool: "ball1".into(),
        rough_tool: rough.into(),
        area_mm: [6.0, 6.0],
        stepover_mm: 0.05,
        job: "runnable".into(),
        ..cfg
    };
    toolpath::run(&cfg, &pocket(1.2), &machine(profile)).unwrap_or_else(|e| panic!("{profile}: {e}"))
}

/// The words of a G-code line outside comments, upper case.
fn words(line: &str) -> Vec<String> {
    let mut out = String::new();
    let mut depth = 0;
    for c in line.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ';' if depth == 0 => break,
            c if depth == 0 => out.push(c.to_ascii_uppercase()),
            _ => {}
        }
    }
    out.split_whitespace().map(str::to_string).collect()
}

fn has_word(line: &str, letter: char, value: f64) -> bool {
    words(line)
        .iter()
        .any(|w| w.starts_with(letter) && w[1..].parse::<f64>().is_ok_and(|v| v == value))
}

fn sim_config(m: &Machine) -> SimulateConfig {
    SimulateConfig {
        tool: Shape::Ball { diameter_mm: 1.0 },
        tools: simulate::tool_table(m),
        pitch_um: 20.0,
        bounds_mm: Some([-2.0, -2.0, 8.0, 8.0]),
        machine: Some(m.clone()),
        ideal: true,
        ..Default::default()
    }
}

#[test]
fn grbl_jobs_are_one_program_per_tool_that_cut_what_the_joined_job_cuts() {
    for (profile, rough) in SETUPS {
        let m = machine(profile);
        let p = program(profile, rough, ToolpathConfig::default());
        assert!(p.summary.roughing_layers > 0, "{profile}: the pocket needs roughing");
        let tools: Vec<Vec<String>> = p.files.iter().map(|f| f.summary.tools.clone()).collect();
        if m.dialect == Dialect::Linuxcnc {
            assert_eq!(p.files.len(), 1, "{profile}: LinuxCNC changes tools itself");
            assert_eq!(tools[0], [rough, "ball1"]);
            continue;
        }
        assert_eq!(tools, [vec![rough.to_string()], vec!["ball1".to_string()]], "{profile}");
        assert_eq!(
            p.files.iter().map(|f| f.summary.file.as_str()).collect::<Vec<_>>(),
            ["program-1.nc", "program-2.nc"]
        );
        for f in &p.files {
            let lines: Vec<&str> = f.gcode.lines().collect();
            // no pause, no optional stop, no tool change: nothing for which GRBL would hold
            for l in &lines {
                assert!(
                    !has_word(l, 'M', 0.0) && !has_word(l, 'M', 1.0) && !has_word(l, 'M', 6.0),
                    "{profile} {}: `{l}`",
                    f.summary.file
                );
            }
            // the tool is named before the first move, and the first move is Z alone, up
            let first_move = lines
                .iter()
                .position(|l| words(l).iter().any(|w| w.starts_with(['X', 'Y', 'Z'])))
                .unwrap();
            assert!(
                lines[..first_move]
                    .iter()
                    .any(|l| words(l).iter().any(|w| w.starts_with('T'))),
                "{profile} {}: no T word before the first move",
                f.summary.file
            );
            let first = words(lines[first_move]);
            assert!(
                first.iter().all(|w| !w.starts_with(['X', 'Y'])),
                "{profile} {}: first move `{}` leaves Z unknown",
                f.summary.file,
                lines[first_move]
            );
            assert!(f.gcode.contains("touch-off pad"), "{profile}: where Z is zeroed");
            assert_eq!(lines.last().map(|l| l.trim()), Some("M30"));
        }
        // the programs one after another on one stock cut exactly what the joined job cuts
        let cfg = sim_config(&m);
        let files = simulate::run_files(&p.texts(), &cfg).unwrap();
        let joined = simulate::run(&p.gcode, &cfg).unwrap();
        assert_eq!(files.heightfield.z_mm, joined.heightfield.z_mm, "{profile}");
        assert_eq!(files.stats.rapid_cuts, 0, "{profile}");
        let lines: usize = p.files.iter().map(|f| f.summary.lines).sum();
        assert_eq!(p.summary.lines, lines);
    }
}

#[test]
fn linuxcnc_retracts_in_machine_coordinates_before_every_tool_change() {
    let p = program("linuxcnc-mill.toml", "ball2", ToolpathConfig::default());
    let lines: Vec<&str> = p.gcode.lines().collect();
    let changes: Vec<usize> = (0..lines.len()).filter(|&k| has_word(lines[k], 'M', 6.0)).collect();
    assert_eq!(changes.len(), 2, "roughing tool, then finishing tool");
    for k in changes {
        // the last line with a word before the change is the retract in machine coordinates
        let before = (0..k).rev().find(|&j| !words(lines[j]).is_empty()).unwrap();
        let w = words(lines[before]);
        assert!(
            w.contains(&"G53".to_string()) && w.contains(&"G0".to_string()) && w.iter().any(|x| x.starts_with('Z')),
            "line {}: `{}` before `{}`",
            before + 1,
            lines[before],
            lines[k]
        );
        assert!(
            words(lines[k + 1]).contains(&format!("H{}", &words(lines[k])[0][1..])),
            "G43 H of the tool after `{}`",
            lines[k]
        );
    }
    // the simulation reads the retract (straight up) and the same cut as without it
    let m = machine("linuxcnc-mill.toml");
    let sim = simulate::run(&p.gcode, &sim_config(&m)).unwrap();
    assert_eq!(sim.stats.rapid_cuts, 0);
    let without: String = lines
        .iter()
        .filter(|l| !l.starts_with("G53"))
        .map(|l| format!("{l}\n"))
        .collect();
    let plain = simulate::run(&without, &sim_config(&m)).unwrap();
    assert_eq!(sim.heightfield.z_mm, plain.heightfield.z_mm);
}

/// LinuxCNC's standalone interpreter on `program` with `table` as its tool table; Err with its message.
fn rs274(program: &str, table: &str) -> Result<usize, String> {
    let dir = tempfile::tempdir().unwrap();
    let (prog, tbl, canon) = (
        dir.path().join("p.ngc"),
        dir.path().join("tool.tbl"),
        dir.path().join("p.canon"),
    );
    std::fs::write(&prog, program).unwrap();
    std::fs::write(&tbl, table).unwrap();
    let out = std::process::Command::new("rs274")
        .arg("-t")
        .arg(&tbl)
        .arg("-g")
        .arg(&prog)
        .arg(&canon)
        .stdin(std::process::Stdio::null())
        .output()
        .expect("rs274 (Debian package linuxcnc-uspace) must be installed for this test");
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let canon = std::fs::read_to_string(&canon).unwrap_or_default();
    if !out.status.success() || !canon.contains("PROGRAM_END") || text.to_lowercase().contains("error") {
        return Err(format!("rs274 exit {:?}: {text}", out.status.code()));
    }
    Ok(canon.lines().count())
}

/// Every program of a one-tool and a roughing job on every shipped profile, with the tool table the job
/// writes: `rs274` reads each to its end.
#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn rs274_accepts_every_program_with_its_tool_table() {
    for (profile, rough) in SETUPS {
        let m = machine(profile);
        let table = brdfmill::gcode::tool_table(&m);
        for r in ["", rough] {
            let p = program(profile, r, ToolpathConfig::default());
            for f in &p.files {
                let n = rs274(&f.gcode, &table).unwrap_or_else(|e| panic!("{profile} {}: {e}", f.summary.file));
                assert!(n > f.summary.lines / 2, "{profile} {}: {n} commands", f.summary.file);
            }
        }
    }
    // the check itself fails on a tool the table does not hold
    let e = rs274(
        "G21 G90\nG53 G0 Z0\nT77 M6\nG43 H77\nM2\n",
        &brdfmill::gcode::tool_table(&machine("linuxcnc-mill.toml")),
    );
    assert!(e.is_err(), "rs274 accepted a tool outside the table");
}

/// The header's estimate (unlimited look-ahead) against a planner that looks only 15 blocks ahead, as GRBL's
/// does, on finishing programs like the default job's (the 0.5 mm ball at a 1 µm scallop: short blocks and
/// arcs): within 5%.
#[test]
fn the_estimate_holds_with_grbls_fifteen_block_buffer() {
    for profile in ["grbl-3018.toml", "grbl-router-6040.toml"] {
        let m = machine(profile);
        let cfg = ToolpathConfig {
            tool: "ball05".into(),
            area_mm: [6.0, 6.0],
            job: "planner".into(),
            ..Default::default()
        };
        let p = toolpath::run(&cfg, &pocket(0.3), &m).unwrap();
        // the program as written, read back (arcs as chords)
        let opt = ParseOptions {
            dialect: m.dialect,
            start_mm: [0.0, 0.0, m.program.clearance_z()],
            arc_tolerance_mm: 2e-3,
            ..Default::default()
        };
        let motion = simulate::gcode::parse(&p.gcode, &opt).unwrap();
        let buffered = planner_with_buffer(&motion.moves, opt.start_mm, &m);
        let ours = p.summary.estimated_unlimited_s;
        println!(
            "{profile}: estimate {ours:.1} s, 15-block planner {buffered:.1} s ({} lines)",
            p.summary.lines
        );
        assert!(
            (buffered - ours).abs() <= 0.05 * ours,
            "{profile}: estimate {ours:.1} s against {buffered:.1} s with a 15-block buffer"
        );
    }
}

/// `toolpath.max_hours`: a program estimated longer is refused, naming the key, the two parts of the time and
/// what would shorten them; the same job with room passes.
#[test]
fn a_job_over_its_time_budget_is_refused_with_what_takes_the_time() {
    let e = toolpath::run(
        &ToolpathConfig {
            tool: "ball1".into(),
            area_mm: [4.0, 4.0],
            max_hours: 0.01,
            ..Default::default()
        },
        &pocket(0.3),
        &machine("grbl-3018.toml"),
    )
    .err()
    .expect("refused")
    .to_string();
    assert!(
        e.contains("max_hours") && e.contains("final raster") && e.contains("scallop_um") && e.contains("area_mm"),
        "{e}"
    );
    assert!(toolpath::run(
        &ToolpathConfig {
            tool: "ball1".into(),
            area_mm: [4.0, 4.0],
            ..Default::default()
        },
        &pocket(0.3),
        &machine("grbl-3018.toml"),
    )
    .is_ok());
}
