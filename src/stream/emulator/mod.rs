//! A virtual GRBL 1.1 controller, for tests and for dry runs (`brdfmill emulate`).
//!
//! Two layers:
//! - [`Controller`]: the controller itself with no I/O and no clock — bytes in, bytes out, simulated time
//!   advanced by the caller. It models GRBL 1.1's 128-byte receive buffer (an overflow is counted and
//!   logged, never hidden), realtime commands (`?`, `!`, `~`, Ctrl-X, feed overrides), the line reader
//!   (comments and spaces stripped, 79-character limit → `error:11`), the G-code subset below with GRBL's
//!   error codes, a 15-block planner that executes blocks at their programmed feed in simulated time,
//!   status reports (`MPos`/`WPos`, `Bf`, `Ln`, `FS`, `WCO`, `Ov`), `$C` check mode, `$$`/`$x=`/`$I`/
//!   `$G`/`$#`/`$X`/`$H`, soft limits raising `ALARM:2`, and injected faults.
//! - [`Emulator`]: runs a controller on a pseudo-terminal in its own thread, pacing bytes both ways at the
//!   configured baud (10 bits per byte, 8N1) and running motion `time_scale` times faster than real time.
//!
//! Modelled G-code: G0 G1 G2 G3 (I/J form, G17 plane) G4 G17 G18 G19 G20 G21 G54 G80 G90 G91 G94,
//! M0 M1 M2 M30 M3 M4 M5 M7 M8 M9, F S T N P words. Not modelled (answered `error:20`, and logged as such):
//! G10 G28 G30 G53 G92 G38.x G43.1 G49 G61 G93 G55–G59, arcs in R form or other planes; `$J=` and `$SLP`
//! (answered `error:3`). Motion has no acceleration: a block takes `length / feed` and a feed hold stops
//! at once, where a real GRBL decelerates over up to `v²/2a`.
//!
//! **Faults** ([`Fault`]) fire once, on the first line carrying line number `N` (or the `k`-th line
//! received): `error` answers `error:code` instead of running the line; `alarm` stops motion at once and
//! raises `ALARM:code` the way a soft limit does (position retained, `[MSG:Reset to continue]`, nothing runs
//! until a soft reset); `disconnect` runs the line and then drops the link — the controller keeps executing
//! what is already complete in its receive buffer and planner (a board with its own power supply), discards
//! a partial line, and opens a new pseudo-terminal after `reconnect_delay`.

use std::collections::{BTreeMap, VecDeque};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::program::{self, MAX_BLOCK_CHARS};
use super::protocol::{PLANNER_BLOCKS, RX_BUFFER_BYTES};

/// The version the emulator announces.
pub const VERSION: &str = "1.1h";

/// A fault to inject.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// Which line triggers it.
    pub at: FaultAt,
    /// What happens.
    pub kind: FaultKind,
}

/// Which line triggers a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultAt {
    /// The first block carrying `N<n>`.
    LineNumber(u32),
    /// The `k`-th non-empty line received (1-based, counting every line since start).
    Received(usize),
}

/// What an injected fault does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// Answer `error:code` instead of running the line.
    Error(u16),
    /// Stop and raise `ALARM:code` (soft-limit behaviour).
    Alarm(u16),
    /// Run the line, then drop the link.
    Disconnect,
}

impl std::str::FromStr for Fault {
    type Err = String;
    /// `N:error[:code]`, `N:alarm[:code]`, `N:disconnect` (N a line number `N` word).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.split(':').collect();
        let n: u32 = parts
            .first()
            .and_then(|n| n.parse().ok())
            .ok_or_else(|| format!("fault `{s}`: expected LINE:KIND[:CODE], LINE a line number"))?;
        let code = |d: u16| -> Result<u16, String> {
            parts
                .get(2)
                .map_or(Ok(d), |c| c.parse().map_err(|_| format!("fault `{s}`: bad code")))
        };
        let kind = match parts.get(1).copied() {
            Some("error") => FaultKind::Error(code(20)?),
            Some("alarm") => FaultKind::Alarm(code(2)?),
            Some("disconnect") => FaultKind::Disconnect,
            _ => return Err(format!("fault `{s}`: kind must be error, alarm or disconnect")),
        };
        Ok(Fault {
            at: FaultAt::LineNumber(n),
            kind,
        })
    }
}

/// Emulator settings.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// Serial speed (bits/s) whose byte rate (baud/10 bytes/s) paces both directions.
    pub baud: u32,
    /// Simulated motion runs this many times faster than real time (1.0 = real time).
    pub time_scale: f64,
    /// Report `Ln` (GRBL built with `USE_LINE_NUMBERS`, as `[OPT:N…]` announces).
    pub line_numbers: bool,
    /// Settings changed from GRBL's defaults at power-up, e.g. `(10, 3.0)` to report `Bf`.
    pub settings: Vec<(u16, f64)>,
    /// Injected faults.
    pub faults: Vec<Fault>,
    /// After an injected disconnect, how long until the new pseudo-terminal opens.
    pub reconnect_delay: Duration,
    /// Keep a symbolic link here pointing at the current pseudo-terminal.
    pub link_path: Option<PathBuf>,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            baud: 115_200,
            time_scale: 1.0,
            line_numbers: true,
            settings: Vec::new(),
            faults: Vec::new(),
            reconnect_delay: Duration::from_millis(50),
            link_path: None,
        }
    }
}

/// A piece of a motion block that the simulated machine executed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// The block's line number (`N`), 0 when it had none.
    pub line: u32,
    /// Where the piece started (machine coordinates, mm).
    pub from_mm: [f64; 3],
    /// Where it ended.
    pub to_mm: [f64; 3],
    /// The block ran to its end (false: cut short by a reset or an alarm).
    pub complete: bool,
}

/// What the controller saw and did.
#[derive(Debug, Clone, Default)]
pub struct EmulatorLog {
    /// Every non-realtime line received, cleaned, in order.
    pub received: Vec<String>,
    /// Executed motion, in order.
    pub executed: Vec<Piece>,
    /// Bytes dropped because the receive buffer was full (a streaming bug: must stay 0).
    pub rx_overflows: u64,
    /// Notable events (alarms, resets, faults fired, unmodelled commands, overflows).
    pub events: Vec<String>,
    /// Bytes received (including realtime bytes).
    pub bytes_in: u64,
    /// Bytes sent.
    pub bytes_out: u64,
}

impl EmulatorLog {
    fn append(&mut self, other: &mut EmulatorLog) {
        self.received.append(&mut other.received);
        self.executed.append(&mut other.executed);
        self.rx_overflows += other.rx_overflows;
        self.events.append(&mut other.events);
        self.bytes_in += other.bytes_in;
        self.bytes_out += other.bytes_out;
        other.rx_overflows = 0;
        other.bytes_in = 0;
        other.bytes_out = 0;
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum BlockKind {
    Rapid,
    Linear,
    Arc { center: [f64; 2], cw: bool },
}

#[derive(Debug, Clone)]
struct Block {
    line: u32,
    from: [f64; 3],
    to: [f64; 3],
    kind: BlockKind,
    /// Simulated seconds at 100 % override.
    duration_s: f64,
    /// Simulated seconds done.
    elapsed_s: f64,
    feed_mm_min: f64,
}

impl Block {
    fn at(&self, t: f64) -> [f64; 3] {
        let t = t.clamp(0.0, 1.0);
        let z = self.from[2] + (self.to[2] - self.from[2]) * t;
        match self.kind {
            BlockKind::Arc { center, cw } => {
                let (a0, sweep) = arc_sweep(self.from, self.to, center, cw);
                let r = ((self.from[0] - center[0]).powi(2) + (self.from[1] - center[1]).powi(2)).sqrt();
                let a = a0 + sweep * t;
                if t >= 1.0 {
                    self.to
                } else {
                    [center[0] + r * a.cos(), center[1] + r * a.sin(), z]
                }
            }
            _ => std::array::from_fn(|i| self.from[i] + (self.to[i] - self.from[i]) * t),
        }
    }
}

/// Start angle and signed sweep of an arc (full circle when start = end).
fn arc_sweep(from: [f64; 3], to: [f64; 3], c: [f64; 2], cw: bool) -> (f64, f64) {
    let a0 = (from[1] - c[1]).atan2(from[0] - c[0]);
    let a1 = (to[1] - c[1]).atan2(to[0] - c[0]);
    let mut sweep = a1 - a0;
    if cw {
        if sweep >= -1e-9 {
            sweep -= std::f64::consts::TAU;
        }
    } else if sweep <= 1e-9 {
        sweep += std::f64::consts::TAU;
    }
    (a0, sweep)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    Run,
    Alarm,
    Check,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct GModal {
    motion: u8, // 0,1,2,3,80
    plane: u8,
    inches: bool,
    incremental: bool,
    feed_mm_min: f64,
    spindle: u8, // 3,4,5
    spindle_rpm: f64,
    mist: bool,
    flood: bool,
}

impl Default for GModal {
    fn default() -> Self {
        GModal {
            motion: 0,
            plane: 17,
            inches: false,
            incremental: false,
            feed_mm_min: 0.0,
            spindle: 5,
            spindle_rpm: 0.0,
            mist: false,
            flood: false,
        }
    }
}

/// What a parsed line waits for before its `ok`.
#[derive(Debug, Clone)]
enum Waiting {
    /// A motion block waiting for planner space.
    Plan(Block),
    /// A spindle/coolant change or dwell waiting for the planner to empty (GRBL synchronises them), then
    /// the block's own motion, if any.
    Sync { dwell_s: f64, then: Option<Block> },
    /// Dwelling until this simulated time, then the block's motion.
    Dwell { until_s: f64, then: Option<Block> },
}

/// GRBL 1.1's default settings (`defaults.h`, generic profile).
fn default_settings() -> BTreeMap<u16, f64> {
    [
        (0, 10.0),
        (1, 25.0),
        (2, 0.0),
        (3, 0.0),
        (4, 0.0),
        (5, 0.0),
        (6, 0.0),
        (10, 1.0),
        (11, 0.010),
        (12, 0.002),
        (13, 0.0),
        (20, 0.0),
        (21, 0.0),
        (22, 0.0),
        (23, 0.0),
        (24, 25.0),
        (25, 500.0),
        (26, 250.0),
        (27, 1.0),
        (30, 1000.0),
        (31, 0.0),
        (32, 0.0),
        (100, 250.0),
        (101, 250.0),
        (102, 250.0),
        (110, 500.0),
        (111, 500.0),
        (112, 500.0),
        (120, 10.0),
        (121, 10.0),
        (122, 10.0),
        (130, 200.0),
        (131, 200.0),
        (132, 200.0),
    ]
    .into_iter()
    .collect()
}

const INTEGER_SETTINGS: [u16; 17] = [0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32];

/// The virtual GRBL 1.1 controller, with no I/O: feed it bytes ([`Controller::receive`]), advance
/// simulated time ([`Controller::advance`]), take what it sends ([`Controller::take_output`]).
#[derive(Debug)]
pub struct Controller {
    line_numbers: bool,
    settings: BTreeMap<u16, f64>,
    state: State,
    /// Waiting for a soft reset after a critical alarm.
    critical: bool,
    hold: bool,
    rx: VecDeque<u8>,
    line: Vec<u8>,
    in_paren: bool,
    in_semicolon: bool,
    line_overflow: bool,
    waiting: Option<Waiting>,
    planner: VecDeque<Block>,
    pos: [f64; 3],
    parser_pos: [f64; 3],
    modal: GModal,
    out: Vec<u8>,
    log: EmulatorLog,
    faults: Vec<(Fault, bool)>,
    received: usize,
    disconnect: bool,
    feed_override: u8,
    sim_time_s: f64,
    wco_counter: u8,
    ovr_pending: bool,
}

impl Controller {
    /// A controller just powered up (its banner queued for output).
    #[must_use]
    pub fn new(cfg: &EmulatorConfig) -> Controller {
        let mut settings = default_settings();
        for &(k, v) in &cfg.settings {
            settings.insert(k, v);
        }
        let mut c = Controller {
            line_numbers: cfg.line_numbers,
            settings,
            state: State::Idle,
            critical: false,
            hold: false,
            rx: VecDeque::with_capacity(RX_BUFFER_BYTES),
            line: Vec::with_capacity(MAX_BLOCK_CHARS + 1),
            in_paren: false,
            in_semicolon: false,
            line_overflow: false,
            waiting: None,
            planner: VecDeque::new(),
            pos: [0.0; 3],
            parser_pos: [0.0; 3],
            modal: GModal::default(),
            out: Vec::new(),
            log: EmulatorLog::default(),
            faults: cfg.faults.iter().map(|&f| (f, false)).collect(),
            received: 0,
            disconnect: false,
            feed_override: 100,
            sim_time_s: 0.0,
            wco_counter: 0,
            ovr_pending: false,
        };
        if c.setting(22) == 1.0 {
            c.state = State::Alarm; // HOMING_INIT_LOCK
        }
        c.banner();
        c
    }

    fn setting(&self, n: u16) -> f64 {
        self.settings.get(&n).copied().unwrap_or(0.0)
    }

    fn say(&mut self, s: &str) {
        self.out.extend_from_slice(s.as_bytes());
        self.out.extend_from_slice(b"\r\n");
    }

    fn banner(&mut self) {
        self.out.extend_from_slice(b"\r\n");
        self.say(&format!("Grbl {VERSION} ['$' for help]"));
        if self.state == State::Alarm {
            self.say("[MSG:'$H'|'$X' to unlock]");
        }
    }

    /// Bytes to send to the host (drained).
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// The log entries since the last call (drained).
    pub fn take_log(&mut self) -> EmulatorLog {
        std::mem::take(&mut self.log)
    }

    /// An injected disconnect fired: the link layer must drop the link (cleared by this call).
    pub fn take_disconnect(&mut self) -> bool {
        std::mem::take(&mut self.disconnect)
    }

    /// The link dropped: a partial line in the reader is discarded, pending output is lost.
    pub fn link_lost(&mut self) {
        self.line.clear();
        self.in_paren = false;
        self.in_semicolon = false;
        self.line_overflow = false;
        // A partial line still in the receive buffer (no newline yet) can never complete safely.
        if let Some(last_nl) = self.rx.iter().rposition(|&b| b == b'\n' || b == b'\r') {
            self.rx.truncate(last_nl + 1);
        } else {
            self.rx.clear();
        }
        self.out.clear();
    }

    /// Machine position, mm.
    #[must_use]
    pub fn position(&self) -> [f64; 3] {
        self.pos
    }

    /// One byte arrived from the host.
    pub fn receive(&mut self, b: u8) {
        self.log.bytes_in += 1;
        match b {
            b'?' => self.status_report(),
            b'!' => {
                if self.state == State::Run && !self.planner.is_empty() {
                    self.hold = true;
                }
            }
            b'~' => {
                if self.hold {
                    self.hold = false;
                }
                if self.state == State::Idle && !self.planner.is_empty() {
                    self.state = State::Run;
                }
            }
            0x18 => self.soft_reset(),
            0x90 => self.feed_override = 100,
            0x91 => self.feed_override = (self.feed_override + 10).min(200),
            0x92 => self.feed_override = self.feed_override.saturating_sub(10).max(10),
            0x93 => self.feed_override = (self.feed_override + 1).min(200),
            0x94 => self.feed_override = self.feed_override.saturating_sub(1).max(10),
            b if super::protocol::Realtime::is_realtime(b) => {}
            _ => {
                if self.rx.len() >= RX_BUFFER_BYTES - 1 {
                    self.log.rx_overflows += 1;
                    self.log.events.push(format!(
                        "RX buffer overflow: byte {b:#04x} dropped ({} bytes buffered)",
                        self.rx.len()
                    ));
                } else {
                    self.rx.push_back(b);
                }
            }
        }
    }

    fn state_word(&self) -> String {
        if self.hold {
            return "Hold:0".into();
        }
        match self.state {
            State::Idle => "Idle",
            State::Run => "Run",
            State::Alarm => "Alarm",
            State::Check => "Check",
        }
        .into()
    }

    fn status_report(&mut self) {
        let mask = self.setting(10) as u32;
        let p = self.pos;
        let mut s = format!("<{}|", self.state_word());
        s += &format!(
            "{}:{:.3},{:.3},{:.3}",
            if mask & 1 == 1 { "MPos" } else { "WPos" },
            p[0],
            p[1],
            p[2]
        );
        if mask & 2 == 2 {
            s += &format!(
                "|Bf:{},{}",
                PLANNER_BLOCKS as usize - self.planner.len().min(PLANNER_BLOCKS as usize),
                RX_BUFFER_BYTES - self.rx.len()
            );
        }
        if self.line_numbers {
            if let Some(b) = self.planner.front() {
                if b.line > 0 {
                    s += &format!("|Ln:{}", b.line);
                }
            }
        }
        let feed = match self.planner.front() {
            Some(b) if self.state == State::Run && !self.hold => {
                if b.kind == BlockKind::Rapid {
                    self.setting(110)
                } else {
                    b.feed_mm_min * f64::from(self.feed_override) / 100.0
                }
            }
            _ => 0.0,
        };
        let rpm = if self.modal.spindle == 5 {
            0.0
        } else {
            self.modal.spindle_rpm
        };
        s += &format!("|FS:{feed:.0},{rpm:.0}");
        if self.wco_counter == 0 {
            self.wco_counter = if self.state == State::Run { 29 } else { 9 };
            self.ovr_pending = true;
            s += "|WCO:0.000,0.000,0.000";
        } else {
            self.wco_counter -= 1;
            if std::mem::take(&mut self.ovr_pending) {
                s += &format!("|Ov:{},100,100", self.feed_override);
            }
        }
        s.push('>');
        self.say(&s);
    }

    fn log_partial_head(&mut self) {
        if let Some(b) = self.planner.front() {
            if b.elapsed_s > 0.0 {
                self.log.executed.push(Piece {
                    line: b.line,
                    from_mm: b.from,
                    to_mm: self.pos,
                    complete: false,
                });
            }
        }
    }

    fn flush_motion(&mut self) {
        self.log_partial_head();
        self.planner.clear();
        self.waiting = None;
        self.hold = false;
        self.parser_pos = self.pos;
    }

    /// Ctrl-X: stop, flush the receive buffer and planner, reset the parser, print the banner. A reset while
    /// moving or holding raises `ALARM:3` (GRBL's `mc_reset`).
    fn soft_reset(&mut self) {
        let moving = (self.state == State::Run || self.hold) && !self.planner.is_empty() && !self.critical;
        self.flush_motion();
        self.rx.clear();
        self.line.clear();
        self.in_paren = false;
        self.in_semicolon = false;
        self.line_overflow = false;
        self.critical = false;
        self.modal = GModal::default();
        self.feed_override = 100;
        if moving {
            self.say("ALARM:3");
            self.log.events.push("ALARM:3 (reset while in motion)".into());
            self.state = State::Alarm;
        } else if self.state != State::Alarm {
            self.state = State::Idle;
        }
        self.log.events.push("soft reset".into());
        self.wco_counter = 0;
        self.banner();
    }

    /// Stop at once and lock with `ALARM:code` until a soft reset (soft-limit behaviour).
    fn alarm(&mut self, code: u16) {
        // Motion stops here; the planner is only cleared by the reset that ends the lock, so status
        // reports until then still name the block that was executing (`Ln`), as in GRBL.
        self.hold = false;
        self.waiting = None;
        self.state = State::Alarm;
        self.critical = true;
        self.say(&format!("ALARM:{code}"));
        self.say("[MSG:Reset to continue]");
        self.log.events.push(format!("ALARM:{code}"));
    }

    /// Advance simulated time by `dt_s` seconds: execute motion, finish dwells, run the main loop.
    pub fn advance(&mut self, dt_s: f64) {
        self.sim_time_s += dt_s;
        let mut dt = dt_s;
        while dt > 0.0 && self.state == State::Run && !self.hold && !self.critical {
            let Some(b) = self.planner.front_mut() else { break };
            let f = if b.kind == BlockKind::Rapid {
                1.0
            } else {
                f64::from(self.feed_override) / 100.0
            };
            let remaining = (b.duration_s - b.elapsed_s) / f;
            if dt >= remaining {
                dt -= remaining;
                let b = self.planner.pop_front().expect("front exists");
                self.pos = b.to;
                self.log.executed.push(Piece {
                    line: b.line,
                    from_mm: b.from,
                    to_mm: b.to,
                    complete: true,
                });
            } else {
                b.elapsed_s += dt * f;
                self.pos = b.at(b.elapsed_s / b.duration_s);
                dt = 0.0;
            }
        }
        if self.state == State::Run && self.planner.is_empty() {
            self.state = State::Idle;
        }
        self.main_loop();
    }

    /// GRBL's main loop: finish what the last line waits for, then read lines from the receive buffer.
    fn main_loop(&mut self) {
        loop {
            if self.critical {
                return;
            }
            if let Some(w) = self.waiting.take() {
                match w {
                    Waiting::Plan(b) => {
                        if self.planner.len() >= PLANNER_BLOCKS as usize {
                            self.start_cycle();
                            self.waiting = Some(Waiting::Plan(b));
                            return;
                        }
                        self.planner.push_back(b);
                        self.say("ok");
                    }
                    Waiting::Sync { dwell_s, then } => {
                        if !self.planner.is_empty() {
                            self.start_cycle();
                            self.waiting = Some(Waiting::Sync { dwell_s, then });
                            return;
                        }
                        self.waiting = Some(Waiting::Dwell {
                            until_s: self.sim_time_s + dwell_s,
                            then,
                        });
                        continue;
                    }
                    Waiting::Dwell { until_s, then } => {
                        if self.sim_time_s < until_s {
                            self.waiting = Some(Waiting::Dwell { until_s, then });
                            return;
                        }
                        match then {
                            Some(b) => {
                                self.waiting = Some(Waiting::Plan(b));
                                continue;
                            }
                            None => self.say("ok"),
                        }
                    }
                }
                if self.planner.len() >= PLANNER_BLOCKS as usize {
                    self.start_cycle();
                }
            }
            let Some(c) = self.rx.pop_front() else {
                self.start_cycle(); // protocol_auto_cycle_start when the receive buffer is empty
                return;
            };
            if c == b'\n' || c == b'\r' {
                let text = String::from_utf8_lossy(&self.line).into_owned();
                let overflow = self.line_overflow;
                self.line.clear();
                self.in_paren = false;
                self.in_semicolon = false;
                self.line_overflow = false;
                self.execute_line(&text, overflow);
            } else if self.in_paren || self.in_semicolon {
                if c == b')' {
                    self.in_paren = false;
                }
            } else if c <= b' ' || c == b'/' {
            } else if c == b'(' {
                self.in_paren = true;
            } else if c == b';' {
                self.in_semicolon = true;
            } else if self.line.len() >= MAX_BLOCK_CHARS {
                self.line_overflow = true;
            } else {
                self.line.push(c.to_ascii_uppercase());
            }
        }
    }

    fn start_cycle(&mut self) {
        if self.state == State::Idle && !self.planner.is_empty() && !self.hold {
            self.state = State::Run;
        }
    }

    fn execute_line(&mut self, text: &str, overflow: bool) {
        if overflow {
            self.say("error:11");
            return;
        }
        if text.is_empty() {
            self.say("ok");
            return;
        }
        self.received += 1;
        self.log.received.push(text.to_string());
        let n = leading_line_number(text);
        let received = self.received;
        let fired = self.faults.iter_mut().find(|(f, done)| {
            !*done
                && match f.at {
                    FaultAt::LineNumber(k) => n == Some(k),
                    FaultAt::Received(k) => k == received,
                }
        });
        let mut disconnect_after = false;
        if let Some((f, done)) = fired {
            *done = true;
            let f = *f;
            self.log.events.push(format!("fault fired at `{text}`: {:?}", f.kind));
            match f.kind {
                FaultKind::Error(code) => {
                    self.say(&format!("error:{code}"));
                    return;
                }
                FaultKind::Alarm(code) => {
                    self.alarm(code);
                    return;
                }
                FaultKind::Disconnect => disconnect_after = true,
            }
        }
        if text.starts_with('$') {
            self.system_command(text);
        } else if self.state == State::Alarm {
            self.say("error:9");
        } else {
            match self.gcode(text) {
                Ok(()) => {}
                Err(code) => self.say(&format!("error:{code}")),
            }
        }
        if disconnect_after {
            self.disconnect = true;
        }
    }

    fn system_command(&mut self, text: &str) {
        let idle_or_alarm = matches!(self.state, State::Idle | State::Alarm) && !self.hold;
        match text {
            "$" => self.say("[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"),
            "$$" => {
                let lines: Vec<String> = self
                    .settings
                    .iter()
                    .map(|(k, v)| {
                        if INTEGER_SETTINGS.contains(k) {
                            format!("${k}={}", *v as i64)
                        } else {
                            format!("${k}={v:.3}")
                        }
                    })
                    .collect();
                for l in lines {
                    self.say(&l);
                }
            }
            "$#" => {
                for g in ["G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30", "G92"] {
                    self.say(&format!("[{g}:0.000,0.000,0.000]"));
                }
                self.say("[TLO:0.000]");
                self.say("[PRB:0.000,0.000,0.000:0]");
            }
            "$G" => {
                let m = self.modal;
                self.say(&format!(
                    "[GC:G{} G54 G{} G{} G{} G94 M{} M9 T0 F{} S{}]",
                    m.motion,
                    m.plane,
                    if m.inches { 20 } else { 21 },
                    if m.incremental { 91 } else { 90 },
                    m.spindle,
                    m.feed_mm_min,
                    m.spindle_rpm
                ));
            }
            "$I" => {
                self.say(&format!("[VER:{VERSION}.20190825:]"));
                let opts = if self.line_numbers { "VNL" } else { "VL" };
                self.say(&format!("[OPT:{opts},{PLANNER_BLOCKS},{RX_BUFFER_BYTES}]"));
            }
            "$N" => {
                self.say("$N0=");
                self.say("$N1=");
            }
            "$X" => {
                if self.state == State::Alarm {
                    self.state = State::Idle;
                    self.say("[MSG:Caution: Unlocked]");
                }
            }
            "$H" => {
                if self.setting(22) != 1.0 {
                    self.say("error:5");
                    return;
                }
                if !idle_or_alarm {
                    self.say("error:8");
                    return;
                }
                self.pos = [0.0; 3];
                self.parser_pos = self.pos;
                self.state = State::Idle;
            }
            "$C" => {
                if self.state == State::Check {
                    self.say("[MSG:Disabled]");
                    self.say("ok");
                    self.soft_reset();
                    return;
                }
                if self.state != State::Idle || self.hold || !self.planner.is_empty() {
                    self.say("error:8");
                    return;
                }
                self.state = State::Check;
                self.say("[MSG:Enabled]");
            }
            t if t.starts_with("$RST=") => {
                if !idle_or_alarm {
                    self.say("error:8");
                    return;
                }
                if !matches!(&t[5..], "$" | "#" | "*") {
                    self.say("error:3");
                    return;
                }
                if t.ends_with('$') || t.ends_with('*') {
                    self.settings = default_settings();
                }
            }
            t if t.starts_with("$N") && t.contains('=') => {
                if !idle_or_alarm {
                    self.say("error:8");
                    return;
                }
            }
            t if t.contains('=') && !t.starts_with("$J=") => {
                let (k, v) = t[1..].split_once('=').expect("contains =");
                let Ok(k) = k.parse::<u16>() else {
                    self.say("error:3");
                    return;
                };
                let Some(v) = parse_grbl_float(v) else {
                    self.say("error:2");
                    return;
                };
                if !self.settings.contains_key(&k) {
                    self.say("error:3");
                    return;
                }
                if v < 0.0 {
                    self.say("error:4");
                    return;
                }
                if !idle_or_alarm {
                    self.say("error:8");
                    return;
                }
                if k == 20 && v != 0.0 && self.setting(22) != 1.0 {
                    self.say("error:10");
                    return;
                }
                self.settings
                    .insert(k, if INTEGER_SETTINGS.contains(&k) { v.trunc() } else { v });
            }
            other => {
                if other.starts_with("$J=") || other == "$SLP" {
                    self.log.events.push(format!("not modelled: `{other}`"));
                }
                self.say("error:3");
                return;
            }
        }
        self.say("ok");
    }

    /// Parse and run one G-code block; `Err(code)` is GRBL's error code.
    fn gcode(&mut self, text: &str) -> Result<(), u16> {
        let ws = program::words(text).map_err(|e| e.code())?;
        let mut m = self.modal;
        let mut seen = std::collections::HashSet::new();
        let mut motion_in_block = None;
        let mut groups = std::collections::HashSet::new();
        let mut dwell = false;
        let mut mcodes_sync = false;
        let mut program_end = false;
        let mut axis: [Option<f64>; 3] = [None; 3];
        let (mut ij, mut f, mut s, mut p) = ([None, None], None, None, None);
        let mut unmodelled = None;
        let mut group = |g: u8| -> Result<(), u16> {
            if groups.insert(g) {
                Ok(())
            } else {
                Err(21)
            }
        };
        for w in &ws {
            let v = w.value;
            let int = v.trunc();
            let mantissa = ((v - int) * 10.0).round() as i32;
            match w.letter {
                'G' => {
                    let g = int as i32;
                    match (g, mantissa) {
                        (0..=3, 0) | (80, 0) => {
                            group(1)?;
                            motion_in_block = Some(g as u8);
                        }
                        (4, 0) => {
                            group(0)?;
                            dwell = true;
                        }
                        (17..=19, 0) => {
                            group(2)?;
                            m.plane = g as u8;
                        }
                        (20 | 21, 0) => {
                            group(6)?;
                            m.inches = g == 20;
                        }
                        (90 | 91, 0) => {
                            group(3)?;
                            m.incremental = g == 91;
                        }
                        (94, 0) => group(5)?,
                        (54, 0) => group(12)?,
                        (10 | 28 | 30 | 53 | 92 | 38 | 43 | 49 | 61 | 93 | 55..=59, _) => {
                            unmodelled = Some(format!("G{v}"));
                        }
                        (_, 0) => return Err(20),
                        _ => return Err(23),
                    }
                }
                'M' => {
                    if mantissa != 0 {
                        return Err(23);
                    }
                    match int as i32 {
                        0 | 1 | 2 | 30 => {
                            group(4)?;
                            program_end = matches!(int as i32, 2 | 30);
                        }
                        c @ 3..=5 => {
                            group(7)?;
                            m.spindle = c as u8;
                            mcodes_sync = true;
                        }
                        7 => {
                            m.mist = true;
                            mcodes_sync = true;
                        }
                        8 => {
                            m.flood = true;
                            mcodes_sync = true;
                        }
                        9 => {
                            m.mist = false;
                            m.flood = false;
                            mcodes_sync = true;
                        }
                        _ => return Err(20),
                    }
                }
                letter => {
                    if !seen.insert(letter) {
                        return Err(25);
                    }
                    match letter {
                        'X' => axis[0] = Some(v),
                        'Y' => axis[1] = Some(v),
                        'Z' => axis[2] = Some(v),
                        'I' => ij[0] = Some(v),
                        'J' => ij[1] = Some(v),
                        'F' => f = Some(v),
                        'S' => s = Some(v),
                        'P' => p = Some(v),
                        'N' => {
                            if !(0.0..=program::MAX_LINE_NUMBER as f64).contains(&v) {
                                return Err(27);
                            }
                        }
                        'T' => {}
                        'K' | 'R' | 'L' => unmodelled = Some(format!("{letter} word")),
                        _ => return Err(20),
                    }
                    if matches!(letter, 'F' | 'S' | 'P' | 'T' | 'N') && v < 0.0 {
                        return Err(4);
                    }
                }
            }
        }
        if let Some(what) = unmodelled {
            self.log.events.push(format!("not modelled: {what} in `{text}`"));
            return Err(20);
        }
        let k = if m.inches { 25.4 } else { 1.0 };
        if let Some(f) = f {
            m.feed_mm_min = f * k;
        }
        if let Some(s) = s {
            m.spindle_rpm = s;
        }
        if let Some(mm) = motion_in_block {
            m.motion = mm;
        }
        let has_axis = axis.iter().any(Option::is_some);
        if dwell && p.is_none() {
            return Err(28);
        }
        if p.is_some() && !dwell {
            return Err(36);
        }
        let arc = has_axis && matches!(m.motion, 2 | 3);
        if ij.iter().any(Option::is_some) && !arc {
            return Err(36);
        }
        if has_axis && m.motion == 80 {
            return Err(31);
        }
        let mut target = self.parser_pos;
        for i in 0..3 {
            if let Some(v) = axis[i] {
                target[i] = if m.incremental { target[i] + v * k } else { v * k };
            }
        }
        let mut block = None;
        if has_axis {
            if m.motion != 0 && m.feed_mm_min <= 0.0 {
                return Err(22);
            }
            let kind = match m.motion {
                0 => BlockKind::Rapid,
                1 => BlockKind::Linear,
                _ => {
                    if m.plane != 17 {
                        self.log
                            .events
                            .push(format!("not modelled: arc outside G17 in `{text}`"));
                        return Err(20);
                    }
                    if axis[0].is_none() && axis[1].is_none() {
                        return Err(32);
                    }
                    if ij[0].is_none() && ij[1].is_none() {
                        return Err(35);
                    }
                    let c = [
                        self.parser_pos[0] + ij[0].unwrap_or(0.0) * k,
                        self.parser_pos[1] + ij[1].unwrap_or(0.0) * k,
                    ];
                    let r0 = ((self.parser_pos[0] - c[0]).powi(2) + (self.parser_pos[1] - c[1]).powi(2)).sqrt();
                    let r1 = ((target[0] - c[0]).powi(2) + (target[1] - c[1]).powi(2)).sqrt();
                    // GRBL: error 33 when the end radius differs by more than 0.5 mm and 0.1 %.
                    if (r1 - r0).abs() > 0.5 && (r1 - r0).abs() > 0.001 * r0 {
                        return Err(33);
                    }
                    BlockKind::Arc {
                        center: c,
                        cw: m.motion == 2,
                    }
                }
            };
            if self.setting(20) == 1.0 {
                for (i, t) in target.iter().enumerate() {
                    if *t > 0.0 || *t < -self.setting(130 + i as u16) {
                        self.modal = m;
                        self.alarm(2);
                        return Ok(());
                    }
                }
            }
            let b = self.block(kind, target, m.feed_mm_min, leading_line_number(text).unwrap_or(0));
            if b.duration_s > 0.0 {
                block = Some(b);
            }
        }
        self.modal = m;
        if self.state == State::Check {
            self.parser_pos = target;
            self.say("ok");
            return Ok(());
        }
        if mcodes_sync || dwell || program_end {
            // Spindle, coolant and dwell wait for the planner to empty first (GRBL synchronises them).
            // Motion in the same block is planned after the synchronised commands.
            self.waiting = Some(Waiting::Sync {
                dwell_s: if dwell { p.unwrap_or(0.0) } else { 0.0 },
                then: block,
            });
            self.parser_pos = target;
            if program_end {
                self.modal = GModal {
                    inches: m.inches,
                    feed_mm_min: m.feed_mm_min,
                    spindle_rpm: m.spindle_rpm,
                    motion: 1,
                    ..GModal::default()
                };
            }
            return Ok(());
        }
        self.parser_pos = target;
        match block {
            Some(b) => self.waiting = Some(Waiting::Plan(b)),
            None => self.say("ok"),
        }
        Ok(())
    }
}

impl Controller {
    /// A motion block from the parser position to `to`, timed at its feed (no acceleration) and limited
    /// by each axis' maximum rate (`$110`–`$112`, mm/min).
    fn block(&self, kind: BlockKind, to: [f64; 3], feed_mm_min: f64, line: u32) -> Block {
        let from = self.parser_pos;
        let d: Vec<f64> = (0..3).map(|i| to[i] - from[i]).collect();
        let axis_limited = (0..3)
            .map(|i| d[i].abs() / (self.setting(110 + i as u16).max(1e-9) / 60.0))
            .fold(0.0, f64::max);
        let length = match kind {
            BlockKind::Arc { center, cw } => {
                let (_, sweep) = arc_sweep(from, to, center, cw);
                let r = ((from[0] - center[0]).powi(2) + (from[1] - center[1]).powi(2)).sqrt();
                ((r * sweep).powi(2) + d[2].powi(2)).sqrt()
            }
            _ => (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
        };
        let duration_s = match kind {
            BlockKind::Rapid => axis_limited,
            _ => (length / (feed_mm_min / 60.0)).max(axis_limited),
        };
        Block {
            line,
            from,
            to,
            kind,
            duration_s: if length < 1e-9 { 0.0 } else { duration_s },
            elapsed_s: 0.0,
            feed_mm_min,
        }
    }
}

/// The `N` word of a cleaned block, if it starts with one.
fn leading_line_number(text: &str) -> Option<u32> {
    let rest = text.strip_prefix('N')?;
    let end = rest.find(|c: char| !c.is_ascii_digit()).unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// GRBL's `read_float` for a setting value.
fn parse_grbl_float(v: &str) -> Option<f64> {
    let ok = !v.is_empty()
        && v.chars()
            .all(|c| c.is_ascii_digit() || c == '.' || c == '-' || c == '+')
        && v.chars().any(|c| c.is_ascii_digit());
    if ok {
        v.parse().ok()
    } else {
        None
    }
}

/// Paces bytes over a simulated serial line: one byte per `10 / baud` seconds, no banked credit while the
/// line is idle.
#[derive(Debug)]
struct Pacer {
    byte_time: Duration,
    next_free: Instant,
}

impl Pacer {
    fn new(baud: u32) -> Pacer {
        Pacer {
            byte_time: Duration::from_secs_f64(10.0 / f64::from(baud.max(1))),
            next_free: Instant::now(),
        }
    }

    /// Bytes were queued on an idle line at `now`: the first one finishes crossing one byte time later.
    fn arrive(&mut self, now: Instant) {
        self.next_free = self.next_free.max(now);
    }

    /// How many of `waiting` bytes have finished crossing the line by `now`.
    fn take(&mut self, now: Instant, waiting: usize) -> usize {
        if waiting == 0 || now < self.next_free + self.byte_time {
            return 0;
        }
        let n = ((now - self.next_free).as_secs_f64() / self.byte_time.as_secs_f64()) as usize;
        let n = n.min(waiting);
        self.next_free += self.byte_time * n as u32;
        n
    }
}

#[derive(Debug, Default)]
struct Shared {
    port: Option<PathBuf>,
    generation: u64,
    log: EmulatorLog,
    failure: Option<String>,
}

/// A virtual GRBL controller running on a pseudo-terminal in its own thread. Dropping it stops it.
#[derive(Debug)]
pub struct Emulator {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// A pseudo-terminal: the master end the emulator reads and writes, and the slave's path.
struct Pty {
    master: OwnedFd,
    path: PathBuf,
}

fn open_pty(link: Option<&Path>) -> std::io::Result<Pty> {
    use nix::sys::termios;
    let pty = nix::pty::openpty(None, None).map_err(std::io::Error::from)?;
    let mut t = termios::tcgetattr(pty.slave.as_fd()).map_err(std::io::Error::from)?;
    termios::cfmakeraw(&mut t);
    termios::tcsetattr(pty.slave.as_fd(), termios::SetArg::TCSANOW, &t).map_err(std::io::Error::from)?;
    let path = nix::unistd::ttyname(pty.slave.as_fd()).map_err(std::io::Error::from)?;
    let flags =
        nix::fcntl::fcntl(pty.master.as_raw_fd(), nix::fcntl::FcntlArg::F_GETFL).map_err(std::io::Error::from)?;
    let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
    nix::fcntl::fcntl(pty.master.as_raw_fd(), nix::fcntl::FcntlArg::F_SETFL(flags)).map_err(std::io::Error::from)?;
    // The slave end is closed here: a client opening it is the only user (so serialport's exclusive
    // lock is released when the client closes it), and the master sees a hang-up when nobody has it open.
    drop(pty.slave);
    if let Some(link) = link {
        let tmp = link.with_extension("tmp-link");
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(&path, &tmp)?;
        std::fs::rename(&tmp, link)?;
    }
    Ok(Pty {
        master: pty.master,
        path,
    })
}

impl Emulator {
    /// Open a pseudo-terminal and start the controller on it.
    pub fn start(cfg: EmulatorConfig) -> std::io::Result<Emulator> {
        let pty = open_pty(cfg.link_path.as_deref())?;
        let shared = Arc::new((
            Mutex::new(Shared {
                port: Some(pty.path.clone()),
                generation: 1,
                ..Shared::default()
            }),
            Condvar::new(),
        ));
        let stop = Arc::new(AtomicBool::new(false));
        let (sh, st) = (Arc::clone(&shared), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name("grbl-emulator".into())
            .spawn(move || {
                if let Err(e) = run_link(cfg, pty, &sh, &st) {
                    let (m, cv) = &*sh;
                    let mut g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                    g.failure = Some(e.to_string());
                    g.port = None;
                    cv.notify_all();
                }
            })?;
        Ok(Emulator {
            shared,
            stop,
            thread: Some(thread),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Shared> {
        self.shared.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The current port path (changes after an injected disconnect; `None` while reconnecting).
    #[must_use]
    pub fn port_path(&self) -> Option<PathBuf> {
        self.lock().port.clone()
    }

    /// Wait up to `timeout` for a port other than the one of connection `generation` (see
    /// [`Emulator::generation`]); returns the new path and generation.
    #[must_use]
    pub fn wait_new_port(&self, generation: u64, timeout: Duration) -> Option<(PathBuf, u64)> {
        let (m, cv) = &*self.shared;
        let g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let (g, _) = cv
            .wait_timeout_while(g, timeout, |s| {
                s.failure.is_none() && (s.generation == generation || s.port.is_none())
            })
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        g.port
            .clone()
            .filter(|_| g.generation != generation)
            .map(|p| (p, g.generation))
    }

    /// How many pseudo-terminals have been opened (1 at start, +1 per injected disconnect).
    #[must_use]
    pub fn generation(&self) -> u64 {
        self.lock().generation
    }

    /// A copy of the log so far.
    #[must_use]
    pub fn log(&self) -> EmulatorLog {
        self.lock().log.clone()
    }

    /// Why the emulator thread stopped, if it failed.
    #[must_use]
    pub fn failure(&self) -> Option<String> {
        self.lock().failure.clone()
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The emulator thread: move bytes between the pseudo-terminal and the controller at the baud rate,
/// advance simulated time, publish the log.
fn run_link(
    cfg: EmulatorConfig,
    first: Pty,
    shared: &Arc<(Mutex<Shared>, Condvar)>,
    stop: &AtomicBool,
) -> std::io::Result<()> {
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    let mut ctl = Controller::new(&cfg);
    let mut pty = Some(first);
    let mut reconnect_at: Option<Instant> = None;
    let mut wire_in: VecDeque<u8> = VecDeque::new();
    let mut wire_out: VecDeque<u8> = VecDeque::new();
    let mut pace_in = Pacer::new(cfg.baud);
    let mut pace_out = Pacer::new(cfg.baud);
    let mut last = Instant::now();
    let mut buf = [0u8; 4096];
    while !stop.load(Ordering::SeqCst) {
        let mut hung_up = false;
        if let Some(p) = &pty {
            let mut fds = [PollFd::new(p.master.as_fd(), PollFlags::POLLIN)];
            let n = poll(&mut fds, PollTimeout::from(1u8)).unwrap_or(0);
            let rev = fds[0].revents().unwrap_or(PollFlags::empty());
            if n > 0 && rev.contains(PollFlags::POLLIN) {
                match nix::unistd::read(p.master.as_raw_fd(), &mut buf) {
                    Ok(k) => {
                        if wire_in.is_empty() {
                            pace_in.arrive(Instant::now());
                        }
                        wire_in.extend(&buf[..k]);
                    }
                    Err(nix::errno::Errno::EAGAIN) => {}
                    Err(_) => hung_up = true,
                }
            } else if n > 0 {
                hung_up = true; // POLLHUP: no client has the port open
            }
        }
        if hung_up || pty.is_none() {
            std::thread::sleep(Duration::from_millis(1));
        }
        let now = Instant::now();
        let dt = (now - last).as_secs_f64();
        last = now;
        let k = pace_in.take(now, wire_in.len());
        for b in wire_in.drain(..k) {
            ctl.receive(b);
        }
        ctl.advance(dt * cfg.time_scale);
        let fresh_out = ctl.take_output();
        if wire_out.is_empty() && !fresh_out.is_empty() {
            pace_out.arrive(now);
        }
        wire_out.extend(fresh_out);
        if ctl.take_disconnect() {
            ctl.link_lost();
            wire_in.clear();
            wire_out.clear();
            pty = None; // closes the master: the client sees a hang-up
            reconnect_at = Some(now + cfg.reconnect_delay);
            let (m, cv) = &**shared;
            let mut g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            g.port = None;
            g.log.events.push("link dropped (injected disconnect)".into());
            cv.notify_all();
        }
        if let Some(p) = &pty {
            let k = pace_out.take(now, wire_out.len());
            if k > 0 {
                let chunk: Vec<u8> = wire_out.iter().take(k).copied().collect();
                match nix::unistd::write(p.master.as_fd(), &chunk) {
                    Ok(w) => {
                        wire_out.drain(..w);
                        ctl.log.bytes_out += w as u64;
                    }
                    Err(nix::errno::Errno::EAGAIN) => {}
                    Err(_) => {} // nobody reading: keep the bytes, a real UART would lose them
                }
            }
        }
        if reconnect_at.is_some_and(|t| now >= t) {
            reconnect_at = None;
            let p = open_pty(cfg.link_path.as_deref())?;
            let (m, cv) = &**shared;
            let mut g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            g.port = Some(p.path.clone());
            g.generation += 1;
            g.log.events.push(format!("link up on {}", p.path.display()));
            cv.notify_all();
            pty = Some(p);
        }
        let mut fresh = ctl.take_log();
        let (m, _) = &**shared;
        m.lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .log
            .append(&mut fresh);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ctl() -> Controller {
        let mut c = Controller::new(&EmulatorConfig {
            settings: vec![(10, 3.0)],
            ..EmulatorConfig::default()
        });
        c.take_output();
        c
    }

    fn send(c: &mut Controller, s: &str) -> String {
        for b in s.bytes() {
            c.receive(b);
        }
        c.advance(0.0);
        String::from_utf8(c.take_output()).unwrap()
    }

    #[test]
    fn answers_like_grbl() {
        let mut c = ctl();
        assert_eq!(send(&mut c, "G1X10\n"), "error:22\r\n");
        assert_eq!(send(&mut c, "X\n"), "error:2\r\n");
        assert_eq!(send(&mut c, "1X\n"), "error:1\r\n");
        assert_eq!(send(&mut c, "G5X1\n"), "error:20\r\n");
        assert_eq!(send(&mut c, "G0G1X1\n"), "error:21\r\n");
        assert_eq!(send(&mut c, "G0X1X2\n"), "error:25\r\n");
        assert_eq!(send(&mut c, "G1X1F100 (comment) ; tail\n"), "ok\r\n");
        assert_eq!(send(&mut c, "\n"), "ok\r\n");
        assert_eq!(send(&mut c, &format!("G1X{}\n", "1".repeat(90))), "error:11\r\n");
        assert_eq!(send(&mut c, "$99=1\n"), "error:3\r\n");
        assert!(send(&mut c, "$I\n").contains("[OPT:VNL,15,128]"));
    }

    #[test]
    fn status_reports_planner_and_line() {
        let mut c = ctl();
        assert_eq!(send(&mut c, "N7G1X60F60\n"), "ok\r\n"); // 60 mm at 60 mm/min: 60 s
        c.advance(30.0);
        let s = send(&mut c, "?");
        assert!(
            s.starts_with("<Run|MPos:30.000,0.000,0.000|Bf:14,128|Ln:7|FS:60,0"),
            "{s}"
        );
        send(&mut c, "!");
        c.advance(10.0);
        assert!(send(&mut c, "?").starts_with("<Hold:0|MPos:30.000"));
        send(&mut c, "~");
        c.advance(31.0);
        assert!(send(&mut c, "?").starts_with("<Idle|MPos:60.000,0.000,0.000|Bf:15,128|FS:0,0"));
        assert_eq!(c.log.executed.len(), 1);
    }

    #[test]
    fn reset_while_holding_raises_alarm_3_and_logs_the_partial_block() {
        let mut c = ctl();
        send(&mut c, "N1G1X10F60\n");
        c.advance(5.0);
        send(&mut c, "!");
        let out = send(&mut c, "\x18");
        assert!(out.starts_with("ALARM:3\r\n\r\nGrbl 1.1h"), "{out}");
        assert!(out.contains("'$X' to unlock"));
        let p = c.log.executed[0];
        assert!(!p.complete && (p.to_mm[0] - 5.0).abs() < 1e-9);
        assert_eq!(send(&mut c, "G0X1\n"), "error:9\r\n");
        assert_eq!(send(&mut c, "$X\n"), "[MSG:Caution: Unlocked]\r\nok\r\n");
    }

    #[test]
    fn planner_holds_fifteen_blocks() {
        let mut c = ctl();
        let mut oks = 0;
        for i in 1..=17 {
            oks += send(&mut c, &format!("G1X{i}F60\n")).matches("ok").count();
        }
        assert_eq!(oks, 15, "the 16th waits for a free block");
        c.advance(1.0);
        assert_eq!(String::from_utf8(c.take_output()).unwrap(), "ok\r\n");
    }

    #[test]
    fn overflow_is_counted_not_hidden() {
        let mut c = ctl();
        send(&mut c, "N1G1X100F1\n"); // a long block keeps the planner busy
        for _ in 0..15 {
            send(&mut c, "G1X1F1\n");
        }
        // The parser now waits for a free planner block; the receive buffer fills up.
        for b in std::iter::repeat_n(b'G', 130) {
            c.receive(b);
        }
        assert_eq!(c.log.rx_overflows, 3);
        assert!(c.log.events.iter().any(|e| e.contains("overflow")));
    }

    #[test]
    fn check_mode_and_soft_limits() {
        let mut c = ctl();
        assert_eq!(send(&mut c, "$C\n"), "[MSG:Enabled]\r\nok\r\n");
        assert_eq!(send(&mut c, "G1X10F100\n"), "ok\r\n");
        assert!(send(&mut c, "?").starts_with("<Check|MPos:0.000"));
        let off = send(&mut c, "$C\n");
        assert!(off.starts_with("[MSG:Disabled]\r\nok\r\n\r\nGrbl"), "{off}");
        assert_eq!(send(&mut c, "$20=1\n"), "error:10\r\n");
        assert_eq!(send(&mut c, "$22=1\n"), "ok\r\n");
        assert_eq!(send(&mut c, "$20=1\n"), "ok\r\n");
        assert_eq!(send(&mut c, "G0X-10\n"), "ok\r\n");
        let a = send(&mut c, "G0X5\n");
        assert_eq!(a, "ALARM:2\r\n[MSG:Reset to continue]\r\n");
        assert_eq!(send(&mut c, "G0X-1\n"), "", "locked until reset");
        assert!(send(&mut c, "\x18").contains("'$X' to unlock"));
    }

    #[test]
    fn faults_fire_once() {
        let mut c = Controller::new(&EmulatorConfig {
            faults: vec!["3:error:20".parse().unwrap(), "4:alarm".parse().unwrap()],
            ..EmulatorConfig::default()
        });
        c.take_output();
        assert_eq!(send(&mut c, "N3G0X1\n"), "error:20\r\n");
        assert_eq!(send(&mut c, "N3G0X1\n"), "ok\r\n");
        assert!(send(&mut c, "N4G0X2\n").starts_with("ALARM:2"));
        assert!("x:error".parse::<Fault>().is_err());
    }

    #[test]
    fn pacer_keeps_the_baud_rate() {
        let mut p = Pacer::new(115_200);
        let t0 = Instant::now() + Duration::from_millis(5);
        p.arrive(t0);
        assert_eq!(p.take(t0, 100), 0);
        assert_eq!(p.take(t0 + Duration::from_millis(1), 100), 11);
        assert_eq!(p.take(t0 + Duration::from_millis(10), 1000), 115 - 11);
    }
}
