//! The `$C` check run (`--check`): GRBL parses every line of the program without moving, and every
//! failing line is collected, so that a program with an error is refused before anything moves. The
//! lines are streamed with their own character counter; the answers do not touch the job's state.

use std::collections::VecDeque;
use std::sync::atomic::Ordering;

use super::{Session, StreamError};
use crate::apps::stream::program::LineKind;
use crate::apps::stream::protocol::{alarm_text, error_text, parse_response, Counter, Decision, Realtime, Response};

/// `(line, message)` for each line check mode rejected.
type Problems = Vec<(usize, String)>;

impl Session<'_> {
    /// The `$C` check run: every line parsed by GRBL without moving; errors collected.
    pub(super) fn check_run(&mut self) -> Result<(), StreamError> {
        self.command_alone("$C")?;
        let (mut problems, alarm) = self.check_lines()?;
        if let Some(a) = alarm {
            problems.push(a);
            self.reset_and_wait_banner()?;
        } else {
            // `$C` again leaves check mode with a soft reset (banner follows).
            self.command_alone("$C")?;
            self.wait_banner()?;
        }
        if problems.is_empty() {
            self.observer.note("check mode: no errors");
            Ok(())
        } else {
            Err(StreamError::CheckFailed {
                path: self.program.path.clone(),
                problems,
            })
        }
    }

    /// Stream the program's G-code lines in check mode; returns the rejected lines and, if check mode
    /// raised an alarm, the line it came at (the stream stops there).
    fn check_lines(&mut self) -> Result<(Problems, Option<(usize, String)>), StreamError> {
        let mut problems = Vec::new();
        let mut q: VecDeque<(usize, String)> = self
            .program
            .sendable()
            .filter(|l| l.kind == LineKind::Gcode)
            .map(|l| (l.number, l.wire_text(self.cfg.number_lines)))
            .collect();
        let mut counter: Counter<usize> = self.counter.clone_empty();
        while !q.is_empty() || counter.outstanding() > 0 {
            if self.stop.load(Ordering::SeqCst) {
                let _ = self.write(&[Realtime::SoftReset.byte()]);
                return Err(StreamError::Interrupted);
            }
            while let Some((n, t)) = q.front() {
                if counter.decide(t.len() + 1, false) != Decision::Send {
                    break;
                }
                let (n, t) = (*n, t.clone());
                self.write(format!("{t}\n").as_bytes())
                    .map_err(|f| self.link_err("check mode", f))?;
                counter.sent(n, t.len() + 1, false);
                q.pop_front();
            }
            let l = self
                .read_line(self.cfg.silence_timeout)
                .map_err(|f| self.link_err("check mode", f))?
                .ok_or_else(|| StreamError::Timeout {
                    port: self.port(),
                    what: "no answer in check mode".into(),
                })?;
            match parse_response(&l) {
                Response::Ok => {
                    counter.answered();
                }
                Response::Error(c) => {
                    if let Some(n) = counter.answered() {
                        problems.push((n, format!("error:{c} ({})", error_text(c))));
                    }
                }
                Response::Alarm(c) => {
                    let n = counter.pending().next().copied().unwrap_or(0);
                    return Ok((problems, Some((n, format!("ALARM:{c} ({})", alarm_text(c))))));
                }
                _ => {}
            }
        }
        Ok((problems, None))
    }
}

impl<T: Clone> Counter<T> {
    /// An empty counter with the same capacity.
    fn clone_empty<U: Clone>(&self) -> Counter<U> {
        Counter::new(self.capacity() + 1)
    }
}
