//! The toolpath stage's acceptance figures (issue "Toolpath: …"): the default job's program passes LinuxCNC's
//! own interpreter, covers the requested area, never dips below the design, and limit violations are
//! refused before anything is written.

use brdfmill::base::heightfield::Heightfield;
use brdfmill::cut::machine::Machine;
use brdfmill::gcode::moves::Move;
use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::facets::{self, FacetsConfig};
use brdfmill::stages::ndf::{self, NdfConfig};
use brdfmill::stages::toolpath::{self, check, ToolpathConfig, ToolpathError};
use std::path::Path;
use std::sync::OnceLock;

/// The default job's tile: beckmann α = 0.3, 32×32 facets of 1 mm at 10 µm.
fn tile() -> &'static Heightfield {
    static T: OnceLock<Heightfield> = OnceLock::new();
    T.get_or_init(|| {
        let n = ndf::run(&NdfConfig::default(), &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
        facets::run(&FacetsConfig::default(), &n.target).unwrap().heightfield
    })
}

fn machine(name: &str) -> Machine {
    Machine::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("machines").join(name)).unwrap()
}

/// LinuxCNC's standalone interpreter `rs274` (Debian package linuxcnc-uspace). The tests that use it are
/// `#[ignore]`d, so that plain `cargo test` reports them as ignored rather than passing them; run with
/// `cargo test -- --ignored` (as `.ci/run` does after installing it), they fail when it is missing.
fn require_rs274() {
    let found = std::process::Command::new("rs274")
        .arg("-h")
        .stdin(std::process::Stdio::null())
        .output()
        .is_ok();
    assert!(
        found,
        "rs274 is required by this test but not installed (apt-get install linuxcnc-uspace)"
    );
}

/// Run LinuxCNC's standalone interpreter on `gcode` with the tool table brdfmill writes for `machine` (as
/// the setup sheet tells the operator to: `rs274 -t tool.tbl -g …`), so that a tool change reads the
/// profile's tools and not whatever table rs274 finds by default; Ok(canonical command count) or Err(its
/// message).
fn interpret(gcode: &str, machine: &Machine) -> Result<usize, String> {
    let dir = tempfile::tempdir().unwrap();
    let (prog, canon) = (dir.path().join("p.ngc"), dir.path().join("p.canon"));
    let table = dir.path().join(brdfmill::gcode::TOOL_TABLE_FILE);
    std::fs::write(&prog, gcode).unwrap();
    std::fs::write(&table, brdfmill::gcode::tool_table(machine)).unwrap();
    let out = std::process::Command::new("rs274")
        .arg("-t")
        .arg(&table)
        .arg("-g")
        .arg(&prog)
        .arg(&canon)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let canon = std::fs::read_to_string(&canon).unwrap_or_default();
    if !out.status.success() || !canon.contains("PROGRAM_END") || text.to_lowercase().contains("error") {
        return Err(format!("rs274 exit {:?}: {text}", out.status.code()));
    }
    Ok(canon.lines().count())
}

/// The default job's finishing program for each machine profile, with the 1 mm ball.
fn default_programs() -> Vec<(&'static str, toolpath::Toolpath)> {
    ["linuxcnc-mill.toml", "grbl-3018.toml"]
        .into_iter()
        .map(|profile| {
            let cfg = ToolpathConfig {
                tool: "ball1".into(),
                ..Default::default()
            };
            (profile, toolpath::run(&cfg, tile(), &machine(profile)).unwrap())
        })
        .collect()
}

#[test]
#[ignore = "slow (the default job's programs simulated): cargo test -- --ignored runs it, and .ci/run"]
fn default_job_covers_the_area_without_gouging() {
    for (profile, p) in default_programs() {
        let s = &p.summary;
        println!("{profile}: {s:?}");
        // the cut covers the requested area: tool-centre extents within one sample of it
        let feeds: Vec<[f64; 3]> = p
            .moves
            .iter()
            .filter_map(|m| if let Move::Feed(q, _) = m { Some(*q) } else { None })
            .collect();
        let (xmin, xmax) = feeds.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, q| {
            (a.0.min(q[0]), a.1.max(q[0]))
        });
        let (ymin, ymax) = feeds.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, q| {
            (a.0.min(q[1]), a.1.max(q[1]))
        });
        let pitch = tile().pitch_mm;
        assert!(
            xmin >= -1e-9 && xmin <= pitch && xmax <= 40.0 + 1e-9 && xmax >= 40.0 - pitch,
            "x {xmin}..{xmax}"
        );
        assert!(ymin.abs() < 1e-9 && (ymax - 40.0).abs() < 1e-9, "y {ymin}..{ymax}");
        // scallop target met and no gouge at any emitted CL point
        assert!(s.scallop_um <= 1.0 + 1e-9);
        // the check reads the written points, arcs along their length: between the design's samples the
        // discrete CL of a ball may stand above a chord or an arc through CL samples by a cap's sag,
        // p²/(8r)·(1 + s²)^{3/2}, s the tile's steepest slope (the vertices themselves are exact)
        let t = tile();
        let steepest = (0..t.ny)
            .flat_map(|j| (0..t.nx).map(move |i| (i, j)))
            .map(|(i, j)| {
                let dx = t.at((i + 1) % t.nx, j) - t.at(i, j);
                let dy = t.at(i, (j + 1) % t.ny) - t.at(i, j);
                dx.abs().max(dy.abs()) / pitch
            })
            .fold(0.0, f64::max);
        let sag_um = 1000.0 * pitch * pitch / (8.0 * 0.5) * (1.0 + steepest * steepest).powf(1.5);
        assert!(
            s.max_gouge_um <= sag_um,
            "gouge {} µm, above {sag_um} µm",
            s.max_gouge_um
        );
        assert!(s.checked_points >= 40_000);
        // the design is deeper than one cut: roughing layers exist
        assert!(s.roughing_layers >= 1);
        assert!(
            p.gcode.contains("G17 G21 G40 G49 G54 G80 G90 G94") && p.gcode.contains("M3 S") && p.gcode.contains("G4 P")
        );
        // the end: spindle (and coolant) off, the XY plane back if arcs left it elsewhere, program end
        let end = p.gcode.trim_end().replace("\nG17\nM30", "\nM30");
        assert!(end.ends_with("M5\nM30") || end.ends_with("M9\nM30"));
        // the spindle starts only after the first retract
        let first_m3 = p.gcode.find("M3 S").unwrap();
        assert!(p.gcode[..first_m3].contains("G0 Z"), "spindle on before the retract");
    }
}

#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn default_job_passes_rs274() {
    require_rs274();
    for (profile, p) in default_programs() {
        let n = interpret(&p.gcode, &machine(profile)).unwrap_or_else(|e| panic!("{profile}: {e}"));
        println!(
            "{profile}: rs274 produced {n} canonical commands for {} lines",
            p.summary.lines
        );
        assert!(
            n > p.summary.lines / 2,
            "rs274 produced {n} canonical commands for {} lines",
            p.summary.lines
        );
    }
}

#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn rs274_check_itself_catches_a_bad_program() {
    require_rs274();
    assert!(
        interpret("G21 G90\nG1 X1 Y1\nM2\n", &machine("linuxcnc-mill.toml")).is_err(),
        "G1 without a feed must be refused"
    );
    assert!(interpret("G21 G90\nG1 X1 F100\nM2\n", &machine("linuxcnc-mill.toml")).is_ok());
}

#[test]
fn limit_violations_are_refused() {
    let small = {
        let mut hf = Heightfield::flat(40, 40, 0.05, true, 0.0);
        for (k, z) in hf.z_mm.iter_mut().enumerate() {
            *z = -0.05 * ((k % 40) as f64 / 40.0 * std::f64::consts::TAU).sin().abs();
        }
        hf
    };
    let m = machine("grbl-3018.toml");
    // larger than the travel
    let cfg = ToolpathConfig {
        area_mm: [40.0, 200.0],
        ..Default::default()
    };
    match toolpath::run(&cfg, &small, &m) {
        Err(ToolpathError::Machine(e)) => assert!(e.contains("travel") && e.contains("180"), "{e}"),
        other => panic!("expected a travel refusal, got {:?}", other.map(|p| p.summary)),
    }
    // a feed above the machine's limit
    let cfg = ToolpathConfig {
        area_mm: [4.0, 4.0],
        feed_mm_min: 5000.0,
        stepover_mm: 0.2,
        ..Default::default()
    };
    // (refused with the configuration, before any planning)
    match toolpath::run(&cfg, &small, &m) {
        Err(ToolpathError::Config(e)) => assert!(e.contains("feed_mm_min") && e.contains("1000"), "{e}"),
        other => panic!("expected a feed refusal, got {:?}", other.map(|p| p.summary)),
    }
    // the machine check refuses the same in a move list, and a feed that would be written as F0
    let tool = m.tool("ball1").unwrap();
    let start = [0.0, 0.0, 3.0];
    let e = check::check(&[Move::Feed([1.0, 0.0, 3.0], 5000.0)], start, &m, tool).unwrap_err();
    assert!(e.contains("exceeds limits.max_feed_mm_min"), "{e}");
    let e = check::check(&[Move::Feed([1.0, 0.0, 3.0], 0.04)], start, &m, tool).unwrap_err();
    assert!(e.contains("F0"), "{e}");
    // a rapid into the stock, and a rapid across X/Y below safe z
    let e = check::check(&[Move::Rapid([0.0, 0.0, -0.2])], start, &m, tool).unwrap_err();
    assert!(e.contains("into the stock"), "{e}");
    let e = check::check(
        &[Move::Rapid([0.0, 0.0, 1.0]), Move::Rapid([5.0, 0.0, 1.0])],
        start,
        &m,
        tool,
    )
    .unwrap_err();
    assert!(e.contains("safe_z_mm"), "{e}");
    let e = check::check(&[Move::SpindleOn(30000.0)], start, &m, tool).unwrap_err();
    assert!(e.contains("spindle") && e.contains("30000"), "{e}");
    // a legal program passes
    let ok = ToolpathConfig {
        area_mm: [4.0, 4.0],
        stepover_mm: 0.2,
        ..Default::default()
    };
    assert!(toolpath::run(&ok, &small, &m).is_ok());
}

// ---- issue 12: programs a machinist would run -------------------------------------------------------

/// A periodic 6×6 mm tile at 20 µm: a round pocket `depth` deep, flat-bottomed to radius 1.5 mm, its wall
/// rising at `depth / 1.2 mm` to the top at radius 2.7 mm (45° for the deep tile), top at 0.
/// A periodic relief deepest at the area's edges (`depth` there, a fifth of it at the centre): passes start
/// inside material, so their entries must ramp.
fn edge_relief(depth: f64) -> Heightfield {
    let (n, p) = (300, 0.02);
    let mut hf = Heightfield::flat(n, n, p, true, 0.0);
    let tau = std::f64::consts::TAU;
    for j in 0..n {
        for i in 0..n {
            let (x, y) = ((i as f64 + 0.5) * p, (j as f64 + 0.5) * p);
            let bowl = 0.5 + 0.25 * ((tau * x / 6.0).cos() + (tau * y / 6.0).cos());
            hf.z_mm[j * n + i] = -depth * (0.2 + 0.8 * bowl);
        }
    }
    hf
}

fn pocket(depth: f64) -> Heightfield {
    let (n, p) = (300, 0.02);
    let mut hf = Heightfield::flat(n, n, p, true, 0.0);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = ((i as f64 + 0.5) * p - 3.0, (j as f64 + 0.5) * p - 3.0);
            let r = (x * x + y * y).sqrt();
            let t = ((2.7 - r) / 1.2).clamp(0.0, 1.0);
            hf.z_mm[j * n + i] = -depth * t;
        }
    }
    hf
}

/// The three profiles with a roughing tool each, finishing with `ball1`.
const SETUPS: [(&str, &str); 3] = [
    ("grbl-3018.toml", "flat3"),
    ("grbl-router-6040.toml", "ball3"),
    ("linuxcnc-mill.toml", "ball2"),
];

fn program(profile: &str, rough: &str, tile: &Heightfield) -> toolpath::Toolpath {
    let cfg = ToolpathConfig {
        tool: "ball1".into(),
        rough_tool: rough.into(),
        area_mm: [6.0, 6.0],
        stepover_mm: 0.05,
        job: "acceptance".into(),
        ..Default::default()
    };
    toolpath::run(&cfg, tile, &machine(profile)).unwrap_or_else(|e| panic!("{profile}: {e}"))
}

/// Simulate `gcode` with the machine's tool table on a fixed grid.
fn simulate(gcode: &str, m: &Machine) -> brdfmill::stages::simulate::Simulation {
    use brdfmill::stages::simulate::{self, Shape, SimulateConfig};
    let cfg = SimulateConfig {
        tool: Shape::Ball { diameter_mm: 1.0 },
        tools: simulate::tool_table(m),
        pitch_um: 20.0,
        bounds_mm: Some([-2.0, -2.0, 8.0, 8.0]),
        machine: Some(m.clone()),
        // what the program commands: a perfect machine (the profile's backlash and runout cut below any
        // program, and are the machine's, not the toolpath's; tests/machine_accuracy.rs checks those)
        ideal: true,
        // each tool's own cut, for the gouge check per tool
        tool_cuts: true,
        ..Default::default()
    };
    simulate::run(gcode, &cfg).unwrap()
}

/// Program line indices where a level starts (the level comments), and the end.
fn level_starts(gcode: &str) -> Vec<(usize, &'static str)> {
    let mut v = vec![];
    for (k, l) in gcode.lines().enumerate() {
        for tag in ["(roughing layer)", "(finishing: intermediate level)", "(finishing)"] {
            if l == tag {
                v.push((k, tag));
            }
        }
    }
    v
}

/// The program up to (not including) line `k`, closed with `M30`.
fn prefix(gcode: &str, k: usize) -> String {
    let mut s: String = gcode.lines().take(k).map(|l| format!("{l}\n")).collect();
    s.push_str("M30\n");
    s
}

/// For each machine profile and a shallow and a deep tile: no tool cuts below the design beyond the
/// tolerance, no level cuts deeper than its tool's depth of cut, and roughing air is under 10% of the
/// roughing length — all measured on the simulated stock.
#[test]
fn every_profile_and_tile_cuts_within_the_design_and_each_tools_depth_of_cut() {
    use brdfmill::stages::simulate::{self, gcode::ParseOptions};
    for (depth, name) in [(0.08, "shallow"), (1.2, "deep"), (0.5, "edge")] {
        let tile = if name == "edge" {
            edge_relief(depth)
        } else {
            pocket(depth)
        };
        for (profile, rough) in SETUPS {
            let m = machine(profile);
            let p = program(profile, rough, &tile);
            let s = &p.summary;
            let sim = simulate(&p.gcode, &m);
            let ball = brdfmill::cut::tool::Shape::Ball { diameter_mm: 1.0 };
            // the gouge check covers each tool
            let mut cuts = sim.tool_cuts.clone();
            if cuts.is_empty() {
                cuts.push(brdfmill::stages::simulate::ToolCut {
                    number: 1,
                    shape: ball,
                    z_mm: sim.heightfield.z_mm.clone(),
                    segments: 0,
                });
            }
            for c in &cuts {
                let d = simulate::deviation(&sim.of_tool(c), &tile, &ball);
                println!("{name} {profile}: T{} gouge {:.3} µm", c.number, d.max_under_um);
                assert!(
                    d.max_under_um < 1.0,
                    "{name} {profile}: T{} cuts {:.3} µm below the design",
                    c.number,
                    d.max_under_um
                );
            }
            // depth of cut per level, from the stock before and after it
            let starts = level_starts(&p.gcode);
            let mut bounds: Vec<usize> = starts.iter().map(|s| s.0).collect();
            bounds.push(p.gcode.lines().count() - 1);
            let motion = simulate::gcode::parse(&p.gcode, &ParseOptions::default()).unwrap();
            let mut before = simulate(&prefix(&p.gcode, bounds[0]), &m);
            let (mut rough_cut, mut rough_air, mut rough_vertical) = (0.0, 0.0, 0.0);
            for (k, (line, tag)) in starts.iter().enumerate() {
                let end = bounds[k + 1];
                let after = simulate(&prefix(&p.gcode, end), &m);
                let segs: Vec<_> = motion
                    .segments
                    .iter()
                    .filter(|sg| (sg.line as usize) > *line && (sg.line as usize) <= end)
                    .copied()
                    .collect();
                let Some(t) = segs.first().map(|sg| sg.tool) else {
                    continue;
                };
                let tool = m.tools.iter().find(|x| x.number == t).unwrap();
                let doc = tool.aluminium.max_depth_of_cut_mm;
                let deepest = before
                    .heightfield
                    .z_mm
                    .iter()
                    .zip(&after.heightfield.z_mm)
                    .map(|(b, a)| b - a)
                    .fold(0.0, f64::max);
                println!("{name} {profile}: {tag} T{t} cuts {deepest:.4} mm (doc {doc})");
                if deepest > doc * 1.05 + 0.002 {
                    let (k, _) = before
                        .heightfield
                        .z_mm
                        .iter()
                        .zip(&after.heightfield.z_mm)
                        .enumerate()
                        .max_by(|a, b| (a.1 .0 - a.1 .1).total_cmp(&(b.1 .0 - b.1 .1)))
                        .unwrap();
                    let nx = before.heightfield.nx;
                    let xy = before.cell_xy(k % nx, k / nx);
                    println!(
                        "  at {xy:?}: before {} after {}",
                        before.heightfield.z_mm[k], after.heightfield.z_mm[k]
                    );
                }
                assert!(
                    deepest <= doc * 1.05 + 0.002,
                    "{name} {profile}: {tag} at line {line}: T{t} cuts {deepest:.4} mm, more than its depth of cut {doc} mm"
                );
                // entries ramp: no straight descent of the level meets material (measured against the
                // stock at the level's start, which only overstates what is there)
                let plunges: Vec<_> = segs
                    .iter()
                    .filter(|sg| (sg.to[0] - sg.from[0]).hypot(sg.to[1] - sg.from[1]) < 1e-9 && sg.to[2] < sg.from[2])
                    .copied()
                    .collect();
                let (plunged, _) = simulate::cut_and_air_mm(&before, tool.shape, &plunges);
                assert!(
                    plunged == 0.0 || tool.max_ramp_deg >= 90.0,
                    "{name} {profile}: {tag} at line {line}: T{t} plunges {plunged:.4} mm straight into material ({} straight descents)",
                    plunges.len()
                );
                if *tag == "(roughing layer)" {
                    // entries and exits (vertical moves through the pocket already cut) are counted apart:
                    // the air that matters is retracing a surface already at its height
                    let (vertical, across): (Vec<_>, Vec<_>) = segs
                        .iter()
                        .partition(|sg| (sg.to[0] - sg.from[0]).hypot(sg.to[1] - sg.from[1]) < 1e-9);
                    let (c, a) = simulate::cut_and_air_mm(&before, tool.shape, &across);
                    let (cv, av) = simulate::cut_and_air_mm(&before, tool.shape, &vertical);
                    rough_cut += c;
                    rough_air += a;
                    rough_vertical += cv + av;
                }
                before = after;
            }
            if rough_cut + rough_air > 0.0 {
                let air = rough_air / (rough_cut + rough_air);
                println!(
                    "{name} {profile}: roughing air {:.1}% of {:.1} mm across, plus {:.1} mm of vertical entries/exits",
                    100.0 * air,
                    rough_cut + rough_air,
                    rough_vertical
                );
                assert!(air < 0.10, "{name} {profile}: roughing air {:.1}%", 100.0 * air);
            }
            println!(
                "{name} {profile}: {} entries ramped, {} plunged",
                s.ramped_entries, s.plunged_entries
            );
            if depth > 1.0 {
                assert!(s.roughing_layers >= 1 && s.tool_changes == 1, "{name} {profile}: {s:?}");
            }
        }
    }
}

/// Numbers within `tol` and everything else equal, word by word: what a machinist compares.
fn same_program(got: &[&str], want: &str, tol: f64) -> Result<(), String> {
    let want: Vec<&str> = want.lines().collect();
    if got.len() != want.len() {
        return Err(format!(
            "{} lines, golden has {}:\n{}",
            got.len(),
            want.len(),
            got.join("\n")
        ));
    }
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        let split = |l: &str| -> Vec<String> {
            if l.starts_with('(') {
                return vec![l.to_string()];
            }
            l.split_whitespace().map(str::to_string).collect()
        };
        let (gw, ww) = (split(g), split(w));
        let same = gw.len() == ww.len()
            && gw.iter().zip(&ww).all(|(a, b)| {
                if a.starts_with('(') || a.len() < 2 || b.len() < 2 {
                    return a == b;
                }
                let (la, na) = a.split_at(1);
                let (lb, nb) = b.split_at(1);
                match (na.parse::<f64>(), nb.parse::<f64>()) {
                    (Ok(x), Ok(y)) => la == lb && (x - y).abs() <= tol * (1.0 + y.abs()),
                    _ => a == b,
                }
            });
        if !same {
            return Err(format!("line {}: `{g}`, golden `{w}`", k + 1));
        }
    }
    Ok(())
}

/// Golden preamble, tool change and postamble per dialect, from the deep tile with a roughing tool.
#[test]
fn golden_preamble_tool_change_and_postamble() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gcode");
    let bless = std::env::var("BRDFMILL_BLESS").is_ok();
    let tile = pocket(1.2);
    for (profile, rough, dialect) in [
        ("grbl-3018.toml", "flat3", "grbl"),
        ("linuxcnc-mill.toml", "ball2", "linuxcnc"),
    ] {
        let p = program(profile, rough, &tile);
        // the joined job (for GRBL the tool change is then a manual change, `T<n> M0`, as the readers take
        // it); GRBL's second program's own start is a fixture of its own below
        let text = p.gcode.clone();
        let lines: Vec<&str> = text.lines().collect();
        let mut extra = vec![];
        if dialect == "grbl" {
            assert_eq!(p.files.len(), 2, "{profile}: one program per tool");
            let second: Vec<&str> = p.files[1].gcode.lines().collect();
            let dwell = second.iter().position(|l| l.starts_with("G4 P")).unwrap();
            extra.push(("program-2-start", second[..=dwell + 1].to_vec()));
        } else {
            assert_eq!(p.files.len(), 1, "{profile}: one program");
        }
        // header comments: one ASCII comment each, no `[GRBL 1.1[`
        let safety = lines
            .iter()
            .position(|l| *l == "G17 G21 G40 G49 G54 G80 G90 G94")
            .unwrap();
        assert!(lines[..safety].iter().all(|l| l.is_ascii()
            && l.starts_with('(')
            && l.ends_with(')')
            && l.len() <= 78
            && l.matches('(').count() == 1));
        assert!(!text.contains("1.1["), "{}", lines[1]);
        let first_dwell = lines
            .iter()
            .position(|l| l.starts_with("G4 P"))
            .unwrap_or_else(|| panic!("{profile}: no second tool {:?}", p.summary));
        let first_m5 = lines
            .iter()
            .position(|l| *l == "M5")
            .unwrap_or_else(|| panic!("{profile}: no M5"));
        let second_dwell = first_m5
            + lines[first_m5..]
                .iter()
                .position(|l| l.starts_with("G4 P"))
                .unwrap_or_else(|| panic!("{profile}: no second tool {:?}", p.summary));
        let last_cut = lines
            .iter()
            .rposition(|l| l.starts_with("G1") || l.starts_with('X') || l.starts_with('Y') || l.starts_with('Z'))
            .unwrap();
        let last_cut = last_cut.min(lines.iter().rposition(|l| l.starts_with("G0")).unwrap() - 1);
        let mut parts = vec![
            ("preamble", lines[safety..=first_dwell + 1].to_vec()),
            ("toolchange", lines[first_m5 - 2..=second_dwell + 1].to_vec()),
            ("postamble", lines[last_cut + 1..].to_vec()),
        ];
        parts.extend(extra);
        for (part, got) in parts {
            let path = dir.join(format!("{dialect}-{part}.nc"));
            if bless {
                std::fs::create_dir_all(&dir).unwrap();
                std::fs::write(&path, got.join("\n") + "\n").unwrap();
            }
            let want = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            same_program(&got, &want, 1e-3).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
    }
}

/// Issue 13: an injected newline in a profile's name is refused at load, naming the field.
#[test]
fn a_name_with_a_newline_is_refused() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/grbl-3018.toml")).unwrap();
    let evil = text.replace(
        "name = \"3018-class desktop router (GRBL 1.1)\"",
        "name = \"evil\\nG0 Z-40\\nG1 X100 F5000\\n;\"",
    );
    let e = Machine::parse(&evil).unwrap_err().to_string();
    assert!(e.contains("`name`") && e.contains("control"), "{e}");
    let e = Machine::parse(&text.replacen("id = \"ball1\"", "id = \"ball1\\r\"", 1))
        .unwrap_err()
        .to_string();
    assert!(e.contains("tools[0].id"), "{e}");
    let cfg = ToolpathConfig {
        job: "job\nG0 Z-40".into(),
        ..Default::default()
    };
    let e = toolpath::run(&cfg, &pocket(0.05), &machine("grbl-3018.toml"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("`job`"), "{e}");
}

/// Issue 13: endless runs and memory bombs are refused before work starts, naming the field.
#[test]
fn endless_settings_are_refused_with_the_field_and_estimate() {
    let tile = pocket(0.3);
    let m = machine("grbl-3018.toml");
    let run = |cfg: ToolpathConfig, m: &Machine| toolpath::run(&cfg, &tile, m).err().map(|e| e.to_string());
    let e = run(
        ToolpathConfig {
            scallop_um: 1e-9,
            ..Default::default()
        },
        &m,
    )
    .unwrap();
    assert!(e.contains("scallop_um") && e.contains("passes"), "{e}");
    let e = run(
        ToolpathConfig {
            stepover_mm: 1e-7,
            ..Default::default()
        },
        &m,
    )
    .unwrap();
    assert!(e.contains("stepover_mm"), "{e}");
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/grbl-3018.toml")).unwrap();
    // ball1 (the default finishing tool) with its own data, a depth of cut of 1e-9 mm
    let tiny = text.replacen(
        "flute_length_mm = 3.0\n",
        "flute_length_mm = 3.0\naluminium = { feed_mm_min = 150.0, plunge_mm_min = 50.0, spindle_rpm = 10000.0, \
         max_depth_of_cut_mm = 1e-9 }\n",
        1,
    );
    let tiny = Machine::parse(&tiny).unwrap();
    let e = run(
        ToolpathConfig {
            area_mm: [4.0, 4.0],
            ..Default::default()
        },
        &tiny,
    )
    .unwrap();
    assert!(e.contains("max_depth_of_cut_mm") && e.contains("layers"), "{e}");
    let huge = text.replacen("diameter_mm = 1.0", "diameter_mm = 1e12", 1);
    let e = Machine::parse(&huge).unwrap_err().to_string();
    assert!(e.contains("diameter_mm"), "{e}");
    // that each refusal comes before the work is what its message says: an estimate, not a partial result
}

/// rs274 accepts every program of every profile (with a tool change), deep and shallow.
#[test]
#[ignore = "needs rs274 (linuxcnc-uspace); CI runs it with --ignored and it fails when rs274 is absent"]
fn rs274_accepts_every_program() {
    std::process::Command::new("rs274")
        .arg("-h")
        .stdin(std::process::Stdio::null())
        .output()
        .expect("rs274 (Debian package linuxcnc-uspace) must be installed for this test");
    for depth in [0.08, 1.2] {
        let tile = pocket(depth);
        for (profile, rough) in SETUPS {
            let p = program(profile, rough, &tile);
            interpret(&p.gcode, &machine(profile)).unwrap_or_else(|e| panic!("{profile} depth {depth}: {e}"));
        }
    }
}

/// On a machine with backlash the final raster runs one way, and so must the intermediate finishing levels:
/// a level run the other way is shifted by the whole backlash against the final passes, and where it rides
/// at the final cutter location it gouges by backlash × slope (docs/MACHINE.md §5). Measured on the program
/// text along the passes (X, at angle 0), on the feeds that do not descend (an entry ramp's back-and-forth
/// descends at every move).
#[test]
fn on_a_machine_with_backlash_the_finishing_levels_run_one_way_with_the_final_passes() {
    let m = machine("grbl-3018.toml");
    assert!(m.has_backlash());
    let p = program("grbl-3018.toml", "flat3", &pocket(1.2));
    let word = |l: &str, c: char| {
        l.split_whitespace()
            .find_map(|w| w.strip_prefix(c))
            .and_then(|v| v.parse::<f64>().ok())
    };
    let (mut at, mut feed, mut level) = ([0.0f64; 2], false, false);
    let (mut with, mut against, mut final_minus, mut final_plus) = (0.0, 0.0, 0.0, 0.0);
    for l in p.gcode.lines() {
        match l {
            "(finishing: intermediate level)" => level = true,
            "(finishing)" | "(roughing layer)" => level = false,
            _ => {}
        }
        for w in l.split_whitespace() {
            match w {
                "G0" => feed = false,
                "G1" | "G2" | "G3" => feed = true,
                _ => {}
            }
        }
        let to = [word(l, 'X').unwrap_or(at[0]), word(l, 'Z').unwrap_or(at[1])];
        let d = to[0] - at[0];
        if feed && to[1] >= at[1] && d != 0.0 {
            match (level, d < 0.0) {
                (true, true) => with -= d,
                (true, false) => against += d,
                (false, true) => final_minus -= d,
                (false, false) => final_plus += d,
            }
        }
        at = to;
    }
    // the final raster (and the roughing before it, counted with it) cuts along −X
    assert!(
        final_minus > 5.0 * final_plus,
        "final: {final_minus:.1} mm −X, {final_plus:.1} mm +X"
    );
    assert!(with > 1.0, "the pocket needs levels ({with:.2} mm of them)");
    assert!(against < 0.05 * with, "levels: {with:.1} mm −X, {against:.1} mm +X");
}
