//! LinuxCNC's sample programs (`/usr/share/linuxcnc/ncfiles/`, Debian package linuxcnc-uspace): those that use
//! only the supported subset parse and simulate; every other one is refused with a line and column inside the
//! file, and none makes the reader or the simulation panic.

use brdfmill::simulate::{self, gcode, Shape, SimulateConfig};
use std::path::{Path, PathBuf};

const NCFILES: &str = "/usr/share/linuxcnc/ncfiles";

/// The folder, or None with a note (a failure when BRDFMILL_REQUIRE_EXTERNAL is set, as `.ci/run` does).
fn ncfiles() -> Option<PathBuf> {
    let p = Path::new(NCFILES);
    match (p.is_dir(), std::env::var("BRDFMILL_REQUIRE_EXTERNAL").is_ok()) {
        (true, _) => Some(p.to_path_buf()),
        (false, true) => panic!("{NCFILES} (Debian package linuxcnc-uspace) is required here but missing"),
        (false, false) => {
            eprintln!("note: {NCFILES} missing (apt-get install linuxcnc-uspace); the sample-program walk did not run");
            None
        }
    }
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
fn linuxcnc_samples_simulate_or_are_refused_with_line_and_column() {
    let Some(dir) = ncfiles() else { return };
    let mut files = vec![];
    walk(&dir, &mut files);
    assert!(files.len() >= 50, "only {} programs under {NCFILES}", files.len());
    let (mut simulated, mut refused, mut cut) = (0, 0, 0);
    let mut report = vec![];
    for f in &files {
        let bytes = std::fs::read(f).unwrap();
        let text = String::from_utf8_lossy(&bytes).to_string();
        let nlines = text.lines().count().max(1);
        let name = f.strip_prefix(&dir).unwrap().display().to_string();
        let cfg = SimulateConfig {
            tool: Shape::Ball { diameter_mm: 3.0 },
            ..Default::default()
        };
        // read first, to size the stock grid to about a million cells whatever the program's extent
        let outcome = std::panic::catch_unwind(|| -> Result<simulate::Simulation, simulate::SimulateError> {
            let prog = gcode::parse(&text, &simulate::parse_options(&cfg))?;
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
                simulated += 1;
                if sim.stats.removed_volume_mm3 > 0.0 {
                    cut += 1;
                }
                assert!(sim.heightfield.check_invariants().is_ok(), "{name}");
                report.push(format!(
                    "simulated {name}: {} moves, {} arcs, {:.3} mm³ removed",
                    sim.stats.moves, sim.stats.arcs, sim.stats.removed_volume_mm3
                ));
            }
            Ok(Err(simulate::SimulateError::Gcode(e))) => {
                refused += 1;
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
                report.push(format!("refused {name}: {e}"));
            }
            Ok(Err(e)) => panic!("{name}: neither simulated nor refused with a position: {e}"),
        }
    }
    println!("{}", report.join("\n"));
    println!(
        "{} programs: {simulated} simulated ({cut} remove material), {refused} refused with line and column",
        files.len()
    );
    assert_eq!(simulated + refused, files.len());
    // Most samples are programs in LinuxCNC's language (O-word subroutines and loops, # parameters: 143 of
    // 185 in linuxcnc-uspace 2.9), lathe (G18) or plasma (M52) programs, beyond DESIGN.md §5's subset. Those
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
    use brdfmill::simulate::gcode::{parse, ParseOptions};
    let p = |t: &str| parse(t, &ParseOptions::default()).unwrap();
    let g = p("T1 M6\nG43 H1\nG0 X1\nT3 M6 (MSG,change)\nM0\nG43 H3\nG0 X2\n");
    assert_eq!(g.segments.iter().map(|s| s.tool).collect::<Vec<_>>(), [1, 3]);
    let g = p("T2\nG0 X1\nT4\nG0 X2\nT4 M0\nG0 X3\n");
    assert_eq!(g.segments.iter().map(|s| s.tool).collect::<Vec<_>>(), [2, 2, 4]);
}
