//! `$C` check-mode throughput against the **real GRBL 1.1h firmware** (the grbl-sim kit), beside a minimal
//! character-counting streamer on the same link, in one run: `brdfmill stream --check` streams a 2,000-line
//! program in check mode, then (killed once the check is over) the minimal streamer sends the same bytes
//! in check mode. Both rates come from the kit's wire log: program bytes sent between the two `$C`, over the
//! time from the first program byte to the last `ok`. Three rounds, alternating.
//!
//! `cargo build --release && cargo run --release --example bench_grbl_check`

#[path = "../tests/grbl_harness/mod.rs"]
mod grbl_harness;

use brdfmill::apps::stream::serial::{Link, SerialLink, DEFAULT_BAUD};
use grbl_harness::*;
use std::time::{Duration, Instant};

/// Bytes of program lines sent between the `$C` that enters check mode and the one that leaves it, and the
/// time from the first of them to the last `ok` before leaving, from the wire log (events after `from`).
fn measure(events: &[Event], from: usize) -> (usize, f64) {
    let ev = &events[from..];
    let c: Vec<usize> = (0..ev.len())
        .filter(|&k| ev[k].tag == "H>C" && ev[k].data.starts_with(b"$C"))
        .collect();
    if c.len() < 2 {
        let tail: Vec<String> = ev
            .iter()
            .rev()
            .take(12)
            .rev()
            .map(|e| format!("{} {} {}", e.t, e.tag, e.text()))
            .collect();
        panic!(
            "the wire log holds {} `$C` since event {from}; its end:\n{}",
            c.len(),
            tail.join("\n")
        );
    }
    let seg = &ev[c[0] + 1..c[1]];
    let sent: usize = seg
        .iter()
        .filter(|e| e.tag == "H>C" && e.data != b"?")
        .map(|e| e.data.len())
        .sum();
    let t0 = seg.iter().find(|e| e.tag == "H>C").map_or(0.0, |e| e.t);
    let t1 = seg
        .iter()
        .filter(|e| e.tag == "C>H" && e.text().contains("ok"))
        .map(|e| e.t)
        .fold(t0, f64::max);
    (sent, t1 - t0)
}

/// A serial link read line by line.
struct Lines {
    link: SerialLink,
    buf: Vec<u8>,
}

impl Lines {
    /// The next line from the controller; ten seconds of silence end the benchmark.
    fn line(&mut self) -> String {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            assert!(Instant::now() < deadline, "the controller went silent");
            if let Some(i) = self.buf.iter().position(|&b| b == b'\n') {
                let l: Vec<u8> = self.buf.drain(..=i).collect();
                return String::from_utf8_lossy(&l).trim().to_string();
            }
            let mut chunk = [0u8; 256];
            let n = self.link.read(&mut chunk, Duration::from_millis(100)).unwrap_or(0);
            self.buf.extend_from_slice(&chunk[..n]);
        }
    }

    /// Send a command and wait for its `ok`; any other answer ends the benchmark with what came back.
    fn command(&mut self, c: &str) {
        self.link.write_all(format!("{c}\n").as_bytes()).unwrap();
        loop {
            match self.line().as_str() {
                "ok" => return,
                l if l.starts_with("error") || l.starts_with("ALARM") => {
                    panic!("the minimal streamer's {c} was answered {l}")
                }
                _ => {}
            }
        }
    }
}

/// The minimal streamer: `$C`, then every line as soon as the bytes in flight allow (≤ 127), counting `ok`s.
fn minimal(port: &std::path::Path, lines: &[String]) {
    let mut io = Lines {
        link: SerialLink::open(port, DEFAULT_BAUD).unwrap(),
        buf: Vec::new(),
    };
    io.command("$X");
    io.command("$C");
    let (mut inflight, mut next) = (std::collections::VecDeque::new(), 0);
    while next < lines.len() || !inflight.is_empty() {
        while next < lines.len() && inflight.iter().sum::<usize>() + lines[next].len() < 127 {
            io.link.write_all(format!("{}\n", lines[next]).as_bytes()).unwrap();
            inflight.push_back(lines[next].len() + 1);
            next += 1;
        }
        let l = io.line();
        if l == "ok" || l.starts_with("error") {
            inflight.pop_front();
        }
    }
    io.command("$C");
}

fn main() {
    let Some((kit, exe)) = kit_or_skip("bench_grbl_check") else {
        std::process::exit(1);
    };
    let sim = Sim::start(&kit, &exe, &[]);
    let prog = zigzag(sim.dir.path(), "p.nc", &["G21G90G94"], 2000, 0.0, 0.01, 0.5, 0.0);
    let text = std::fs::read_to_string(&prog).unwrap();
    // what brdfmill sends: each block numbered with its line
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| format!("N{}{l}", i + 1))
        .collect();
    let mut ratios = vec![];
    for round in 1..=3 {
        let from = sim.wire().len();
        let j = sim.path(&format!("j{round}.jsonl"));
        let args = stream_args(&sim, &prog, &j, &["--check"]);
        let mut child = brdfmill_bg(&args.iter().map(String::as_str).collect::<Vec<_>>());
        // the check is over once check mode was left ($C a second time) and its banner came
        let end = Instant::now() + Duration::from_secs(300);
        while Instant::now() < end {
            let w = sim.wire();
            let c: Vec<usize> = (from..w.len())
                .filter(|&k| w[k].tag == "H>C" && w[k].data.starts_with(b"$C"))
                .collect();
            if c.len() >= 2 && w[c[1]..].iter().any(|e| e.tag == "C>H" && e.text().contains("Grbl")) {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = child.kill();
        let _ = child.wait();
        std::thread::sleep(Duration::from_millis(500));
        // stop what the real run had started after its check: a reset during motion raises ALARM:3, so
        // unlock before the minimal streamer's turn
        sim.ctl("inject 18");
        std::thread::sleep(Duration::from_secs(1));
        sim.ctl("inject 18");
        std::thread::sleep(Duration::from_secs(1));
        let (b_bytes, b_s) = measure(&sim.wire(), from);
        let from = sim.wire().len();
        minimal(&sim.port, &lines);
        std::thread::sleep(Duration::from_secs(1)); // the kit's wire log is written a moment after the bytes
        let (m_bytes, m_s) = measure(&sim.wire(), from);
        let (b, m) = (b_bytes as f64 / b_s, m_bytes as f64 / m_s);
        println!(
            "round {round}: brdfmill --check {b_bytes} B in {b_s:.3} s = {b:.0} B/s; minimal streamer {m_bytes} B in \
             {m_s:.3} s = {m:.0} B/s; ratio {:.1}%",
            100.0 * b / m
        );
        ratios.push(b / m);
    }
    let (lo, hi) = ratios
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), r| (a.min(*r), b.max(*r)));
    println!(
        "$C throughput of brdfmill against the minimal streamer: {:.1}–{:.1}%",
        100.0 * lo,
        100.0 * hi
    );
}
