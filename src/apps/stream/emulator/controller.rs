//! The controller itself, with no I/O and no clock: its state (idle, running, alarm, check mode; feed
//! hold), the 128-byte receive buffer and the realtime bytes that bypass it, soft reset and alarms, and
//! GRBL's main loop, which serves the line waiting on the planner and then reads the next lines out of the
//! receive buffer and hands them to the `$` commands or the G-code interpreter.

use std::collections::{BTreeMap, VecDeque};

use super::fault::{Fault, FaultKind};
use super::line_reader::{LineReader, ReadLine};
use super::planner::{Block, Served, Waiting};
use super::system::default_settings;
use super::{EmulatorConfig, EmulatorLog, VERSION};
use crate::apps::stream::program::Modal;
use crate::apps::stream::protocol::{Realtime, RX_BUFFER_BYTES};
use crate::gcode::interp::Interpreter;
use crate::gcode::Dialect;

/// GRBL 1.1h's `report_alarm_message` waits this long after printing a critical alarm (`delay_ms(500)`),
/// then clears a reset that came meanwhile, s.
pub const CRITICAL_ALARM_DELAY_S: f64 = 0.5;

/// GRBL's machine state, as far as it is modelled (a feed hold is the separate `hold` flag).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum State {
    Idle,
    Run,
    Alarm,
    Check,
}

/// The virtual GRBL 1.1 controller, with no I/O: feed it bytes ([`Controller::receive`]), advance
/// simulated time ([`Controller::advance`]), take what it sends ([`Controller::take_output`]).
#[derive(Debug)]
pub struct Controller {
    pub(super) line_numbers: bool,
    pub(super) settings: BTreeMap<u16, f64>,
    pub(super) state: State,
    /// Waiting for a soft reset after a critical alarm.
    pub(super) critical: bool,
    /// After a critical alarm, the simulated time at which 1.1h prints `[MSG:Reset to continue]`: until then
    /// it sits in `report_alarm_message`'s `delay_ms(500)` and a reset that arrives is cleared unheard.
    pub(super) deaf_until_s: Option<f64>,
    /// A soft limit came during a cycle: the machine is coming to a controlled stop (a feed hold), after
    /// which `ALARM:2` locks the controller (GRBL's `limits_soft_check`).
    pub(super) soft_limit_pending: bool,
    /// A feed hold is in force (`Hold:1` while decelerating, `Hold:0` once stopped).
    pub(super) hold: bool,
    /// Simulated seconds of deceleration left in the current feed hold (0: the hold is complete).
    pub(super) decel_left_s: f64,
    /// The whole deceleration of the current hold, s (its speed falls linearly over this time).
    pub(super) decel_total_s: f64,
    /// Output is held back (not lost) until this simulated time: an injected silence.
    pub(super) mute_until_s: f64,
    /// An injected stall: no motion until the receive buffer holds this many bytes, or until this many
    /// more status reports have been answered.
    pub(super) stall: Option<(usize, usize)>,
    pub(super) rx: VecDeque<u8>,
    pub(super) reader: LineReader,
    pub(super) waiting: Option<Waiting>,
    pub(super) planner: VecDeque<Block>,
    pub(super) pos: [f64; 3],
    /// The G-code interpreter: the parser's modal state and position (machine mm), the work coordinate
    /// systems G54–G59 and G28/G30 positions (kept across resets: GRBL keeps them in EEPROM), the G92 and
    /// G43.1 offsets and G93 (a reset clears them).
    pub(super) interp: Interpreter,
    /// The planner holds `$J=` jog motion (state `Jog`).
    pub(super) jogging: bool,
    /// A jog cancel (0x85, or `!` while jogging) is decelerating; the jog is flushed once stopped.
    pub(super) jog_cancel: bool,
    pub(super) out: Vec<u8>,
    pub(super) log: EmulatorLog,
    pub(super) faults: Vec<(Fault, bool)>,
    pub(super) received: usize,
    pub(super) disconnect: bool,
    pub(super) feed_override: u8,
    pub(super) sim_time_s: f64,
    pub(super) wco_counter: u8,
    pub(super) ovr_pending: bool,
    /// The touch plate's machine Z (see `EmulatorConfig::probe_plate_z_mm`).
    pub(super) probe_plate_z_mm: Option<f64>,
    /// A probing cycle in progress: the fraction of its block where the contact changes, and whether it
    /// has (GRBL's `sys_probe_state`).
    pub(super) probing: Option<Probing>,
    /// The last probe position, machine mm, and whether it succeeded (`[PRB:]`; a reset clears both).
    pub(super) probe_result: ([f64; 3], bool),
}

/// A G38.x cycle in progress.
#[derive(Debug, Clone, Copy)]
pub(super) struct Probing {
    /// Fraction of the probing block at which the contact changes (`None`: it never does).
    pub(super) trigger_at: Option<f64>,
    /// The contact changed.
    pub(super) hit: bool,
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
            deaf_until_s: None,
            soft_limit_pending: false,
            hold: false,
            decel_left_s: 0.0,
            decel_total_s: 0.0,
            mute_until_s: 0.0,
            stall: None,
            rx: VecDeque::with_capacity(RX_BUFFER_BYTES),
            reader: LineReader::new(),
            waiting: None,
            planner: VecDeque::new(),
            pos: [0.0; 3],
            interp: Interpreter {
                m7: cfg.enable_m7,
                ..Interpreter::new(Dialect::Grbl, Modal::default(), [0.0; 3])
            },
            jogging: false,
            jog_cancel: false,
            out: Vec::new(),
            log: EmulatorLog::default(),
            faults: cfg.faults.iter().map(|&f| (f, false)).collect(),
            received: 0,
            disconnect: false,
            feed_override: 100,
            sim_time_s: 0.0,
            wco_counter: 0,
            ovr_pending: false,
            probe_plate_z_mm: cfg.probe_plate_z_mm,
            probing: None,
            probe_result: ([0.0; 3], false),
        };
        if c.setting(22) == 1.0 {
            c.state = State::Alarm; // HOMING_INIT_LOCK
        }
        c.banner();
        c
    }

    /// The work coordinate offset `WCO` of the coordinate system `select` with this G92 offset and tool
    /// length offset: work position = machine position − WCO.
    pub(super) fn wco_of(&self, select: usize, g92: [f64; 3], tlo: f64) -> [f64; 3] {
        self.interp.offsets.wco_of(select, g92, tlo)
    }

    /// The machine target of a block's axis words (`None`: the axis stays), in mm once scaled by `k` (25.4
    /// for inches): machine coordinates for G53, else relative to the parser position when `incremental`,
    /// else work coordinates through `wco`. Shared by G-code blocks and `$J=` jogs.
    pub(super) fn axis_target(
        &self,
        axis: [Option<f64>; 3],
        k: f64,
        machine: bool,
        incremental: bool,
        wco: [f64; 3],
    ) -> [f64; 3] {
        let mut target = self.interp.pos;
        for (i, t) in target.iter_mut().enumerate() {
            if let Some(v) = axis[i] {
                *t = if machine {
                    v * k
                } else if incremental {
                    *t + v * k
                } else {
                    v * k + wco[i]
                };
            }
        }
        target
    }

    /// Soft limits are on (`$20=1`) and machine position `t` lies outside the travel `[−$13x, 0]`.
    pub(super) fn beyond_soft_limits(&self, t: [f64; 3]) -> bool {
        self.setting(20) == 1.0 && (0..3).any(|i| t[i] > 0.0 || t[i] < -self.setting(130 + i as u16))
    }

    /// The current `WCO`.
    pub(super) fn wco(&self) -> [f64; 3] {
        self.wco_of(
            self.interp.offsets.select,
            self.interp.offsets.g92,
            self.interp.offsets.tlo,
        )
    }

    /// Setting `$n` (0 when unknown).
    pub(super) fn setting(&self, n: u16) -> f64 {
        self.settings.get(&n).copied().unwrap_or(0.0)
    }

    /// Send one line to the host.
    pub(super) fn say(&mut self, s: &str) {
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

    /// Bytes to send to the host (drained). During an injected silence nothing is released: the bytes
    /// wait, as they would in a stalled controller, and go out when the silence ends.
    pub fn take_output(&mut self) -> Vec<u8> {
        if self.sim_time_s < self.mute_until_s {
            return Vec::new();
        }
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
        self.reader.clear();
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
            // A controller locked by a critical alarm serves nothing but the reset (`protocol.c`).
            b'?' if self.critical => {}
            b'?' => self.status_report(),
            // GRBL: a feed hold during a jog cancels it
            b'!' | 0x85 if self.jogging => {
                self.feed_hold();
                self.jog_cancel = true;
            }
            0x85 => {}
            b'!' => self.feed_hold(),
            b'~' => {
                if self.hold && self.decel_left_s <= 0.0 {
                    self.hold = false;
                }
                if self.state == State::Idle && !self.planner.is_empty() {
                    self.state = State::Run;
                }
            }
            0x18 if self.deaf_until_s.is_some() => self
                .log
                .events
                .push("soft reset ignored: inside 1.1h's half second after a critical alarm".into()),
            0x18 => self.soft_reset(),
            0x90 => self.feed_override = 100,
            0x91 => self.feed_override = (self.feed_override + 10).min(200),
            0x92 => self.feed_override = self.feed_override.saturating_sub(10).max(10),
            0x93 => self.feed_override = (self.feed_override + 1).min(200),
            0x94 => self.feed_override = self.feed_override.saturating_sub(1).max(10),
            b if Realtime::is_realtime(b) => {}
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

    /// `!`: a feed hold. Running, the machine decelerates along the planned path at `$120` (the lowest of
    /// the axes' accelerations, as a conservative stand-in for GRBL's per-block limit) and reports `Hold:1`
    /// until it stops; idle, the hold is complete at once (`Hold:0`), as in GRBL's `protocol.c`.
    fn feed_hold(&mut self) {
        if matches!(self.state, State::Alarm | State::Check) || self.hold {
            return;
        }
        self.hold = true;
        let v = match self.planner.front() {
            Some(b) if self.state == State::Run => self.block_speed_mm_s(b),
            _ => 0.0,
        };
        let a = (120..=122)
            .map(|k| self.setting(k))
            .fold(f64::INFINITY, f64::min)
            .max(1e-6);
        self.decel_total_s = v / a;
        self.decel_left_s = self.decel_total_s;
    }

    /// Ctrl-X: stop, flush the receive buffer and planner, reset the parser, print the banner. As GRBL's
    /// `mc_reset`, the reset raises `ALARM:3` only while motion is executing — a cycle, or a hold still
    /// decelerating; after a completed hold (`Hold:0`) it raises none and the controller comes back Idle.
    /// The line GRBL was executing when the reset came — waiting for planner space, for the planner to empty,
    /// in a dwell or a probe, or the line a critical alarm stopped (the 1.1h PC build was seen to do this) —
    /// returns from the abort and is answered `ok` after any `ALARM:3`, before the banner.
    pub(super) fn soft_reset(&mut self) {
        let executing = self.state == State::Run && (!self.hold || self.decel_left_s > 0.0);
        let moving = executing && !self.planner.is_empty() && !self.critical;
        // a line GRBL was still executing (blocked waiting for planner space, the planner to empty, a dwell
        // or a probe, or locked in a critical alarm) returns from the abort and is answered `ok`
        let answered = self.critical || self.soft_limit_pending || self.waiting.is_some();
        if moving {
            self.say("ALARM:3");
            self.log.events.push("ALARM:3 (reset while in motion)".into());
        }
        if answered {
            self.say("ok");
        }
        self.flush_motion();
        self.stall = None;
        self.rx.clear();
        self.reader.clear();
        self.critical = false;
        self.soft_limit_pending = false;
        self.interp.modal = Modal::default();
        // GRBL's gc_init: G54 selected, the G92 and tool length offsets cleared (G54–G59, G28, G30 are kept)
        self.interp.offsets.select = 0;
        self.interp.offsets.g92 = [0.0; 3];
        self.interp.offsets.tlo = 0.0;
        self.interp.inverse_time = false;
        self.jogging = false;
        self.jog_cancel = false;
        self.feed_override = 100;
        self.probing = None;
        self.probe_result = ([0.0; 3], false);
        if moving {
            self.state = State::Alarm;
        } else if self.state != State::Alarm {
            self.state = State::Idle;
        }
        self.log.events.push("soft reset".into());
        self.wco_counter = 0;
        self.banner();
    }

    /// A target beyond the soft limits (GRBL's `limits_soft_check`): during a cycle a feed hold first brings
    /// the machine to a controlled stop along its path (`Hold:1` meanwhile, the position kept), then the
    /// reset and `ALARM:2`; otherwise `ALARM:2` at once. The line concerned is answered only by the `ok` that
    /// follows the reset.
    pub(super) fn soft_limit(&mut self) {
        self.waiting = None;
        if self.state == State::Run && !self.planner.is_empty() {
            self.feed_hold();
            self.soft_limit_pending = true;
            self.log
                .events
                .push("soft limit: controlled stop before ALARM:2".into());
            if self.decel_left_s <= 0.0 {
                self.soft_limit_pending = false;
                self.alarm(2);
            }
        } else {
            self.alarm(2);
        }
    }

    /// Stop at once and lock with `ALARM:code` until a soft reset (a critical alarm: a hard limit stops the
    /// steppers where they are; a soft limit's controlled stop has already happened).
    pub(super) fn alarm(&mut self, code: u16) {
        // Motion stops here; the planner is only cleared by the reset that ends the lock, so status
        // reports until then still name the block that was executing (`Ln`), as in GRBL.
        self.hold = false;
        self.decel_left_s = 0.0;
        self.waiting = None;
        self.state = State::Alarm;
        self.critical = true;
        self.say(&format!("ALARM:{code}"));
        // `[MSG:Reset to continue]` follows after `report_alarm_message`'s `delay_ms(500)`, which also
        // swallows any reset sent meanwhile ([`Controller::deaf_until_s`])
        self.deaf_until_s = Some(self.sim_time_s + CRITICAL_ALARM_DELAY_S);
        self.log.events.push(format!("ALARM:{code}"));
    }

    /// The half second after a critical alarm is over: 1.1h says it now waits for the reset.
    pub(super) fn end_alarm_delay(&mut self) {
        if self.deaf_until_s.is_some_and(|t| self.sim_time_s >= t) {
            self.deaf_until_s = None;
            self.say("[MSG:Reset to continue]");
        }
    }

    /// An alarm that `$X` or a reset clears and that still answers `?` (a probe failure): `ALARM:code`,
    /// the state Alarm, motion already at rest.
    pub(super) fn alarm_unlockable(&mut self, code: u16) {
        self.state = State::Alarm;
        self.say(&format!("ALARM:{code}"));
        self.log.events.push(format!("ALARM:{code}"));
    }

    /// The probe is in contact with the tool tip at `p` (machine mm).
    pub(super) fn probe_contact(&self, p: [f64; 3]) -> bool {
        self.probe_plate_z_mm.is_some_and(|z| p[2] <= z)
    }

    /// GRBL's main loop: finish what the last line waits for, then read lines from the receive buffer.
    /// Nothing is parsed or planned while a feed hold or jog cancel is in force: GRBL's
    /// `protocol_exec_rt_suspend` keeps the main program waiting until the hold is resumed or reset (lines
    /// sent meanwhile wait in the receive buffer, unanswered).
    pub(super) fn main_loop(&mut self) {
        loop {
            if self.critical || self.hold {
                return;
            }
            match self.serve_waiting() {
                Served::Blocked => return,
                Served::Again => continue,
                Served::Done => {}
            }
            let Some(c) = self.rx.pop_front() else {
                self.start_cycle(); // protocol_auto_cycle_start when the receive buffer is empty
                return;
            };
            if let Some(line) = self.reader.push(c) {
                self.execute_line(line);
            }
        }
    }

    /// A complete line: an overflow or an injected fault answers it, else a `$` command or G-code runs.
    fn execute_line(&mut self, line: ReadLine) {
        let ReadLine { text, overflow } = line;
        if overflow {
            self.say("error:11");
            return;
        }
        if text.is_empty() {
            self.say("ok");
            return;
        }
        self.received += 1;
        self.log.received.push(text.clone());
        let mut disconnect_after = false;
        match self.fire_fault(&text) {
            Some(FaultKind::Error(code)) => {
                self.say(&format!("error:{code}"));
                return;
            }
            // ALARM:2 as the firmware raises it, after a controlled stop; any other code at once
            Some(FaultKind::Alarm(2)) => {
                self.soft_limit();
                return;
            }
            Some(FaultKind::Alarm(code)) => {
                self.alarm(code);
                return;
            }
            Some(FaultKind::Disconnect) => disconnect_after = true,
            Some(FaultKind::Silence(ms)) => self.mute_until_s = self.sim_time_s + f64::from(ms) / 1000.0,
            Some(FaultKind::Stall(bytes)) => {
                self.stall = Some((usize::from(bytes), super::fault::STALL_LIMIT_REPORTS));
            }
            None => {}
        }
        if text.starts_with('$') {
            self.system_command(&text);
        } else if self.state == State::Alarm || self.jogging {
            self.say("error:9"); // G-code is locked in alarm and while jogging
        } else if let Err(code) = self.gcode(&text) {
            self.say(&format!("error:{code}"));
        }
        if disconnect_after {
            self.disconnect = true;
        }
    }
}
