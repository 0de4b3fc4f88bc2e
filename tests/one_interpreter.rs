//! One G-code interpreter, three readers: the simulator, the virtual controller and the streamer's program
//! model read the same programs through `brdfmill::gcode::interp`, so they must agree on where every move ends.
//! Each program here is read by all three as a GRBL 1.1h program: the simulator's segments (the last one of
//! each line), the virtual controller's executed motion (the last piece of each line, run block by block with
//! line numbers), and the program model's end position of each line (where it knows it). Every line that moves
//! in one reader moves in the others, to the same point.

use brdfmill::apps::stream::emulator::{Controller, EmulatorConfig};
use brdfmill::apps::stream::program::Program;
use brdfmill::gcode::Dialect;
use brdfmill::stages::simulate::gcode::{parse, ParseOptions};
use std::collections::BTreeMap;
use std::path::Path;

type Ends = BTreeMap<usize, [f64; 3]>;

/// The simulator's reading: the end of each line's last segment.
fn simulator(text: &str) -> Ends {
    let opt = ParseOptions {
        dialect: Dialect::Grbl,
        ..ParseOptions::default()
    };
    let m = parse(text, &opt).unwrap_or_else(|e| panic!("the simulator refuses it: {e}"));
    m.segments.iter().map(|s| (s.line as usize, s.to)).collect()
}

/// The virtual controller's reading: each block sent alone with its line number and run to its end (a pause
/// resumed with cycle starts); the end of each line's last executed piece.
fn controller(text: &str) -> Ends {
    let mut c = Controller::new(&EmulatorConfig {
        // faster axes, so long programs run in few simulated minutes; soft limits off (the default)
        settings: vec![
            (110, 6000.0),
            (111, 6000.0),
            (112, 6000.0),
            (120, 500.0),
            (121, 500.0),
            (122, 500.0),
        ],
        ..EmulatorConfig::default()
    });
    c.take_output();
    let program = Program::parse(Path::new("p.nc"), text, 0, true).unwrap();
    for l in program.sendable() {
        let block = l.wire_text(true);
        for b in format!("{block}\n").bytes() {
            c.receive(b);
        }
        let mut out = String::new();
        for step in 0..200_000 {
            c.advance(0.01);
            out += &String::from_utf8(c.take_output()).unwrap();
            if out.contains("ok") || out.contains("error") || out.contains("ALARM") {
                break;
            }
            // M0 waits for the motion before it to finish, then holds; a cycle start sent while that motion
            // runs is ignored (as GRBL does), so it is repeated until the pause is over
            if step % 10 == 9 && block.contains("M0") {
                c.receive(b'~');
            }
        }
        assert!(
            out.contains("ok"),
            "line {}, `{block}`: the controller answered {out:?}",
            l.number
        );
    }
    c.advance(1e5);
    let log = c.take_log();
    assert!(log.executed.iter().all(|p| p.complete), "a block cut short");
    log.executed.iter().map(|p| (p.line as usize, p.to_mm)).collect()
}

/// The program model's reading: each line whose start and end it knows, with its end and whether it moves.
fn model(text: &str) -> BTreeMap<usize, ([f64; 3], bool)> {
    let p = Program::parse(Path::new("p.nc"), text, 0, true).unwrap();
    if let Some(l) = p.lines.iter().find(|l| l.refusal.is_some()) {
        panic!("the model says GRBL refuses line {}: {:?}", l.number, l.refusal);
    }
    let known = |p: [Option<f64>; 3]| Some([p[0]?, p[1]?, p[2]?]);
    p.lines
        .iter()
        .filter(|l| !l.block.is_empty())
        .filter_map(|l| {
            known(l.start_mm)?;
            Some((l.number, (known(l.end_mm)?, l.moves)))
        })
        .collect()
}

fn assert_agree(name: &str, text: &str) {
    let sim = simulator(text);
    let emu = controller(text);
    let model = model(text);
    assert!(!sim.is_empty(), "{name}: nothing moves");
    let lines = |e: &Ends| e.keys().copied().collect::<Vec<_>>();
    assert_eq!(
        lines(&sim),
        lines(&emu),
        "{name}: the lines that move, simulator against controller"
    );
    let gap = |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
    for (line, s) in &sim {
        let e = &emu[line];
        assert!(
            gap(s, e) < 1e-9,
            "{name} line {line}: simulator {s:?}, controller {e:?}"
        );
    }
    // where the program model knows a line's start and end, it moves exactly when the others do, to the same end
    assert!(
        model.len() * 2 > sim.len(),
        "{name}: the model knows too few lines ({})",
        model.len()
    );
    for (line, (end, moves)) in &model {
        assert_eq!(*moves, sim.contains_key(line), "{name} line {line}: moves");
        if let Some(s) = sim.get(line) {
            assert!(
                gap(s, end) < 1e-9,
                "{name} line {line}: simulator {s:?}, program model {end:?}"
            );
        }
    }
}

fn corpus(name: &str) -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/gcode")
            .join(name),
    )
    .unwrap()
}

/// Straight moves and arcs in every plane and both forms, incremental and inch sections, dwells, spindle and
/// a tool change by pause, between the corpus's preamble and postamble.
#[test]
fn the_three_readers_agree_on_a_hand_written_program() {
    let moves = "G0 X1 Y1 Z2\nG1 Z-0.1 F300\nX4 Y2\nG2 X6 Y2 I1 J0\nG3 X8 Y2 R1\nG2 X9 Y3 R-1\n\
                 G18 G2 X10 Z-0.3 I0.5 K-0.1\nG3 X11 Z-0.1 R0.6\nG19 G2 Y4 Z-0.1 J0.5 K0\nG17\n\
                 G91 G1 X0.5 Y0.25\nX0.5 Z-0.05\nG90\nG20 G1 X0.5 Y0.2 F10\nG2 X0.6 Y0.3 I0.1 J0\nG21\n\
                 N99 G0 Z3 ; a line number of its own\nX12 Y5\n";
    let text = format!(
        "{}{moves}{}{}{}",
        corpus("grbl-preamble.nc"),
        corpus("grbl-toolchange.nc"),
        "G0 X13 Y6\nG1 Z-0.2 F200\nX14 Y7\n",
        corpus("grbl-postamble.nc")
    );
    assert_agree("hand-written", &text);
}

/// A program the toolpath stage writes for the GRBL profile (roughing, finishing with `G18` arcs).
#[test]
fn the_three_readers_agree_on_a_generated_program() {
    use brdfmill::cut::machine::{Machine, Stock};
    use brdfmill::stages::brdf::Brdf;
    use brdfmill::stages::facets::{self, FacetsConfig};
    use brdfmill::stages::ndf::{self, NdfConfig};
    use brdfmill::stages::toolpath::{self, ToolpathConfig};
    let n = ndf::run(
        &NdfConfig {
            res: 64,
            ..Default::default()
        },
        &Brdf::parse("beckmann:alpha=0.2").unwrap(),
        None,
    )
    .unwrap();
    let mut fcfg = FacetsConfig {
        facets_x: 4,
        facets_y: 4,
        pitch_um: 20.0,
        ..Default::default()
    };
    fcfg.anneal.sweeps = 300;
    let tile = facets::run(&fcfg, &n.target).unwrap();
    let machine = Machine::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/grbl-3018.toml")).unwrap();
    let tcfg = ToolpathConfig {
        area_mm: [2.0, 2.0],
        scallop_um: 5.0,
        stock: Stock::Wax,
        ..Default::default()
    };
    let p = toolpath::run(&tcfg, &tile.heightfield, &machine).unwrap();
    assert!(p.gcode.contains("G2") || p.gcode.contains("G3"), "the program has arcs");
    assert_agree("generated", &p.gcode);
}

/// LinuxCNC's sample programs (Debian package `linuxcnc-uspace`): those the simulator accepts as GRBL
/// programs (most use words GRBL lacks) are read alike by all three.
#[test]
#[ignore = "needs LinuxCNC's sample programs (/usr/share/linuxcnc/ncfiles, package linuxcnc-uspace)"]
fn the_three_readers_agree_on_linuxcnc_samples() {
    let dir = Path::new("/usr/share/linuxcnc/ncfiles");
    let mut read = 0;
    let mut entries: Vec<_> = std::fs::read_dir(dir).expect("LinuxCNC's samples").flatten().collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let Ok(text) = std::fs::read_to_string(e.path()) else {
            continue;
        };
        let opt = ParseOptions {
            dialect: Dialect::Grbl,
            ..ParseOptions::default()
        };
        let accepted = parse(&text, &opt).is_ok_and(|m| !m.segments.is_empty() && m.segments.len() < 50_000);
        if accepted && Program::parse(Path::new("p.nc"), &text, 0, true).is_ok() {
            assert_agree(&e.path().display().to_string(), &text);
            read += 1;
        }
    }
    assert!(read > 0, "no sample was read as a GRBL program");
}
