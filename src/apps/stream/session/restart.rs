//! Is the controller on the other end still the one the job left? A GRBL board that restarted — an
//! Arduino resets when its port is opened (DTR), a power cut, a watchdog — has lost its machine position,
//! its G92 and tool length offsets and its modal state, and reports a position from wherever the tool stood
//! when it came up. Nothing it reports then says which lines ran, and a resume from it would cut the rest of
//! the program in the wrong place. The evidence, each read from the controller, none inferred:
//! - its banner arrived unasked while the port was being opened (a start the streamer did not cause);
//! - its work offset (`WCO`) differs from the one recorded when the job started;
//! - after a disconnect (no reset from the streamer), its modal state is the power-up one (`M5`, `F0`)
//!   where the program had left the spindle on or a feed set (`$G`).
//!
//! On any of them the resume stops before anything is sent, journals a `restart` stop and asks the user to
//! re-establish the position; `--position-reestablished` says they did, and the resume then reads where the
//! tool stands as the truth. A banner on that very connection still stops it: the position just
//! re-established was lost again as the port opened.

use std::path::Path;
use std::time::{Duration, Instant};

use super::handshake::Info;
use super::{Session, StreamError};
use crate::apps::stream::journal::{Journal, JournalState, Record};
use crate::apps::stream::program::{Modal, Spindle};
use crate::apps::stream::protocol::{parse_response, Response};

/// Work offsets closer than this (mm) are the same.
const WCO_TOLERANCE_MM: f64 = 1e-3;

impl Session<'_> {
    /// Refuse a resume on a controller that restarted since the job's last run (module notes), journaling
    /// the stop; with `--position-reestablished`, accept one whose position the user set again.
    pub(super) fn refuse_if_restarted(
        &mut self,
        info: &Info,
        st: &JournalState,
        journal_path: &Path,
    ) -> Result<(), StreamError> {
        let Some(evidence) = self.restart_evidence(info, st) else {
            return Ok(());
        };
        if self.cfg.position_reestablished && !info.restarted {
            self.observer.note(&format!(
                "the controller restarted or its offsets changed since the job's last run ({evidence}); \
                 taking its position as re-established, as --position-reestablished says"
            ));
            return Ok(());
        }
        let again = if self.cfg.position_reestablished {
            " It restarted as this connection opened, so the position set before was lost again: re-establish \
             it with the port held open (home with $H), or keep the board from resetting when its port opens."
        } else {
            ""
        };
        let what = format!(
            "the controller restarted since the job's last run ({evidence}): it lost its position, its G92 and \
             tool length offsets and its modal state, so which lines ran cannot be read from it and nothing was \
             sent. Re-establish where the machine is — home ($H) if it has limit switches, or set the work \
             coordinates of where the tool now stands (G10 L20 P1 X.. Y.. Z.., or touch off) — then resume with \
             --resume --position-reestablished.{again}"
        );
        let mut j = Journal::append(journal_path)?;
        j.record_synced(&Record::Stop {
            reason: "restart".into(),
            line: None,
            message: what.clone(),
            located: false,
            position_retained: false,
        })?;
        Err(StreamError::Resume {
            journal: journal_path.to_path_buf(),
            what,
        })
    }

    /// Why the controller is not the one the job left, if anything says so.
    fn restart_evidence(&mut self, info: &Info, st: &JournalState) -> Option<String> {
        if info.restarted {
            return Some("its banner came unasked as the port opened: an Arduino resets when its port opens".into());
        }
        if let (Some(then), true) = (st.wco, self.wco_seen) {
            let now = self.wco;
            if (0..3).any(|i| (now[i] - then[i]).abs() > WCO_TOLERANCE_MM) {
                return Some(format!(
                    "its work offset is {} where the job ran with {}",
                    fmt3(now),
                    fmt3(then)
                ));
            }
        }
        // after the streamer's own reset the modal state is the power-up one anyway
        let untouched = match &st.stop {
            Some(Record::Stop { reason, .. }) => reason == "disconnect",
            _ => true,
        };
        if !untouched {
            return None;
        }
        // The controller parsed every line up to the last one it answered, and perhaps some sent after it
        // (a disconnect loses what was in flight): its modal state is the one after one of those lines. Only a
        // state that none of them leaves is evidence; before any answer there is none.
        let last_ok = *st.ok.iter().next_back()?;
        let candidates: Vec<_> = st.sent.range(last_ok..).filter_map(|&n| self.program.line(n)).collect();
        let last = *candidates.last()?;
        let (spindle, feed) = self.modal_report()?;
        let contradicts = |after: &Modal| {
            (after.spindle != Spindle::Off && !spindle) || (after.feed_mm_min.is_some_and(|f| f > 0.0) && feed == 0.0)
        };
        if !candidates.iter().all(|l| contradicts(&l.after)) {
            return None;
        }
        let expected = last.after;
        Some(format!(
            "its modal state is the power-up one ({}, F{feed}) where line {} had left {}",
            if spindle { "spindle on" } else { "M5" },
            last.number,
            [
                (expected.spindle != Spindle::Off).then(|| format!("the spindle on at S{}", expected.spindle_rpm)),
                expected.feed_mm_min.map(|f| format!("F{f}")),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" and ")
        ))
    }

    /// `$G`: whether the spindle is on (`M3`/`M4`) and the feed (`F`), or `None` when it does not answer.
    fn modal_report(&mut self) -> Option<(bool, f64)> {
        self.write(b"$G\n").ok()?;
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        let mut found = None;
        while Instant::now() < deadline {
            let Ok(Some(l)) = self.read_line(Duration::from_millis(100)) else {
                continue;
            };
            match parse_response(&l) {
                Response::Feedback(f) if f.starts_with("GC:") => {
                    let words: Vec<&str> = f[3..].split_whitespace().collect();
                    let spindle = words.iter().any(|w| *w == "M3" || *w == "M4");
                    let feed = words
                        .iter()
                        .find_map(|w| w.strip_prefix('F').and_then(|v| v.parse().ok()))
                        .unwrap_or(0.0);
                    found = Some((spindle, feed));
                }
                Response::Ok => return found,
                Response::Error(_) => return None,
                Response::Status(s) => self.on_status(s),
                _ => {}
            }
        }
        None
    }
}

fn fmt3(p: [f64; 3]) -> String {
    format!("{:.3},{:.3},{:.3}", p[0], p[1], p[2])
}
