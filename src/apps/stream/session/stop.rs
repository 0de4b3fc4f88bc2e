//! The safe stop after a fault: feed hold (unless an alarm already stopped motion), wait for a stopped
//! state, soft reset so nothing buffered runs, read where motion stopped, work out which planned lines ran
//! (`locate`), and journal the stop. A disconnect skips the controller part: what ran is found on resume,
//! from the position the controller then reports.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::{
    locate, record_located, Evidence, Fault, Located, Outcome, Session, StopReason, StopReport, StreamError, Tag,
};
use crate::apps::stream::journal::Record;
use crate::apps::stream::program::Line;
use crate::apps::stream::protocol::{alarm_text, error_text, parse_response, MachineState, Realtime, Response, Status};

impl Session<'_> {
    /// Stop safely after `fault` and find out what ran, from evidence only.
    pub(super) fn safe_stop(&mut self, fault: Fault) -> Result<Outcome, StreamError> {
        let (reason, mut line, mut message) = self.describe(&fault);
        let mut located = false;
        let mut retained = false;
        if !matches!(fault, Fault::Disconnect(_)) {
            let (stopped, after, note) = self.hold_and_reset(&fault);
            if let Some(n) = note {
                message += &format!("; {n}");
            }
            retained = match &fault {
                Fault::Alarm(c) => *c == 2,
                _ => stopped
                    .as_ref()
                    .is_some_and(|st| matches!(st.state, Some(MachineState::Hold { sub: 0 } | MachineState::Idle))),
            };
            located = self.locate_stop(stopped.as_ref(), after.as_ref(), &mut line, &mut message)?;
        }
        if let Some(j) = self.journal.as_mut() {
            j.record_synced(&Record::Stop {
                reason: match reason {
                    StopReason::Error(_) => "error",
                    StopReason::Alarm(_) => "alarm",
                    StopReason::User => "user",
                    StopReason::Disconnect => "disconnect",
                    StopReason::Protocol => "protocol",
                }
                .into(),
                line,
                message: message.clone(),
                located,
                position_retained: retained,
            })?;
        }
        let resume_line = self
            .program
            .sendable()
            .map(|l| l.number)
            .find(|n| !self.executed.contains(n));
        Ok(Outcome::Stopped(
            StopReport {
                reason,
                line,
                message,
                located,
                lines_done: self.executed.len(),
                resume_line,
            },
            self.stats.clone(),
        ))
    }

    /// Why the run stops, the line concerned and the message for the user.
    fn describe(&self, fault: &Fault) -> (StopReason, Option<usize>, String) {
        match fault {
            Fault::Error { line, code } => (
                StopReason::Error(*code),
                *line,
                format!(
                    "error:{code} ({}){}",
                    error_text(*code),
                    line.and_then(|n| self.program.line(n)).map_or(
                        " in a resume approach line".to_string(),
                        |l| format!(" in `{}`", l.source.trim())
                    )
                ),
            ),
            Fault::Alarm(code) => (
                StopReason::Alarm(*code),
                self.counter.pending().find_map(|t| match t {
                    Tag::Line(n) => Some(*n),
                    Tag::Synthetic => None,
                }),
                format!("ALARM:{code} ({}){}", alarm_text(*code), alarm_advice(*code)),
            ),
            Fault::User => (StopReason::User, None, "stopped by the user (Ctrl-C)".to_string()),
            Fault::Disconnect(m) => (StopReason::Disconnect, None, format!("link lost: {m}")),
            Fault::Protocol(m) => (StopReason::Protocol, None, m.clone()),
        }
    }

    /// From the stopped status (`Ln`) and the position after the reset, decide which planned lines ran and
    /// journal it. Returns whether that is known; if not, says why in `message`. Names the line concerned
    /// in `line` when the fault did not. The empty planner after the reset is no evidence: only `Ln` and the
    /// position are.
    fn locate_stop(
        &mut self,
        stopped: Option<&Status>,
        after: Option<&Status>,
        line: &mut Option<usize>,
        message: &mut String,
    ) -> Result<bool, StreamError> {
        let ln = stopped.and_then(|s| s.line);
        let p = after.or(stopped).and_then(|s| self.work_position(s));
        // Only planned lines (answered `ok`) can have run — and the oldest unanswered one when GRBL answers it
        // after its motion (an arc it was still planning chord by chord, a move ending the program): the
        // rest were flushed by the reset or, at an alarm, never parsed.
        let candidates: Vec<usize> = self.planned.iter().copied().chain(self.unanswered_running).collect();
        let Some(p) = p else {
            *message += "; the controller reported no position";
            return Ok(false);
        };
        let moved = self
            .executed
            .iter()
            .any(|&n| self.program.line(n).is_some_and(|l| l.moves));
        let ev = Evidence {
            ln,
            position: p,
            origin: if moved { None } else { self.origin },
            arc_tolerance_mm: self.arc_tolerance_mm(),
            at_rest: false,
        };
        let loc: Located = match locate(self.program, &candidates, &ev, self.cfg.position_tolerance_mm) {
            Ok(loc) => loc,
            Err(e) => {
                *message += &format!("; cannot tell which lines ran: {e}");
                return Ok(false);
            }
        };
        if let Some(why) = &loc.ambiguous {
            *message += &format!("; {why}");
        }
        if line.is_none() {
            *line = loc.partial.map(|x| x.0).or_else(|| loc.executed.last().copied());
        }
        self.planned.clear();
        for n in &loc.executed {
            self.executed.insert(*n);
        }
        if let Some(j) = self.journal.as_mut() {
            record_located(j, &loc)?;
        }
        Ok(true)
    }

    /// Feed hold (unless an alarm already stopped motion), wait for a stopped state, then soft reset so
    /// nothing buffered runs — also when the hold did not complete in time or a second Ctrl-C came, since a
    /// machine that may still be moving must be stopped. Returns the status seen stopped before the reset
    /// (none at an alarm: a critical alarm answers no `?` until reset), one after it, and a note for the
    /// user.
    fn hold_and_reset(&mut self, fault: &Fault) -> (Option<Status>, Option<Status>, Option<String>) {
        let alarm = matches!(fault, Fault::Alarm(_));
        let mut notes: Vec<String> = Vec::new();
        let mut stopped = None;
        // At an alarm motion has stopped, and a critical one makes GRBL serve nothing but the reset: no
        // hold, no polling.
        if !alarm {
            if let Err(e) = self.write(&[Realtime::FeedHold.byte()]) {
                return (None, None, Some(format!("feed hold not sent: {e:?}")));
            }
            match self.wait_stopped() {
                Ok(Some(st)) => stopped = Some(st),
                Ok(None) => notes.push("second Ctrl-C: reset at once, while the machine may still move".into()),
                Err(e) => notes.push(format!("{e}; resetting to stop it")),
            }
        }
        if let Fault::Alarm(code) = fault {
            let what = format!("ALARM:{code} ({}){}", alarm_text(*code), alarm_advice(*code));
            if !self.observer.reset_after_alarm(&what) {
                return (
                    None,
                    None,
                    Some("left in alarm, as asked: nothing was reset or sent after the alarm, and the controller answers nothing until it is reset (Ctrl-X); `--resume` resets it and reads where motion stopped".into()),
                );
            }
        }
        self.reset_sent = true;
        let critical = matches!(fault, Fault::Alarm(1 | 2));
        if let Err(e) = self.reset_flushing(alarm, critical) {
            notes.push(e);
            return (stopped, None, Some(notes.join("; ")));
        }
        self.unanswered_running = match self.counter.pending().next() {
            Some(Tag::Line(n)) => {
                Some(*n).filter(|&n| self.program.line(n).is_some_and(Line::answered_after_its_motion))
            }
            _ => None,
        };
        self.counter.flush();
        let after = match self.status_after_reset() {
            Ok(a) => a,
            Err(e) => {
                notes.push(e);
                None
            }
        };
        (stopped, after, (!notes.is_empty()).then(|| notes.join("; ")))
    }

    /// Poll until a report (newer than the fault) shows motion stopped: `Hold:0`, `Idle` or `Alarm`.
    /// `Ok(None)`: the user pressed Ctrl-C again and wants the reset now.
    fn wait_stopped(&mut self) -> Result<Option<Status>, String> {
        let seq0 = self.status_seq;
        self.next_poll = Instant::now();
        let deadline = Instant::now() + self.cfg.hold_timeout;
        while Instant::now() < deadline {
            if self.stop.swap(false, Ordering::SeqCst) {
                return Ok(None);
            }
            self.maybe_poll().map_err(|e| format!("{e:?}"))?;
            let wait = self
                .next_poll
                .saturating_duration_since(Instant::now())
                .min(Duration::from_millis(50));
            if let Some(l) = self.read_line(wait).map_err(|e| format!("{e:?}"))? {
                match parse_response(&l) {
                    Response::Ok => self.late_answer(None),
                    Response::Error(code) => self.late_answer(Some(code)),
                    Response::Status(st) => {
                        let s = st.state;
                        self.on_status(st.clone());
                        if self.status_seq > seq0
                            && matches!(
                                s,
                                Some(MachineState::Hold { sub: 0 } | MachineState::Idle | MachineState::Alarm)
                            )
                        {
                            return Ok(Some(st));
                        }
                    }
                    _ => {}
                }
            }
        }
        Err(format!("motion did not stop within {:?}", self.cfg.hold_timeout))
    }

    /// Flush GRBL's receive buffer and planner with a soft reset — nothing more may run — and wait for
    /// the banner. Answers that arrive meanwhile are credited to the lines in flight, except after an alarm:
    /// the locked controller parsed nothing, and the one `ok` 1.1h sends on its reset answers no line.
    ///
    /// After a critical alarm (`ALARM:1`, `ALARM:2`) GRBL 1.1h is deaf to a reset for half a second: it
    /// reports the alarm, waits in `delay_ms(500)`, prints `[MSG:Reset to continue]`, clears any reset that
    /// came meanwhile and only then waits for one. So the reset goes out once that message is seen (or after
    /// [`CRITICAL_MESSAGE_WAIT`]), and is sent again every [`RESET_RESEND`] until the banner comes.
    fn reset_flushing(&mut self, after_alarm: bool, critical: bool) -> Result<(), String> {
        if critical {
            self.await_reset_to_continue()?;
        }
        self.write(&[Realtime::SoftReset.byte()])
            .map_err(|e| format!("{e:?}"))?;
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        let mut resend = Instant::now() + RESET_RESEND;
        let mut resets = 1;
        while Instant::now() < deadline {
            if Instant::now() >= resend {
                self.write(&[Realtime::SoftReset.byte()])
                    .map_err(|e| format!("{e:?}"))?;
                resend = Instant::now() + RESET_RESEND;
                resets += 1;
            }
            if let Some(l) = self
                .read_line(Duration::from_millis(50))
                .map_err(|e| format!("{e:?}"))?
            {
                match parse_response(&l) {
                    Response::Ok if after_alarm => self.observer.note("controller: `ok` on the reset (ignored)"),
                    Response::Ok => self.late_answer(None),
                    Response::Error(code) if !after_alarm => self.late_answer(Some(code)),
                    Response::Banner(_) => {
                        if resets > 1 {
                            self.observer
                                .note(&format!("the controller took the soft reset after {resets} tries"));
                        }
                        return Ok(());
                    }
                    Response::Status(st) => self.on_status(st),
                    _ => {}
                }
            }
        }
        Err(format!(
            "no banner after {resets} soft resets in {:?}",
            self.cfg.handshake_timeout
        ))
    }

    /// Wait (at most [`CRITICAL_MESSAGE_WAIT`]) for `[MSG:Reset to continue]`, GRBL's word that it now
    /// listens for the reset after a critical alarm.
    fn await_reset_to_continue(&mut self) -> Result<(), String> {
        let until = Instant::now() + CRITICAL_MESSAGE_WAIT;
        while Instant::now() < until {
            if let Some(l) = self
                .read_line(Duration::from_millis(50))
                .map_err(|e| format!("{e:?}"))?
            {
                if let Response::Message(m) = parse_response(&l) {
                    if m.starts_with("Reset to continue") {
                        return Ok(());
                    }
                }
            }
        }
        Ok(())
    }

    /// One fresh report after the reset: the position where everything stopped.
    fn status_after_reset(&mut self) -> Result<Option<Status>, String> {
        let seq = self.status_seq;
        let _ = self.write(&[Realtime::Status.byte()]);
        let deadline = Instant::now() + Duration::from_secs(2);
        while self.status_seq == seq && Instant::now() < deadline {
            if let Some(l) = self
                .read_line(Duration::from_millis(50))
                .map_err(|e| format!("{e:?}"))?
            {
                if let Response::Status(st) = parse_response(&l) {
                    self.on_status(st);
                }
            }
        }
        Ok((self.status_seq != seq).then(|| self.status.clone()).flatten())
    }

    /// An `ok` (`code` = None) or `error:code` that arrives while stopping: credit it to the oldest line in
    /// flight and journal it best-effort (the stop itself must not fail on the journal).
    fn late_answer(&mut self, code: Option<u16>) {
        if let Some(Tag::Line(n)) = self.counter.answered() {
            match code {
                None => {
                    let _ = self.journal(&Record::Ok { line: n });
                    self.planned_ok(n);
                }
                Some(code) => {
                    let _ = self.journal(&Record::Error { line: n, code });
                    self.errors.insert(n);
                }
            }
        }
    }
}

/// How long to wait after a critical alarm for `[MSG:Reset to continue]` before resetting anyway (1.1h prints
/// it 500 ms after the alarm).
const CRITICAL_MESSAGE_WAIT: Duration = Duration::from_millis(1500);

/// How often the soft reset is sent again until the banner answers it (longer than 1.1h's deaf half second,
/// so a second try always lands after it).
const RESET_RESEND: Duration = Duration::from_millis(700);

/// What to check after an alarm, for the user.
fn alarm_advice(code: u16) -> &'static str {
    match code {
        1 => {
            "; a limit switch tripped and the position is lost: check the switch and free the axis, then home \
              ($H) before resuming with --unlock"
        }
        2 => {
            "; a move would leave the machine's travel ($130-$132 from the homed origin): check the work \
              offset (G54/WCO) and the program's extent; the position is kept"
        }
        3 => {
            "; the controller was reset while moving and the position may be lost: home ($H) before resuming \
              with --unlock"
        }
        _ => "",
    }
}
