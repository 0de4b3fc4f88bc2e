//! LinuxCNC's sample programs (`/usr/share/linuxcnc/ncfiles/`, Debian package linuxcnc-uspace): those that use
//! only the supported subset parse and simulate; every other one is refused with a line and column inside the
//! file, and none makes the reader or the simulation panic.
//!
//! The walk over the installed samples needs the package, so it is `#[ignore]`d (plain `cargo test` lists it
//! as ignored; `cargo test -- --ignored`, as `.ci/run` runs it, fails when the folder is missing). The same
//! check runs without the package on programs written here in LinuxCNC's language.

use brdfmill::stages::simulate::{self, gcode, Shape, SimulateConfig};
use std::path::{Path, PathBuf};

const NCFILES: &str = "/usr/share/linuxcnc/ncfiles";

/// What became of one program.
#[derive(Debug, PartialEq)]
enum Checked {
    /// Simulated; whether it removed material.
    Simulated { cuts: bool },
    /// Refused with a usable position: line and column (1-based).
    Refused { line: usize, column: usize },
}

/// Read and simulate one program (stock grid sized to about a million cells whatever its extent); panics
/// unless it simulates or is refused with a line and column that lie inside `text`.
fn check_program(name: &str, text: &str) -> (Checked, String) {
    let nlines = text.lines().count().max(1);
    let cfg = SimulateConfig {
        tool: Shape::Ball { diameter_mm: 3.0 },
        ..Default::default()
    };
    let outcome = std::panic::catch_unwind(|| -> Result<simulate::Simulation, simulate::SimulateError> {
        let prog = gcode::parse(text, &simulate::parse_options(&cfg))?;
        let probe = SimulateConfig {
            max_cells: usize::MAX,
            ..cfg.clone()
        };
        let g = simulate::stock_grid(&prog, &probe)?;
        let area = g.nx as f64 * g.ny as f64 * g.pitch * g.pitch;
        let pitch_um = ((area / 1e6).sqrt() * 1e3).max(20.0);
        simulate::simulate(
            &prog,
            &SimulateConfig {
                pitch_um,
                ..cfg.clone()
            },
        )
    });
    match outcome {
        Err(_) => panic!("{name}: the reader or the simulation panicked"),
        Ok(Ok(sim)) => {
            assert!(sim.heightfield.check_invariants().is_ok(), "{name}");
            (
                Checked::Simulated {
                    cuts: sim.stats.removed_volume_mm3 > 0.0,
                },
                format!(
                    "simulated {name}: {} moves, {} arcs, {:.3} mm³ removed",
                    sim.stats.moves, sim.stats.arcs, sim.stats.removed_volume_mm3
                ),
            )
        }
        Ok(Err(simulate::SimulateError::Gcode(e))) => {
            assert!(
                e.line >= 1 && e.line <= nlines && e.column >= 1,
                "{name}: refusal without a usable position: {e}"
            );
            let line_text = text.lines().nth(e.line - 1).unwrap_or("");
            assert!(
                e.column <= line_text.chars().count().max(1),
                "{name}: column {} beyond the line `{line_text}`",
                e.column
            );
            (
                Checked::Refused {
                    line: e.line,
                    column: e.column,
                },
                format!("refused {name}: {e}"),
            )
        }
        Ok(Err(e)) => panic!("{name}: neither simulated nor refused with a position: {e}"),
    }
}

/// Programs in LinuxCNC's language beyond DESIGN.md §5's subset, each refused at the line and column of the
/// first construct outside it (written for this test, so the positions are known), and two inside it that
/// simulate (one an inch program of R-form arcs, as `arcspiral.ngc` is).
#[test]
fn linuxcnc_language_is_refused_at_its_line_and_column() {
    let refused: [(&str, &str, usize, usize); 5] = [
        // (name, program, line, column of the refused word)
        (
            "o-word",
            "G21 G90\nG0 Z1\nO100 sub\nG1 X1 F100\nO100 endsub\nM2\n",
            3,
            1,
        ),
        ("parameter", "G21 G90\nG0 Z1\nG1 X#1 F100\nM2\n", 3, 5),
        ("assignment", "G21 G90\n#1 = 5\nM2\n", 2, 1),
        // (`G53 G0 Z…` alone is read, as a tool change's retract)
        ("machine coordinates", "G21 G90\nG0 Z1\nG53 G0 X5 Z0\nM2\n", 3, 1),
        ("plasma", "G21 G90\nM52 P1\nM2\n", 2, 1),
    ];
    for (name, text, line, column) in refused {
        let (c, note) = check_program(name, text);
        println!("{note}");
        assert_eq!(c, Checked::Refused { line, column }, "{name}: {note}");
    }
    // arcs in the ZX plane, as brdfmill's own programs write them
    let (c, note) = check_program(
        "G18 arcs",
        "G21 G90\nG0 X0 Y0 Z1\nG1 Z0 F100\nG18 G2 X2 Z0 I1 K0\nG17\nM2\n",
    );
    println!("{note}");
    assert_eq!(c, Checked::Simulated { cuts: true }, "G18 arcs: {note}");
    let inch_arcs = "G20 G90 G17\nG0 X0 Y0 Z0.1\nG1 Z-0.01 F10\nG2 X0.2 Y0 R0.1\nG2 X0 Y0 R0.1\nG0 Z0.1\nM2\n";
    let (c, note) = check_program("inch R-form arcs", inch_arcs);
    println!("{note}");
    assert_eq!(c, Checked::Simulated { cuts: true });
    let (c, note) = check_program("rapids only", "G21 G90\nG0 X1 Y1 Z5\nG0 X2\nM2\n");
    println!("{note}");
    assert_eq!(c, Checked::Simulated { cuts: false });
}

/// The sample folder; a failure when it is missing (the test that calls this is `#[ignore]`d).
fn ncfiles() -> PathBuf {
    let p = Path::new(NCFILES);
    assert!(
        p.is_dir(),
        "{NCFILES} is required by this test but missing (apt-get install linuxcnc-uspace)"
    );
    p.to_path_buf()
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, out);
        } else if matches!(
            p.extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref(),
            Some("ngc" | "nc" | "tap")
        ) {
            out.push(p);
        }
    }
}

#[test]
#[ignore = "needs linuxcnc-uspace (its sample programs in /usr/share/linuxcnc/ncfiles)"]
fn linuxcnc_samples_simulate_or_are_refused_with_line_and_column() {
    let dir = ncfiles();
    let mut files = vec![];
    walk(&dir, &mut files);
    assert!(files.len() >= 50, "only {} programs under {NCFILES}", files.len());
    let (mut simulated, mut refused, mut cut) = (0, 0, 0);
    let mut report = vec![];
    for f in &files {
        let bytes = std::fs::read(f).unwrap();
        let text = String::from_utf8_lossy(&bytes).to_string();
        let name = f.strip_prefix(&dir).unwrap().display().to_string();
        let (c, note) = check_program(&name, &text);
        match c {
            Checked::Simulated { cuts } => {
                simulated += 1;
                cut += usize::from(cuts);
            }
            Checked::Refused { .. } => refused += 1,
        }
        report.push(note);
    }
    println!("{}", report.join("\n"));
    println!(
        "{} programs: {simulated} simulated ({cut} remove material), {refused} refused with line and column",
        files.len()
    );
    // Most samples are programs in LinuxCNC's language (O-word subroutines and loops, # parameters: 143 of
    // 185 in linuxcnc-uspace 2.9), lathe or plasma (M52) programs, beyond DESIGN.md §5's subset. Those
    // within it simulate; among them arcspiral.ngc (inches, 999 R-form arcs) cuts.
    assert!(simulated >= 5, "only {simulated} sample programs simulate");
    assert!(cut >= 1, "no sample program removes material");
    assert!(
        report.iter().any(|l| l.starts_with("simulated arcspiral.ngc")),
        "arcspiral.ngc should simulate"
    );
}

/// Tool changes tag the segments: LinuxCNC's `T M6` and GRBL's `T… M0` manual change; a `T` before the first
/// move is the mounted tool.
#[test]
fn tool_changes_tag_segments() {
    use brdfmill::stages::simulate::gcode::{parse, ParseOptions};
    let p = |t: &str| parse(t, &ParseOptions::default()).unwrap();
    let g = p("T1 M6\nG43 H1\nG0 X1\nT3 M6 (MSG,change)\nM0\nG43 H3\nG0 X2\n");
    assert_eq!(g.segments.iter().map(|s| s.tool).collect::<Vec<_>>(), [1, 3]);
    let g = p("T2\nG0 X1\nT4\nG0 X2\nT4 M0\nG0 X3\n");
    assert_eq!(g.segments.iter().map(|s| s.tool).collect::<Vec<_>>(), [2, 2, 4]);
}
