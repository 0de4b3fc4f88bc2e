//! A virtual GRBL 1.1 controller, for tests and for dry runs (`brdfmill emulate`).
//!
//! Two layers:
//! - [`Controller`]: the controller itself with no I/O and no clock — bytes in, bytes out, simulated time
//!   advanced by the caller. It models GRBL 1.1's 128-byte receive buffer (an overflow is counted and
//!   logged, never hidden), realtime commands (`?`, `!`, `~`, Ctrl-X, feed overrides), the line reader
//!   (comments and spaces stripped, 79-character limit → `error:11`), the G-code subset below with GRBL's
//!   error codes, a 15-block planner that executes blocks at their programmed feed in simulated time,
//!   status reports (`MPos`/`WPos`, `Bf`, `Ln`, `FS`, `WCO`, `Ov`), `$C` check mode, `$$`/`$x=`/`$I`/
//!   `$G`/`$#`/`$X`/`$H`, soft limits raising `ALARM:2` (after a controlled stop when in a cycle), and
//!   injected faults.
//! - [`Emulator`]: runs a controller on a pseudo-terminal in its own thread, pacing bytes both ways at the
//!   configured baud (10 bits per byte, 8N1) and running motion `time_scale` times faster than real time.
//!
//! Modelled G-code: G0 G1 G2 G3 (offset form `I J K` or radius form `R`, in the G17, G18 or G19 plane) G4 G17 G18 G19 G20 G21 G40
//! G80 G90 G91 G91.1 G93 G94 (inverse time: F on every motion block, a block takes 1/F minutes), work coordinates (G54–G59, G10 L2/L20, G92/G92.1, G43.1/G49, G53, G28/G28.1,
//! G30/G30.1: see `interpreter`), M0 M1 M2 M30 M3 M4 M5 M7 M8 M9, F S T N P L R words; G61 is accepted
//! as GRBL's only path control mode (G61.1 and G64 answer `error:20`). Not modelled: `$SLP` (answered
//! `error:3`), and an `R` arc with no travel in its plane (GRBL's centre would be NaN; answered `error:33`
//! and logged). G38.2–G38.5 probing is modelled against a touch plate (`probe_plate_z_mm`; see `planner`).
//! `$J=` jogging is modelled (state `Jog`, jog cancel 0x85, see `system`). An arc is planned as GRBL's
//! `mc_arc` chords (`$12`), one planner block each, and answered once its last chord is planned, so a long
//! arc runs before its `ok`. Blocks cruise at their feed (no acceleration between them); a feed hold
//! decelerates at `$120`–`$122` along the planned path, and while it is in force (or a jog cancel) nothing
//! is parsed: lines wait in the receive buffer, unanswered, as in GRBL's suspend loop.
//!
//! **Faults** ([`Fault`]) fire once, on the first line carrying line number `N` (or the `k`-th line
//! received): `error` answers `error:code` instead of running the line; `alarm` raises `ALARM:code` as a
//! critical alarm (`[MSG:Reset to continue]`, nothing answered or run until a soft reset) — for code 2 the
//! way a soft limit does, after a controlled stop with the position retained, for any other code at once;
//! `silence` runs the line and then holds all output back for a while; `stall` runs the line and then
//! moves nothing until the receive buffer holds a given number of bytes (the planner fills, lines back up:
//! a full buffer a test can assert without a clock); `disconnect` runs the line and then drops the link — the controller keeps executing
//! what is already complete in its receive buffer and planner (a board with its own power supply), discards
//! a partial line, and opens a new pseudo-terminal after `reconnect_delay`.
//!
//! One file per concept, as in GRBL's own sources:
//! - `controller`: the [`Controller`] state, the realtime bytes and the receive buffer, resets and alarms,
//!   and the main loop that hands complete lines to the rest;
//! - `line_reader`: GRBL's serial line reader (`protocol.c`): comments, spaces, upper case, 79 characters;
//! - `interpreter`: the G-code parser and its error codes (`gcode.c`), on [`program::words`] and
//!   [`program::Modal`](crate::apps::stream::program::Modal);
//! - `planner`: motion blocks, the 15-block planner, synchronised commands and dwells, simulated motion;
//! - `system`: the `$` commands and the settings (`system.c`, `settings.c`);
//! - `status`: the `?` status report (`report.c`);
//! - `fault`: injected faults ([`Fault`]);
//! - `pty`: the [`Emulator`], a controller on a pseudo-terminal in its own thread, with a paced line.
//!
//! [`program::words`]: crate::apps::stream::program::words

mod controller;
mod fault;
mod interpreter;
mod line_reader;
mod planner;
mod pty;
mod status;
mod system;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_suspend;

use std::path::PathBuf;
use std::time::Duration;

pub use controller::Controller;
pub use fault::{Fault, FaultAt, FaultKind, STALL_LIMIT_REPORTS};
pub use pty::Emulator;

/// The version the emulator announces.
pub const VERSION: &str = "1.1h";

/// The build date the emulator announces in `[VER:]` (that of the 1.1h release).
pub const BUILD_DATE: &str = "20190830";

/// Emulator settings.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// Serial speed (bits/s) whose byte rate (baud/10 bytes/s) paces both directions.
    pub baud: u32,
    /// Simulated motion runs this many times faster than real time (1.0 = real time).
    pub time_scale: f64,
    /// Report `Ln` (GRBL built with `USE_LINE_NUMBERS`, as `[OPT:N…]` announces). Off by default: a
    /// stock 1.1h build reports `[OPT:V,15,128]`.
    pub line_numbers: bool,
    /// Accept `M7` (GRBL built with `ENABLE_M7`, `M` in `[OPT:]`). Off by default, as in a stock build,
    /// where `M7` is `error:20`.
    pub enable_m7: bool,
    /// Settings changed from GRBL's defaults at power-up, e.g. `(10, 3.0)` to report `Bf` (the default,
    /// `$10=1`, reports `MPos` and no `Bf`).
    pub settings: Vec<(u16, f64)>,
    /// Injected faults.
    pub faults: Vec<Fault>,
    /// After an injected disconnect, how long until the new pseudo-terminal opens.
    pub reconnect_delay: Duration,
    /// Keep a symbolic link here pointing at the current pseudo-terminal.
    pub link_path: Option<PathBuf>,
    /// A touch plate for G38.x probing: the probe is in contact wherever the tool tip is at or below this
    /// machine Z, mm (`None`: no probe connected, it never touches).
    pub probe_plate_z_mm: Option<f64>,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            baud: 115_200,
            time_scale: 1.0,
            line_numbers: false,
            enable_m7: false,
            settings: Vec::new(),
            faults: Vec::new(),
            reconnect_delay: Duration::from_millis(50),
            link_path: None,
            probe_plate_z_mm: None,
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
