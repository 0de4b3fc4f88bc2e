//! Issue 8's acceptance figures, through a real pseudo-terminal: the streamer (on `serialport`) against the
//! virtual GRBL 1.1 controller. Every wait is bounded; no sleep is used for synchronisation, and no clock
//! decides a result: the tests assert what the protocol requires, read off the bytes on the wire and the
//! controller's own reports. The throughput figures (share of the baud rate, lines/s against send-and-wait)
//! are measured by `cargo run --release --example bench_stream`.

use std::collections::VecDeque;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use brdfmill::stream::emulator::{Emulator, EmulatorConfig, Fault, FaultAt, FaultKind, Piece};
use brdfmill::stream::program::{LineKind, Program};
use brdfmill::stream::serial::{Link, SerialLink};
use brdfmill::stream::session::{self, Config, Mode, Outcome, Silent, StopReason};

fn program(dir: &Path, name: &str, text: &str) -> Program {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    Program::read(&p, true).unwrap()
}

fn emulator(baud: u32, time_scale: f64, faults: Vec<Fault>) -> Emulator {
    Emulator::start(EmulatorConfig {
        baud,
        time_scale,
        // `$10=3`: status reports carry `Bf:<planner blocks free>,<receive-buffer bytes free>`
        settings: vec![(10, 3.0)],
        faults,
        ..EmulatorConfig::default()
    })
    .expect("pseudo-terminal")
}

fn stream_on(link: &mut dyn Link, prog: &Program, journal: &Path, mode: Mode) -> Outcome {
    let cfg = Config {
        spindle_dwell_s: 0.1,
        ..Config::default()
    };
    session::run(link, prog, &cfg, journal, mode, &mut Silent, &AtomicBool::new(false)).unwrap()
}

fn stream(emu: &Emulator, baud: u32, prog: &Program, journal: &Path, mode: Mode) -> Outcome {
    let port = emu.port_path().expect("port up");
    let mut link = SerialLink::open(&port, baud).unwrap();
    stream_on(&mut link, prog, journal, mode)
}

/// One call the streamer made on its link.
#[derive(Debug, Clone)]
enum Call {
    Write(Vec<u8>),
    /// A read and what it returned (empty: the streamer waited and nothing came).
    Read(Vec<u8>),
}

/// A link that records every call made on it, in order.
struct Recording<L: Link> {
    inner: L,
    calls: Vec<Call>,
}

impl<L: Link> Link for Recording<L> {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.calls.push(Call::Write(bytes.to_vec()));
        self.inner.write_all(bytes)
    }
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        let n = self.inner.read(buf, timeout)?;
        self.calls.push(Call::Read(buf[..n].to_vec()));
        Ok(n)
    }
    fn name(&self) -> &str {
        self.inner.name()
    }
}

/// Stream `prog` fresh over a recording link to `emu`; the outcome and the calls.
fn stream_recorded(emu: &Emulator, baud: u32, prog: &Program, journal: &Path) -> (Outcome, Vec<Call>) {
    let port = emu.port_path().expect("port up");
    let mut link = Recording {
        inner: SerialLink::open(&port, baud).unwrap(),
        calls: Vec::new(),
    };
    let outcome = stream_on(&mut link, prog, journal, Mode::Fresh);
    (outcome, link.calls)
}

/// GRBL 1.1's serial receive buffer is a 128-byte ring, of which 127 bytes are usable (GRBL's
/// `doc/markdown/interface.md`, "Streaming Protocol: Character-Counting"); a byte beyond is lost.
const RX_USABLE: usize = 127;
const RX_BUFFER: usize = 128;

/// What the wire shows of a clean run, worked out from the recorded calls alone (not from the streamer's
/// own counters). Panics where the protocol is broken.
#[derive(Debug, Default)]
struct Wire {
    /// Program lines written (without the newline), in order.
    lines: Vec<String>,
    /// `ok`s received for them.
    oks: usize,
    /// `error:N` received for them.
    errors: Vec<String>,
    /// The most bytes sent and not yet answered, just after any write.
    max_in_flight: usize,
    /// Reads (the streamer waiting for the controller) while a program line was still to be sent.
    waits_with_lines_queued: usize,
    /// The fewest lines in flight at such a wait.
    min_lines_in_flight_at_wait: usize,
    /// Status reports received while streaming.
    status_reports: usize,
    /// The fullest receive buffer a status report showed (`128 − Bf`'s second field).
    max_rx_used: usize,
}

/// Replay the calls of a fresh run of `expected` (wire texts of G-code lines) and check, at every step:
/// - the program's lines are written once each, in order, and nothing else but realtime bytes after the
///   first one;
/// - bytes in flight (written, not yet answered by `ok`/`error:`; each answer frees the oldest line) never
///   exceed the 127 usable bytes;
/// - the streamer never waits for an answer while the next line would fit (no idle gap while lines wait);
/// - every status report's receive-buffer fill is at most what is in flight at that point of the stream
///   (the controller cannot hold bytes that were never sent or are already answered), so at most 127.
fn replay(calls: &[Call], expected: &[String]) -> Wire {
    let mut w = Wire {
        min_lines_in_flight_at_wait: usize::MAX,
        ..Wire::default()
    };
    let mut in_flight: VecDeque<usize> = VecDeque::new();
    let (mut out_line, mut in_buf) = (Vec::<u8>::new(), Vec::<u8>::new());
    let streaming = |w: &Wire| !w.lines.is_empty();
    for call in calls {
        match call {
            Call::Write(bytes) => {
                for &b in bytes {
                    // realtime bytes (`?`, `!`, `~`, Ctrl-X, 0x80–0xFF) never enter the receive buffer
                    if matches!(b, b'?' | b'!' | b'~' | 0x18) || b >= 0x80 {
                        continue;
                    }
                    if b != b'\n' {
                        out_line.push(b);
                        continue;
                    }
                    let line = String::from_utf8(std::mem::take(&mut out_line)).unwrap();
                    let next = w.lines.len();
                    if next < expected.len() && line == expected[next] {
                        w.lines.push(line);
                        in_flight.push_back(expected[next].len() + 1);
                        let used: usize = in_flight.iter().sum();
                        assert!(
                            used <= RX_USABLE,
                            "line {next} put {used} bytes in flight: {:?}",
                            w.lines.last()
                        );
                        w.max_in_flight = w.max_in_flight.max(used);
                    } else {
                        assert!(!streaming(&w), "written while streaming, not the next line: `{line}`");
                    }
                }
            }
            Call::Read(bytes) => {
                let next = w.lines.len();
                if streaming(&w) && next < expected.len() {
                    let used: usize = in_flight.iter().sum();
                    assert!(
                        used + expected[next].len() + 1 > RX_USABLE,
                        "the streamer waited with {used} bytes in flight although line {next} (`{}`) fits",
                        expected[next]
                    );
                    w.waits_with_lines_queued += 1;
                    w.min_lines_in_flight_at_wait = w.min_lines_in_flight_at_wait.min(in_flight.len());
                }
                in_buf.extend_from_slice(bytes);
                while let Some(i) = in_buf.iter().position(|&b| b == b'\n') {
                    let raw: Vec<u8> = in_buf.drain(..=i).collect();
                    let text = String::from_utf8_lossy(&raw).trim().to_string();
                    if !streaming(&w) {
                        continue; // the handshake's answers
                    }
                    if text == "ok" || text.starts_with("error:") {
                        assert!(in_flight.pop_front().is_some(), "`{text}` with nothing in flight");
                        if text == "ok" {
                            w.oks += 1;
                        } else {
                            w.errors.push(text);
                        }
                    } else if text.starts_with('<') {
                        w.status_reports += 1;
                        let bf = text
                            .split(['|', '>'])
                            .find_map(|f| f.strip_prefix("Bf:"))
                            .unwrap_or_else(|| panic!("no Bf in `{text}`"));
                        let rx_free: usize = bf.split(',').nth(1).unwrap().parse().unwrap();
                        let rx_used = RX_BUFFER - rx_free;
                        let sent_unanswered: usize = in_flight.iter().sum();
                        assert!(
                            rx_used <= sent_unanswered && rx_used <= RX_USABLE,
                            "`{text}`: {rx_used} bytes in the receive buffer, {sent_unanswered} in flight"
                        );
                        w.max_rx_used = w.max_rx_used.max(rx_used);
                    }
                }
            }
        }
    }
    assert!(in_flight.is_empty(), "{} lines never answered", in_flight.len());
    w
}

/// The wire texts of a program's lines, all plain G-code (no line that GRBL needs alone).
fn wire_lines(prog: &Program) -> Vec<String> {
    assert!(prog.sendable().all(|l| l.kind == LineKind::Gcode));
    prog.sendable().map(|l| l.wire_text(true)).collect()
}

/// The wire checks have teeth: send-and-wait (a wait with room for the next line) and a streamer that
/// overfills the buffer are both caught.
#[test]
#[should_panic(expected = "although line 1")]
fn replay_catches_a_wait_with_room_for_the_next_line() {
    let lines = vec!["N1X1".to_string(), "N2X2".to_string()];
    let calls = vec![
        Call::Write(b"N1X1\n".to_vec()),
        Call::Read(b"ok\r\n".to_vec()),
        Call::Write(b"N2X2\n".to_vec()),
        Call::Read(b"ok\r\n".to_vec()),
    ];
    replay(&calls, &lines);
}

#[test]
#[should_panic(expected = "bytes in flight")]
fn replay_catches_an_overfilled_buffer() {
    let lines: Vec<String> = (1..=20).map(|n| format!("N{n}X{}", "1".repeat(5))).collect();
    let calls: Vec<Call> = lines
        .iter()
        .map(|l| Call::Write(format!("{l}\n").into_bytes()))
        .collect();
    replay(&calls, &lines);
}

#[test]
fn ten_thousand_lines_at_115200_baud() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("G21G90\nG1F3000\n");
    for i in 0..9_998 {
        let a = i as f64 * 0.01;
        text += &format!("X{:.3}Y{:.3}\n", 10.0 * a.cos(), 10.0 * a.sin());
    }
    let prog = program(dir.path(), "big.nc", &text);
    assert_eq!(prog.sendable().count(), 10_000);
    let expected = wire_lines(&prog);
    // Motion simulated much faster than the link can feed it: the link is the bottleneck.
    let emu = emulator(115_200, 1e4, vec![]);
    let (outcome, calls) = stream_recorded(&emu, 115_200, &prog, &dir.path().join("j"));
    let Outcome::Completed(stats) = outcome else {
        panic!("did not complete: {outcome:?}")
    };
    let log = emu.log();
    let received: Vec<&String> = log.received.iter().filter(|l| !l.starts_with('$')).collect();
    assert_eq!(received.len(), expected.len(), "every line arrives once");
    assert!(
        received.iter().zip(&expected).all(|(a, b)| *a == b),
        "lines arrive in order and intact"
    );
    assert_eq!(log.rx_overflows, 0, "receive buffer overflowed");
    let w = replay(&calls, &expected);
    println!(
        "10,000 lines: {} bytes; at most {} bytes in flight; {} waits with lines queued, at least {} lines in \
         flight at each; {} status reports, fullest receive buffer {} bytes",
        stats.bytes_sent,
        w.max_in_flight,
        w.waits_with_lines_queued,
        w.min_lines_in_flight_at_wait,
        w.status_reports,
        w.max_rx_used
    );
    assert_eq!(w.lines, expected, "the wire carries every line once, in order");
    assert_eq!((w.oks, w.errors.len()), (10_000, 0), "{:?}", w.errors);
    // The link is slower than the controller: the streamer waits on it thousands of times, each time with
    // the buffer too full for the next line, and GRBL's reports were checked against the wire.
    assert!(
        w.waits_with_lines_queued >= 1_000,
        "{} waits",
        w.waits_with_lines_queued
    );
    assert!(w.status_reports >= 1, "no status report to check");
    // The streamer's own figures agree with the wire.
    assert_eq!(stats.max_in_flight, w.max_in_flight);
    assert_eq!(stats.lines_sent, 10_000);
    assert_eq!(stats.bytes_sent, expected.iter().map(|l| l.len() + 1).sum::<usize>());
}

/// Send-and-wait has one line in flight at every wait. Character counting, on a link slower than the
/// controller, waits only when the next line does not fit: with lines of at most `L` bytes (newline
/// included) at least `128 − L` bytes, so at least ⌈(128 − L)/L⌉ lines, are in flight at each wait — 14 for
/// these lines of at most 9 bytes (`N1499X1`, `N1500X-1`; the modes are set on lines as short), which is
/// what lets it keep the link busy while send-and-wait idles for every round trip.
#[test]
fn character_counting_keeps_many_short_lines_in_flight() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1_500;
    let mut text = String::from("G91\nG1\nF6000\n");
    for i in 0..n - 3 {
        text += if i % 2 == 0 { "X1\n" } else { "X-1\n" };
    }
    let prog = program(dir.path(), "short.nc", &text);
    let expected = wire_lines(&prog);
    let emu = emulator(115_200, 1e4, vec![]);
    let (outcome, calls) = stream_recorded(&emu, 115_200, &prog, &dir.path().join("j"));
    assert!(matches!(outcome, Outcome::Completed(_)), "{outcome:?}");
    assert_eq!(emu.log().rx_overflows, 0);
    assert_eq!(emu.log().executed.len(), n - 3, "every move ran");
    let w = replay(&calls, &expected);
    let l_max = expected.iter().map(|l| l.len() + 1).max().unwrap();
    let floor = (RX_BUFFER - l_max).div_ceil(l_max);
    println!(
        "short lines (at most {l_max} bytes): {} waits with lines queued, at least {} lines in flight at each \
         (bound {floor})",
        w.waits_with_lines_queued, w.min_lines_in_flight_at_wait
    );
    assert_eq!(w.lines, expected);
    assert!(w.waits_with_lines_queued >= 100, "{} waits", w.waits_with_lines_queued);
    assert!(
        w.min_lines_in_flight_at_wait >= floor && floor >= 14,
        "{} lines in flight at a wait, bound {floor}",
        w.min_lines_in_flight_at_wait
    );
}

/// A controller slower than the link: the planner fills (15 blocks), then its receive buffer, and the
/// streamer has to hold lines back. The buffer is full and never overflows: while the planner is full the
/// link is quiet, the parser holds one line waiting for a block, and the streamer waits only when the next
/// line does not fit — so the buffer holds at least `128 − 2L` bytes (L the longest line with its newline),
/// and what the controller reports in `Bf` never exceeds what is in flight.
#[test]
fn a_slow_controller_fills_its_receive_buffer_without_overflow() {
    let dir = tempfile::tempdir().unwrap();
    // 100 moves of 1 mm at 1200 mm/min: 50 ms each in real time, 5 s in all; 15 in the planner and about
    // 16 lines in the buffer, so the buffer stays full for about 3.5 s, some 17 status polls at 5 Hz.
    let mut text = String::from("G91\nG1\nF1200\n");
    for i in 0..100 {
        text += if i % 2 == 0 { "X1\n" } else { "X-1\n" };
    }
    let prog = program(dir.path(), "slow.nc", &text);
    let expected = wire_lines(&prog);
    let emu = emulator(115_200, 1.0, vec![]);
    let (outcome, calls) = stream_recorded(&emu, 115_200, &prog, &dir.path().join("j"));
    assert!(matches!(outcome, Outcome::Completed(_)), "{outcome:?}");
    let log = emu.log();
    assert_eq!(log.rx_overflows, 0, "{:?}", log.events);
    let w = replay(&calls, &expected);
    let l_max = expected.iter().map(|l| l.len() + 1).max().unwrap();
    println!(
        "slow controller: at most {} bytes in flight, fullest receive buffer reported {} bytes over {} reports \
         (bound {})",
        w.max_in_flight,
        w.max_rx_used,
        w.status_reports,
        RX_BUFFER - 2 * l_max
    );
    assert_eq!(w.lines, expected);
    assert_eq!(w.oks, expected.len());
    assert!(
        w.max_rx_used >= RX_BUFFER - 2 * l_max,
        "the buffer never filled: at most {} bytes reported",
        w.max_rx_used
    );
    assert_eq!(log.executed.len(), 100, "every move ran");
}

/// A tiny deterministic generator (xorshift64*), so trials are reproducible from their seed.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// A program of random cuts in a 20 × 20 mm square, every motion line with a distinct end point.
fn random_program(rng: &mut Rng, moves: usize) -> String {
    let mut t = String::from("G21 G90\nG0 X0 Y0 Z2\nM3 S8000\nG1 Z-0.5 F1200\n");
    let (mut px, mut py) = (0.0f64, 0.0f64);
    for i in 0..moves {
        // Cuts of at least 3 mm, so that the planner is busy when a fault comes.
        let (x, y) = loop {
            let x = rng.below(20_000) as f64 / 1000.0;
            let y = rng.below(20_000) as f64 / 1000.0;
            if (x - px).hypot(y - py) >= 3.0 {
                break (x, y);
            }
        };
        (px, py) = (x, y);
        let z = -0.5 - (i % 5) as f64 * 0.01;
        t += &format!("G1 X{x:.3} Y{y:.3} Z{z:.3}\n");
    }
    t += "G0 Z5\nM5\n";
    t
}

/// Every moving line's pieces in the controller's log cover it exactly once: from its start to its end,
/// contiguous, without overlap (within `tol` mm).
fn assert_exactly_once(prog: &Program, pieces: &[Piece], tol: f64, seed: u64) {
    for l in prog.lines.iter().filter(|l| l.moves) {
        // The emulator powers up at the machine origin, where the program model does not know the tool is.
        let a: Vec<f64> = l.start_mm.iter().map(|v| v.unwrap_or(0.0)).collect();
        let b: Vec<f64> = l.end_mm.iter().map(|v| v.unwrap()).collect();
        let d: Vec<f64> = (0..3).map(|i| b[i] - a[i]).collect();
        let len = d.iter().map(|v| v * v).sum::<f64>().sqrt();
        let t = |p: [f64; 3]| (0..3).map(|i| (p[i] - a[i]) * d[i]).sum::<f64>() / (len * len);
        let mut spans: Vec<(f64, f64)> = pieces
            .iter()
            .filter(|p| p.line as usize == l.number)
            .map(|p| (t(p.from_mm), t(p.to_mm)))
            .collect();
        spans.sort_by(|x, y| x.0.total_cmp(&y.0));
        let eps = tol / len;
        assert!(!spans.is_empty(), "seed {seed}: line {} never ran", l.number);
        let mut at = 0.0;
        for (s, e) in &spans {
            assert!(
                (s - at).abs() <= eps,
                "seed {seed}: line {} pieces {spans:?} leave a gap or overlap",
                l.number
            );
            at = *e;
        }
        assert!(
            (at - 1.0).abs() <= eps,
            "seed {seed}: line {} ends at t = {at}",
            l.number
        );
    }
}

fn fault_trial(seed: u64) -> (FaultKind, usize) {
    let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let dir = tempfile::tempdir().unwrap();
    let text = random_program(&mut rng, 16);
    let prog = program(dir.path(), "p.nc", &text);
    let n_lines = prog.sendable().count();
    let kind = match rng.below(3) {
        0 => FaultKind::Error(20),
        1 => FaultKind::Alarm(2),
        _ => FaultKind::Disconnect,
    };
    // An alarm stops the controller itself and a disconnect lets it finish what it received, so any line
    // will do. GRBL keeps running the lines behind a rejected one until the feed hold arrives, so an error
    // is injected where the planner already holds cuts (from the third cut on): earlier, the next motion
    // may start before the hold and the streamer refuses to resume (see `resume_refuses_out_of_order_*`).
    let first_allowed: usize = if matches!(kind, FaultKind::Error(_)) { 7 } else { 1 };
    let line = (first_allowed + rng.below((n_lines - first_allowed + 1) as u64) as usize) as u32;
    let baud = 1_000_000;
    let emu = emulator(
        baud,
        8.0,
        vec![Fault {
            at: FaultAt::LineNumber(line),
            kind,
        }],
    );
    let journal = dir.path().join("p.journal.jsonl");
    let gen = emu.generation();
    let first = stream(&emu, baud, &prog, &journal, Mode::Fresh);
    let Outcome::Stopped(report, _) = first else {
        panic!("seed {seed}: {kind:?} at line {line} did not stop the job")
    };
    match kind {
        FaultKind::Error(c) => {
            assert_eq!(report.reason, StopReason::Error(c));
            assert_eq!(
                report.line,
                Some(line as usize),
                "seed {seed}: the stop names the rejected line"
            );
        }
        FaultKind::Alarm(c) => assert_eq!(report.reason, StopReason::Alarm(c)),
        FaultKind::Disconnect => {
            assert_eq!(report.reason, StopReason::Disconnect);
            // The emulator reopens after 50 ms; the bound only keeps a hang from lasting forever.
            emu.wait_new_port(gen, Duration::from_secs(60))
                .expect("new port after the disconnect");
        }
    }
    // The journal is consistent (load checks it) and agrees with the report.
    let st = brdfmill::stream::journal::Journal::load(&journal).unwrap();
    assert!(st.stop.is_some() && !st.complete);
    let second = stream(&emu, baud, &prog, &journal, Mode::Resume);
    assert!(
        matches!(second, Outcome::Completed(_)),
        "seed {seed}: resume did not complete: {second:?}"
    );
    let st = brdfmill::stream::journal::Journal::load(&journal).unwrap();
    assert!(st.complete, "seed {seed}: journal not complete");
    let log = emu.log();
    if std::env::var("TRIAL_DEBUG").is_ok() {
        eprintln!(
            "seed {seed}: {kind:?} at {line}\n{}\n{:#?}\n{:?}",
            std::fs::read_to_string(&journal).unwrap(),
            log.executed,
            log.events
        );
    }
    assert_eq!(log.rx_overflows, 0);
    assert_exactly_once(&prog, &log.executed, 0.01, seed);
    (kind, line as usize)
}

#[test]
fn injected_faults_then_resume_run_every_motion_line_exactly_once() {
    let trials = 100;
    let seeds: Vec<u64> = match std::env::var("TRIAL_SEED") {
        Ok(s) => vec![s.parse().unwrap()],
        Err(_) => (1..=trials).collect(),
    };
    let results: Vec<(FaultKind, usize)> = std::thread::scope(|s| {
        let chunks: Vec<Vec<u64>> = (0..4)
            .map(|k| seeds.iter().copied().filter(|x| x % 4 == k).collect())
            .collect();
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|c| s.spawn(move || c.into_iter().map(fault_trial).collect::<Vec<_>>()))
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    let count = |f: fn(&FaultKind) -> bool| results.iter().filter(|r| f(&r.0)).count();
    println!(
        "{} fault trials ({} error, {} alarm, {} disconnect): every motion line ran exactly once",
        results.len(),
        count(|k| matches!(k, FaultKind::Error(_))),
        count(|k| matches!(k, FaultKind::Alarm(_))),
        count(|k| matches!(k, FaultKind::Disconnect)),
    );
    assert_eq!(results.len(), seeds.len());
}
