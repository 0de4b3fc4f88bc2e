//! The streamer: handshake, optional `$C` check run, character-counted streaming with the journal, and a
//! safe stop on any fault — feed hold, wait until motion has stopped, read where it stopped, soft reset
//! (which flushes GRBL's buffers so nothing more runs), then work out exactly which lines executed.
//!
//! **What "executed" means.** An `ok` only means *planned*. A line is known executed when a status report
//! shows a later line executing (`Ln`), when the controller is idle with an empty planner, or — at a stop —
//! when the stop position places it before the point where motion stopped. The line executing at the stop
//! is recorded as *partial* with the stop point; a resume finishes it from there.

use std::collections::{BTreeSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::journal::{Journal, JournalError, JournalState, Record, VERSION};
use super::program::{LineKind, MotionMode, Program, Spindle, Units};
use super::protocol::{
    alarm_text, error_text, parse_response, Counter, Decision, MachineState, Realtime, Response, Status,
    RX_BUFFER_BYTES,
};
use super::serial::Link;

/// Streaming settings. Lengths in mm, feeds in mm/min.
#[derive(Debug, Clone)]
pub struct Config {
    /// Prefix every block with `N<file line>` so status reports name the executing line (`Ln`).
    pub number_lines: bool,
    /// Run the program in GRBL's `$C` check mode first; stream only if it has no error.
    pub check_first: bool,
    /// Report `error:N` and carry on instead of stopping.
    pub continue_on_error: bool,
    /// Height (work Z, mm) from which a resume approaches the resume point.
    pub safe_z_mm: f64,
    /// Spindle spin-up dwell after re-starting it on resume, s.
    pub spindle_dwell_s: f64,
    /// Plunge feed to the resume point when the program has no feed there yet, mm/min.
    pub plunge_feed_mm_min: f64,
    /// Allow `$X` (unlock) on resume even when the journal does not say the position was retained.
    pub unlock: bool,
    /// Status poll period (GRBL asks for at most 5 Hz: ≥ 200 ms).
    pub status_interval: Duration,
    /// How long the handshake may take.
    pub handshake_timeout: Duration,
    /// How long a feed hold may take to come to a stop.
    pub hold_timeout: Duration,
    /// How long the controller may stay silent (no status report, no answer) before the job is stopped.
    pub silence_timeout: Duration,
    /// How long a resume waits for the controller to finish what it was running.
    pub settle_timeout: Duration,
    /// Distance (mm) within which a reported position counts as lying on a line.
    pub position_tolerance_mm: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            number_lines: true,
            check_first: false,
            continue_on_error: false,
            safe_z_mm: 5.0,
            spindle_dwell_s: 2.0,
            plunge_feed_mm_min: 100.0,
            unlock: false,
            status_interval: Duration::from_millis(200),
            handshake_timeout: Duration::from_secs(5),
            hold_timeout: Duration::from_secs(30),
            silence_timeout: Duration::from_secs(5),
            settle_timeout: Duration::from_secs(600),
            position_tolerance_mm: 0.005,
        }
    }
}

/// Start afresh or resume from a journal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// A new job; the journal must not exist.
    Fresh,
    /// Continue the job in the journal.
    Resume,
}

/// What the progress display gets.
#[derive(Debug, Clone, Default)]
pub struct Progress {
    /// Program lines to run in this job (non-empty lines).
    pub lines_total: usize,
    /// Lines known executed.
    pub lines_done: usize,
    /// Lines answered `ok`.
    pub lines_acked: usize,
    /// Last reported machine state.
    pub state: Option<MachineState>,
    /// Last reported work position, mm.
    pub position_mm: Option<[f64; 3]>,
    /// Estimated time left.
    pub eta: Option<Duration>,
}

/// Receives progress and notes while streaming (the CLI draws a progress bar).
pub trait Observer {
    /// Progress changed.
    fn progress(&mut self, _p: &Progress) {}
    /// Something worth telling the user (a message from the controller, an error carried over).
    fn note(&mut self, _msg: &str) {}
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Silent;
impl Observer for Silent {}

/// Why a run stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StopReason {
    /// GRBL rejected a line.
    Error(u16),
    /// GRBL raised an alarm.
    Alarm(u16),
    /// The user asked (Ctrl-C).
    User,
    /// The link dropped.
    Disconnect,
    /// The controller did something the protocol does not allow (silence, unexpected reset, stray `ok`).
    Protocol,
}

/// A run that stopped before the end.
#[derive(Debug, Clone)]
pub struct StopReport {
    /// Why.
    pub reason: StopReason,
    /// The program line concerned (the rejected one, the one being parsed at an alarm, the one executing).
    pub line: Option<usize>,
    /// The controller's message, or what happened.
    pub message: String,
    /// Which lines executed is known exactly.
    pub located: bool,
    /// Lines known executed so far (whole job).
    pub lines_done: usize,
    /// Where a resume would start.
    pub resume_line: Option<usize>,
}

/// Figures of a run.
#[derive(Debug, Clone, Default)]
pub struct Stats {
    /// Lines written (program and synthetic).
    pub lines_sent: usize,
    /// Bytes written for those lines, newlines included.
    pub bytes_sent: usize,
    /// From the first line written to the last answer.
    pub streaming_time: Duration,
    /// Largest number of bytes in flight (must stay ≤ 127).
    pub max_in_flight: usize,
}

/// How a run ended.
#[derive(Debug, Clone)]
pub enum Outcome {
    /// Every line executed.
    Completed(Stats),
    /// Stopped safely before the end; the journal says where to resume.
    Stopped(StopReport, Stats),
}

/// Streaming failed before or outside a job (nothing was moved by this run when these are returned
/// before streaming starts).
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// The port answered, but not like GRBL 1.1.
    #[error("{port} does not answer like a GRBL 1.1 controller (no `[VER:1.1…]` or status report within {timeout:?}); received: {saw:?}")]
    NotGrbl {
        /// The port.
        port: String,
        /// The handshake timeout.
        timeout: Duration,
        /// What came back (first bytes).
        saw: String,
    },
    /// The link failed outside streaming.
    #[error("{port}: {what}")]
    Link {
        /// The port.
        port: String,
        /// What was being done.
        what: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The controller is in alarm and may not be unlocked automatically.
    #[error(
        "{port}: controller is in alarm{detail}; check the machine, home it ($H) or unlock it ($X), or pass --unlock"
    )]
    InAlarm {
        /// The port.
        port: String,
        /// What is known about the alarm.
        detail: String,
    },
    /// The controller did not reach an expected state in time.
    #[error("{port}: {what}")]
    Timeout {
        /// The port.
        port: String,
        /// What was awaited.
        what: String,
    },
    /// The check run found errors: nothing was run.
    #[error("{path}: check mode ($C) found {} problem(s), nothing was run:{}", problems.len(), list(problems))]
    CheckFailed {
        /// The program.
        path: PathBuf,
        /// `(line, message)`.
        problems: Vec<(usize, String)>,
    },
    /// The journal cannot be resumed.
    #[error("cannot resume from {journal}: {what}")]
    Resume {
        /// The journal.
        journal: PathBuf,
        /// Why.
        what: String,
    },
    /// Journal I/O or consistency.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// Interrupted by the user before streaming.
    #[error("interrupted before streaming started; nothing was run")]
    Interrupted,
}

fn list(p: &[(usize, String)]) -> String {
    let mut s: String = p.iter().take(10).map(|(l, m)| format!("\n  line {l}: {m}")).collect();
    if p.len() > 10 {
        s += &format!("\n  … and {} more", p.len() - 10);
    }
    s
}

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

/// What the handshake learned.
#[derive(Debug, Clone)]
struct Info {
    rx_bytes: usize,
    line_numbers: bool,
    status: Option<Status>,
    critical: bool,
}

struct Session<'a> {
    link: &'a mut dyn Link,
    program: &'a Program,
    cfg: &'a Config,
    observer: &'a mut dyn Observer,
    stop: &'a AtomicBool,
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
    let resume_state = match mode {
        Mode::Resume => {
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
            Some(st)
        }
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
    let now = Instant::now();
    let mut s = Session {
        link,
        program,
        cfg,
        observer,
        stop,
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
    };
    let info = s.handshake()?;
    s.counter = Counter::new(info.rx_bytes);
    s.line_numbers = info.line_numbers && cfg.number_lines;
    match resume_state {
        None => {
            s.require_idle(&info, false)?;
            if cfg.check_first {
                s.check_run()?;
            }
            let mut j = Journal::create(journal_path)?;
            j.record_synced(&start_record(program, cfg, 1))?;
            s.journal = Some(j);
            let queue = program
                .sendable()
                .map(|l| Outgoing {
                    text: l.wire_text(cfg.number_lines),
                    tag: Tag::Line(l.number),
                    alone: l.kind != LineKind::Gcode,
                })
                .collect();
            s.stream(queue)
        }
        Some(mut st) => {
            let retained = matches!(
                st.stop,
                Some(Record::Stop {
                    position_retained: true,
                    ..
                })
            );
            s.require_idle(&info, retained || cfg.unlock)?;
            let mut j = Journal::append(journal_path)?;
            let located = matches!(st.stop, Some(Record::Stop { located: true, .. }));
            if !located {
                // The last run ended without knowing what ran (a disconnect): the position tells.
                let status = s.settled_status()?;
                let p = s.work_position(&status).ok_or_else(|| StreamError::Resume {
                    journal: journal_path.to_path_buf(),
                    what: "the controller reports no position".into(),
                })?;
                let candidates: Vec<usize> = st
                    .sent
                    .iter()
                    .copied()
                    .filter(|n| !st.executed.contains(n) && !st.errors.iter().any(|e| e.0 == *n && !st.ok.contains(n)))
                    .collect();
                let loc = locate(program, &candidates, status.line, p, cfg.position_tolerance_mm).map_err(|what| {
                    StreamError::Resume {
                        journal: journal_path.to_path_buf(),
                        what: format!("cannot tell which lines ran before the link dropped: {what}"),
                    }
                })?;
                record_located(&mut j, &loc)?;
                for n in &loc.executed {
                    st.executed.insert(*n);
                }
                st.partial = loc.partial;
            }
            if program.sendable().all(|l| st.executed.contains(&l.number)) {
                // The controller finished everything before the fault was noticed.
                j.record_synced(&Record::Complete)?;
                return Ok(Outcome::Completed(Stats::default()));
            }
            let (first, queue) = plan_resume(program, &st, cfg).map_err(|what| StreamError::Resume {
                journal: journal_path.to_path_buf(),
                what,
            })?;
            s.executed = st.executed.clone();
            j.record_synced(&start_record(program, cfg, first))?;
            s.journal = Some(j);
            s.observer.note(&format!(
                "resuming at line {first} ({} lines already executed)",
                st.executed.len()
            ));
            s.stream(queue)
        }
    }
}

fn start_record(program: &Program, cfg: &Config, from_line: usize) -> Record {
    Record::Start {
        version: VERSION,
        program: program.path.display().to_string(),
        fingerprint: program.fingerprint,
        lines: program.lines.len(),
        numbered: cfg.number_lines,
        from_line,
    }
}

fn record_located(j: &mut Journal, loc: &Located) -> Result<(), JournalError> {
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

impl Session<'_> {
    fn port(&self) -> String {
        self.link.name().to_string()
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), Fault> {
        self.link
            .write_all(bytes)
            .map_err(|e| Fault::Disconnect(format!("write failed: {e}")))
    }

    /// Next complete line from the controller, waiting at most `timeout`.
    fn read_line(&mut self, timeout: Duration) -> Result<Option<String>, Fault> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(i) = self.rbuf.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = self.rbuf.drain(..=i).collect();
                let text = String::from_utf8_lossy(&raw).trim().to_string();
                if text.is_empty() {
                    continue;
                }
                self.last_rx = Instant::now();
                return Ok(Some(text));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let mut buf = [0u8; 512];
            let n = self
                .link
                .read(&mut buf, deadline - now)
                .map_err(|e| Fault::Disconnect(format!("read failed: {e}")))?;
            if self.saw.len() < 120 {
                self.saw.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
            self.rbuf.extend_from_slice(&buf[..n]);
        }
    }

    fn link_err(&self, what: &str, f: Fault) -> StreamError {
        let msg = match f {
            Fault::Disconnect(m) | Fault::Protocol(m) => m,
            other => format!("{other:?}"),
        };
        StreamError::Link {
            port: self.port(),
            what: what.into(),
            source: std::io::Error::new(std::io::ErrorKind::BrokenPipe, msg),
        }
    }

    /// Wake the controller and identify it: `\r\n\r\n`, then `$I` (expects `[VER:1.1…]`, `[OPT:…]`, `ok`)
    /// and `?`. A banner in between means the board just reset: the probe is repeated. A controller
    /// locked in a critical alarm answers only `?`; it is soft-reset once (motion has stopped in alarm).
    fn handshake(&mut self) -> Result<Info, StreamError> {
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        let mut info = Info {
            rx_bytes: RX_BUFFER_BYTES,
            line_numbers: false,
            status: None,
            critical: false,
        };
        self.write(b"\r\n\r\n").map_err(|f| self.link_err("wake-up", f))?;
        let mut probe_sent = false;
        let mut got_ver = false;
        let mut got_opt = false;
        let mut reset_sent = false;
        let mut first_status_at: Option<Instant> = None;
        let mut resend_at: Option<Instant> = None;
        loop {
            if resend_at.is_some_and(|t| Instant::now() >= t) {
                resend_at = None;
                probe_sent = false;
            }
            if self.stop.load(Ordering::SeqCst) {
                return Err(StreamError::Interrupted);
            }
            if !probe_sent {
                self.write(b"$I\n?").map_err(|f| self.link_err("handshake", f))?;
                probe_sent = true;
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(StreamError::NotGrbl {
                    port: self.port(),
                    timeout: self.cfg.handshake_timeout,
                    saw: self.saw.clone(),
                });
            }
            let line = self
                .read_line((deadline - now).min(Duration::from_millis(100)))
                .map_err(|f| self.link_err("handshake", f))?;
            let Some(line) = line else {
                // Locked in a critical alarm: `$I` is not processed, `?` is.
                if let (Some(t), Some(st)) = (first_status_at, &info.status) {
                    if st.state == Some(MachineState::Alarm) && !reset_sent && t.elapsed() > Duration::from_millis(500)
                    {
                        self.write(&[Realtime::SoftReset.byte()])
                            .map_err(|f| self.link_err("reset", f))?;
                        reset_sent = true;
                        info.critical = true;
                    }
                }
                continue;
            };
            match parse_response(&line) {
                Response::Banner(_) => {
                    // A (re)start — or a banner printed before the port was opened. If the probe was lost
                    // in a reset, ask again, but only once it is clear no answer is coming: a second `$I`
                    // whose `ok` arrived during streaming would be taken for a program line's.
                    got_ver = false;
                    got_opt = false;
                    resend_at = Some(Instant::now() + Duration::from_millis(1500));
                }
                Response::Feedback(f) if f.starts_with("VER:") => {
                    if !f.starts_with("VER:1.1") {
                        return Err(StreamError::NotGrbl {
                            port: self.port(),
                            timeout: self.cfg.handshake_timeout,
                            saw: format!("[{f}] (GRBL other than 1.1)"),
                        });
                    }
                    got_ver = true;
                    resend_at = None;
                }
                Response::Feedback(f) if f.starts_with("OPT:") => {
                    let parts: Vec<&str> = f[4..].split(',').collect();
                    info.line_numbers = parts.first().is_some_and(|o| o.contains('N'));
                    if let Some(rx) = parts.get(2).and_then(|r| r.parse().ok()) {
                        info.rx_bytes = rx;
                    }
                    got_opt = true;
                }
                Response::Ok if got_ver && got_opt => {
                    // `$I`'s own ok: every earlier probe byte has been answered (answers come in order).
                    self.write(b"?").map_err(|f| self.link_err("handshake", f))?;
                    loop {
                        let now = Instant::now();
                        if now >= deadline {
                            return Err(StreamError::NotGrbl {
                                port: self.port(),
                                timeout: self.cfg.handshake_timeout,
                                saw: self.saw.clone(),
                            });
                        }
                        if let Some(l) = self
                            .read_line(deadline - now)
                            .map_err(|f| self.link_err("handshake", f))?
                        {
                            if let Response::Status(st) = parse_response(&l) {
                                self.on_status(st.clone());
                                info.status = Some(st);
                                return Ok(info);
                            }
                        }
                    }
                }
                Response::Status(st) => {
                    first_status_at.get_or_insert_with(Instant::now);
                    info.status = Some(st);
                }
                _ => {}
            }
        }
    }

    /// The controller must be idle to start; in alarm it is unlocked only when allowed.
    fn require_idle(&mut self, info: &Info, may_unlock: bool) -> Result<(), StreamError> {
        let state = info.status.as_ref().and_then(|s| s.state);
        match state {
            Some(MachineState::Idle) => Ok(()),
            Some(MachineState::Alarm) if may_unlock => {
                self.observer.note("controller in alarm: unlocking ($X)");
                self.command_alone("$X")
            }
            Some(MachineState::Alarm) => Err(StreamError::InAlarm {
                port: self.port(),
                detail: if info.critical {
                    " (it needed a reset)".into()
                } else {
                    String::new()
                },
            }),
            Some(MachineState::Run | MachineState::Hold { .. } | MachineState::Jog) => {
                let st = self.settled_status()?;
                if st.state == Some(MachineState::Idle) {
                    Ok(())
                } else {
                    Err(StreamError::Timeout {
                        port: self.port(),
                        what: format!(
                            "controller is {} and must be Idle to start",
                            st.state.map_or("unknown".into(), |s| s.to_string())
                        ),
                    })
                }
            }
            other => Err(StreamError::Timeout {
                port: self.port(),
                what: format!(
                    "controller is {} and must be Idle to start",
                    other.map_or("in an unknown state".into(), |s| s.to_string())
                ),
            }),
        }
    }

    /// Send one line alone and wait for its `ok` (handshake-time commands).
    fn command_alone(&mut self, cmd: &str) -> Result<(), StreamError> {
        self.write(format!("{cmd}\n").as_bytes())
            .map_err(|f| self.link_err(cmd, f))?;
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        while Instant::now() < deadline {
            let line = self
                .read_line(Duration::from_millis(100))
                .map_err(|f| self.link_err(cmd, f))?;
            if let Some(l) = line {
                match parse_response(&l) {
                    Response::Ok => return Ok(()),
                    Response::Error(c) => {
                        return Err(StreamError::Timeout {
                            port: self.port(),
                            what: format!("`{cmd}` answered error:{c} ({})", error_text(c)),
                        })
                    }
                    Response::Status(st) => self.on_status(st),
                    _ => {}
                }
            }
        }
        Err(StreamError::Timeout {
            port: self.port(),
            what: format!("no answer to `{cmd}`"),
        })
    }

    /// Poll until the controller is neither running nor holding (bounded by `settle_timeout`).
    fn settled_status(&mut self) -> Result<Status, StreamError> {
        let deadline = Instant::now() + self.cfg.settle_timeout;
        loop {
            let seq = self.status_seq;
            self.write(b"?").map_err(|f| self.link_err("status", f))?;
            let asked = Instant::now();
            while self.status_seq == seq && asked.elapsed() < Duration::from_secs(2) {
                if let Some(l) = self
                    .read_line(Duration::from_millis(50))
                    .map_err(|f| self.link_err("status", f))?
                {
                    if let Response::Status(st) = parse_response(&l) {
                        self.on_status(st);
                    }
                }
            }
            if let Some(st) = self.status.clone() {
                let busy = matches!(
                    st.state,
                    Some(MachineState::Run | MachineState::Jog | MachineState::Home)
                ) || matches!(st.state, Some(MachineState::Hold { sub: 1 }))
                    || (st.state == Some(MachineState::Idle) && st.line.is_some());
                if !busy && self.status_seq != seq {
                    return Ok(st);
                }
            }
            if Instant::now() >= deadline {
                return Err(StreamError::Timeout {
                    port: self.port(),
                    what: format!("controller still busy after {:?}", self.cfg.settle_timeout),
                });
            }
            std::thread::sleep(self.cfg.status_interval.max(Duration::from_millis(200)));
        }
    }

    fn work_position(&self, st: &Status) -> Option<[f64; 3]> {
        if let Some(w) = st.wpos {
            return Some(w);
        }
        st.mpos
            .map(|m| [m[0] - self.wco[0], m[1] - self.wco[1], m[2] - self.wco[2]])
    }

    /// An `ok` (`code` = None) or `error:code` that arrives while stopping: credit it to the oldest line in
    /// flight and journal it best-effort (the stop itself must not fail on the journal).
    fn late_answer(&mut self, code: Option<u16>) {
        if let Some(Tag::Line(n)) = self.counter.answered() {
            match code {
                None => {
                    let _ = self.journal(&Record::Ok { line: n });
                    self.planned.push_back(n);
                }
                Some(code) => {
                    let _ = self.journal(&Record::Error { line: n, code });
                    self.errors.insert(n);
                }
            }
        }
    }

    fn on_status(&mut self, st: Status) {
        if let Some(w) = st.wco {
            self.wco = w;
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
        } else if st.state == Some(MachineState::Idle) && self.planner_known_empty(&st) {
            newly.extend(self.planned.drain(..));
        }
        self.mark_executed(&newly);
        self.status = Some(st);
        self.report_progress();
    }

    /// Idle with nothing in the planner: without `Ln` (when line numbers are reported) or with `Bf` full.
    fn planner_known_empty(&self, st: &Status) -> bool {
        (self.line_numbers && st.line.is_none()) || st.planner_free == Some(super::protocol::PLANNER_BLOCKS)
    }

    fn mark_executed(&mut self, lines: &[usize]) {
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

    fn journal(&mut self, r: &Record) -> Result<(), Fault> {
        match self.journal.as_mut() {
            Some(j) => j
                .record(r)
                .map_err(|e| Fault::Protocol(format!("journal write failed: {e}"))),
            None => Ok(()),
        }
    }

    fn maybe_poll(&mut self) -> Result<(), Fault> {
        let now = Instant::now();
        if now >= self.next_poll {
            self.write(&[Realtime::Status.byte()])?;
            self.next_poll = now + self.cfg.status_interval.max(Duration::from_millis(200));
        }
        Ok(())
    }

    /// Handle one received line while streaming; returns a fault when the job must stop.
    fn handle(&mut self, line: &str) -> Result<Option<Fault>, Fault> {
        match parse_response(line) {
            Response::Ok => {
                let tag = self
                    .counter
                    .answered()
                    .ok_or_else(|| Fault::Protocol("`ok` with no line in flight".into()))?;
                self.last_ack = Some(Instant::now());
                self.ack_seq += 1;
                self.status_after_ack = false;
                if let Tag::Line(n) = tag {
                    self.journal(&Record::Ok { line: n })?;
                    self.planned.push_back(n);
                }
            }
            Response::Error(code) => {
                let tag = self
                    .counter
                    .answered()
                    .ok_or_else(|| Fault::Protocol(format!("`error:{code}` with no line in flight")))?;
                self.last_ack = Some(Instant::now());
                self.status_after_ack = false;
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
                        } else {
                            return Ok(Some(Fault::Error { line: Some(n), code }));
                        }
                    }
                    Tag::Synthetic => return Ok(Some(Fault::Error { line: None, code })),
                }
            }
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

    /// The `$C` check run: every line parsed by GRBL without moving; errors collected.
    fn check_run(&mut self) -> Result<(), StreamError> {
        self.command_alone("$C")?;
        let mut problems = Vec::new();
        let mut q: VecDeque<(usize, String)> = self
            .program
            .sendable()
            .filter(|l| l.kind == LineKind::Gcode)
            .map(|l| (l.number, l.wire_text(self.cfg.number_lines)))
            .collect();
        let mut counter: Counter<usize> = self.counter.clone_empty();
        let mut alarm = None;
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
                    alarm = Some((n, format!("ALARM:{c} ({})", alarm_text(c))));
                    break;
                }
                _ => {}
            }
        }
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

    fn wait_banner(&mut self) -> Result<(), StreamError> {
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        while Instant::now() < deadline {
            if let Some(l) = self
                .read_line(Duration::from_millis(100))
                .map_err(|f| self.link_err("reset", f))?
            {
                if matches!(parse_response(&l), Response::Banner(_)) {
                    return Ok(());
                }
            }
        }
        Err(StreamError::Timeout {
            port: self.port(),
            what: "no banner after reset".into(),
        })
    }

    fn reset_and_wait_banner(&mut self) -> Result<(), StreamError> {
        self.write(&[Realtime::SoftReset.byte()])
            .map_err(|f| self.link_err("reset", f))?;
        self.wait_banner()
    }

    /// Stream the queue. Returns when everything executed or after a safe stop.
    fn stream(&mut self, queue: Vec<Outgoing>) -> Result<Outcome, StreamError> {
        let mut q: VecDeque<Outgoing> = queue.into();
        self.started = Instant::now();
        self.last_rx = Instant::now();
        let run = self.stream_loop(&mut q);
        match run {
            Ok(()) => {
                if let Some(j) = self.journal.as_mut() {
                    j.record_synced(&Record::Complete)?;
                }
                Ok(Outcome::Completed(self.stats.clone()))
            }
            Err(f) => self.safe_stop(f),
        }
    }

    fn stream_loop(&mut self, q: &mut VecDeque<Outgoing>) -> Result<(), Fault> {
        loop {
            if self.stop.load(Ordering::SeqCst) {
                return Err(Fault::User);
            }
            self.maybe_poll()?;
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
            if q.is_empty() && self.counter.outstanding() == 0 {
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

    fn idle(&self) -> bool {
        self.status.as_ref().is_some_and(|s| {
            matches!(
                s.state,
                Some(MachineState::Idle | MachineState::Alarm | MachineState::Check)
            ) && s.line.is_none()
        })
    }

    /// Stop safely after `fault` and find out exactly what ran.
    fn safe_stop(&mut self, fault: Fault) -> Result<Outcome, StreamError> {
        let (reason, mut line, mut message) = match &fault {
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
                format!("ALARM:{code} ({})", alarm_text(*code)),
            ),
            Fault::User => (StopReason::User, None, "stopped by the user (Ctrl-C)".to_string()),
            Fault::Disconnect(m) => (StopReason::Disconnect, None, format!("link lost: {m}")),
            Fault::Protocol(m) => (StopReason::Protocol, None, m.clone()),
        };
        let mut located = false;
        let mut retained = false;
        if !matches!(fault, Fault::Disconnect(_)) {
            match self.hold_and_reset(&fault) {
                Ok((stopped, after)) => {
                    retained = match &fault {
                        Fault::Alarm(c) => *c == 2,
                        _ => stopped.as_ref().is_some_and(|s| {
                            matches!(s.state, Some(MachineState::Hold { sub: 0 } | MachineState::Idle))
                        }),
                    };
                    let ln = stopped.as_ref().and_then(|s| s.line);
                    let p = after.as_ref().or(stopped.as_ref()).and_then(|s| self.work_position(s));
                    // Only planned lines (answered `ok`) can have run: the rest were flushed by the reset
                    // or, at an alarm, never parsed.
                    let candidates: Vec<usize> = self.planned.iter().copied().collect();
                    match p {
                        Some(p) => match locate(self.program, &candidates, ln, p, self.cfg.position_tolerance_mm) {
                            Ok(loc) => {
                                if line.is_none() {
                                    line = loc.partial.map(|x| x.0).or_else(|| loc.executed.last().copied());
                                }
                                self.planned.clear();
                                for n in &loc.executed {
                                    self.executed.insert(*n);
                                }
                                if let Some(j) = self.journal.as_mut() {
                                    record_located(j, &loc)?;
                                }
                                located = true;
                            }
                            Err(e) => message += &format!("; cannot tell which lines ran: {e}"),
                        },
                        None => message += "; the controller reported no position",
                    }
                }
                Err(e) => message += &format!("; stopping: {e}"),
            }
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

    /// Feed hold (unless an alarm already stopped motion), wait for a stopped state, then soft reset
    /// so nothing buffered runs. Returns the status seen stopped (before the reset) and one after.
    fn hold_and_reset(&mut self, fault: &Fault) -> Result<(Option<Status>, Option<Status>), String> {
        let alarm = matches!(fault, Fault::Alarm(_));
        if !alarm {
            self.write(&[Realtime::FeedHold.byte()]).map_err(|e| format!("{e:?}"))?;
        }
        let seq0 = self.status_seq;
        self.next_poll = Instant::now();
        let deadline = Instant::now() + self.cfg.hold_timeout;
        let mut stopped = None;
        while Instant::now() < deadline {
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
                            stopped = Some(st);
                            break;
                        }
                    }
                    _ => {}
                }
            }
        }
        if stopped.is_none() {
            return Err(format!("motion did not stop within {:?}", self.cfg.hold_timeout));
        }
        // Flush GRBL's receive buffer and planner: nothing more may run.
        self.write(&[Realtime::SoftReset.byte()])
            .map_err(|e| format!("{e:?}"))?;
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        let mut banner = false;
        while Instant::now() < deadline && !banner {
            if let Some(l) = self
                .read_line(Duration::from_millis(50))
                .map_err(|e| format!("{e:?}"))?
            {
                match parse_response(&l) {
                    Response::Ok => self.late_answer(None),
                    Response::Error(code) => self.late_answer(Some(code)),
                    Response::Banner(_) => banner = true,
                    Response::Status(st) => self.on_status(st),
                    _ => {}
                }
            }
        }
        if !banner {
            return Err("no banner after the soft reset".into());
        }
        self.counter.flush();
        // One fresh report after the reset: the position where everything stopped.
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
        let after = (self.status_seq != seq).then(|| self.status.clone()).flatten();
        Ok((stopped, after))
    }
}

impl<T: Clone> Counter<T> {
    /// An empty counter with the same capacity.
    fn clone_empty<U: Clone>(&self) -> Counter<U> {
        Counter::new(self.capacity() + 1)
    }
}

/// Which of the candidate lines ran, from where motion stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// Candidates that executed completely, in order.
    pub executed: Vec<usize>,
    /// The candidate cut mid-way and the stop point (work coordinates, mm).
    pub partial: Option<(usize, [f64; 3])>,
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn known(p: [Option<f64>; 3]) -> Option<[f64; 3]> {
    Some([p[0]?, p[1]?, p[2]?])
}

/// Given the lines that may have run (`candidates`, in order; execution is a prefix of them), the line
/// reported executing when motion stopped (`ln`, if the controller reports `Ln`) and the stop position
/// `p` (work mm), find which candidates ran completely and which one was cut, and where.
///
/// Every point along the candidates' path that lies within `tol` of `p` is a consistent explanation; if
/// two of them are separated by a moving line, the answer is ambiguous and an error is returned rather
/// than a guess. Otherwise the furthest explanation is taken (the lines between are non-moving ones).
pub fn locate(
    program: &Program,
    candidates: &[usize],
    ln: Option<u32>,
    p: [f64; 3],
    tol: f64,
) -> Result<Located, String> {
    let cands: Vec<usize> = candidates.to_vec();
    let pre = Vec::new();
    if let Some(ln) = ln.map(|l| l as usize).filter(|l| cands.contains(l)) {
        // The controller names the line: every candidate before it ran; where on it motion stopped
        // decides between complete, not started and cut (which needs no known start point).
        let mut executed: Vec<usize> = cands.iter().copied().filter(|&n| n < ln).collect();
        let l = program
            .line(ln)
            .ok_or_else(|| format!("line {ln} is not in the program"))?;
        let (start, end) = (known(l.start_mm), known(l.end_mm));
        if !l.moves || end.is_some_and(|b| dist(b, p) <= tol) {
            executed.push(ln);
            return Ok(Located {
                executed,
                partial: None,
            });
        }
        if start.is_some_and(|a| dist(a, p) <= tol) {
            return Ok(Located {
                executed,
                partial: None,
            });
        }
        if let (Some(a), Some(b)) = (start, end) {
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            let t = ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1] + (p[2] - a[2]) * d[2]) / len2;
            let q = [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]];
            if dist(q, p) > tol || !(0.0..=1.0).contains(&t) {
                return Err(format!(
                    "the controller reports line {ln} executing but the stop position ({:.3}, {:.3}, {:.3}) is not on it",
                    p[0], p[1], p[2]
                ));
            }
        }
        return Ok(Located {
            executed,
            partial: Some((ln, p)),
        });
    }
    // Progress = (index, fraction): candidates[..index] complete, candidates[index] done up to fraction.
    let mut consistent: Vec<(usize, f64)> = Vec::new();
    for (i, &n) in cands.iter().enumerate() {
        let l = program
            .line(n)
            .ok_or_else(|| format!("line {n} is not in the program"))?;
        if !l.moves {
            if let Some(s) = known(l.start_mm) {
                if dist(s, p) <= tol {
                    consistent.push((i, 0.0));
                    consistent.push((i + 1, 0.0));
                }
            } else if i == 0 && cands.len() == 1 {
                consistent.push((1, 0.0));
            }
            continue;
        }
        let Some(b) = known(l.end_mm) else {
            return Err(format!("line {n}'s end position is unknown to the program model"));
        };
        if dist(b, p) <= tol {
            consistent.push((i + 1, 0.0));
        }
        // From an unknown start only the end can be recognised.
        let Some(a) = known(l.start_mm) else { continue };
        if dist(a, p) <= tol {
            consistent.push((i, 0.0));
        }
        if matches!(l.motion, Some(MotionMode::Rapid | MotionMode::Linear)) {
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            let t = ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1] + (p[2] - a[2]) * d[2]) / len2;
            let q = [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]];
            if t > 0.0 && t < 1.0 && dist(q, p) <= tol && dist(a, p) > tol && dist(b, p) > tol {
                consistent.push((i, t));
            }
        }
    }
    if cands.is_empty() {
        return Ok(Located {
            executed: pre,
            partial: None,
        });
    }
    if consistent.is_empty() {
        // Nothing ran yet: the position is where the first candidate starts.
        return Err(format!(
            "the stop position ({:.3}, {:.3}, {:.3}) lies on none of lines {:?}",
            p[0],
            p[1],
            p[2],
            &cands[..cands.len().min(8)]
        ));
    }
    let cmp = |x: &(usize, f64), y: &(usize, f64)| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1));
    let lo = *consistent.iter().min_by(|x, y| cmp(x, y)).expect("non-empty");
    let hi = *consistent.iter().max_by(|x, y| cmp(x, y)).expect("non-empty");
    let spans_motion = (lo.0..hi.0).any(|i| program.line(cands[i]).is_some_and(|l| l.moves));
    if spans_motion {
        return Err(format!(
            "the stop position ({:.3}, {:.3}, {:.3}) is on the path more than once (lines {} and {})",
            p[0],
            p[1],
            p[2],
            cands[lo.0],
            cands[(hi.0).min(cands.len() - 1)]
        ));
    }
    let mut executed = pre;
    executed.extend_from_slice(&cands[..hi.0.min(cands.len())]);
    let partial = (hi.1 > 0.0 && hi.0 < cands.len()).then(|| (cands[hi.0], p));
    Ok(Located { executed, partial })
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
    let line = program.line(first).expect("first is a program line");
    let moved = st.executed.iter().any(|&n| program.line(n).is_some_and(|l| l.moves)) || st.partial.is_some();
    let partial = st.partial.filter(|(n, _)| *n == first);
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
    let restore = |m: &super::program::Modal| {
        let k = if m.units == Units::Inch { 25.4 } else { 1.0 };
        let mut s = String::from(if m.units == Units::Inch { "G20" } else { "G21" });
        s += if m.distance == super::program::Distance::Incremental {
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
    };
    let mut queue: Vec<Outgoing> = pre
        .into_iter()
        .map(|text| Outgoing {
            text,
            tag: Tag::Synthetic,
            alone: false,
        })
        .collect();
    let mut rest_from = first;
    if let Some((n, _)) = partial {
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
        queue.push(Outgoing {
            text: format!(
                "{num}G21G90{mode}X{}Y{}Z{}{feed}",
                fmt_mm(end[0]),
                fmt_mm(end[1]),
                fmt_mm(end[2])
            ),
            tag: Tag::Line(n),
            alone: false,
        });
        queue.push(Outgoing {
            text: restore(&line.after),
            tag: Tag::Synthetic,
            alone: false,
        });
        rest_from = n + 1;
    } else {
        queue.push(Outgoing {
            text: restore(&m),
            tag: Tag::Synthetic,
            alone: false,
        });
    }
    for l in program.sendable().filter(|l| l.number >= rest_from) {
        queue.push(Outgoing {
            text: l.wire_text(cfg.number_lines),
            tag: Tag::Line(l.number),
            alone: l.kind != LineKind::Gcode,
        });
    }
    Ok((first, queue))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prog(text: &str) -> Program {
        Program::parse(Path::new("t.nc"), text, 1, true).unwrap()
    }

    const SQUARE: &str = "G21G90\nG0X0Y0Z1\nM3S1000\nG1Z-1F100\nG1X10\nG1Y10\nG1X0\nG1Y0\nG0Z1\n";

    #[test]
    fn locates_a_stop_inside_a_line() {
        let p = prog(SQUARE);
        let c: Vec<usize> = (4..=9).collect();
        let loc = locate(&p, &c, None, [10.0, 4.0, -1.0], 0.005).unwrap();
        assert_eq!(loc.executed, vec![4, 5]);
        assert_eq!(loc.partial, Some((6, [10.0, 4.0, -1.0])));
        // With Ln the line is named by the controller.
        let loc = locate(&p, &c, Some(6), [10.0, 4.0, -1.0], 0.005).unwrap();
        assert_eq!(loc.executed, vec![4, 5]);
        // At a corner: the line ending there is complete, the next not started.
        let loc = locate(&p, &c, None, [10.0, 10.0, -1.0], 0.005).unwrap();
        assert_eq!((loc.executed, loc.partial), (vec![4, 5, 6], None));
    }

    #[test]
    fn refuses_ambiguous_and_unknown_positions() {
        let p = prog(SQUARE);
        let c: Vec<usize> = (4..=9).collect();
        // (0,0,-1) is both where line 5 starts and where line 8 ends: a full square apart.
        assert!(locate(&p, &c, None, [0.0, 0.0, -1.0], 0.005)
            .unwrap_err()
            .contains("more than once"));
        assert!(locate(&p, &c, None, [3.0, 3.0, 3.0], 0.005)
            .unwrap_err()
            .contains("none of"));
    }

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

    #[test]
    fn ranges_group_consecutive_lines() {
        assert_eq!(ranges(&[1, 2, 3, 5, 7, 8]), vec![(1, 3), (5, 5), (7, 8)]);
    }
}
