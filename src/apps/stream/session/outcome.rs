//! What a run reports: progress while streaming (through an [`Observer`]) and how it ended ([`Outcome`]:
//! completed, or stopped with a [`StopReport`] saying why, where and where a resume would start). These are
//! the types the CLI draws and the tests assert on; the streamer only fills them in.

use std::time::Duration;

use crate::apps::stream::protocol::MachineState;

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
    /// The `$C` check run (`--check`) ended: one line that says how, `check passed: N lines, no error` or
    /// `check failed at line N: error:K (…)…; nothing was run`. The default passes it on as a note.
    fn check_result(&mut self, line: &str) {
        self.note(line);
    }
    /// Asked before the soft reset that follows a critical alarm (`alarm` says which and what to check).
    /// Motion has already stopped; the reset only lets the controller answer again. `false` leaves the
    /// controller in alarm, and nothing more is sent: a `--resume` resets it later and reads where motion
    /// stopped. The default resets.
    fn reset_after_alarm(&mut self, _alarm: &str) -> bool {
        true
    }
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
    /// How the end of the job was read.
    pub end_detection: Option<EndDetection>,
}

/// How the streamer learns that the last line has executed, from what the controller offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndDetection {
    /// `Ln` in status reports (a build with `USE_LINE_NUMBERS`, `N` in `[OPT:]`, and numbered blocks):
    /// idle with no `Ln` means the planner is empty.
    LineNumbers,
    /// `Bf` in status reports (`$10` bit 2): idle with all 15 planner blocks free.
    PlannerBlocks,
    /// Neither (a stock build with `$10=1`): every line answered, then Idle on consecutive status
    /// reports at the program's end point.
    IdleAtEndPoint,
}

impl std::fmt::Display for EndDetection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            EndDetection::LineNumbers => "line numbers (Ln) in status reports",
            EndDetection::PlannerBlocks => "planner blocks free (Bf) in status reports",
            EndDetection::IdleAtEndPoint => "Idle on consecutive status reports at the program's end point",
        })
    }
}

/// How a run ended.
#[derive(Debug, Clone)]
pub enum Outcome {
    /// Every line executed.
    Completed(Stats),
    /// Stopped safely before the end; the journal says where to resume.
    Stopped(StopReport, Stats),
}
