//! Before a job: wake the controller and make sure it is GRBL 1.1 (`$I`, then a status report), learn its
//! receive buffer and whether it reports line numbers, and wait until it is idle (unlocking an alarm only
//! when allowed). Also the small exchanges used around a job: a command sent alone and waited for, a
//! soft reset and its banner, and polling until the controller has settled.

use std::collections::BTreeMap;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::{EndDetection, Session, StreamError};
use crate::apps::stream::protocol::{
    error_text, parse_response, MachineState, Realtime, Response, Status, RX_BUFFER_BYTES,
};

/// What the handshake learned.
#[derive(Debug, Clone)]
pub(super) struct Info {
    pub(super) rx_bytes: usize,
    pub(super) line_numbers: bool,
    pub(super) status: Option<Status>,
    pub(super) critical: bool,
    /// A banner came that no reset of the streamer's caused: the controller started as the port opened.
    pub(super) restarted: bool,
}

/// Where the `$I` probe stands.
#[derive(Debug, Default)]
struct Probe {
    sent: bool,
    got_ver: bool,
    got_opt: bool,
    reset_sent: bool,
    first_status_at: Option<Instant>,
    resend_at: Option<Instant>,
    /// When the probe was first sent.
    started: Option<Instant>,
    /// `[MSG:Reset to continue]` came: the controller is locked in a critical alarm.
    critical_message: bool,
}

/// How long a controller may stay silent to `$I` and `?` before it is taken for one locked in a critical
/// alarm (GRBL 1.1h answers `?` in every other state) and soft-reset once.
const SILENT_LOCKED: Duration = Duration::from_millis(1500);

impl Session<'_> {
    /// Wake the controller and identify it: `\r\n\r\n`, then `$I` (expects `[VER:1.1…]`, `[OPT:…]`, `ok`)
    /// and `?`. A banner in between means the board just reset: the probe is repeated. A controller
    /// locked in a critical alarm answers nothing, or (other builds) only `?` with `Alarm`; either way it is
    /// soft-reset once (motion has stopped in alarm).
    pub(super) fn handshake(&mut self) -> Result<Info, StreamError> {
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        let mut info = Info {
            rx_bytes: RX_BUFFER_BYTES,
            line_numbers: false,
            status: None,
            critical: false,
            restarted: false,
        };
        self.write(b"\r\n\r\n").map_err(|f| self.link_err("wake-up", f))?;
        let mut probe = Probe::default();
        loop {
            if probe.resend_at.is_some_and(|t| Instant::now() >= t) {
                probe.resend_at = None;
                probe.sent = false;
            }
            if self.stop.swap(false, Ordering::SeqCst) {
                return Err(StreamError::Interrupted);
            }
            if !probe.sent {
                self.write(b"$I\n?").map_err(|f| self.link_err("handshake", f))?;
                probe.sent = true;
                probe.started.get_or_insert_with(Instant::now);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(self.not_grbl());
            }
            let line = self
                .read_line((deadline - now).min(Duration::from_millis(100)))
                .map_err(|f| self.link_err("handshake", f))?;
            match line {
                None => self.reset_if_locked(&mut probe, &mut info)?,
                Some(line) => {
                    if self.probe_answer(&line, &mut probe, &mut info)? {
                        return self.first_status(deadline, info);
                    }
                }
            }
        }
    }

    fn not_grbl(&self) -> StreamError {
        StreamError::NotGrbl {
            port: self.port(),
            timeout: self.cfg.handshake_timeout,
            saw: self.saw.clone(),
        }
    }

    /// Nothing came: a controller locked in a critical alarm does not process `$I`; 1.1h answers nothing at
    /// all, not even `?` (a streamer left it so when the user declined the reset after the alarm), and
    /// other builds answer `?` with `Alarm`. After [`SILENT_LOCKED`] of silence, or half a second of
    /// `Alarm` reports, soft-reset it once: in either case motion has stopped.
    fn reset_if_locked(&mut self, probe: &mut Probe, info: &mut Info) -> Result<(), StreamError> {
        if probe.reset_sent {
            return Ok(());
        }
        let alarm_reports = match (probe.first_status_at, &info.status) {
            (Some(t), Some(st)) => st.state == Some(MachineState::Alarm) && t.elapsed() > Duration::from_millis(500),
            _ => false,
        };
        let silent = self.saw.is_empty() && probe.started.is_some_and(|t| t.elapsed() > SILENT_LOCKED);
        // 1.1h prints it half a second after a critical alarm: a streamer that left the controller in alarm
        // just before (the user declined the reset) leaves it to be read by the next one
        let told = probe.critical_message && !probe.got_ver;
        if alarm_reports || silent || told {
            if silent {
                self.observer
                    .note("the controller answers nothing, as GRBL 1.1h in a critical alarm: soft reset");
            }
            self.write(&[Realtime::SoftReset.byte()])
                .map_err(|f| self.link_err("reset", f))?;
            self.reset_sent = true;
            probe.reset_sent = true;
            info.critical = true;
        }
        Ok(())
    }

    /// One line answering the probe. Returns true on `$I`'s own `ok` (after `[VER:]` and `[OPT:]`).
    fn probe_answer(&mut self, line: &str, probe: &mut Probe, info: &mut Info) -> Result<bool, StreamError> {
        match parse_response(line) {
            Response::Banner(_) => {
                info.restarted |= !probe.reset_sent;
                // A (re)start — or a banner printed before the port was opened. If the probe was lost
                // in a reset, ask again, but only once it is clear no answer is coming: a second `$I`
                // whose `ok` arrived during streaming would be taken for a program line's.
                probe.got_ver = false;
                probe.got_opt = false;
                probe.resend_at = Some(Instant::now() + Duration::from_millis(1500));
            }
            Response::Feedback(f) if f.starts_with("VER:") => {
                if !f.starts_with("VER:1.1") {
                    return Err(StreamError::NotGrbl {
                        port: self.port(),
                        timeout: self.cfg.handshake_timeout,
                        saw: format!("[{f}] (GRBL other than 1.1)"),
                    });
                }
                probe.got_ver = true;
                probe.resend_at = None;
            }
            Response::Feedback(f) if f.starts_with("OPT:") => {
                let parts: Vec<&str> = f[4..].split(',').collect();
                info.line_numbers = parts.first().is_some_and(|o| o.contains('N'));
                if let Some(rx) = parts.get(2).and_then(|r| r.parse().ok()) {
                    info.rx_bytes = rx;
                }
                probe.got_opt = true;
            }
            Response::Ok if probe.got_ver && probe.got_opt => return Ok(true),
            Response::Message(m) if m.starts_with("Reset to continue") => probe.critical_message = true,
            Response::Status(st) => {
                probe.first_status_at.get_or_insert_with(Instant::now);
                // GRBL sends `WCO` in the first report after a boot or reset and then only every 10–30
                // reports: keep it from this one
                self.on_status(st.clone());
                info.status = Some(st);
            }
            _ => {}
        }
        Ok(false)
    }

    /// After `$I`'s own ok every earlier probe byte has been answered (answers come in order): one fresh
    /// status report completes the handshake.
    fn first_status(&mut self, deadline: Instant, mut info: Info) -> Result<Info, StreamError> {
        self.write(b"?").map_err(|f| self.link_err("handshake", f))?;
        loop {
            let now = Instant::now();
            if now >= deadline {
                return Err(self.not_grbl());
            }
            if let Some(l) = self
                .read_line(deadline - now)
                .map_err(|f| self.link_err("handshake", f))?
            {
                if let Response::Status(st) = parse_response(&l) {
                    self.on_status(st.clone());
                    info.status = Some(st);
                    return Ok(info);
                }
            }
        }
    }

    /// Read the controller's settings (`$$`) and decide from them and `$I` how the end of the job is read:
    /// `Ln` when the build reports line numbers and blocks are numbered, `Bf` when `$10` asks for it, else
    /// Idle at the end point. Nothing is changed on the controller. A controller that does not list its
    /// settings (busy, or not answering) is taken as a stock one, and the user is told.
    pub(super) fn read_settings(&mut self, info: &Info) {
        let bf_reported = info.status.as_ref().is_some_and(|st| st.planner_free.is_some());
        match self.settings_listing() {
            Ok(settings) => self.settings = settings,
            Err(e) => self.observer.note(&format!("could not read the settings ($$): {e}")),
        }
        let mask = self.settings.get(&10).map(|&v| v as u32);
        self.end_detection = if self.line_numbers {
            EndDetection::LineNumbers
        } else if mask.map_or(bf_reported, |m| m & 2 == 2) {
            EndDetection::PlannerBlocks
        } else {
            EndDetection::IdleAtEndPoint
        };
    }

    /// The program's header asks for GRBL's arc tolerance `$12` at most `T` (the chords its verdict's
    /// simulation cut, `Program::arc_tolerance_asked_mm`): a controller set coarser cuts every arc further
    /// inside than the verdict saw (docs/MACHINE.md §3.1), so it is refused before a line is sent, unless
    /// accepted (`Config::accept_coarser_arcs`, then noted). A controller whose `$$` did not give `$12` is
    /// refused alike: nothing says what it will cut.
    pub(super) fn require_arc_tolerance(&mut self) -> Result<(), StreamError> {
        let Some(want) = self.program.arc_tolerance_asked_mm() else {
            return Ok(());
        };
        let have = self.settings.get(&12).copied();
        if have.is_some_and(|h| h <= want * (1.0 + 1e-9)) {
            return Ok(());
        }
        let what = format!(
            "the program was simulated with GRBL's arc tolerance $12 = {want} mm, and the controller's {}: its chords would stand further inside every arc than the verdict saw. Send `$12={want}` (a setting GRBL keeps across restarts), or stream with --accept-coarser-arcs",
            match have {
                Some(h) => format!("$12 is {h} mm"),
                None => "$12 could not be read ($$)".to_string(),
            }
        );
        if self.cfg.accept_coarser_arcs {
            self.observer.note(&format!("accepted: {what}"));
            return Ok(());
        }
        Err(StreamError::Setting {
            port: self.port(),
            what,
        })
    }

    /// `$$`, sent alone: every `$n=value` line up to its `ok`.
    fn settings_listing(&mut self) -> Result<BTreeMap<u16, f64>, String> {
        self.write(b"$$\n").map_err(|f| format!("{f:?}"))?;
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        let mut out = BTreeMap::new();
        while Instant::now() < deadline {
            let Some(l) = self
                .read_line(Duration::from_millis(100))
                .map_err(|f| format!("{f:?}"))?
            else {
                continue;
            };
            match parse_response(&l) {
                Response::Setting(n, v) => {
                    if let Ok(v) = v.parse() {
                        out.insert(n, v);
                    }
                }
                Response::Ok => return Ok(out),
                Response::Error(c) => return Err(format!("error:{c} ({})", error_text(c))),
                Response::Status(st) => self.on_status(st),
                _ => {}
            }
        }
        Err("no answer".into())
    }

    /// The controller must be idle to start; in alarm it is unlocked only when allowed.
    pub(super) fn require_idle(&mut self, info: &Info, may_unlock: bool) -> Result<(), StreamError> {
        let state = info.status.as_ref().and_then(|s| s.state);
        match state {
            Some(MachineState::Idle) => Ok(()),
            Some(MachineState::Alarm) if may_unlock => {
                self.observer.note("controller in alarm: unlocking ($X)");
                self.command_alone("$X")
            }
            Some(MachineState::Alarm) => Err(StreamError::InAlarm {
                port: self.port(),
                detail: if info.critical {
                    " (it needed a reset)".into()
                } else {
                    String::new()
                },
            }),
            Some(MachineState::Run | MachineState::Hold { .. } | MachineState::Jog) => {
                let st = self.settled_status()?;
                if st.state == Some(MachineState::Idle) {
                    Ok(())
                } else {
                    Err(StreamError::Timeout {
                        port: self.port(),
                        what: format!(
                            "controller is {} and must be Idle to start",
                            st.state.map_or("unknown".into(), |s| s.to_string())
                        ),
                    })
                }
            }
            other => Err(StreamError::Timeout {
                port: self.port(),
                what: format!(
                    "controller is {} and must be Idle to start",
                    other.map_or("in an unknown state".into(), |s| s.to_string())
                ),
            }),
        }
    }

    /// Send one line alone and wait for its `ok` (handshake-time commands).
    pub(super) fn command_alone(&mut self, cmd: &str) -> Result<(), StreamError> {
        self.write(format!("{cmd}\n").as_bytes())
            .map_err(|f| self.link_err(cmd, f))?;
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        while Instant::now() < deadline {
            let line = self
                .read_line(Duration::from_millis(100))
                .map_err(|f| self.link_err(cmd, f))?;
            if let Some(l) = line {
                match parse_response(&l) {
                    Response::Ok => return Ok(()),
                    Response::Error(c) => {
                        return Err(StreamError::Timeout {
                            port: self.port(),
                            what: format!("`{cmd}` answered error:{c} ({})", error_text(c)),
                        })
                    }
                    Response::Status(st) => self.on_status(st),
                    _ => {}
                }
            }
        }
        Err(StreamError::Timeout {
            port: self.port(),
            what: format!("no answer to `{cmd}`"),
        })
    }

    /// Ask for one status report (`?`) and read until it arrives (taken in by `on_status`) or `wait` has
    /// passed; whether it arrived.
    fn request_status(&mut self, wait: Duration) -> Result<bool, StreamError> {
        let seq = self.status_seq;
        self.write(b"?").map_err(|f| self.link_err("status", f))?;
        let asked = Instant::now();
        while self.status_seq == seq && asked.elapsed() < wait {
            if let Some(l) = self
                .read_line(Duration::from_millis(50))
                .map_err(|f| self.link_err("status", f))?
            {
                if let Response::Status(st) = parse_response(&l) {
                    self.on_status(st);
                }
            }
        }
        Ok(self.status_seq != seq)
    }

    /// Poll until the controller is neither running nor holding (bounded by `settle_timeout`).
    pub(super) fn settled_status(&mut self) -> Result<Status, StreamError> {
        let deadline = Instant::now() + self.cfg.settle_timeout;
        loop {
            let fresh = self.request_status(Duration::from_secs(2))?;
            if let Some(st) = self.status.clone() {
                let busy = matches!(
                    st.state,
                    Some(MachineState::Run | MachineState::Jog | MachineState::Home)
                ) || matches!(st.state, Some(MachineState::Hold { sub: 1 }))
                    || (st.state == Some(MachineState::Idle) && st.line.is_some());
                if !busy && fresh {
                    return Ok(st);
                }
            }
            if Instant::now() >= deadline {
                return Err(StreamError::Timeout {
                    port: self.port(),
                    what: format!("controller still busy after {:?}", self.cfg.settle_timeout),
                });
            }
            std::thread::sleep(self.cfg.status_interval.max(Duration::from_millis(200)));
        }
    }

    /// Make sure the work offset is known before a position is read as work coordinates: a controller that
    /// reports `MPos` sends `WCO` only every 10–30 reports, so ask (at most 32 reports, 50 ms apart) until one
    /// carries it. `Err` when none does: no work position can be trusted then.
    pub(super) fn ensure_wco(&mut self) -> Result<(), StreamError> {
        let wpos = self.status.as_ref().is_some_and(|s| s.wpos.is_some());
        for _ in 0..32 {
            if self.wco_seen || wpos {
                return Ok(());
            }
            self.request_status(Duration::from_secs(1))?;
            std::thread::sleep(Duration::from_millis(50));
        }
        Err(StreamError::Timeout {
            port: self.port(),
            what: "the controller reported no work offset (WCO) in 32 status reports, so its machine position \
                   cannot be read as work coordinates"
                .into(),
        })
    }

    /// Wait for the banner that follows a reset.
    pub(super) fn wait_banner(&mut self) -> Result<(), StreamError> {
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        while Instant::now() < deadline {
            if let Some(l) = self
                .read_line(Duration::from_millis(100))
                .map_err(|f| self.link_err("reset", f))?
            {
                if matches!(parse_response(&l), Response::Banner(_)) {
                    return Ok(());
                }
            }
        }
        Err(StreamError::Timeout {
            port: self.port(),
            what: "no banner after reset".into(),
        })
    }

    /// Soft reset (Ctrl-X) and wait for the banner.
    pub(super) fn reset_and_wait_banner(&mut self) -> Result<(), StreamError> {
        self.write(&[Realtime::SoftReset.byte()])
            .map_err(|f| self.link_err("reset", f))?;
        self.reset_sent = true;
        self.wait_banner()
    }
}
