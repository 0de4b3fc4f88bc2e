//! From design to machine: a program made by the toolpath stage for a GRBL profile streams to the virtual
//! GRBL 1.1 controller over a real pseudo-terminal, every block is accepted (an `ok` for each, no `error:`,
//! read off the wire), the receive buffer never overflows, and the controller ends where the program ends.

use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig};
use brdfmill::apps::stream::program::Program;
use brdfmill::apps::stream::serial::{Link, SerialLink};
use brdfmill::apps::stream::session::{self, Config, Mode, Outcome, Silent};
use brdfmill::cut::machine::{Machine, Stock};
use brdfmill::gcode::moves::Move;
use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::facets::{self, FacetsConfig};
use brdfmill::stages::ndf::{self, NdfConfig};
use brdfmill::stages::toolpath::{self, ToolpathConfig};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

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

/// A small program for the 3018's profile, written to a temporary folder: the toolpath, the folder, the file.
fn grbl_program() -> (toolpath::Toolpath, tempfile::TempDir, std::path::PathBuf, Machine) {
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
        area_mm: [3.0, 3.0],
        scallop_um: 5.0,
        stock: Stock::Wax,
        ..Default::default()
    };
    let p = toolpath::run(&tcfg, &tile.heightfield, &machine).unwrap();
    assert!(p.gcode.lines().all(|l| l.len() < 80), "GRBL's line buffer");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.nc");
    std::fs::write(&path, &p.gcode).unwrap();
    (p, dir, path, machine)
}

#[test]
fn a_generated_grbl_program_streams_to_the_virtual_controller() {
    let (p, dir, path, machine) = grbl_program();
    let prog = Program::read(&path, true).unwrap();
    let baud = 1_000_000;
    // the controller set as the profile asks (`$12`, which the program's header states)
    let arc_mm = machine.limits.arc_tolerance_mm.expect("the 3018 declares its $12");
    assert_eq!(prog.arc_tolerance_asked_mm(), Some(arc_mm));
    let emu = Emulator::start(EmulatorConfig {
        baud,
        time_scale: 1000.0,
        settings: vec![(12, arc_mm)],
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
    let outcome = session::run(
        &mut link,
        &prog,
        &cfg,
        &dir.path().join("p.journal"),
        Mode::Fresh,
        &mut Silent,
        &AtomicBool::new(false),
    )
    .unwrap();
    assert!(matches!(outcome, Outcome::Completed(_)), "{outcome:?}");
    let log = emu.log();
    assert_eq!(log.rx_overflows, 0);
    // The controller's answers once streaming began: no `error:` (neither a rejected block nor an unmodelled
    // word, which the virtual controller answers `error:20`), and one `ok` per program line.
    let answers = String::from_utf8_lossy(&link.received);
    let errors: Vec<&str> = answers.lines().filter(|l| l.trim().starts_with("error:")).collect();
    assert!(errors.is_empty(), "{errors:?}");
    let oks = answers.lines().filter(|l| l.trim() == "ok").count();
    assert_eq!(oks, prog.sendable().count(), "one ok per line");
    let sent: Vec<String> = prog.sendable().map(|l| l.wire_text(true)).collect();
    assert!(log.received.ends_with(&sent), "every line arrived once, in order");
    let last = log.executed.last().expect("motion executed").to_mm;
    let end = p
        .moves
        .iter()
        .rev()
        .find_map(|m| {
            if let Move::Rapid(q) | Move::Feed(q, _) = m {
                Some(*q)
            } else {
                None
            }
        })
        .unwrap();
    for k in 0..3 {
        assert!(
            (last[k] - end[k]).abs() < 1e-3,
            "controller ends at {last:?}, program at {end:?}"
        );
    }
}

/// A controller left at GRBL's default `$12` (0.002 mm), coarser than the 0.001 mm the program's header
/// says its verdict was simulated with: the stream is refused after `$$`, before a program line or a journal
/// is written, and the message says how to set it; `--accept-coarser-arcs` streams it anyway.
#[test]
fn a_controller_with_a_coarser_arc_tolerance_is_refused_before_a_line_is_sent() {
    let (_, dir, path, _) = grbl_program();
    let prog = Program::read(&path, true).unwrap();
    let baud = 1_000_000;
    let run = |cfg: &Config, journal: &str| {
        let emu = Emulator::start(EmulatorConfig {
            baud,
            time_scale: 1000.0,
            ..EmulatorConfig::default()
        })
        .expect("pseudo-terminal");
        let mut link = SerialLink::open(&emu.port_path().unwrap(), baud).unwrap();
        let r = session::run(
            &mut link,
            &prog,
            cfg,
            &dir.path().join(journal),
            Mode::Fresh,
            &mut Silent,
            &AtomicBool::new(false),
        );
        (r, emu.log())
    };
    let (refused, log) = run(&Config::default(), "refused.journal");
    let err = refused.expect_err("a coarser $12 is refused");
    let msg = err.to_string();
    assert!(
        msg.contains("$12 is 0.002 mm") && msg.contains("`$12=0.001`") && msg.contains("--accept-coarser-arcs"),
        "{msg}"
    );
    let sent: Vec<String> = prog.sendable().map(|l| l.wire_text(true)).collect();
    assert!(
        !log.received.iter().any(|r| sent.contains(r)),
        "no program line reached the controller: {:?}",
        log.received
    );
    assert!(!dir.path().join("refused.journal").exists(), "no journal was started");
    let accept = Config {
        accept_coarser_arcs: true,
        spindle_dwell_s: 0.1,
        ..Config::default()
    };
    let (ran, log) = run(&accept, "accepted.journal");
    assert!(matches!(ran, Ok(Outcome::Completed(_))), "{ran:?}");
    assert!(
        log.received.ends_with(&sent),
        "accepted, every line arrived once, in order"
    );
}
