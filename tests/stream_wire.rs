//! The streaming protocol on the wire, through a real pseudo-terminal: the streamer (on `serialport`)
//! against the virtual GRBL 1.1 controller with `Bf` reports (`$10=3`). Every wait is bounded; no sleep is used for synchronisation, and no clock
//! decides a result: the tests assert what the protocol requires, read off the bytes on the wire and the
//! controller's own reports. The throughput figures (share of the baud rate, lines/s against send-and-wait)
//! are measured by `cargo run --release --example bench_stream`.

use std::collections::VecDeque;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig, Fault, FaultAt, FaultKind};
use brdfmill::apps::stream::program::{LineKind, Program};
use brdfmill::apps::stream::serial::{Link, SerialLink};
use brdfmill::apps::stream::session::{self, Config, Mode, Outcome, Silent};

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

/// One call the streamer made on its link.
#[derive(Debug, Clone)]
enum Call {
    Write(Vec<u8>),
    /// A read and what it returned (empty: the streamer waited and nothing came).
    Read(Vec<u8>),
}

/// A link that records every call made on it, in order. With `query_after` it also asks for one status
/// report itself (`?`, recorded) once that many lines have been written: a report mid-stream that does not
/// depend on when the streamer's 5 Hz polls land.
struct Recording<L: Link> {
    inner: L,
    calls: Vec<Call>,
    query_after: Option<usize>,
    newlines: usize,
}

impl<L: Link> Link for Recording<L> {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.calls.push(Call::Write(bytes.to_vec()));
        self.inner.write_all(bytes)?;
        self.newlines += bytes.iter().filter(|&&b| b == b'\n').count();
        if self.query_after.is_some_and(|n| self.newlines >= n) {
            self.query_after = None;
            self.calls.push(Call::Write(b"?".to_vec()));
            self.inner.write_all(b"?")?;
        }
        Ok(())
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

/// Stream `prog` fresh over a recording link to `emu` (which asks for a status report itself after
/// `query_after` lines); the outcome and the calls.
fn stream_recorded(
    emu: &Emulator,
    baud: u32,
    prog: &Program,
    journal: &Path,
    query_after: Option<usize>,
) -> (Outcome, Vec<Call>) {
    let port = emu.port_path().expect("port up");
    let mut link = Recording {
        inner: SerialLink::open(&port, baud).unwrap(),
        calls: Vec::new(),
        query_after,
        newlines: 0,
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
    // one status report halfway, asked for by the link itself, so that the per-report check runs whatever
    // the timing; how many the 5 Hz polls bring is wall-clock (`examples/bench_stream.rs` prints it)
    let (outcome, calls) = stream_recorded(&emu, 115_200, &prog, &dir.path().join("j"), Some(5_000));
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
        "10,000 lines: {} bytes; at most {} bytes in flight",
        stats.bytes_sent, w.max_in_flight
    );
    assert_eq!(w.lines, expected, "the wire carries every line once, in order");
    assert_eq!((w.oks, w.errors.len()), (10_000, 0), "{:?}", w.errors);
    // How often the streamer waited on the link, and how many reports its polls brought, depend on how fast
    // this machine runs the streamer against the paced link: wall-clock figures, measured by
    // `examples/bench_stream.rs`, not asserted here. What every wait and every report must satisfy is
    // checked in `replay`; the link's own query guarantees a report to check.
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
    let (outcome, calls) = stream_recorded(&emu, 115_200, &prog, &dir.path().join("j"), None);
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
    // the number of waits is a wall-clock figure (see above); the bound holds at every one of them
    assert!(
        w.min_lines_in_flight_at_wait >= floor && floor >= 14,
        "{} lines in flight at a wait, bound {floor}",
        w.min_lines_in_flight_at_wait
    );
}

/// A controller slower than the link: the planner fills (15 blocks), then its receive buffer, and the
/// streamer has to hold lines back. The buffer fills and never overflows: while the planner is full no
/// `ok` comes back, and the streamer writes until the next line does not fit, so the bytes in flight on the
/// wire reach more than `127 − L` (L the longest line with its newline); what the controller reports in
/// `Bf` never exceeds what is in flight (checked at every report by `replay`). That the buffer fills does
/// not rest on the streamer outrunning a real-time controller (a starved test runner might not): an
/// injected stall holds the controller's motion until its receive buffer holds `128 − 2L` bytes (one line
/// in flight may be out of it, waiting for planner space), which only a streamer that writes until the
/// next line does not fit brings about (a stall that gives up instead, after 50 status polls answered
/// meanwhile, fails the test: a count of the streamer's own polls, not a time). Nothing here
/// depends on the clock: how full a 5 Hz status poll catches the buffer does, and is measured by
/// `examples/bench_stream.rs` (a controller in real time), not here.
#[test]
fn a_slow_controller_fills_its_receive_buffer_without_overflow() {
    let dir = tempfile::tempdir().unwrap();
    // 100 moves of 1 mm at 1200 mm/min, 50 ms each, run 10× faster than real time: 5 ms a move, still
    // slower than the link's 0.3–0.4 ms a line; the stall, not this speed, is what fills the buffer
    let mut text = String::from("G91\nG1\nF1200\n");
    for i in 0..100 {
        text += if i % 2 == 0 { "X1\n" } else { "X-1\n" };
    }
    let prog = program(dir.path(), "slow.nc", &text);
    let expected = wire_lines(&prog);
    let l_max = expected.iter().map(|l| l.len() + 1).max().unwrap();
    // from the tenth line received on, nothing moves until the receive buffer holds 128 − 2L bytes: with
    // more than 127 − L in flight, at most one line (the one waiting for planner space, already read out
    // of the buffer, as in GRBL) is not in it
    let stall = Fault {
        at: FaultAt::Received(10),
        kind: FaultKind::Stall(u16::try_from(RX_USABLE + 1 - 2 * l_max).unwrap()),
    };
    let emu = emulator(115_200, 10.0, vec![stall]);
    let (outcome, calls) = stream_recorded(&emu, 115_200, &prog, &dir.path().join("j"), None);
    assert!(matches!(outcome, Outcome::Completed(_)), "{outcome:?}");
    let log = emu.log();
    assert_eq!(log.rx_overflows, 0, "{:?}", log.events);
    assert!(
        log.events.iter().any(|e| e.starts_with("stall released")),
        "{:?}",
        log.events
    );
    let w = replay(&calls, &expected);
    assert_eq!(w.lines, expected);
    assert_eq!(w.oks, expected.len());
    assert!(
        w.max_in_flight + l_max > RX_USABLE,
        "the buffer never filled: at most {} bytes in flight, lines of up to {l_max} bytes",
        w.max_in_flight
    );
    assert_eq!(log.executed.len(), 100, "every move ran");
}
