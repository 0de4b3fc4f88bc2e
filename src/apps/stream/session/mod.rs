//! The streamer: handshake, optional `$C` check run, character-counted streaming with the journal, and a
//! safe stop on any fault — feed hold, wait until motion has stopped, read where it stopped, soft reset
//! (which flushes GRBL's buffers so nothing more runs), then work out exactly which lines executed.
//!
//! **What "executed" means.** An `ok` only means *planned*. A line is known executed when a status report
//! shows a later line executing (`Ln`), when the controller is idle with an empty planner, or — at a stop —
//! when the stop position places it before the point where motion stopped. The line executing at the stop
//! is recorded as *partial* with the stop point; a resume finishes it from there.
//!
//! [`run`] is the entry point. One `Session` value holds the state of a run; its steps live in one file
//! per concept, so that each can be read without the others:
//! - `config`, `outcome`, `error`: the public types ([`Config`], [`Outcome`], [`StreamError`]…);
//! - `wire`: lines in and bytes out over the [`Link`], and the status poll;
//! - `handshake`: identifying the controller, waiting for it to be idle, commands sent alone;
//! - `check`: the `$C` check run;
//! - `send`: character-counted streaming and the answers that come back;
//! - `tracking`: which lines executed, from status reports and answers, the journal and progress;
//! - `stop`: the safe stop after a fault;
//! - `locate`: which lines ran, from the position where motion stopped ([`locate`]);
//! - `restart`: whether the controller restarted since the job's last run (then a resume stops);
//! - `resume`: checking a journal for resume, and building what a resume sends.

mod check;
mod config;
mod error;
mod handshake;
mod locate;
mod outcome;
mod restart;
mod resume;
mod send;
mod stop;
mod tracking;
mod wire;

use std::collections::{BTreeSet, VecDeque};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

pub use config::{Config, Mode};
pub use error::StreamError;
pub use locate::{locate, Evidence, Located};
pub use outcome::{EndDetection, Observer, Outcome, Progress, Silent, Stats, StopReason, StopReport};

use super::journal::{Journal, JournalError, Record, VERSION};
use super::program::{Line, LineKind, Program};
use super::protocol::{Counter, Status, RX_BUFFER_BYTES};
use super::serial::Link;
use handshake::Info;

/// Something that ends streaming.
#[derive(Debug)]
enum Fault {
    Error { line: Option<usize>, code: u16 },
    Alarm(u16),
    User,
    Disconnect(String),
    Protocol(String),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tag {
    Line(usize),
    Synthetic,
}

#[derive(Debug, Clone)]
struct Outgoing {
    text: String,
    tag: Tag,
    alone: bool,
}

impl Outgoing {
    /// A program line as sent (`N`-numbered when `numbered`); `$` lines go alone.
    fn program_line(l: &Line, numbered: bool) -> Outgoing {
        Outgoing {
            text: l.wire_text(numbered),
            tag: Tag::Line(l.number),
            alone: l.kind != LineKind::Gcode,
        }
    }

    /// A line the streamer adds (a resume's preamble and approach).
    fn synthetic(text: String) -> Outgoing {
        Outgoing {
            text,
            tag: Tag::Synthetic,
            alone: false,
        }
    }
}

struct Session<'a> {
    link: &'a mut dyn Link,
    program: &'a Program,
    cfg: &'a Config,
    observer: &'a mut dyn Observer,
    stop: &'a AtomicBool,
    /// Interactive hold and resume requests ([`Controls`]), taken when acted on.
    hold_request: &'a AtomicBool,
    resume_request: &'a AtomicBool,
    /// A feed hold asked for by the user is in force (cleared by the resume request).
    user_hold: bool,
    /// The program pause (`M0`) the user was last told about (its line).
    pause_noted: Option<usize>,
    journal: Option<Journal>,
    rbuf: Vec<u8>,
    saw: String,
    counter: Counter<Tag>,
    line_numbers: bool,
    next_poll: Instant,
    last_rx: Instant,
    status: Option<Status>,
    status_seq: u64,
    wco: [f64; 3],
    /// Acked-ok program lines not yet known executed, in order.
    planned: VecDeque<usize>,
    /// At the last stop, the oldest unanswered line was one GRBL answers after (part of) its motion ran
    /// ([`Line::answered_after_its_motion`]: an arc, a move ending the program).
    unanswered_running: Option<usize>,
    sent: BTreeSet<usize>,
    errors: BTreeSet<usize>,
    executed: BTreeSet<usize>,
    started: Instant,
    total: usize,
    stats: Stats,
    first_send: Option<Instant>,
    last_ack: Option<Instant>,
    ack_seq: u64,
    status_after_ack: bool,
    /// A soft reset went out in this session: from then on an idle controller with an empty planner
    /// proves nothing about which lines ran (the reset emptied it).
    reset_sent: bool,
    /// How the end of the job is read, from what the controller offers (`$I`, `$$`).
    end_detection: EndDetection,
    /// Every line is sent and answered: only execution is still awaited.
    all_answered: bool,
    /// Consecutive status reports since the last answer showing Idle at the program's end point.
    idle_at_end: u32,
    /// The controller's settings as `$$` reported them (empty if it did not).
    settings: std::collections::BTreeMap<u16, f64>,
    /// A `WCO` has been reported, so `wco` is the controller's work offset, not a default.
    wco_seen: bool,
    /// Work position before the first line, when known (fresh run: the handshake's report).
    origin: Option<[f64; 3]>,
}

/// What the user can ask of a running stream, each a flag raised from outside (a signal handler) and taken
/// when the streamer acts on it.
#[derive(Clone, Copy, Debug)]
pub struct Controls<'a> {
    /// Stop (Ctrl-C): feed hold, then a reset once motion has stopped; raised again while waiting for the
    /// hold, a reset at once.
    pub stop: &'a AtomicBool,
    /// Feed hold, and keep streaming into the controller's buffer (`SIGUSR1`): the machine decelerates
    /// along its path and waits, spindle on, at `Hold:0`; nothing is lost or re-sent.
    pub hold: &'a AtomicBool,
    /// Cycle start after a user's hold (`SIGUSR2`).
    pub resume: &'a AtomicBool,
}

/// Stream `program` over `link`, journaling to `journal_path`. `stop` is raised by Ctrl-C: the run then
/// holds, stops safely and returns [`Outcome::Stopped`].
pub fn run(
    link: &mut dyn Link,
    program: &Program,
    cfg: &Config,
    journal_path: &Path,
    mode: Mode,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
) -> Result<Outcome, StreamError> {
    let (hold, resume) = (AtomicBool::new(false), AtomicBool::new(false));
    let controls = Controls {
        stop,
        hold: &hold,
        resume: &resume,
    };
    run_with(link, program, cfg, journal_path, mode, observer, controls)
}

/// [`run`] with interactive hold and resume ([`Controls`]).
pub fn run_with(
    link: &mut dyn Link,
    program: &Program,
    cfg: &Config,
    journal_path: &Path,
    mode: Mode,
    observer: &mut dyn Observer,
    controls: Controls<'_>,
) -> Result<Outcome, StreamError> {
    let resume_state = match mode {
        Mode::Resume => Some(resume::load_state(program, cfg, journal_path)?),
        Mode::Fresh => {
            if journal_path.exists() {
                return Err(JournalError::Exists {
                    path: journal_path.to_path_buf(),
                }
                .into());
            }
            None
        }
    };
    // The program modelled from where the tool was before its first line, once that is known (the
    // handshake's report on a fresh run, the journal's start record on a resume): a first move along Z
    // alone, or incremental moves, then have known ends, so a stop on them can be located.
    let anchored: Program;
    let mut s = Session::new(link, program, cfg, observer, controls);
    let info = s.handshake()?;
    s.counter = Counter::new(info.rx_bytes);
    s.line_numbers = info.line_numbers && cfg.number_lines;
    match resume_state {
        None => {
            if let Some(origin) = s.prepare_fresh(&info)? {
                anchored = program.anchored(origin);
                s.program = &anchored;
            }
            s.start_fresh(journal_path)
        }
        Some(st) => {
            if let Some(origin) = st.origin {
                anchored = program.anchored(origin);
                s.program = &anchored;
            }
            s.run_resume(&info, journal_path, st)
        }
    }
}

impl<'a> Session<'a> {
    fn new(
        link: &'a mut dyn Link,
        program: &'a Program,
        cfg: &'a Config,
        observer: &'a mut dyn Observer,
        controls: Controls<'a>,
    ) -> Session<'a> {
        let now = Instant::now();
        Session {
            link,
            program,
            cfg,
            observer,
            stop: controls.stop,
            hold_request: controls.hold,
            resume_request: controls.resume,
            user_hold: false,
            pause_noted: None,
            journal: None,
            rbuf: Vec::new(),
            saw: String::new(),
            counter: Counter::new(RX_BUFFER_BYTES),
            line_numbers: false,
            next_poll: now,
            last_rx: now,
            status: None,
            status_seq: 0,
            wco: [0.0; 3],
            planned: VecDeque::new(),
            unanswered_running: None,
            sent: BTreeSet::new(),
            errors: BTreeSet::new(),
            executed: BTreeSet::new(),
            started: now,
            total: program.sendable().count(),
            stats: Stats::default(),
            first_send: None,
            last_ack: None,
            ack_seq: 0,
            status_after_ack: false,
            reset_sent: false,
            end_detection: EndDetection::IdleAtEndPoint,
            all_answered: false,
            idle_at_end: 0,
            settings: std::collections::BTreeMap::new(),
            wco_seen: false,
            origin: None,
        }
    }
}

impl Session<'_> {
    /// Before a new job: the controller must be idle; its settings read; check mode first if asked; the
    /// work position before the first line (returned, when the controller reports one).
    fn prepare_fresh(&mut self, info: &Info) -> Result<Option<[f64; 3]>, StreamError> {
        self.require_idle(info, false)?;
        self.read_settings(info);
        self.require_arc_tolerance()?;
        if self.cfg.check_first {
            self.check_run()?;
        }
        self.ensure_wco()?;
        self.origin = self.status.as_ref().and_then(|st| self.work_position(st));
        Ok(self.origin)
    }

    /// A new job: the journal, then the whole program. Lines GRBL 1.1h will refuse, as the one interpreter
    /// reads them, are named first: the job will stop there with `error:N`.
    fn start_fresh(&mut self, journal_path: &Path) -> Result<Outcome, StreamError> {
        let refused: Vec<String> = self
            .program
            .lines
            .iter()
            .filter_map(|l| {
                l.refusal
                    .as_ref()
                    .map(|r| format!("line {} `{}`: error:{} ({r})", l.number, l.source.trim(), r.code))
            })
            .collect();
        if let Some(first) = refused.first() {
            let more = match refused.len() {
                1 => String::new(),
                n => format!(" and {} more", n - 1),
            };
            self.observer
                .note(&format!("GRBL 1.1h will refuse {first}{more}: the job will stop there"));
        }
        let mut j = Journal::create(journal_path)?;
        j.record_synced(&start_record(
            self.program,
            self.cfg,
            1,
            self.origin,
            self.wco_seen.then_some(self.wco),
        ))?;
        self.journal = Some(j);
        let queue = self
            .program
            .sendable()
            .map(|l| Outgoing::program_line(l, self.cfg.number_lines))
            .collect();
        self.stream(queue)
    }
}

fn start_record(
    program: &Program,
    cfg: &Config,
    from_line: usize,
    position_mm: Option<[f64; 3]>,
    wco_mm: Option<[f64; 3]>,
) -> Record {
    Record::Start {
        position_mm,
        wco_mm,
        version: VERSION,
        program: program.path.display().to_string(),
        fingerprint: program.fingerprint,
        lines: program.lines.len(),
        numbered: cfg.number_lines,
        from_line,
    }
}

fn record_located(j: &mut Journal, loc: &Located) -> Result<(), JournalError> {
    if let Some(why) = &loc.ambiguous {
        j.record(&Record::Ambiguous { message: why.clone() })?;
    }
    for (a, b) in ranges(&loc.executed) {
        j.record(&Record::Executed { from: a, to: b })?;
    }
    if let Some((line, at_mm)) = loc.partial {
        j.record(&Record::Partial { line, at_mm })?;
    }
    j.sync()
}

/// Consecutive runs of increasing line numbers.
fn ranges(v: &[usize]) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for &n in v {
        match out.last_mut() {
            Some((_, b)) if *b + 1 == n => *b = n,
            _ => out.push((n, n)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_group_consecutive_lines() {
        assert_eq!(ranges(&[1, 2, 3, 5, 7, 8]), vec![(1, 3), (5, 5), (7, 8)]);
    }
}
