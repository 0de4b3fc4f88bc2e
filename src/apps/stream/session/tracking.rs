//! Which lines executed, as the streamer learns it while streaming: status reports (`Ln`, an idle
//! controller with an empty planner) move `ok`-ed lines from *planned* to *executed*, each change is
//! journaled, and progress is reported. Also the work position (a report's `WPos`, or `MPos` − the last
//! `WCO`) and the journal writes shared by the other steps.

use std::time::Duration;

use super::locate::known;
use super::{ranges, EndDetection, Fault, Progress, Session};
use crate::apps::stream::journal::Record;
use crate::apps::stream::protocol::{MachineState, Status, PLANNER_BLOCKS};

impl Session<'_> {
    /// The controller's arc tolerance `$12` (mm) from its settings, GRBL's default when not read.
    pub(super) fn arc_tolerance_mm(&self) -> f64 {
        self.settings
            .get(&12)
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
            .unwrap_or(super::locate::DEFAULT_ARC_TOLERANCE_MM)
    }

    /// The work position of a report: `WPos`, or `MPos` less the last `WCO` — `None` until a `WCO` has been
    /// reported (a machine position is not a work position: [`Session::ensure_wco`] asks for one).
    pub(super) fn work_position(&self, st: &Status) -> Option<[f64; 3]> {
        if let Some(w) = st.wpos {
            return Some(w);
        }
        if !self.wco_seen {
            return None;
        }
        st.mpos
            .map(|m| [m[0] - self.wco[0], m[1] - self.wco[1], m[2] - self.wco[2]])
    }

    /// A status report: lines planned before the executing one (`Ln`) have executed; so have all of them
    /// when the controller shows it is idle with an empty planner — but only before any reset in this
    /// session (a reset empties the planner without running it), and, on a build that reports neither
    /// `Ln` nor `Bf`, only once every line is answered and two consecutive reports since the last answer
    /// show Idle at the program's end point.
    pub(super) fn on_status(&mut self, st: Status) {
        if let Some(w) = st.wco {
            self.wco = w;
            self.wco_seen = true;
        }
        self.status_seq += 1;
        self.status_after_ack = true;
        let mut newly = Vec::new();
        if let Some(ln) = st.line {
            // Block `ln` is executing: every line planned before it has run.
            while let Some(&n) = self.planned.front() {
                if n >= ln as usize {
                    break;
                }
                newly.push(n);
                self.planned.pop_front();
            }
        } else if st.state == Some(MachineState::Idle) && !self.reset_sent && self.planner_known_empty(&st) {
            newly.extend(self.planned.drain(..));
        } else if self.idle_at_end_point(&st) {
            self.idle_at_end += 1;
            if self.idle_at_end >= 2 {
                newly.extend(self.planned.drain(..));
            }
        } else {
            self.idle_at_end = 0;
        }
        self.mark_executed(&newly);
        self.status = Some(st);
        self.report_progress();
    }

    /// Idle with nothing executing: with `Ln` (when line numbers are reported and used) none, or `Bf`
    /// reporting every planner block free.
    fn planner_known_empty(&self, st: &Status) -> bool {
        match self.end_detection {
            EndDetection::LineNumbers => st.line.is_none() && self.line_numbers,
            EndDetection::PlannerBlocks => st.planner_free == Some(PLANNER_BLOCKS),
            EndDetection::IdleAtEndPoint => false,
        }
    }

    /// On a build without `Ln` and `Bf`: every line answered, no reset, and the report shows Idle at the
    /// end point of the last line planned (work mm, within the position tolerance).
    fn idle_at_end_point(&self, st: &Status) -> bool {
        if self.end_detection != EndDetection::IdleAtEndPoint
            || self.reset_sent
            || !self.all_answered
            || st.state != Some(MachineState::Idle)
        {
            return false;
        }
        let Some(&last) = self.planned.back() else {
            return false;
        };
        let end = self.program.line(last).and_then(|l| known(l.end_mm));
        match (end, self.work_position(st)) {
            (Some(e), Some(p)) => (0..3).all(|i| (e[i] - p[i]).abs() <= self.cfg.position_tolerance_mm),
            // The program model does not know where the job ends: Idle twice after the last answer.
            (None, _) => true,
            (Some(_), None) => false,
        }
    }

    /// Record `lines` as executed, in the journal too.
    pub(super) fn mark_executed(&mut self, lines: &[usize]) {
        if lines.is_empty() {
            return;
        }
        for &n in lines {
            self.executed.insert(n);
        }
        if let Some(j) = self.journal.as_mut() {
            for (a, b) in ranges(lines) {
                // A journal write failure must not go unnoticed: it is reported at the next stop.
                if let Err(e) = j.record(&Record::Executed { from: a, to: b }) {
                    self.observer.note(&format!("journal: {e}"));
                }
            }
        }
    }

    /// Tell the observer where the job stands, with an ETA from the rate so far.
    fn report_progress(&mut self) {
        let done = self.executed.len();
        let elapsed = self.started.elapsed().as_secs_f64();
        let rate = done as f64 / elapsed.max(1e-3);
        let eta =
            (rate > 0.0 && done > 0).then(|| Duration::from_secs_f64(self.total.saturating_sub(done) as f64 / rate));
        let p = Progress {
            lines_total: self.total,
            lines_done: done,
            lines_acked: self.stats.lines_sent.saturating_sub(self.counter.outstanding()),
            state: self.status.as_ref().and_then(|s| s.state),
            position_mm: self.status.as_ref().and_then(|s| self.work_position(s)),
            eta,
        };
        self.observer.progress(&p);
    }

    /// Journal a record while streaming (a write failure stops the job).
    pub(super) fn journal(&mut self, r: &Record) -> Result<(), Fault> {
        match self.journal.as_mut() {
            Some(j) => j
                .record(r)
                .map_err(|e| Fault::Protocol(format!("journal write failed: {e}"))),
            None => Ok(()),
        }
    }

    /// The last report shows a machine at rest with nothing executing.
    pub(super) fn idle(&self) -> bool {
        self.status.as_ref().is_some_and(|s| {
            matches!(
                s.state,
                Some(MachineState::Idle | MachineState::Alarm | MachineState::Check)
            ) && s.line.is_none()
        })
    }
}
