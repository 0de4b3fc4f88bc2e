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

/// What the check run saw: how many lines it sent, the lines rejected, and the alarm it stopped at, if any.
type Checked = (usize, Problems, Option<(usize, String)>);

impl Session<'_> {
    /// The `$C` check run: every line parsed by GRBL without moving; errors collected.
    pub(super) fn check_run(&mut self) -> Result<(), StreamError> {
        self.command_alone("$C")?;
        let (checked, mut problems, alarm) = self.check_lines()?;
        if let Some(a) = alarm {
            problems.push(a);
            self.reset_and_wait_banner()?;
        } else {
            // `$C` again leaves check mode with a soft reset (banner follows).
            self.command_alone("$C")?;
            self.wait_banner()?;
        }
        self.observer.check_result(&result_line(checked, &problems));
        if problems.is_empty() {
            Ok(())
        } else {
            Err(StreamError::CheckFailed {
                path: self.program.path.clone(),
                problems,
            })
        }
    }

    /// Stream the program's G-code lines in check mode; returns how many there are, the rejected lines and,
    /// if check mode raised an alarm, the line it came at (the stream stops there).
    fn check_lines(&mut self) -> Result<Checked, StreamError> {
        let mut problems = Vec::new();
        let mut q: VecDeque<(usize, String)> = self
            .program
            .sendable()
            .filter(|l| l.kind == LineKind::Gcode)
            .map(|l| (l.number, l.wire_text(self.cfg.number_lines)))
            .collect();
        let checked = q.len();
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
                    return Ok((checked, problems, Some((n, format!("ALARM:{c} ({})", alarm_text(c))))));
                }
                _ => {}
            }
        }
        Ok((checked, problems, None))
    }
}

/// The check run's result in one line: `check passed: 4 lines, no error`, or the first line it failed at
/// with GRBL's answer, how many more failed, and that nothing was run.
fn result_line(checked: usize, problems: &Problems) -> String {
    let lines = if checked == 1 { "line" } else { "lines" };
    match problems.iter().min_by_key(|(n, _)| *n) {
        None => format!("check passed: {checked} {lines}, no error"),
        Some((n, what)) => {
            let more = match problems.len() - 1 {
                0 => String::new(),
                1 => ", and 1 more line".to_string(),
                k => format!(", and {k} more lines"),
            };
            format!("check failed at line {n}: {what}{more}; nothing was run")
        }
    }
}

impl<T: Clone> Counter<T> {
    /// An empty counter with the same capacity.
    fn clone_empty<U: Clone>(&self) -> Counter<U> {
        Counter::new(self.capacity() + 1)
    }
}
