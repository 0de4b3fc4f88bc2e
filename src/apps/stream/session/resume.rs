//! Resuming a job from its journal (`--resume`): check that the journal belongs to this program and can be
//! resumed, find what ran before a disconnect from the position the controller reports, then build what a
//! resume sends — the modal preamble, the approach from safe Z with the spindle restarted, the rest of a
//! line cut mid-way, and every line not yet executed — refusing when the path already diverged.

use std::path::Path;

use super::handshake::Info;
use super::locate::{arc_of, known};
use super::{
    locate, record_located, start_record, Config, Evidence, Outcome, Outgoing, Session, Stats, StreamError, Tag,
};
use crate::apps::stream::journal::{Journal, JournalState, Record};
use crate::apps::stream::program::{words, Distance, Line, Modal, MotionMode, Program, Spindle, Units};
use crate::apps::stream::protocol::MachineState;
use crate::gcode::program::MAX_BLOCK_CHARS;

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
    /// Continue the job in the journal: find what ran if the last run could not tell, plan the resume, and
    /// only then — when nothing refused — unlock (only if the position was retained, or `--unlock`) and
    /// stream the plan.
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
        self.ensure_wco()?;
        self.refuse_if_restarted(info, &st, journal_path)?;
        let skips = rejected_to_skip(&st, &self.cfg.skip_lines).map_err(|what| StreamError::Resume {
            journal: journal_path.to_path_buf(),
            what,
        })?;
        st.skipped.extend(&skips);
        self.read_settings(info);
        self.require_arc_tolerance()?;
        let mut j = Journal::append(journal_path)?;
        let located = matches!(st.stop, Some(Record::Stop { located: true, .. }));
        if !located {
            self.locate_after_disconnect(journal_path, &mut j, &mut st)?;
        }
        let program = self.program;
        if program
            .sendable()
            .all(|l| st.executed.contains(&l.number) || st.is_skipped(l.number))
        {
            // The controller finished everything before the fault was noticed.
            j.record_synced(&Record::Complete)?;
            return Ok(Outcome::Completed(Stats::default()));
        }
        let travel = self.travel().map_err(|what| StreamError::Resume {
            journal: journal_path.to_path_buf(),
            what,
        })?;
        let (first, queue) =
            plan_resume(program, &st, self.cfg, travel.as_ref()).map_err(|what| StreamError::Resume {
                journal: journal_path.to_path_buf(),
                what,
            })?;
        self.require_idle(info, retained || self.cfg.unlock)?;
        for &(line, code) in &skips {
            j.record(&Record::Skip { line, code })?;
        }
        self.executed = st.executed.clone();
        let here = self.status.as_ref().and_then(|s| self.work_position(s));
        j.record_synced(&start_record(
            program,
            self.cfg,
            first,
            here,
            self.wco_seen.then_some(self.wco),
        ))?;
        self.journal = Some(j);
        self.observer.note(&format!(
            "resuming at line {first} ({} lines already executed)",
            st.executed.len()
        ));
        self.stream(queue)
    }

    /// The last run ended without knowing what ran (a disconnect, or an alarm the user left unreset): the
    /// position tells. Journals what is found and adds it to `st`.
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
        let program = self.program;
        let moved = st.partial.is_some() || st.executed.iter().any(|&n| program.line(n).is_some_and(|l| l.moves));
        let ev = Evidence {
            ln: status.line,
            position: p,
            // Before anything moved the tool is where the first run found it.
            origin: if moved { None } else { st.origin },
            arc_tolerance_mm: self.arc_tolerance_mm(),
            // Idle with nothing executing: the controller finished what it had, so motion ended at the
            // end of a block — when nothing stopped it: the link dropped (or the streamer died) and it ran
            // on. Not after an alarm, nor after the streamer's own hold and reset (an error, Ctrl-C, a
            // silence): motion stopped wherever it was, and the controller is Idle only because it was
            // reset (and unlocked).
            at_rest: status.state == Some(MachineState::Idle)
                && status.line.is_none()
                && match &st.stop {
                    Some(Record::Stop { reason, .. }) => reason == "disconnect",
                    _ => true,
                },
        };
        let loc =
            locate(program, &candidates, &ev, self.cfg.position_tolerance_mm).map_err(|what| StreamError::Resume {
                journal: journal_path.to_path_buf(),
                what: format!("cannot tell which lines ran before the link dropped: {what}"),
            })?;
        if let Some(why) = &loc.ambiguous {
            self.observer.note(why);
        }
        record_located(j, &loc)?;
        for n in &loc.executed {
            st.executed.insert(*n);
        }
        st.partial = loc.partial;
        Ok(())
    }
}

/// The lines `--skip-line` names, each with the code GRBL rejected it with; refuses a line GRBL did not
/// reject (only a rejected line may be left out: any other would leave the program's path).
fn rejected_to_skip(st: &JournalState, lines: &[usize]) -> Result<Vec<(usize, u16)>, String> {
    lines
        .iter()
        .map(|&n| {
            st.rejection(n).map(|code| (n, code)).ok_or_else(|| {
                    format!("--skip-line {n}: GRBL did not reject line {n}; only a line it answered with error:N may be left out")
                })
        })
        .collect()
}

/// Where the machine may go, when its coordinates mean something: with homing enabled (`$22=1`) GRBL's
/// machine space runs from `-$13x` to 0 on each axis, and the work offset places the program in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Travel {
    /// `$130`–`$132`, mm.
    pub(super) max_mm: [f64; 3],
    /// The work coordinate offset (machine = work + offset), mm.
    pub(super) wco_mm: [f64; 3],
}

impl Travel {
    /// The work-coordinate range of axis `i`.
    fn work_range(&self, i: usize) -> (f64, f64) {
        (-self.max_mm[i] - self.wco_mm[i], -self.wco_mm[i])
    }
}

impl Session<'_> {
    /// The machine's travel, when `$$` says homing is on (`$22=1`) and reported `$130`–`$132`. GRBL sends
    /// the work offset (`WCO`) only every 10–30 reports, so up to 12 more are asked for; without it the
    /// approach cannot be checked against the travel and the resume is refused.
    fn travel(&mut self) -> Result<Option<Travel>, String> {
        let s = &self.settings;
        if s.get(&22).copied() != Some(1.0) {
            return Ok(None);
        }
        let (Some(&x), Some(&y), Some(&z)) = (s.get(&130), s.get(&131), s.get(&132)) else {
            return Ok(None);
        };
        for _ in 0..12 {
            if self.wco_seen {
                break;
            }
            self.settled_status().map_err(|e| e.to_string())?;
            std::thread::sleep(self.cfg.status_interval.max(std::time::Duration::from_millis(200)));
        }
        if !self.wco_seen {
            return Err(
                "the controller reported no work offset (WCO), so the approach cannot be checked \
                        against the machine's travel"
                    .into(),
            );
        }
        Ok(Some(Travel {
            max_mm: [x, y, z],
            wco_mm: self.wco,
        }))
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
fn plan_resume(
    program: &Program,
    st: &JournalState,
    cfg: &Config,
    travel: Option<&Travel>,
) -> Result<(usize, Vec<Outgoing>), String> {
    let first = program
        .sendable()
        .map(|l| l.number)
        .find(|&n| !st.executed.contains(&n) && !st.is_skipped(n))
        .ok_or_else(|| "every line has already executed".to_string())?;
    check_in_order(program, st, first)?;
    refuse_rejected(program, st, first)?;
    let line = program.line(first).expect("first is a program line");
    let moved = st.executed.iter().any(|&n| program.line(n).is_some_and(|l| l.moves)) || st.partial.is_some();
    let partial = st.partial.filter(|(n, _)| *n == first);
    let pre = approach(line, first, moved, partial, cfg, travel)?;
    let mut queue: Vec<Outgoing> = pre.into_iter().map(Outgoing::synthetic).collect();
    let mut rest_from = first;
    if let Some((n, at)) = partial {
        queue.push(finish_cut(line, n, at, cfg)?);
        queue.push(Outgoing::synthetic(restore_modal(&line.after)));
        rest_from = n + 1;
    } else {
        queue.push(Outgoing::synthetic(restore_modal(&line.before)));
    }
    // the approach ended in G1: the first line that moves in the arc mode it inherits needs the mode written
    let mut inherits_arc = partial.is_none();
    for l in program
        .sendable()
        .filter(|l| l.number >= rest_from && !st.is_skipped(l.number))
    {
        let mut out = Outgoing::program_line(l, cfg.number_lines);
        if inherits_arc {
            let (text, settled) = with_modal_arc(l, &out.text)?;
            out.text = text;
            inherits_arc = !settled;
        }
        queue.push(out);
    }
    Ok((first, queue))
}

/// A resumed line, `text` as sent, when it moves in the arc mode (`G2`/`G3`) it inherits from the lines
/// before the resume point: the approach ended in `G1`, and a block of only axis words and offsets would
/// then be read as `G1` (GRBL refuses its unused `I J K`), so the mode is written into it, after any `N` word.
/// Also says whether the motion mode is settled from this line on (it moves, or sets its own mode).
fn with_modal_arc(l: &Line, text: &str) -> Result<(String, bool), String> {
    let ws = words(&l.block).unwrap_or_default();
    let own_motion = ws
        .iter()
        .any(|w| w.letter == 'G' && ([0.0, 1.0, 2.0, 3.0, 80.0].contains(&w.value) || (38.0..39.0).contains(&w.value)));
    let axis = ws.iter().any(|w| matches!(w.letter, 'X' | 'Y' | 'Z'));
    let word = match l.before.motion {
        MotionMode::ArcCw => "G2",
        MotionMode::ArcCcw => "G3",
        _ => return Ok((text.to_string(), true)),
    };
    if own_motion || !axis {
        return Ok((text.to_string(), own_motion));
    }
    // after the `N` word the streamer numbers the line with, if any
    let at = if text.starts_with('N') {
        text.find(|c: char| c.is_ascii_alphabetic() && c != 'N')
            .unwrap_or(text.len())
    } else {
        0
    };
    let out = format!("{}{word}{}", &text[..at], &text[at..]);
    if out.len() > MAX_BLOCK_CHARS {
        return Err(format!(
            "line {} continues the arc mode {word} of the lines before it; written into it for the resume it \
             would be {} characters, more than GRBL's {MAX_BLOCK_CHARS}",
            l.number,
            out.len()
        ));
    }
    Ok((out, true))
}

/// Refuse a resume that would send again a line GRBL rejected and will reject again — the one interpreter,
/// reading the line as 1.1h does, refuses it too (a line rejected for another reason, a byte corrupted on
/// the wire, is sent again): it would stop there again, every time, each try repeating the approach. Say
/// which line, why GRBL refused it, and how to go on.
fn refuse_rejected(program: &Program, st: &JournalState, first: usize) -> Result<(), String> {
    let pending = st.errors.iter().find(|(n, _)| {
        *n >= first
            && !st.ok.contains(n)
            && !st.executed.contains(n)
            && !st.is_skipped(*n)
            && program.line(*n).is_some_and(|l| l.refusal.is_some())
    });
    let Some(&(n, code)) = pending else {
        return Ok(());
    };
    let line = program.line(n).expect("a line of the program");
    let why = line.refusal.as_ref().map_or(String::new(), |r| format!(": {r}"));
    Err(format!(
        "GRBL rejected line {n} (`{}`) with error:{code} ({}){why}; a resume would send it again and stop there \
         again. Fix the program and start the job over, or leave the line out on purpose: --resume --skip-line {n}",
        line.source.trim(),
        crate::apps::stream::protocol::error_text(code)
    ))
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
    travel: Option<&Travel>,
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
        pre.push(format!("G0Z{}", fmt_mm(safe_z(cfg, target, travel)?)));
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

/// The height the approach travels at: `--safe-z-mm` (never below the resume point), lowered to the top of
/// the machine's travel when that is known and lower. Refuses a resume point outside the travel, where the
/// approach would hit a limit.
fn safe_z(cfg: &Config, target: [f64; 3], travel: Option<&Travel>) -> Result<f64, String> {
    let mut z = cfg.safe_z_mm.max(target[2]);
    if let Some(t) = travel {
        for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
            let (lo, hi) = t.work_range(i);
            if target[i] < lo - 1e-9 || target[i] > hi + 1e-9 {
                return Err(format!(
                    "the resume point {axis}{} lies outside the machine's travel (work {axis} {} to {}, from \
                     ${} and the work offset): the approach would hit a limit",
                    fmt_mm(target[i]),
                    fmt_mm(lo),
                    fmt_mm(hi),
                    130 + i
                ));
            }
        }
        z = z.min(t.work_range(2).1);
    }
    Ok(z)
}

/// The program's units, distance mode, motion mode and feed, as one block.
fn restore_modal(m: &Modal) -> String {
    let k = if m.units == Units::Inch { 25.4 } else { 1.0 };
    let mut s = String::from(if m.units == Units::Inch { "G20" } else { "G21" });
    // the preamble selected G17
    s += &format!("G{}", m.plane);
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

/// The rest of line `n`, cut mid-way at `at` (work mm, where the approach brought the tool): an absolute
/// `G0`/`G1` to its end, or for an arc the same arc on from there — its plane, direction and end, the
/// offsets `I J K` taken from the point the approach reached (`at` as written) to the arc's centre.
fn finish_cut(line: &Line, n: usize, at: [f64; 3], cfg: &Config) -> Result<Outgoing, String> {
    let end = known(line.end_mm).ok_or_else(|| format!("line {n}'s end position is unknown"))?;
    let (mode, offsets) = match line.motion {
        Some(MotionMode::Rapid) => ("G0".to_string(), String::new()),
        Some(MotionMode::Linear) => ("G1".to_string(), String::new()),
        Some(MotionMode::ArcCw | MotionMode::ArcCcw) => {
            let arc = known(line.start_mm)
                .and_then(|start| arc_of(line, start))
                .ok_or_else(|| format!("line {n} is an arc cut mid-way whose centre is not known (its start, or a valid `R` or `I J K`)"))?;
            let (a, b, _) = arc.plane.axes();
            let reached = |i: usize| fmt_mm(at[i]).parse::<f64>().unwrap_or(at[i]);
            let offset = |i: usize| format!("{}{}", ['I', 'J', 'K'][i], fmt_mm(arc.center[i] - reached(i)));
            (
                format!("G{}{}", arc.plane.g(), if arc.cw { "G2" } else { "G3" }),
                offset(a.min(b)) + &offset(a.max(b)),
            )
        }
        _ => return Err(format!("line {n} is cut mid-way and is not a G0, G1, G2 or G3 move")),
    };
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
            "{num}G21G90{mode}X{}Y{}Z{}{offsets}{feed}",
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
        let (first, q) = plan_resume(&p, &st, &Config::default(), None).unwrap();
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
                "G21G17G90G1F100"
            ]
        );
        assert_eq!(texts[8], "N7G1X0");
        assert_eq!(q[6].tag, Tag::Line(6));
    }

    /// Issue 14: with homing on and the work offset at the machine's top, `G0 Z5` would lie beyond machine
    /// Z 0 and raise a new soft-limit alarm: the approach stays at Z 0; a point outside travel is refused.
    #[test]
    fn the_approach_stays_inside_machine_travel() {
        let p = prog(SQUARE);
        let st = JournalState {
            executed: (1..=5).collect(),
            partial: Some((6, [10.0, 4.0, -1.0])),
            ..JournalState::default()
        };
        let t = Travel {
            max_mm: [200.0; 3],
            wco_mm: [-100.0, -100.0, 0.0],
        };
        let (_, q) = plan_resume(&p, &st, &Config::default(), Some(&t)).unwrap();
        assert_eq!(q[1].text, "G0Z0");
        let far = Travel {
            wco_mm: [-5.0, -100.0, 0.0],
            ..t
        };
        let e = plan_resume(&p, &st, &Config::default(), Some(&far)).unwrap_err();
        assert!(e.contains("outside the machine's travel"), "{e}");
    }

    /// A stop inside an arc resumes on the same arc: approach to the stop point, then `G2`/`G3` in the
    /// arc's plane to its end with the offsets from that point to the centre — the same radius, within what
    /// GRBL accepts (error 33 beyond 0.005 mm) — and the plane restored for the lines after it.
    #[test]
    fn a_cut_arc_resumes_on_the_same_arc() {
        // G18 (Z→X): a half turn of radius 2 about (2, 0, −1) from (0, 0, −1) to (4, 0, −1), clockwise
        let p = prog("G21G90\nG0X0Y0Z-1\nG18G1F100\nG2X4Z-1I2K0\nG1X5\n");
        let arc = arc_of(p.line(4).unwrap(), [0.0, 0.0, -1.0]).unwrap();
        let at = arc.point_at([0.0, 0.0, -1.0], 0.3);
        let st = JournalState {
            executed: (1..=3).collect(),
            partial: Some((4, at)),
            ..JournalState::default()
        };
        let (first, q) = plan_resume(&p, &st, &Config::default(), None).unwrap();
        assert_eq!(first, 4);
        let cut = &q.iter().find(|o| o.tag == Tag::Line(4)).unwrap().text;
        assert!(cut.starts_with("N4G21G90G18G2X4Y0Z-1I"), "{cut}");
        let word = |c: char| -> f64 {
            let rest = &cut[cut.find(c).unwrap() + 1..];
            let end = rest.find(|ch: char| ch.is_ascii_alphabetic()).unwrap_or(rest.len());
            rest[..end].parse().unwrap()
        };
        let reached = [
            fmt_mm(at[0]).parse::<f64>().unwrap(),
            0.0,
            fmt_mm(at[2]).parse::<f64>().unwrap(),
        ];
        let (cx, cz) = (reached[0] + word('I'), reached[2] + word('K'));
        assert!(
            (cx - 2.0).abs() < 1e-4 && (cz + 1.0).abs() < 1e-4,
            "centre ({cx}, {cz}) from {cut}"
        );
        let r_end = (4.0 - cx).hypot(-1.0 - cz);
        let r_start = (reached[0] - cx).hypot(reached[2] - cz);
        assert!((r_end - r_start).abs() < 0.005, "{r_start} vs {r_end}");
        let next = q.iter().position(|o| o.tag == Tag::Line(4)).unwrap() + 1;
        assert!(q[next].text.starts_with("G21G18G90"), "{}", q[next].text);
    }

    /// A resume that starts at a line moving in the arc mode of the lines before it writes the mode into
    /// that line (the approach ended in `G1`); a line with its own motion word is sent as it is.
    #[test]
    fn a_resume_at_a_modal_arc_line_restates_the_arc_mode() {
        let p = prog("G21G90\nG0X0Y0Z1\nG1Z-1F100\nG2X2Y0I1J0\nX4Y0I1J0\nG3X6Y0I1J0\nF200\nX8Y0I1J0\n");
        // (lines done, first resumed, the line looked at, as sent): a line without axis words passes the
        // mode on to the next
        for (done, first, n, expect) in [
            (4, 5, 5, "N5G2X4Y0I1J0"),
            (5, 6, 6, "N6G3X6Y0I1J0"),
            (6, 7, 7, "N7F200"),
            (6, 7, 8, "N8G3X8Y0I1J0"),
        ] {
            let st = JournalState {
                executed: (1..=done).collect(),
                ..JournalState::default()
            };
            let (f, q) = plan_resume(&p, &st, &Config::default(), None).unwrap();
            assert_eq!(f, first);
            let sent = &q.iter().find(|o| o.tag == Tag::Line(n)).unwrap().text;
            assert_eq!(sent, expect);
        }
    }

    #[test]
    fn resume_refuses_out_of_order_execution() {
        let p = prog(SQUARE);
        let st = JournalState {
            executed: [1, 2, 3, 4, 6].into_iter().collect(),
            ..JournalState::default()
        };
        assert!(plan_resume(&p, &st, &Config::default(), None)
            .unwrap_err()
            .contains("diverged"));
    }
}
