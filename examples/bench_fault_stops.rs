//! Where injected stops land: seeded `ALARM:2` faults (a soft limit's controlled stop) at random lines of
//! programs that are half arcs (in offset and `R` form), against the virtual GRBL 1.1h controller over a
//! real pseudo-terminal, motion 8× real time. It counts the stops that came inside an arc (the streamer
//! then resumes by finishing that arc from the point reached) and the resumes that completed.
//!
//! ```sh
//! cargo run --release --example bench_fault_stops          # 40 trials
//! cargo run --release --example bench_fault_stops -- 200
//! ```
//!
//! Where a stop lands depends on how fast this machine runs the streamer beside the emulator, so these
//! are wall-clock figures, measured here and not asserted by a test: `tests/stream_emulator.rs`'s fault
//! trials assert that no line is lost and every line runs once wherever the stops land, and the unit
//! tests of `stream::session::locate` and `resume` place and finish stops inside arcs without a clock.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig, Fault, FaultAt, FaultKind};
use brdfmill::apps::stream::journal::Journal;
use brdfmill::apps::stream::program::{MotionMode, Program};
use brdfmill::apps::stream::serial::SerialLink;
use brdfmill::apps::stream::session::{self, Config, Mode, Outcome, Silent};

const BAUD: u32 = 1_000_000;

/// xorshift: the same programs and fault lines for the same seed.
struct Rng(u64);
impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) % n
    }
}

/// Sixteen cuts of at least 3 mm in a 20 mm square, every other one a quarter-ish arc: `I J` and `R`
/// form alternately.
fn program_text(rng: &mut Rng) -> String {
    let mut t = String::from("G21 G90\nG0 X0 Y0 Z2\nM3 S8000\nG1 Z-0.5 F1200\n");
    let (mut px, mut py) = (0.0f64, 0.0f64);
    for i in 0..16 {
        let (x, y) = loop {
            let (x, y) = (rng.below(20_000) as f64 / 1000.0, rng.below(20_000) as f64 / 1000.0);
            if (x - px).hypot(y - py) >= 3.0 {
                break (x, y);
            }
        };
        if i % 2 == 0 {
            t += &format!("G1 X{x:.3} Y{y:.3}\n");
        } else {
            // the centre half a chord to the left: a G3 the short way (90°), the same as `R` rounded up
            let (cx, cy) = ((px + x) / 2.0 - 0.5 * (y - py), (py + y) / 2.0 + 0.5 * (x - px));
            let r = ((cx - px).hypot(cy - py) * 1000.0 + 1.0).ceil() / 1000.0;
            t += &if i % 4 == 1 {
                format!("G3 X{x:.3} Y{y:.3} I{:.3} J{:.3}\n", cx - px, cy - py)
            } else {
                format!("G3 X{x:.3} Y{y:.3} R{r:.3}\n")
            };
        }
        (px, py) = (x, y);
    }
    t + "G0 Z5\nM5\n"
}

fn run(emu: &Emulator, prog: &Program, journal: &Path, mode: Mode, cfg: &Config) -> Outcome {
    let mut link = SerialLink::open(&emu.port_path().expect("port up"), BAUD).unwrap();
    session::run(
        &mut link,
        prog,
        cfg,
        journal,
        mode,
        &mut Silent,
        &AtomicBool::new(false),
    )
    .unwrap()
}

fn main() {
    let trials: u64 = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(40);
    let cfg = Config {
        spindle_dwell_s: 0.1,
        silence_timeout: Duration::from_secs(5),
        ..Config::default()
    };
    let t0 = Instant::now();
    let (mut stopped, mut in_arc, mut resumed) = (0, 0, 0);
    for seed in 1..=trials {
        let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.nc");
        std::fs::write(&path, program_text(&mut rng)).unwrap();
        let prog = Program::read(&path, true).unwrap();
        let lines = prog.sendable().count() as u64;
        let line = 5 + rng.below(lines - 4) as u32;
        let emu = Emulator::start(EmulatorConfig {
            baud: BAUD,
            time_scale: 8.0,
            faults: vec![Fault {
                at: FaultAt::LineNumber(line),
                kind: FaultKind::Alarm(2),
            }],
            ..EmulatorConfig::default()
        })
        .expect("pseudo-terminal");
        let journal = dir.path().join("p.journal.jsonl");
        if !matches!(run(&emu, &prog, &journal, Mode::Fresh, &cfg), Outcome::Stopped(..)) {
            continue;
        }
        stopped += 1;
        let st = Journal::load(&journal).unwrap();
        let arc = |n: usize| {
            matches!(
                prog.line(n).and_then(|l| l.motion),
                Some(MotionMode::ArcCw | MotionMode::ArcCcw)
            )
        };
        if st.partial.is_some_and(|(n, _)| arc(n)) {
            in_arc += 1;
        }
        if matches!(run(&emu, &prog, &journal, Mode::Resume, &cfg), Outcome::Completed(_)) {
            resumed += 1;
        }
    }
    println!(
        "{trials} trials (ALARM:2 at a random line, programs half arcs): {stopped} stopped, {in_arc} of them \
         inside an arc, {resumed} resumed to completion; {:.1} s",
        t0.elapsed().as_secs_f64()
    );
}
