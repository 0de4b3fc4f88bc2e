//! What a run is told: the streaming settings ([`Config`]) and whether it starts afresh or resumes
//! ([`Mode`]). Kept apart from the streamer so the CLI and the tests can build a run's settings without
//! reading the streaming code.

use std::time::Duration;

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
    /// On resume: the user re-established the machine's position after the controller restarted (homed, or
    /// set the work coordinates of where the tool stands), so its report is the truth again.
    pub position_reestablished: bool,
    /// On resume: lines GRBL rejected (`error:N`) that the user chose to leave out, on purpose.
    pub skip_lines: Vec<usize>,
    /// Stream even when the controller's arc tolerance `$12` is coarser than the program's header asks
    /// (`controller: $12=…`, the tolerance its verdict's simulation cut the arcs with).
    pub accept_coarser_arcs: bool,
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
            position_reestablished: false,
            skip_lines: Vec::new(),
            accept_coarser_arcs: false,
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
