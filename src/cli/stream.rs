//! `brdfmill stream`: send a G-code program to a GRBL 1.1 controller (see `docs/STREAM.md`).

use std::os::fd::AsFd;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use brdfmill::apps::stream::program::Program;
use brdfmill::apps::stream::serial::{SerialLink, DEFAULT_BAUD};
use brdfmill::apps::stream::session::{self, Config, Mode, Observer, Outcome, Progress, StopReason};

/// Arguments of `brdfmill stream`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The G-code program.
    pub program: PathBuf,
    /// Serial port of the controller (e.g. /dev/ttyUSB0, or the path `brdfmill emulate` prints).
    #[arg(long)]
    pub port: PathBuf,
    /// Serial speed, bits/s (8N1).
    #[arg(long, default_value_t = DEFAULT_BAUD)]
    pub baud: u32,
    /// Run the whole program in GRBL's $C check mode first; stream only if it has no error.
    #[arg(long)]
    pub check: bool,
    /// Journal file [default: PROGRAM.journal.jsonl].
    #[arg(long)]
    pub journal: Option<PathBuf>,
    /// Resume the interrupted job recorded in the journal.
    #[arg(long)]
    pub resume: bool,
    /// Report `error:N` and carry on instead of stopping the job.
    #[arg(long)]
    pub continue_on_error: bool,
    /// Safe height for the resume approach (work Z, mm).
    #[arg(long, default_value_t = 5.0)]
    pub safe_z_mm: f64,
    /// Spindle spin-up dwell on resume (s).
    #[arg(long, default_value_t = 2.0)]
    pub spindle_dwell_s: f64,
    /// Plunge feed on resume when the program has no feed rate there yet (mm/min).
    #[arg(long, default_value_t = 100.0)]
    pub plunge_feed_mm_min: f64,
    /// On resume, unlock ($X) a controller in alarm even when the journal does not show the position was kept.
    #[arg(long)]
    pub unlock: bool,
    /// On resume after the controller restarted: you re-established its position (homed, or set the work
    /// coordinates of where the tool stands), so its report is the truth again.
    #[arg(long)]
    pub position_reestablished: bool,
    /// On resume: leave out line N, which GRBL rejected (error:N), on purpose (journaled; repeatable).
    #[arg(long = "skip-line", value_name = "N")]
    pub skip_line: Vec<usize>,
    /// Do not prefix blocks with N line numbers (status reports then cannot name the executing line).
    #[arg(long)]
    pub no_line_numbers: bool,
    /// Stream even when the controller's arc tolerance `$12` is coarser than the program's header asks (the
    /// `$12` its verdict's simulation cut the arcs with): its arcs are then cut further from the design
    #[arg(long)]
    pub accept_coarser_arcs: bool,
}

struct Bar {
    bar: indicatif::ProgressBar,
    /// The keys typed, when the streamer reads a terminal: the alarm's question is asked there.
    keys: Option<std::sync::mpsc::Receiver<u8>>,
    /// Ctrl-C.
    stop: Arc<AtomicBool>,
}

impl Observer for Bar {
    fn progress(&mut self, p: &Progress) {
        self.bar.set_length(p.lines_total as u64);
        self.bar.set_position(p.lines_done as u64);
        let state = p.state.map_or("?".to_string(), |s| s.to_string());
        let pos = p
            .position_mm
            .map_or(String::new(), |q| format!(" X{:.3} Y{:.3} Z{:.3}", q[0], q[1], q[2]));
        let eta = p.eta.map_or(String::new(), |e| format!(" ETA {}s", e.as_secs()));
        self.bar.set_message(format!("{state}{pos}{eta}"));
    }
    fn reset_after_alarm(&mut self, alarm: &str) -> bool {
        use std::sync::mpsc::RecvTimeoutError;
        let Some(keys) = &self.keys else {
            return true; // no terminal to ask: reset, as a script expects
        };
        while keys.try_recv().is_ok() {} // what was typed before the alarm answers nothing
        self.bar.println(format!(
            "{alarm}\nMotion has stopped. Reset the controller now (it answers nothing until reset)? Enter or y: reset; n or Ctrl-C: leave it in alarm"
        ));
        loop {
            if self.stop.load(Ordering::SeqCst) {
                self.bar.println("left in alarm (Ctrl-C)");
                return false;
            }
            match keys.recv_timeout(Duration::from_millis(100)) {
                Ok(b'y' | b'Y' | b'\r' | b'\n') => return true,
                Ok(b'n' | b'N') => {
                    self.bar.println("left in alarm");
                    return false;
                }
                Ok(_) | Err(RecvTimeoutError::Timeout) => {}
                // the terminal went away: nobody to ask
                Err(RecvTimeoutError::Disconnected) => return true,
            }
        }
    }
    fn note(&mut self, msg: &str) {
        // off a terminal the bar is hidden and would drop the line
        if self.bar.is_hidden() {
            eprintln!("{msg}");
        } else {
            self.bar.println(msg);
        }
    }
    fn check_result(&mut self, line: &str) {
        // the result, on stdout with the job's own (a failed check ends the run with it)
        self.bar.suspend(|| println!("{line}"));
    }
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    let journal = a.journal.clone().unwrap_or_else(|| {
        let mut p = a.program.clone().into_os_string();
        p.push(".journal.jsonl");
        PathBuf::from(p)
    });
    // Everything about the program is checked before the port is touched.
    let program = Program::read(&a.program, !a.no_line_numbers)?;
    let cfg = Config {
        number_lines: !a.no_line_numbers,
        check_first: a.check,
        continue_on_error: a.continue_on_error,
        safe_z_mm: a.safe_z_mm,
        spindle_dwell_s: a.spindle_dwell_s,
        plunge_feed_mm_min: a.plunge_feed_mm_min,
        unlock: a.unlock,
        position_reestablished: a.position_reestablished,
        skip_lines: a.skip_line.clone(),
        accept_coarser_arcs: a.accept_coarser_arcs,
        ..Config::default()
    };
    if !a.resume && (a.position_reestablished || !a.skip_line.is_empty()) {
        bail!("--position-reestablished and --skip-line go with --resume");
    }
    if !(cfg.safe_z_mm.is_finite() && cfg.spindle_dwell_s >= 0.0 && cfg.plunge_feed_mm_min > 0.0) {
        bail!("--safe-z-mm must be finite, --spindle-dwell-s ≥ 0 and --plunge-feed-mm-min > 0");
    }
    let mut link = SerialLink::open(&a.port, a.baud)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        // The streamer takes the flag when it acts on it: a first Ctrl-C holds and then resets, a second one
        // while it waits for the hold resets at once.
        let presses = std::sync::atomic::AtomicUsize::new(0);
        ctrlc::set_handler(move || {
            stop.store(true, Ordering::SeqCst);
            if presses.fetch_add(1, Ordering::SeqCst) == 0 {
                eprintln!("\nCtrl-C: feed hold, then reset once motion has stopped (Ctrl-C again: reset at once)");
            }
        })
        .context("cannot install the Ctrl-C handler")?;
    }
    let (hold, resume) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
    signal_hook::flag::register(signal_hook::consts::SIGUSR1, Arc::clone(&hold))
        .context("cannot install the SIGUSR1 (hold) handler")?;
    signal_hook::flag::register(signal_hook::consts::SIGUSR2, Arc::clone(&resume))
        .context("cannot install the SIGUSR2 (resume) handler")?;
    // Keys on a terminal raise the same flags; the listener restores the terminal when it is dropped, after
    // the session on every way out.
    let mut keys =
        brdfmill::apps::stream::keys::Keys::listen(std::io::stdin().as_fd(), Arc::clone(&hold), Arc::clone(&resume))
            .context("cannot read keys from the terminal")?;
    let by_key = if keys.is_some() { "`!` or space, or " } else { "" };
    let resume_key = if keys.is_some() { "`~` or Enter, or " } else { "" };
    eprintln!(
        "streaming; hold: {by_key}kill -USR1 {pid}; resume: {resume_key}kill -USR2 {pid}; stop: Ctrl-C",
        pid = std::process::id()
    );
    let bar = indicatif::ProgressBar::new(program.sendable().count() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} lines {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(250));
    let mut obs = Bar {
        bar,
        keys: keys.as_mut().and_then(|k| k.take_input()),
        stop: Arc::clone(&stop),
    };
    let mode = if a.resume { Mode::Resume } else { Mode::Fresh };
    let controls = session::Controls {
        stop: &stop,
        hold: &hold,
        resume: &resume,
    };
    let outcome = session::run_with(&mut link, &program, &cfg, &journal, mode, &mut obs, controls);
    drop(keys);
    obs.bar.finish_and_clear();
    match outcome? {
        Outcome::Completed(s) => {
            let secs = s.streaming_time.as_secs_f64().max(1e-9);
            println!(
                "done: {} lines, {} bytes in {:.1} s ({:.0} bytes/s); journal {}",
                s.lines_sent,
                s.bytes_sent,
                secs,
                s.bytes_sent as f64 / secs,
                journal.display()
            );
            if let Some(m) = s.end_detection {
                println!("end of the job read from: {m}");
            }
            Ok(())
        }
        Outcome::Stopped(r, _) => {
            let at = r.line.map_or(String::new(), |l| format!(" at line {l}"));
            let resume = match (r.located, r.resume_line, &r.reason, r.line) {
                (true, Some(_), StopReason::Error(_), Some(bad)) => format!(
                    "; {} lines done. GRBL rejected line {bad}: fix the program and start the job over, or resume \
                     without that line, on purpose, with: brdfmill stream {} --port {} --resume --skip-line {bad}",
                    r.lines_done,
                    a.program.display(),
                    a.port.display()
                ),
                (true, Some(l), _, _) => format!(
                    "; {} lines done, resume from line {l} with: brdfmill stream {} --port {} --resume",
                    r.lines_done,
                    a.program.display(),
                    a.port.display()
                ),
                (false, ..) => {
                    "; which lines ran is not known yet: --resume will read the controller's position".into()
                }
                _ => String::new(),
            };
            bail!("job stopped{at}: {}{resume} (journal {})", r.message, journal.display())
        }
    }
}
