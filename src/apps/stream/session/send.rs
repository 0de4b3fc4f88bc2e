//! Streaming proper: send the queue with character counting (never more than the receive buffer holds,
//! `$` lines alone on an idle machine), journal each line *before* its bytes go out, poll the status, and
//! turn each answer into progress or a fault. A fault ends the loop and hands over to the safe stop.

use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::{Fault, Outcome, Outgoing, Session, StreamError, Tag};
use crate::apps::stream::journal::Record;
use crate::apps::stream::program::Line;
use crate::apps::stream::protocol::{error_text, parse_response, Decision, MachineState, Realtime, Response};

impl Session<'_> {
    /// Stream the queue. Returns when everything executed or after a safe stop.
    pub(super) fn stream(&mut self, queue: Vec<Outgoing>) -> Result<Outcome, StreamError> {
        let mut q: VecDeque<Outgoing> = queue.into();
        // A reset before streaming (the handshake's) flushed nothing of this job's.
        self.reset_sent = false;
        self.started = Instant::now();
        self.last_rx = Instant::now();
        let run = self.stream_loop(&mut q);
        match run {
            Ok(()) => {
                self.stats.end_detection = Some(self.end_detection);
                if let Some(j) = self.journal.as_mut() {
                    j.record_synced(&Record::Complete)?;
                }
                Ok(Outcome::Completed(self.stats.clone()))
            }
            Err(f) => self.safe_stop(f),
        }
    }

    /// Send, read and poll until every line has been answered and is known executed, or a fault.
    fn stream_loop(&mut self, q: &mut VecDeque<Outgoing>) -> Result<(), Fault> {
        loop {
            // Taken, not just read: a second Ctrl-C while stopping then means "reset at once".
            if self.stop.swap(false, Ordering::SeqCst) {
                return Err(Fault::User);
            }
            self.interactive_hold()?;
            self.maybe_poll()?;
            self.send_what_fits(q)?;
            self.all_answered = q.is_empty() && self.counter.outstanding() == 0;
            if self.all_answered {
                if let (Some(a), Some(b)) = (self.first_send, self.last_ack) {
                    self.stats.streaming_time = b.saturating_duration_since(a);
                }
                if self.planned.is_empty() {
                    return Ok(());
                }
            }
            let wait = self
                .next_poll
                .saturating_duration_since(Instant::now())
                .min(Duration::from_millis(50));
            if let Some(l) = self.read_line(wait)? {
                if let Some(f) = self.handle(&l)? {
                    return Err(f);
                }
            }
            if self.last_rx.elapsed() > self.cfg.silence_timeout {
                return Err(Fault::Protocol(format!(
                    "the controller sent nothing for {:?} (no status report, no answer)",
                    self.cfg.silence_timeout
                )));
            }
        }
    }

    /// Act on the user's hold and resume requests: a feed hold (`!`) decelerates the machine along its path
    /// to `Hold:0`, where it waits with the spindle on; streaming goes on into the controller's buffer, and
    /// what executed is still read from the status reports. A cycle start (`~`) resumes. A resume without a
    /// hold of the user's is ignored (a hold from the machine's own button stays the machinist's), except at
    /// the program's own pause (`M0`, as at a tool change): GRBL waits at `Hold:0` for a cycle start, and the
    /// user is told to do what the program asks and resume.
    fn interactive_hold(&mut self) -> Result<(), Fault> {
        if self.hold_request.swap(false, Ordering::SeqCst) && !self.user_hold {
            self.write(&[Realtime::FeedHold.byte()])?;
            self.user_hold = true;
            self.observer
                .note("feed hold: the machine decelerates and waits (SIGUSR2 resumes, Ctrl-C stops the job)");
        }
        let pause = self.program_pause();
        if let Some(n) = pause.filter(|&n| self.pause_noted != Some(n)) {
            self.pause_noted = Some(n);
            self.observer.note(&format!(
                "the program pauses at line {n} (M0): do what its comments before it ask (a tool change: \
                 change the bit, touch off Z again), then resume (`~` or Enter, SIGUSR2); Ctrl-C stops the job"
            ));
        }
        if self.resume_request.swap(false, Ordering::SeqCst) && (self.user_hold || pause.is_some()) {
            self.write(&[Realtime::CycleStart.byte()])?;
            self.user_hold = false;
            self.observer.note("cycle start: resuming");
        }
        Ok(())
    }

    /// The line of the program's pause (`M0`) GRBL is waiting at: the oldest unanswered line holds `M0` and
    /// the last report shows a completed hold.
    fn program_pause(&self) -> Option<usize> {
        let held = self
            .status
            .as_ref()
            .is_some_and(|s| s.state == Some(MachineState::Hold { sub: 0 }));
        match self.counter.pending().next() {
            Some(Tag::Line(n)) if held => self.program.line(*n).is_some_and(Line::pauses).then_some(*n),
            _ => None,
        }
    }

    /// Send queued lines while the receive buffer has room for them (a line sent alone also waits for an
    /// idle machine).
    fn send_what_fits(&mut self, q: &mut VecDeque<Outgoing>) -> Result<(), Fault> {
        while let Some(o) = q.front() {
            let bytes = o.text.len() + 1;
            match self.counter.decide(bytes, o.alone) {
                Decision::Send => {}
                Decision::TooLong { needed } => {
                    return Err(Fault::Protocol(format!(
                        "`{}` needs {needed} bytes, more than the receive buffer",
                        o.text
                    )))
                }
                _ => break,
            }
            if o.alone && !(self.status_after_ack && self.idle()) {
                break; // settings need an idle machine: wait for a status report showing it
            }
            let o = q.pop_front().expect("front exists");
            if let Tag::Line(n) = o.tag {
                self.journal(&Record::Sent { line: n })?;
                self.sent.insert(n);
            }
            let mut wire = o.text.into_bytes();
            wire.push(b'\n');
            self.first_send.get_or_insert_with(Instant::now);
            self.write(&wire)?;
            self.counter.sent(o.tag, bytes, o.alone);
            self.stats.lines_sent += 1;
            self.stats.bytes_sent += bytes;
            self.stats.max_in_flight = self.stats.max_in_flight.max(self.counter.used());
        }
        Ok(())
    }

    /// Handle one received line while streaming; returns a fault when the job must stop.
    fn handle(&mut self, line: &str) -> Result<Option<Fault>, Fault> {
        match parse_response(line) {
            Response::Ok => self.on_ok()?,
            Response::Error(code) => return self.on_error(code),
            Response::Alarm(code) => return Ok(Some(Fault::Alarm(code))),
            Response::Status(st) => self.on_status(st),
            Response::Message(m) => self.observer.note(&format!("controller: {m}")),
            Response::Banner(_) => {
                return Ok(Some(Fault::Protocol(
                    "the controller reset itself during the job".into(),
                )));
            }
            _ => {}
        }
        Ok(None)
    }

    /// `ok`: the oldest line in flight is planned.
    fn on_ok(&mut self) -> Result<(), Fault> {
        let tag = self
            .counter
            .answered()
            .ok_or_else(|| Fault::Protocol("`ok` with no line in flight".into()))?;
        self.last_ack = Some(Instant::now());
        self.ack_seq += 1;
        self.status_after_ack = false;
        self.idle_at_end = 0;
        if let Tag::Line(n) = tag {
            self.journal(&Record::Ok { line: n })?;
            self.planned_ok(n);
        }
        Ok(())
    }

    /// Line `n` was answered `ok`: it is planned. If it is a line GRBL answers only once the planner has
    /// emptied, the answer proves that it and every line before it executed — unless a reset went out,
    /// since a reset cuts the wait short and GRBL still answers `ok`.
    pub(super) fn planned_ok(&mut self, n: usize) {
        self.planned.push_back(n);
        if !self.reset_sent && self.program.line(n).is_some_and(|l| l.synchronises()) {
            let done: Vec<usize> = self.planned.drain(..).collect();
            self.mark_executed(&done);
        }
    }

    /// `error:code`: the oldest line in flight was rejected; the job stops unless told to carry on.
    fn on_error(&mut self, code: u16) -> Result<Option<Fault>, Fault> {
        let tag = self
            .counter
            .answered()
            .ok_or_else(|| Fault::Protocol(format!("`error:{code}` with no line in flight")))?;
        self.last_ack = Some(Instant::now());
        self.status_after_ack = false;
        self.idle_at_end = 0;
        match tag {
            Tag::Line(n) => {
                self.journal(&Record::Error { line: n, code })?;
                self.errors.insert(n);
                if self.cfg.continue_on_error {
                    let src = self.program.line(n).map_or("", |l| l.source.as_str());
                    self.observer.note(&format!(
                        "line {n}: error:{code} ({}) in `{src}`; continuing",
                        error_text(code)
                    ));
                    Ok(None)
                } else {
                    Ok(Some(Fault::Error { line: Some(n), code }))
                }
            }
            Tag::Synthetic => Ok(Some(Fault::Error { line: None, code })),
        }
    }
}
