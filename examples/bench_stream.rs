//! Streaming throughput against the virtual GRBL 1.1 controller over a real pseudo-terminal (docs/PERFORMANCE.md's
//! performance table): 10,000 lines at 115200 baud as a share of the link's byte rate (baud/10 bytes/s,
//! 8N1), and short lines by character counting against send-and-wait over the same link, with motion
//! simulated 10⁴× faster than real time, so the link, not the controller, is the bottleneck; then a
//! controller in real time, slower than the link, and how full its status reports (`Bf`, polled at 5 Hz)
//! show its receive buffer while the streamer holds lines back.
//!
//! ```sh
//! cargo run --release --example bench_stream            # both measurements, once
//! cargo run --release --example bench_stream -- 3       # each three times
//! ```
//!
//! These are wall-clock figures and move with the machine's load (printed first); the tests in
//! `tests/stream_emulator.rs` and `tests/stream_wire.rs` assert the behaviour behind them instead (bytes in
//! flight, no idle wait, the buffer filled on the wire).

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig};
use brdfmill::apps::stream::program::Program;
use brdfmill::apps::stream::protocol::{parse_response, Response, Status, RX_BUFFER_BYTES};
use brdfmill::apps::stream::serial::{Link, SerialLink};
use brdfmill::apps::stream::session::{self, Config, Mode, Outcome, Silent, Stats};

const BAUD: u32 = 115_200;

fn program(dir: &Path, name: &str, text: &str) -> Program {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    Program::read(&p, true).unwrap()
}

fn emulator() -> Emulator {
    emulator_at(1e4)
}

fn emulator_at(time_scale: f64) -> Emulator {
    Emulator::start(EmulatorConfig {
        baud: BAUD,
        time_scale,
        settings: vec![(10, 3.0)],
        ..EmulatorConfig::default()
    })
    .expect("pseudo-terminal")
}

/// Stream `prog` with character counting; the streamer's figures (its time runs from the first line
/// written to the last answer).
fn stream(emu: &Emulator, prog: &Program, journal: &Path) -> Stats {
    let mut link = SerialLink::open(&emu.port_path().expect("port up"), BAUD).unwrap();
    stream_on(emu, &mut link, prog, journal)
}

/// [`stream`] over any link.
fn stream_on(emu: &Emulator, link: &mut dyn Link, prog: &Program, journal: &Path) -> Stats {
    let cfg = Config {
        spindle_dwell_s: 0.1,
        ..Config::default()
    };
    match session::run(
        link,
        prog,
        &cfg,
        journal,
        Mode::Fresh,
        &mut Silent,
        &AtomicBool::new(false),
    )
    .unwrap()
    {
        Outcome::Completed(stats) => {
            assert_eq!(emu.log().rx_overflows, 0, "receive buffer overflowed");
            stats
        }
        other => panic!("did not complete: {other:?}"),
    }
}

/// Send-and-wait over the same link: each line is written only once the previous one's `ok` came back.
fn send_and_wait(link: &mut SerialLink, lines: &[String]) -> Duration {
    let t0 = Instant::now();
    let mut buf = Vec::new();
    for l in lines {
        link.write_all(format!("{l}\n").as_bytes()).unwrap();
        loop {
            let mut b = [0u8; 64];
            let n = link.read(&mut b, Duration::from_secs(2)).unwrap();
            assert!(n > 0, "no answer to `{l}`");
            buf.extend_from_slice(&b[..n]);
            if let Some(i) = buf.windows(4).position(|w| w == b"ok\r\n") {
                buf.drain(..i + 4);
                break;
            }
            assert!(
                !String::from_utf8_lossy(&buf).contains("error"),
                "{}",
                String::from_utf8_lossy(&buf)
            );
        }
    }
    t0.elapsed()
}

fn ten_thousand_lines(dir: &Path, run: usize) {
    let mut text = String::from("G21G90\nG1F3000\n");
    for i in 0..9_998 {
        let a = i as f64 * 0.01;
        text += &format!("X{:.3}Y{:.3}\n", 10.0 * a.cos(), 10.0 * a.sin());
    }
    let prog = program(dir, &format!("big{run}.nc"), &text);
    let emu = emulator();
    let mut tap = BfTap {
        inner: SerialLink::open(&emu.port_path().expect("port up"), BAUD).unwrap(),
        pending: Vec::new(),
        reports: 0,
        max_used: 0,
    };
    let t0 = Instant::now();
    let stats = stream_on(&emu, &mut tap, &prog, &dir.join(format!("big{run}.journal")));
    let wall = t0.elapsed().as_secs_f64();
    let limit = f64::from(BAUD) / 10.0;
    let secs = stats.streaming_time.as_secs_f64();
    let bps = stats.bytes_sent as f64 / secs;
    println!(
        "10,000 lines at {BAUD} baud: {} bytes in {secs:.2} s = {bps:.0} bytes/s, {:.1}% of the {limit:.0} bytes/s \
         limit; {:.0} lines/s; at most {} bytes in flight; {} status reports (5 Hz polls), the fullest receive \
         buffer {} of {RX_BUFFER_BYTES} bytes (wall {wall:.1} s with the handshake)",
        stats.bytes_sent,
        100.0 * bps / limit,
        stats.lines_sent as f64 / secs,
        stats.max_in_flight,
        tap.reports,
        tap.max_used
    );
}

fn short_lines(dir: &Path, run: usize) {
    let n = 1_500;
    let mut text = String::from("G21G91G1F6000\n");
    for i in 0..n - 1 {
        text += if i % 2 == 0 { "X1\n" } else { "X-1\n" };
    }
    let prog = program(dir, &format!("short{run}.nc"), &text);
    let emu = emulator();
    let stats = stream(&emu, &prog, &dir.join(format!("short{run}.journal")));
    let counted = n as f64 / stats.streaming_time.as_secs_f64();
    let lines: Vec<String> = prog.sendable().map(|l| l.wire_text(true)).collect();
    let mut link = SerialLink::open(&emu.port_path().unwrap(), BAUD).unwrap();
    let waited = n as f64 / send_and_wait(&mut link, &lines).as_secs_f64();
    assert_eq!(emu.log().rx_overflows, 0);
    println!(
        "{n} short lines ({:.1} bytes each) at {BAUD} baud: character counting {counted:.0} lines/s, \
         send-and-wait {waited:.0} lines/s: {:.2}×",
        stats.bytes_sent as f64 / n as f64,
        counted / waited
    );
}

/// A link that reads the receive-buffer fill off every status report it passes on (`Bf:<blocks>,<bytes
/// free>` of GRBL's 128-byte buffer), with the streamer's own parser.
struct BfTap {
    inner: SerialLink,
    pending: Vec<u8>,
    reports: usize,
    max_used: usize,
}

impl Link for BfTap {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.inner.write_all(bytes)
    }
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        let n = self.inner.read(buf, timeout)?;
        self.pending.extend_from_slice(&buf[..n]);
        while let Some(i) = self.pending.iter().position(|&b| b == b'\n') {
            let line: Vec<u8> = self.pending.drain(..=i).collect();
            if let Response::Status(Status {
                rx_free: Some(free), ..
            }) = parse_response(String::from_utf8_lossy(&line).trim())
            {
                self.reports += 1;
                self.max_used = self.max_used.max(RX_BUFFER_BYTES.saturating_sub(usize::from(free)));
            }
        }
        Ok(n)
    }
    fn name(&self) -> &str {
        self.inner.name()
    }
}

/// 100 moves of 1 mm at 1200 mm/min in real time (5 s): the planner fills, then the receive buffer.
fn slow_controller(dir: &Path, run: usize) {
    let mut text = String::from("G91\nG1\nF1200\n");
    for i in 0..100 {
        text += if i % 2 == 0 { "X1\n" } else { "X-1\n" };
    }
    let prog = program(dir, &format!("slow{run}.nc"), &text);
    let emu = emulator_at(1.0);
    let mut tap = BfTap {
        inner: SerialLink::open(&emu.port_path().expect("port up"), BAUD).unwrap(),
        pending: Vec::new(),
        reports: 0,
        max_used: 0,
    };
    let stats = stream_on(&emu, &mut tap, &prog, &dir.join(format!("slow{run}.journal")));
    let l_max = prog.sendable().map(|l| l.wire_text(true).len() + 1).max().unwrap_or(0);
    println!(
        "slow controller (103 lines of at most {l_max} bytes, real time): at most {} bytes in flight; the \
         fullest receive buffer a status report showed: {} of {RX_BUFFER_BYTES} bytes, over {} reports",
        stats.max_in_flight, tap.max_used, tap.reports
    );
}

fn main() {
    let repeat: usize = std::env::args().nth(1).map_or(1, |a| a.parse().expect("repeat count"));
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{} CPUs, load average {}",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
    let dir = tempfile::tempdir().unwrap();
    for run in 0..repeat {
        ten_thousand_lines(dir.path(), run);
        short_lines(dir.path(), run);
        slow_controller(dir.path(), run);
    }
}
