//! Injected faults: an `error:N` instead of running a line, an alarm (`ALARM:2` after a soft limit's
//! controlled stop, any other code at once), a silence, a stalled planner, or a dropped link after the line. Each fires once, on the first line that matches it (see the module
//! documentation of [`emulator`](super) for what each does to the controller).

use super::controller::Controller;
use super::line_reader::leading_line_number;

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
    /// Raise `ALARM:code` as a critical alarm: code 2 as a soft limit does (a controlled stop first, the
    /// position kept), any other at once.
    Alarm(u16),
    /// Run the line, then drop the link.
    Disconnect,
    /// Run the line, then send nothing (answers and reports wait) for this many simulated milliseconds.
    Silence(u32),
    /// Run the line, then move nothing until the receive buffer holds at least this many bytes (or
    /// [`STALL_LIMIT_REPORTS`] status reports have been answered meanwhile, or a reset): the planner fills,
    /// GRBL stops taking lines, and the stream backs up into the receive buffer whatever the speed of
    /// either side — a fill a test can assert without a clock.
    Stall(u16),
}

/// The status reports a [`FaultKind::Stall`] answers before it gives up, so that a streamer that never
/// fills the buffer fails its test instead of hanging it. Counted in the host's own polls, not in time:
/// bytes reach the controller in the order they were written, so a poll it answers comes after every line
/// written before it, and a streamer that writes until the next line does not fit has filled the buffer
/// by its first poll after the stall, however slowly either side runs (50 is 10 s of 5 Hz polls).
pub const STALL_LIMIT_REPORTS: usize = 50;

impl std::str::FromStr for Fault {
    type Err = String;
    /// `N:error[:code]`, `N:alarm[:code]`, `N:disconnect`, `N:silence[:ms]`, `N:stall[:bytes]` (N a line
    /// number `N` word; a silence of at most 65535 ms; a stall until the receive buffer holds `bytes`,
    /// default 100).
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
            Some("silence") => FaultKind::Silence(u32::from(code(5000)?)),
            Some("stall") => FaultKind::Stall(code(100)?),
            _ => {
                return Err(format!(
                    "fault `{s}`: kind must be error, alarm, disconnect, silence or stall"
                ))
            }
        };
        Ok(Fault {
            at: FaultAt::LineNumber(n),
            kind,
        })
    }
}

impl Controller {
    /// The first fault not yet fired that `text` (the `received`-th line) triggers, marked fired and
    /// logged.
    pub(super) fn fire_fault(&mut self, text: &str) -> Option<FaultKind> {
        let n = leading_line_number(text);
        let received = self.received;
        let (f, done) = self.faults.iter_mut().find(|(f, done)| {
            !*done
                && match f.at {
                    FaultAt::LineNumber(k) => n == Some(k),
                    FaultAt::Received(k) => k == received,
                }
        })?;
        *done = true;
        let kind = f.kind;
        self.log.events.push(format!("fault fired at `{text}`: {kind:?}"));
        Some(kind)
    }
}
