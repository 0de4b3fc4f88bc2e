//! From design to machine: a program made by the toolpath stage for a GRBL profile streams to the virtual
//! GRBL 1.1 controller over a real pseudo-terminal, every block is accepted (no `error:`), the receive buffer
//! never overflows, and the controller ends where the program ends.

use brdfmill::brdf::Brdf;
use brdfmill::facets::{self, FacetsConfig};
use brdfmill::gcode::moves::Move;
use brdfmill::ndf::{self, NdfConfig};
use brdfmill::stream::emulator::{Emulator, EmulatorConfig};
use brdfmill::stream::program::Program;
use brdfmill::stream::serial::SerialLink;
use brdfmill::stream::session::{self, Config, Mode, Outcome, Silent};
use brdfmill::toolpath::{self, machine::Machine, machine::Stock, ToolpathConfig};
use std::path::Path;
use std::sync::atomic::AtomicBool;

#[test]
fn a_generated_grbl_program_streams_to_the_virtual_controller() {
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
    let prog = Program::read(&path, true).unwrap();
    let baud = 1_000_000;
    let emu = Emulator::start(EmulatorConfig {
        baud,
        time_scale: 1000.0,
        ..EmulatorConfig::default()
    })
    .expect("pseudo-terminal");
    let mut link = SerialLink::open(&emu.port_path().unwrap(), baud).unwrap();
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
    assert!(!log.events.iter().any(|e| e.contains("error")), "{:?}", log.events);
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
