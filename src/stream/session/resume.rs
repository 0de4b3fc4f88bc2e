//! Resuming a job from its journal (`--resume`): check that the journal belongs to this program and can be
//! resumed, find what ran before a disconnect from the position the controller reports, then build what a
//! resume sends — the modal preamble, the approach from safe Z with the spindle restarted, the rest of a
//! line cut mid-way, and every line not yet executed — refusing when the path already diverged.

use std::path::Path;

use super::handshake::Info;
use super::locate::known;
use super::{locate, record_located, start_record, Config, Outcome, Outgoing, Session, Stats, StreamError, Tag};
use crate::stream::journal::{Journal, JournalState, Record};
use crate::stream::program::{Distance, Line, Modal, MotionMode, Program, Spindle, Units};

/// Load the journal and check that this run can resume it.
pub(super) fn load_state(program: &Program, cfg: &Config, journal_path: &Path) -> Result<JournalState, StreamError> {
    let st = Journal::load(journal_path)?;
    let bad = |what: String| StreamError::Resume {
        journal: journal_path.to_path_buf(),
        what,
    };
    if st.runs == 0 {
        return Err(bad("the journal has no run in it".into()));
    }
    if st.fingerprint != program.fingerprint || st.lines != program.lines.len() {
        return Err(bad(format!(
            "it was written for a different program than {}",
            program.path.display()
        )));
    }
    if st.numbered != cfg.number_lines {
        return Err(bad("line numbering differs from the interrupted run".into()));
    }
    if st.complete {
        return Err(bad("the job already completed".into()));
    }
    Ok(st)
}

impl Session<'_> {
    /// Continue the job in the journal: unlock only if the position was retained (or `--unlock`), find
    /// what ran if the last run could not tell, then stream the resume plan.
    pub(super) fn run_resume(
        &mut self,
        info: &Info,
        journal_path: &Path,
        mut st: JournalState,
    ) -> Result<Outcome, StreamError> {
        let retained = matches!(
            st.stop,
            Some(Record::Stop {
                position_retained: true,
                ..
            })
        );
        self.require_idle(info, retained || self.cfg.unlock)?;
        let mut j = Journal::append(journal_path)?;
        let located = matches!(st.stop, Some(Record::Stop { located: true, .. }));
        if !located {
            self.locate_after_disconnect(journal_path, &mut j, &mut st)?;
        }
        let program = self.program;
        if program.sendable().all(|l| st.executed.contains(&l.number)) {
            // The controller finished everything before the fault was noticed.
            j.record_synced(&Record::Complete)?;
            return Ok(Outcome::Completed(Stats::default()));
        }
        let (first, queue) = plan_resume(program, &st, self.cfg).map_err(|what| StreamError::Resume {
            journal: journal_path.to_path_buf(),
            what,
        })?;
        self.executed = st.executed.clone();
        j.record_synced(&start_record(program, self.cfg, first))?;
        self.journal = Some(j);
        self.observer.note(&format!(
            "resuming at line {first} ({} lines already executed)",
            st.executed.len()
        ));
        self.stream(queue)
    }

    /// The last run ended without knowing what ran (a disconnect): the position tells. Journals what is
    /// found and adds it to `st`.
    fn locate_after_disconnect(
        &mut self,
        journal_path: &Path,
        j: &mut Journal,
        st: &mut JournalState,
    ) -> Result<(), StreamError> {
        let status = self.settled_status()?;
        let p = self.work_position(&status).ok_or_else(|| StreamError::Resume {
            journal: journal_path.to_path_buf(),
            what: "the controller reports no position".into(),
        })?;
        let candidates: Vec<usize> = st
            .sent
            .iter()
            .copied()
            .filter(|n| !st.executed.contains(n) && !st.errors.iter().any(|e| e.0 == *n && !st.ok.contains(n)))
            .collect();
        let loc = locate(
            self.program,
            &candidates,
            status.line,
            p,
            self.cfg.position_tolerance_mm,
        )
        .map_err(|what| StreamError::Resume {
            journal: journal_path.to_path_buf(),
            what: format!("cannot tell which lines ran before the link dropped: {what}"),
        })?;
        record_located(j, &loc)?;
        for n in &loc.executed {
            st.executed.insert(*n);
        }
        st.partial = loc.partial;
        Ok(())
    }
}

fn fmt_mm(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

/// Build what a resume sends: the modal preamble, the approach from safe Z, the rest of a line cut mid-way,
/// and every line not yet executed. Returns the first program line and the queue.
fn plan_resume(program: &Program, st: &JournalState, cfg: &Config) -> Result<(usize, Vec<Outgoing>), String> {
    let first = program
        .sendable()
        .map(|l| l.number)
        .find(|n| !st.executed.contains(n))
        .ok_or_else(|| "every line has already executed".to_string())?;
    check_in_order(program, st, first)?;
    let line = program.line(first).expect("first is a program line");
    let moved = st.executed.iter().any(|&n| program.line(n).is_some_and(|l| l.moves)) || st.partial.is_some();
    let partial = st.partial.filter(|(n, _)| *n == first);
    let pre = approach(line, first, moved, partial, cfg)?;
    let mut queue: Vec<Outgoing> = pre.into_iter().map(Outgoing::synthetic).collect();
    let mut rest_from = first;
    if let Some((n, _)) = partial {
        queue.push(finish_cut(line, n, cfg)?);
        queue.push(Outgoing::synthetic(restore_modal(&line.after)));
        rest_from = n + 1;
    } else {
        queue.push(Outgoing::synthetic(restore_modal(&line.before)));
    }
    for l in program.sendable().filter(|l| l.number >= rest_from) {
        queue.push(Outgoing::program_line(l, cfg.number_lines));
    }
    Ok((first, queue))
}

/// Refuse when a moving line after `first` ran, or was cut, although `first` did not: GRBL had already
/// planned it when the fault came, and the machine's path diverged from the program.
fn check_in_order(program: &Program, st: &JournalState, first: usize) -> Result<(), String> {
    if let Some(&later) = st
        .executed
        .iter()
        .find(|&&m| m > first && program.line(m).is_some_and(|l| l.moves))
    {
        return Err(format!(
            "line {later} ran although line {first} before it did not (GRBL had already planned it when the \
             fault came); the path diverged from the program, so resuming automatically is unsafe"
        ));
    }
    if let Some((cut, _)) = st.partial.filter(|(n, _)| *n > first) {
        return Err(format!(
            "line {cut} was cut mid-way although line {first} before it never ran (GRBL had already planned \
             it when the fault came); the path diverged from the program, so resuming automatically is unsafe"
        ));
    }
    Ok(())
}

/// The preamble: known modes, and — when anything moved — up to safe Z, the spindle and coolant back on,
/// over to the resume point (the stop point of a cut line, else the start of `first`) and down to it.
fn approach(
    line: &Line,
    first: usize,
    moved: bool,
    partial: Option<(usize, [f64; 3])>,
    cfg: &Config,
) -> Result<Vec<String>, String> {
    let m = line.before;
    let mut pre: Vec<String> = vec!["G21G90G17G94".into()];
    if moved {
        let target = match partial {
            Some((_, at)) => at,
            None => known(line.start_mm).ok_or_else(|| {
                format!("the position before line {first} is unknown to the program model (G28/G92/G53/homing or incremental moves from an unknown start)")
            })?,
        };
        pre.push(format!("G0Z{}", fmt_mm(cfg.safe_z_mm.max(target[2]))));
        if m.spindle != Spindle::Off {
            let word = if m.spindle == Spindle::Cw { "M3" } else { "M4" };
            pre.push(format!("{word}S{}", fmt_mm(m.spindle_rpm)));
            if cfg.spindle_dwell_s > 0.0 {
                pre.push(format!("G4P{}", fmt_mm(cfg.spindle_dwell_s)));
            }
        }
        if m.mist {
            pre.push("M7".into());
        }
        if m.flood {
            pre.push("M8".into());
        }
        pre.push(format!("G0X{}Y{}", fmt_mm(target[0]), fmt_mm(target[1])));
        let plunge = m.feed_mm_min.unwrap_or(cfg.plunge_feed_mm_min);
        pre.push(format!("G1Z{}F{}", fmt_mm(target[2]), fmt_mm(plunge)));
    } else if m.spindle != Spindle::Off {
        let word = if m.spindle == Spindle::Cw { "M3" } else { "M4" };
        pre.push(format!("{word}S{}", fmt_mm(m.spindle_rpm)));
        pre.push(format!("G4P{}", fmt_mm(cfg.spindle_dwell_s)));
    }
    Ok(pre)
}

/// The program's units, distance mode, motion mode and feed, as one block.
fn restore_modal(m: &Modal) -> String {
    let k = if m.units == Units::Inch { 25.4 } else { 1.0 };
    let mut s = String::from(if m.units == Units::Inch { "G20" } else { "G21" });
    s += if m.distance == Distance::Incremental {
        "G91"
    } else {
        "G90"
    };
    match m.motion {
        MotionMode::Rapid => s += "G0",
        MotionMode::Linear => s += "G1",
        _ => {}
    }
    if let Some(f) = m.feed_mm_min {
        s += &format!("F{}", fmt_mm(f / k));
    }
    s
}

/// The rest of line `n`, cut mid-way: an absolute `G0`/`G1` to its end from wherever the tool is.
fn finish_cut(line: &Line, n: usize, cfg: &Config) -> Result<Outgoing, String> {
    let mode = match line.motion {
        Some(MotionMode::Rapid) => "G0",
        Some(MotionMode::Linear) => "G1",
        _ => {
            return Err(format!(
                "line {n} is an arc cut mid-way; resuming inside an arc is not supported"
            ))
        }
    };
    let end = known(line.end_mm).ok_or_else(|| format!("line {n}'s end position is unknown"))?;
    let feed = line
        .after
        .feed_mm_min
        .map(|f| format!("F{}", fmt_mm(f)))
        .unwrap_or_default();
    let num = if cfg.number_lines {
        format!("N{n}")
    } else {
        String::new()
    };
    Ok(Outgoing {
        text: format!(
            "{num}G21G90{mode}X{}Y{}Z{}{feed}",
            fmt_mm(end[0]),
            fmt_mm(end[1]),
            fmt_mm(end[2])
        ),
        tag: Tag::Line(n),
        alone: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prog(text: &str) -> Program {
        Program::parse(Path::new("t.nc"), text, 1, true).unwrap()
    }

    const SQUARE: &str = "G21G90\nG0X0Y0Z1\nM3S1000\nG1Z-1F100\nG1X10\nG1Y10\nG1X0\nG1Y0\nG0Z1\n";

    #[test]
    fn resume_plan_approaches_from_safe_z_and_finishes_the_cut_line() {
        let p = prog(SQUARE);
        let st = JournalState {
            executed: (1..=5).collect(),
            partial: Some((6, [10.0, 4.0, -1.0])),
            ..JournalState::default()
        };
        let (first, q) = plan_resume(&p, &st, &Config::default()).unwrap();
        assert_eq!(first, 6);
        let texts: Vec<&str> = q.iter().map(|o| o.text.as_str()).collect();
        assert_eq!(
            &texts[..8],
            &[
                "G21G90G17G94",
                "G0Z5",
                "M3S1000",
                "G4P2",
                "G0X10Y4",
                "G1Z-1F100",
                "N6G21G90G1X10Y10Z-1F100",
                "G21G90G1F100"
            ]
        );
        assert_eq!(texts[8], "N7G1X0");
        assert_eq!(q[6].tag, Tag::Line(6));
    }

    #[test]
    fn resume_refuses_out_of_order_execution() {
        let p = prog(SQUARE);
        let st = JournalState {
            executed: [1, 2, 3, 4, 6].into_iter().collect(),
            ..JournalState::default()
        };
        assert!(plan_resume(&p, &st, &Config::default())
            .unwrap_err()
            .contains("diverged"));
    }
}
