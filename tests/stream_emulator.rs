//! The streamer (on `serialport`) against the virtual GRBL 1.1h controller through a real pseudo-terminal:
//! streaming correctness (every line once, in order, no overflow), stock builds, and seeded fault trials
//! checked against the controller's own record of executed motion. Every wait is bounded; no sleep is
//! used for synchronisation; no timing figure is asserted (throughput is `examples/bench_stream.rs`).

mod fault_programs;

use fault_programs::{random_program, Rng};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig, Fault, FaultAt, FaultKind, Piece};
use brdfmill::apps::stream::journal::{Journal, JournalState};
use brdfmill::apps::stream::program::{MotionMode, Program};
use brdfmill::apps::stream::serial::{Link, SerialLink};
use brdfmill::apps::stream::session::{
    self, Config, EndDetection, Mode, Observer, Outcome, Progress, Silent, StopReason,
};

fn program(dir: &Path, name: &str, text: &str) -> Program {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    Program::read(&p, true).unwrap()
}

/// Which GRBL build and `$10` the virtual controller has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Build {
    /// `[OPT:V,15,128]`, `$10=1`: neither `Ln` nor `Bf`.
    Stock,
    /// `USE_LINE_NUMBERS`, `$10=1`: `Ln`, no `Bf`.
    LineNumbers,
    /// A stock build with `$10=3`: `Bf`, no `Ln`.
    PlannerBlocks,
}

fn emulator_for(build: Build, baud: u32, time_scale: f64, faults: Vec<Fault>) -> Emulator {
    Emulator::start(EmulatorConfig {
        baud,
        time_scale,
        line_numbers: build == Build::LineNumbers,
        settings: if build == Build::PlannerBlocks {
            vec![(10, 3.0)]
        } else {
            vec![]
        },
        faults,
        ..EmulatorConfig::default()
    })
    .expect("pseudo-terminal")
}

fn test_config() -> Config {
    Config {
        spindle_dwell_s: 0.1,
        // shorter than the 5 s default so silence faults resolve quickly, yet over seven status periods
        // (200 ms): 600 ms of scheduling delay was seen on a loaded 2-core machine. The silence trials mute
        // the controller for 32 s simulated = 4 s real at ×8, well beyond it.
        silence_timeout: Duration::from_millis(1500),
        ..Config::default()
    }
}

/// [`test_config`] with the default 5 s silence timeout, for a stream into which no silence is injected:
/// on a heavily loaded machine (CI beside a build) a resume once went 1.5 s without hearing from the
/// controller, and the short timeout then ended a job nothing was wrong with.
fn patient_config() -> Config {
    Config {
        silence_timeout: Config::default().silence_timeout,
        ..test_config()
    }
}

fn stream(emu: &Emulator, baud: u32, prog: &Program, journal: &Path, mode: Mode) -> Outcome {
    stream_with(emu, baud, prog, journal, mode, &mut Silent, &AtomicBool::new(false))
}

/// [`stream`] with [`patient_config`].
fn stream_patiently(emu: &Emulator, baud: u32, prog: &Program, journal: &Path, mode: Mode) -> Outcome {
    let port = emu.port_path().expect("port up");
    let mut link = SerialLink::open(&port, baud).unwrap();
    session::run(
        &mut link,
        prog,
        &patient_config(),
        journal,
        mode,
        &mut Silent,
        &AtomicBool::new(false),
    )
    .unwrap_or_else(|e| {
        let log = emu.log();
        panic!(
            "{e}\nprogram:\n{}\njournal:\n{}\nexecuted: {:#?}\nevents: {:?}",
            prog.lines
                .iter()
                .map(|l| l.source.as_str())
                .collect::<Vec<_>>()
                .join("\n"),
            std::fs::read_to_string(journal).unwrap_or_default(),
            log.executed,
            log.events
        )
    })
}

fn stream_with(
    emu: &Emulator,
    baud: u32,
    prog: &Program,
    journal: &Path,
    mode: Mode,
    obs: &mut dyn Observer,
    stop: &AtomicBool,
) -> Outcome {
    let port = emu.port_path().expect("port up");
    let mut link = SerialLink::open(&port, baud).unwrap();
    session::run(&mut link, prog, &test_config(), journal, mode, obs, stop).unwrap()
}

/// A point's fraction of the way along a line.
type Param = Box<dyn Fn([f64; 3]) -> f64>;

/// How far along moving line `l` (from `a` to `b`, work mm) a point is, 0 at its start and 1 at its end,
/// and the line's length: by projection on a straight line, by angle about the centre on an arc (`I J`
/// or `R` read from the block here, independently of the streamer's arc model).
fn path_param(l: &brdfmill::apps::stream::program::Line, a: [f64; 3], b: [f64; 3]) -> (Param, f64) {
    use brdfmill::apps::stream::program::words;
    let d: Vec<f64> = (0..3).map(|i| b[i] - a[i]).collect();
    let len = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cw = match l.motion {
        Some(MotionMode::ArcCw) => true,
        Some(MotionMode::ArcCcw) => false,
        _ => {
            return (
                Box::new(move |p: [f64; 3]| (0..3).map(|i| (p[i] - a[i]) * d[i]).sum::<f64>() / (len * len)),
                len,
            )
        }
    };
    let ws = words(&l.block).unwrap();
    let word = |c: char| ws.iter().find(|w| w.letter == c).map_or(0.0, |w| w.value);
    let (cx, cy) = match ws.iter().find(|w| w.letter == 'R') {
        // the radius form: the centre beside the chord's midpoint at h = √(r² − d²/4), to the left of the
        // chord for G3 with R > 0 and for G2 with R < 0, else to the right
        Some(r) => {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let d = dx.hypot(dy);
            let h = (r.value * r.value - d * d / 4.0).max(0.0).sqrt() / d;
            let h = if cw == (r.value > 0.0) { -h } else { h };
            ((a[0] + b[0]) / 2.0 - h * dy, (a[1] + b[1]) / 2.0 + h * dx)
        }
        None => (a[0] + word('I'), a[1] + word('J')),
    };
    let ang = move |p: [f64; 3]| (p[1] - cy).atan2(p[0] - cx);
    let tau = std::f64::consts::TAU;
    let turn = move |p: [f64; 3]| {
        let raw = (ang(p) - ang(a)).rem_euclid(tau);
        if cw {
            (tau - raw).rem_euclid(tau)
        } else {
            raw
        }
    };
    let travel = turn(b);
    let r = (a[0] - cx).hypot(a[1] - cy);
    (
        Box::new(move |p: [f64; 3]| {
            let d = turn(p);
            // a point at the start may read as a full turn
            (if d > (travel + tau) / 2.0 { d - tau } else { d }) / travel
        }),
        r * travel,
    )
}

/// Every moving line's pieces in the controller's log cover it exactly once: from its start to its end,
/// contiguous, without overlap (within `tol` mm); an arc's pieces are its chords.
/// With `overlap_allowed` (a stop whose position was ambiguous, resumed from the earliest explanation) a line
/// may partly run twice, but still none may be left out.
fn assert_exactly_once(prog: &Program, pieces: &[Piece], tol: f64, seed: u64, overlap_allowed: bool) {
    for l in prog.lines.iter().filter(|l| l.moves) {
        // The emulator powers up at the machine origin, where the program model does not know the tool is.
        let a: [f64; 3] = std::array::from_fn(|i| l.start_mm[i].unwrap_or(0.0));
        let b: [f64; 3] = std::array::from_fn(|i| l.end_mm[i].unwrap());
        let (t, len) = path_param(l, a, b);
        let mut spans: Vec<(f64, f64)> = pieces
            .iter()
            .filter(|p| p.line as usize == l.number)
            .map(|p| (t(p.from_mm), t(p.to_mm)))
            .collect();
        spans.sort_by(|x, y| x.0.total_cmp(&y.0));
        let eps = tol / len;
        assert!(!spans.is_empty(), "seed {seed}: line {} never ran", l.number);
        // `at`: how far the pieces so far cover the line, without a gap
        let mut at: f64 = 0.0;
        for (s, e) in &spans {
            assert!(
                *s <= at + eps,
                "seed {seed}: line {} pieces {spans:?} leave a gap",
                l.number
            );
            // the part of this piece already covered ran twice; pieces starting within `tol` of each other
            // (a stop just past a chord's start, and the resume from the reported, rounded position) may come
            // in either order
            assert!(
                overlap_allowed || at.min(*e) - s <= eps,
                "seed {seed}: line {} pieces {spans:?} overlap",
                l.number
            );
            at = at.max(*e);
        }
        assert!(
            (at - 1.0).abs() <= eps,
            "seed {seed}: line {} ends at t = {at}",
            l.number
        );
    }
}

/// Every line the journal records as executed (or cut) really ran, by the controller's record: the
/// journal claims nothing that evidence does not show (issue 14: 16 lines recorded as run that never ran).
fn assert_journal_truthful(prog: &Program, st: &JournalState, pieces: &[Piece], tol: f64, what: &str) {
    let near = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() <= tol);
    for &n in &st.executed {
        let l = prog.line(n).unwrap();
        if !l.moves {
            continue;
        }
        let end: Vec<f64> = l.end_mm.iter().map(|v| v.unwrap()).collect();
        let end = [end[0], end[1], end[2]];
        assert!(
            pieces.iter().any(|p| p.line as usize == n && near(p.to_mm, end)),
            "{what}: the journal says line {n} executed, the controller never reached its end"
        );
    }
    if let Some((n, at)) = st.partial {
        // The tool reached `at` on line `n`: it stopped there, or (an ambiguous stop, resumed from the
        // earliest explanation) passed through it.
        let on = |p: &Piece| {
            let d: Vec<f64> = (0..3).map(|i| p.to_mm[i] - p.from_mm[i]).collect();
            let len2: f64 = d.iter().map(|v| v * v).sum();
            let t = ((0..3).map(|i| (at[i] - p.from_mm[i]) * d[i]).sum::<f64>() / len2.max(1e-18)).clamp(0.0, 1.0);
            (0..3).all(|i| (p.from_mm[i] + t * d[i] - at[i]).abs() <= tol)
        };
        assert!(
            pieces
                .iter()
                .any(|p| p.line as usize == n && (near(p.to_mm, at) || on(p))),
            "{what}: the journal says line {n} was cut at {at:?}, the controller never was there on it"
        );
    }
}

/// Raises the stop flag (a Ctrl-C) once, when `at` lines have been answered.
struct StopAt<'a> {
    at: usize,
    stop: &'a AtomicBool,
    fired: bool,
}
impl Observer for StopAt<'_> {
    fn progress(&mut self, p: &Progress) {
        if !self.fired && p.lines_acked >= self.at {
            self.fired = true;
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

/// The faults a trial injects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Trial {
    Error,
    Alarm,
    /// Ctrl-C: feed hold, `Hold:0`, then a reset that raises no `ALARM:3`.
    ResetAfterHold,
    /// The controller sends nothing for a while; the streamer holds and resets.
    Silence,
    Disconnect,
}

/// What one trial did.
struct TrialResult {
    trial: Trial,
    /// The stop position was ambiguous (journaled): the resume started from the earliest explanation.
    ambiguous: bool,
}

/// One seeded trial.
fn fault_trial(seed: u64) -> TrialResult {
    let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let dir = tempfile::tempdir().unwrap();
    let text = random_program(&mut rng, 16);
    let prog = program(dir.path(), "p.nc", &text);
    let n_lines = prog.sendable().count();
    let trial = [
        Trial::Error,
        Trial::Alarm,
        Trial::ResetAfterHold,
        Trial::Silence,
        Trial::Disconnect,
    ][rng.below(5) as usize];
    let build = [Build::Stock, Build::LineNumbers, Build::PlannerBlocks][rng.below(3) as usize];
    // GRBL keeps running the lines behind a rejected one until the feed hold arrives, so an error is
    // injected where the planner holds seconds of motion: from the third cut on, right after two straight
    // cuts (an arc's 15 planned chords last a fraction of a second). With less, the next motion may start
    // before the hold and the streamer refuses to resume (see docs/STREAM.md, known limit). A program with no
    // two straight cuts in a row gets its error on the last line.
    let line = if trial == Trial::Error {
        let straight = |k: usize| {
            prog.line(k)
                .is_some_and(|l| l.moves && l.motion == Some(MotionMode::Linear))
        };
        let eligible: Vec<usize> = (7..=n_lines).filter(|&k| straight(k - 1) && straight(k - 2)).collect();
        let pick = rng.below(eligible.len().max(1) as u64) as usize;
        eligible.get(pick).copied().unwrap_or(n_lines)
    } else {
        1 + rng.below(n_lines as u64) as usize
    };
    let kind = match trial {
        Trial::Error => Some(FaultKind::Error(20)),
        Trial::Alarm => Some(FaultKind::Alarm(2)),
        Trial::Silence => Some(FaultKind::Silence(32_000)),
        Trial::Disconnect => Some(FaultKind::Disconnect),
        Trial::ResetAfterHold => None,
    };
    let faults = kind
        .map(|kind| Fault {
            at: FaultAt::LineNumber(line as u32),
            kind,
        })
        .into_iter()
        .collect();
    let baud = 1_000_000;
    let emu = emulator_for(build, baud, 8.0, faults);
    let journal = dir.path().join("p.journal.jsonl");
    let gen = emu.generation();
    let what = format!("seed {seed}: {trial:?} at line {line} on {build:?}");
    let stop = AtomicBool::new(false);
    let mut obs = StopAt {
        at: if trial == Trial::ResetAfterHold {
            line
        } else {
            usize::MAX
        },
        stop: &stop,
        fired: false,
    };
    let first = stream_with(&emu, baud, &prog, &journal, Mode::Fresh, &mut obs, &stop);
    let report = match first {
        Outcome::Stopped(report, _) => Some(report),
        // A Ctrl-C after the last answer can come too late to stop anything.
        Outcome::Completed(_) if trial == Trial::ResetAfterHold => None,
        other => panic!("{what}: did not stop the job: {other:?}"),
    };
    if let Some(report) = &report {
        match trial {
            Trial::Error => {
                assert_eq!(report.reason, StopReason::Error(20), "{what}");
                assert_eq!(report.line, Some(line), "{what}: the stop names the rejected line");
            }
            Trial::Alarm => assert_eq!(report.reason, StopReason::Alarm(2), "{what}"),
            Trial::ResetAfterHold => assert_eq!(report.reason, StopReason::User, "{what}"),
            Trial::Silence => assert_eq!(report.reason, StopReason::Protocol, "{what}"),
            Trial::Disconnect => {
                assert_eq!(report.reason, StopReason::Disconnect, "{what}");
                emu.wait_new_port(gen, Duration::from_secs(5))
                    .expect("new port after the disconnect");
            }
        }
        // The journal is consistent (load checks it) and claims only what the controller did.
        let st = Journal::load(&journal).unwrap();
        assert!(st.stop.is_some() && !st.complete, "{what}");
        if std::env::var("TRIAL_DEBUG").is_ok() {
            let log = emu.log();
            eprintln!(
                "{what}\n{}\n{:#?}\n{:?}",
                std::fs::read_to_string(&journal).unwrap(),
                log.executed,
                log.events
            );
        }
        assert_journal_truthful(&prog, &st, &emu.log().executed, 0.01, &what);
        // the fault fired once: nothing is injected into the resume
        let second = stream_patiently(&emu, baud, &prog, &journal, Mode::Resume);
        assert!(
            matches!(second, Outcome::Completed(_)),
            "{what}: resume did not complete: {second:?}\n{}",
            std::fs::read_to_string(&journal).unwrap()
        );
    }
    let st = Journal::load(&journal).unwrap();
    assert!(st.complete, "{what}: journal not complete");
    let log = emu.log();
    if std::env::var("TRIAL_DEBUG").is_ok() {
        eprintln!(
            "{what}\n{}\n{:#?}\n{:?}",
            std::fs::read_to_string(&journal).unwrap(),
            log.executed,
            log.events
        );
    }
    assert_eq!(log.rx_overflows, 0, "{what}");
    let text = std::fs::read_to_string(&journal).unwrap();
    let ambiguous = text.contains("\"event\":\"ambiguous\"");
    assert_exactly_once(&prog, &log.executed, 0.01, seed, ambiguous);
    TrialResult { trial, ambiguous }
}

/// 200 seeded trials of error, alarm, reset after a completed hold, silence and disconnect at random lines,
/// on stock, `Ln` and `Bf` builds: across fault and resume no motion line is lost and, unless the stop
/// position was ambiguous (journaled), every one runs exactly once, by the controller's own record.
#[test]
#[ignore = "slow (200 fault trials): cargo test -- --ignored runs it, and .ci/run"]
fn injected_faults_then_resume_run_every_motion_line_exactly_once() {
    let trials = 200;
    let seeds: Vec<u64> = match std::env::var("TRIAL_SEED") {
        Ok(s) => vec![s.parse().unwrap()],
        Err(_) => (1..=trials).collect(),
    };
    let results: Vec<TrialResult> = std::thread::scope(|s| {
        let chunks: Vec<Vec<u64>> = (0..4)
            .map(|k| seeds.iter().copied().filter(|x| x % 4 == k).collect())
            .collect();
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|c| s.spawn(move || c.into_iter().map(fault_trial).collect::<Vec<_>>()))
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    let count = |t: Trial| results.iter().filter(|r| r.trial == t).count();
    // how many stops land inside an arc depends on the machine's speed beside the emulator: a wall-clock
    // figure, measured by `examples/bench_fault_stops.rs`, not asserted here
    println!(
        "{} fault trials ({} error, {} alarm, {} reset after hold, {} silence, {} disconnect): no motion line \
         lost; every one ran exactly once except in {} trials whose stop position was ambiguous (resumed from \
         the earliest line that may not have run)",
        results.len(),
        count(Trial::Error),
        count(Trial::Alarm),
        count(Trial::ResetAfterHold),
        count(Trial::Silence),
        count(Trial::Disconnect),
        results.iter().filter(|r| r.ambiguous).count()
    );
    assert_eq!(results.len(), seeds.len());
}

/// Ends a run that would never end, from the protocol's own evidence rather than a clock: once every
/// line is answered `ok` and the controller reports Idle, a streamer that still has not finished after this
/// many further status reports never will (the end needs two consecutive Idle reports at the end point).
const IDLE_REPORTS_AFTER_THE_LAST_OK: usize = 50;

/// Sets `stop` after [`IDLE_REPORTS_AFTER_THE_LAST_OK`] Idle reports past the last `ok`, so a hung streamer
/// returns `Stopped` and the test fails instead of hanging.
struct HangGuard<'a> {
    stop: &'a AtomicBool,
    idle_after_last_ok: usize,
}

impl Observer for HangGuard<'_> {
    fn progress(&mut self, p: &Progress) {
        if p.lines_acked >= p.lines_total && p.state == Some(brdfmill::apps::stream::protocol::MachineState::Idle) {
            self.idle_after_last_ok += 1;
            if self.idle_after_last_ok > IDLE_REPORTS_AFTER_THE_LAST_OK {
                self.stop.store(true, Ordering::SeqCst);
            }
        }
    }
}

/// Issue 14, row 1: a 12-line program on a stock build (`[OPT:V,15,128]`, `$10=1`: no `Ln`, no `Bf`)
/// completes — the end is read from Idle at the end point — and nothing is changed on the controller.
#[test]
fn a_stock_build_completes_and_says_how_the_end_was_read() {
    let out = {
        let dir = tempfile::tempdir().unwrap();
        let mut text = String::from("G21G90\nG0X0Y0Z1\nG1Z-0.2F300\n");
        for i in 0..8 {
            text += &format!("G1X{}Y{}\n", (i % 2) * 5, i + 1);
        }
        text += "G0Z1\n";
        let prog = program(dir.path(), "twelve.nc", &text);
        assert_eq!(prog.sendable().count(), 12);
        let emu = emulator_for(Build::Stock, 115_200, 20.0, vec![]);
        let stop = AtomicBool::new(false);
        let mut guard = HangGuard {
            stop: &stop,
            idle_after_last_ok: 0,
        };
        let journal = dir.path().join("j");
        let outcome = stream_with(&emu, 115_200, &prog, &journal, Mode::Fresh, &mut guard, &stop);
        (outcome, emu.log())
    };
    let (Outcome::Completed(stats), log) = out else {
        panic!("did not complete: {out:?}")
    };
    assert_eq!(stats.end_detection, Some(EndDetection::IdleAtEndPoint));
    assert!(
        !log.received.iter().any(|l| l.starts_with('$') && l.contains('=')),
        "a setting was written: {:?}",
        log.received
    );
    assert_eq!(
        log.executed.iter().filter(|p| p.complete).count(),
        11,
        "every motion ran"
    );
}

/// A link whose reads and writes are now and then interrupted by a signal (EINTR), as a Ctrl-C does.
struct Interrupting {
    inner: SerialLink,
    calls: u64,
}
impl Link for Interrupting {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.calls += 1;
        if self.calls % 5 == 0 {
            return Err(std::io::ErrorKind::Interrupted.into());
        }
        self.inner.write_all(bytes)
    }
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        self.calls += 1;
        if self.calls % 3 == 0 {
            return Err(std::io::ErrorKind::Interrupted.into());
        }
        self.inner.read(buf, timeout)
    }
    fn name(&self) -> &str {
        self.inner.name()
    }
}

/// Issue 14: an interrupted system call is retried, never taken for a lost link.
#[test]
fn interrupted_system_calls_are_not_a_lost_link() {
    let dir = tempfile::tempdir().unwrap();
    let text = "G21G90\nG0X0Y0Z1\nG1Z-0.2F300\nG1X5\nG1Y5\nG1X0\nG1Y0\nG0Z1\n";
    let prog = program(dir.path(), "sq.nc", text);
    let emu = emulator_for(Build::LineNumbers, 115_200, 20.0, vec![]);
    let mut link = Interrupting {
        inner: SerialLink::open(&emu.port_path().unwrap(), 115_200).unwrap(),
        calls: 0,
    };
    let outcome = session::run(
        &mut link,
        &prog,
        &test_config(),
        &dir.path().join("j"),
        Mode::Fresh,
        &mut Silent,
        &AtomicBool::new(false),
    )
    .unwrap();
    assert!(matches!(outcome, Outcome::Completed(_)), "{outcome:?}");
}

/// Work = machine coordinates (no offset), homed at the top corner: 24 lines, all motion at negative
/// coordinates.
fn negative_program(dir: &Path) -> Program {
    let mut text = String::from("G21G90\nG0X-10Y-10Z-1\nG1Z-3F300\n");
    for i in 0..20 {
        text += &format!("G1X{}Y{}\n", -10 - (i % 2) * 8, -11 - i);
    }
    text += "G0Z-1\n";
    program(dir, "neg.nc", &text)
}

/// A stock controller at 1 Mbaud and 8× time with `settings`, raising `ALARM:2` on line 15.
fn alarm_at_line_15(settings: Vec<(u16, f64)>) -> Emulator {
    Emulator::start(EmulatorConfig {
        baud: 1_000_000,
        time_scale: 8.0,
        settings,
        faults: vec![Fault {
            at: FaultAt::LineNumber(15),
            kind: FaultKind::Alarm(2),
        }],
        ..EmulatorConfig::default()
    })
    .unwrap()
}

/// Issue 14, row 3: a soft limit on a homed machine. The controller first comes to a controlled stop
/// (`Hold:1`, as 1.1h's `limits_soft_check`), then answers nothing until reset; the streamer stops without
/// waiting out the hold timeout, resets, journals only what ran, and the resume approach stays inside
/// machine travel (today's `G0 Z5` lies beyond machine Z 0 and raises a new `ALARM:2`); every line then ran
/// exactly once.
#[test]
fn a_soft_limit_stops_under_control_and_the_resume_stays_inside_travel() {
    let dir = tempfile::tempdir().unwrap();
    let prog = negative_program(dir.path());
    let emu = alarm_at_line_15(vec![(22, 1.0), (20, 1.0)]);
    // Home first: a machine with homing enabled powers up locked.
    let mut link = SerialLink::open(&emu.port_path().unwrap(), 1_000_000).unwrap();
    link.write_all(b"$H\n").unwrap();
    let mut seen = String::new();
    // at most 50 reads of 100 ms: a bounded wait, not a timing assertion
    for _ in 0..50 {
        if seen.contains("ok") {
            break;
        }
        let mut b = [0u8; 256];
        let n = link.read(&mut b, Duration::from_millis(100)).unwrap();
        seen += &String::from_utf8_lossy(&b[..n]);
    }
    drop(link);
    let journal = dir.path().join("j");
    let Outcome::Stopped(r, _) = stream(&emu, 1_000_000, &prog, &journal, Mode::Fresh) else {
        panic!("the alarm did not stop the job")
    };
    assert_eq!(r.reason, StopReason::Alarm(2));
    assert!(r.located, "{}", r.message);
    assert!(r.message.contains("travel"), "says what to check: {}", r.message);
    // no wait for a status that never comes: the stop is reported as the alarm, not as motion that did not
    // stop
    assert!(!r.message.contains("did not stop"), "{}", r.message);
    let st = Journal::load(&journal).unwrap();
    assert_journal_truthful(&prog, &st, &emu.log().executed, 0.01, "soft limit");
    let second = stream(&emu, 1_000_000, &prog, &journal, Mode::Resume);
    assert!(matches!(second, Outcome::Completed(_)), "{second:?}");
    let log = emu.log();
    assert_eq!(
        log.events.iter().filter(|e| e.starts_with("ALARM:2")).count(),
        1,
        "the resume raised a new alarm: {:?}",
        log.events
    );
    assert!(log.received.iter().any(|l| l == "G0Z0"), "{:?}", log.received);
    assert!(
        log.events.iter().any(|e| e.contains("controlled stop")),
        "{:?}",
        log.events
    );
    assert_exactly_once(&prog, &log.executed, 0.01, 0, false);
}

/// Declines the reset after an alarm, and remembers what it was asked.
#[derive(Default)]
struct LeaveInAlarm {
    asked: Vec<String>,
}
impl Observer for LeaveInAlarm {
    fn reset_after_alarm(&mut self, alarm: &str) -> bool {
        self.asked.push(alarm.to_string());
        false
    }
}

/// Issue 14: asked before the reset after a critical alarm, a user who says no gets a controller left in
/// alarm: nothing more reaches it (no reset, no line), the stop says so, and a later `--resume` resets it,
/// reads where motion stopped and finishes the job with every motion line run exactly once.
#[test]
fn a_user_can_leave_the_controller_in_alarm_and_resume_later() {
    let dir = tempfile::tempdir().unwrap();
    let prog = negative_program(dir.path());
    let emu = alarm_at_line_15(vec![]);
    let journal = dir.path().join("j");
    let port = emu.port_path().expect("port up");
    let mut link = SerialLink::open(&port, 1_000_000).unwrap();
    let mut obs = LeaveInAlarm::default();
    let first = session::run(
        &mut link,
        &prog,
        &patient_config(),
        &journal,
        Mode::Fresh,
        &mut obs,
        &AtomicBool::new(false),
    )
    .unwrap();
    drop(link);
    let Outcome::Stopped(r, _) = first else {
        panic!("the alarm did not stop the job: {first:?}")
    };
    assert_eq!(r.reason, StopReason::Alarm(2));
    assert_eq!(obs.asked.len(), 1, "asked once: {:?}", obs.asked);
    assert!(
        obs.asked[0].starts_with("ALARM:2") && obs.asked[0].contains("travel"),
        "{:?}",
        obs.asked
    );
    assert!(r.message.contains("left in alarm"), "{}", r.message);
    let log = emu.log();
    let alarm_at = log
        .events
        .iter()
        .position(|e| e.starts_with("ALARM:2"))
        .expect("the alarm");
    assert!(
        !log.events[alarm_at..].iter().any(|e| e.contains("soft reset")),
        "reset although the user said no: {:?}",
        log.events
    );
    let second = stream_patiently(&emu, 1_000_000, &prog, &journal, Mode::Resume);
    assert!(matches!(second, Outcome::Completed(_)), "{second:?}");
    let log = emu.log();
    assert_eq!(
        log.events.iter().filter(|e| e.starts_with("ALARM:2")).count(),
        1,
        "{:?}",
        log.events
    );
    let ambiguous = std::fs::read_to_string(&journal)
        .unwrap()
        .contains("\"event\":\"ambiguous\"");
    assert_exactly_once(&prog, &log.executed, 0.01, 0, ambiguous);
}

/// Raises the hold flag when `at` lines have been answered, watches the controller settle at `Hold:0`
/// and stay there (the same position over `still` reports), then raises the resume flag.
struct HoldThenResume<'a> {
    at: usize,
    still: usize,
    hold: &'a AtomicBool,
    resume: &'a AtomicBool,
    /// Positions reported at `Hold:0` before the resume.
    held_at: Vec<[f64; 3]>,
    done_when_held: Option<usize>,
    resumed: bool,
}
impl Observer for HoldThenResume<'_> {
    fn progress(&mut self, p: &Progress) {
        if self.resumed {
            return;
        }
        if p.lines_acked >= self.at && !self.hold.load(Ordering::SeqCst) && self.held_at.is_empty() {
            self.hold.store(true, Ordering::SeqCst);
        }
        if matches!(
            p.state,
            Some(brdfmill::apps::stream::protocol::MachineState::Hold { sub: 0 })
        ) {
            if let Some(pos) = p.position_mm {
                self.held_at.push(pos);
                self.done_when_held.get_or_insert(p.lines_done);
            }
            if self.held_at.len() >= self.still {
                self.resumed = true;
                self.resume.store(true, Ordering::SeqCst);
            }
        }
    }
}

/// Interactive hold and resume (`SIGUSR1`/`SIGUSR2` in the CLI): the machine decelerates to `Hold:0` and
/// stays put while held (no line completes meanwhile), the cycle start resumes it, and the job completes
/// with every motion line executed exactly once by the controller's own record, on each build.
#[test]
fn a_users_hold_waits_in_place_and_the_resume_finishes_every_line_once() {
    for (seed, build) in [
        (11u64, Build::Stock),
        (12, Build::LineNumbers),
        (13, Build::PlannerBlocks),
    ] {
        let mut rng = Rng(seed);
        let dir = tempfile::tempdir().unwrap();
        let prog = program(dir.path(), "p.nc", &random_program(&mut rng, 16));
        let baud = 1_000_000;
        let emu = emulator_for(build, baud, 8.0, vec![]);
        let journal = dir.path().join("p.journal.jsonl");
        let (stop, hold, resume) = (AtomicBool::new(false), AtomicBool::new(false), AtomicBool::new(false));
        let mut obs = HoldThenResume {
            at: 8,
            still: 6,
            hold: &hold,
            resume: &resume,
            held_at: vec![],
            done_when_held: None,
            resumed: false,
        };
        let port = emu.port_path().expect("port up");
        let mut link = SerialLink::open(&port, baud).unwrap();
        let controls = session::Controls {
            stop: &stop,
            hold: &hold,
            resume: &resume,
        };
        // no silence is injected here
        let cfg = patient_config();
        let outcome = session::run_with(&mut link, &prog, &cfg, &journal, Mode::Fresh, &mut obs, controls).unwrap();
        let what = format!("seed {seed} on {build:?}");
        assert!(matches!(outcome, Outcome::Completed(_)), "{what}: {outcome:?}");
        assert!(
            obs.resumed,
            "{what}: the controller never reported Hold:0 after the hold"
        );
        let first = obs.held_at[0];
        assert!(
            obs.held_at
                .iter()
                .all(|p| (0..3).all(|i| (p[i] - first[i]).abs() < 1e-9)),
            "{what}: the machine moved while held: {:?}",
            obs.held_at
        );
        let log = emu.log();
        assert!(
            log.events.iter().all(|e| !e.contains("ALARM")),
            "{what}: {:?}",
            log.events
        );
        assert_eq!(log.rx_overflows, 0, "{what}");
        assert_exactly_once(&prog, &log.executed, 1e-6, seed, false);
        assert!(
            Journal::load(&journal).unwrap().complete,
            "{what}: the journal records completion"
        );
    }
}

/// Resumes (a cycle start) when the streamer says the program pauses, and remembers what it was told.
struct ResumeAtPause<'a> {
    resume: &'a AtomicBool,
    notes: Vec<String>,
    held: usize,
}

impl Observer for ResumeAtPause<'_> {
    fn note(&mut self, what: &str) {
        if what.contains("pauses at line") {
            self.resume.store(true, Ordering::SeqCst);
        }
        self.notes.push(what.to_string());
    }
    fn progress(&mut self, p: &Progress) {
        if p.state == Some(brdfmill::apps::stream::protocol::MachineState::Hold { sub: 0 }) {
            self.held += 1;
        }
    }
}

/// A GRBL tool change as brdfmill writes it: `M5`, `M0` and a comment naming the next bit. The controller
/// holds at `Hold:0` after the pause's motion and answers it only after a cycle start; the streamer tells
/// the user, sends `~` on the user's resume although the hold is the program's, and the job completes with
/// every line once. Nothing else moves while paused.
#[test]
fn a_program_pause_for_a_tool_change_resumes_on_the_users_cycle_start() {
    let dir = tempfile::tempdir().unwrap();
    let text = "G21G90\nG0X0Y0Z2\nM3S8000\nG1Z-0.5F600\nG1X5\nG0Z5\nM5\n(tool T2: ball D0.5 mm - mount it)\nM0\nM3S8000\nG1Z-0.5F600\nG1X0\nG0Z5\nM5\n";
    let prog = program(dir.path(), "tc.nc", text);
    let emu = emulator_for(Build::Stock, 1_000_000, 8.0, vec![]);
    let journal = dir.path().join("tc.journal.jsonl");
    let (stop, hold, resume) = (AtomicBool::new(false), AtomicBool::new(false), AtomicBool::new(false));
    let mut obs = ResumeAtPause {
        resume: &resume,
        notes: vec![],
        held: 0,
    };
    let mut link = SerialLink::open(&emu.port_path().unwrap(), 1_000_000).unwrap();
    let controls = session::Controls {
        stop: &stop,
        hold: &hold,
        resume: &resume,
    };
    let outcome = session::run_with(
        &mut link,
        &prog,
        &patient_config(),
        &journal,
        Mode::Fresh,
        &mut obs,
        controls,
    )
    .unwrap();
    assert!(matches!(outcome, Outcome::Completed(_)), "{outcome:?}\n{:?}", obs.notes);
    assert!(obs.held > 0, "the controller held at the pause");
    assert!(
        obs.notes.iter().any(|n| n.contains("pauses at line 9 (M0)")),
        "{:?}",
        obs.notes
    );
    assert!(obs.notes.iter().any(|n| n.contains("cycle start")), "{:?}", obs.notes);
    assert_exactly_once(&prog, &emu.log().executed, 1e-6, 0, false);
    assert!(Journal::load(&journal).unwrap().complete);
}
