//! `brdfmill emulate`: a virtual GRBL 1.1 controller on a pseudo-terminal, for dry runs (see `docs/STREAM.md`).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig, Fault};

/// Arguments of `brdfmill emulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial speed to emulate, bits/s (bytes are paced at baud/10 per second both ways).
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Run simulated motion this many times faster than real time.
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
    /// Inject a fault: LINE:error[:CODE], LINE:alarm[:CODE], LINE:disconnect, LINE:silence[:MS] or
    /// LINE:stall[:BYTES] (no motion until the receive buffer holds BYTES, 50 status reports are answered
    /// meanwhile, or a reset)
    /// (LINE = the N line number; a silence holds every answer back for MS simulated milliseconds).
    #[arg(long = "fail-at")]
    pub fail_at: Vec<Fault>,
    /// Change a setting at power-up, N=VALUE (e.g. 10=3 to report Bf); repeatable.
    #[arg(long = "setting")]
    pub settings: Vec<String>,
    /// Keep a symbolic link at this path pointing to the current port (it changes after a disconnect).
    #[arg(long)]
    pub link: Option<PathBuf>,
    /// Emulate a build with line numbers (`USE_LINE_NUMBERS`: `N` in `[OPT:]`, `Ln:` in status reports).
    /// The default is a stock 1.1h build, `[OPT:V,15,128]`.
    #[arg(long)]
    pub line_numbers: bool,
    /// Emulate a build with `ENABLE_M7` (a stock build answers `M7` with error:20).
    #[arg(long)]
    pub enable_m7: bool,
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    if !(a.time_scale > 0.0 && a.time_scale.is_finite()) || a.baud == 0 {
        bail!("--time-scale must be a positive number and --baud positive");
    }
    let settings = a
        .settings
        .iter()
        .map(|s| {
            let (k, v) = s.split_once('=').context("--setting expects N=VALUE")?;
            Ok((k.trim_start_matches('$').parse()?, v.parse()?))
        })
        .collect::<Result<Vec<(u16, f64)>>>()
        .context("bad --setting")?;
    let emu = Emulator::start(EmulatorConfig {
        baud: a.baud,
        time_scale: a.time_scale,
        settings,
        faults: a.fail_at.clone(),
        link_path: a.link.clone(),
        line_numbers: a.line_numbers,
        enable_m7: a.enable_m7,
        ..EmulatorConfig::default()
    })
    .context("cannot open a pseudo-terminal")?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)).context("cannot install the Ctrl-C handler")?;
    }
    let mut gen = emu.generation();
    if let Some(p) = emu.port_path() {
        println!("{}", p.display());
    }
    eprintln!(
        "virtual GRBL 1.1 at {} baud, time scale {}; Ctrl-C to stop",
        a.baud, a.time_scale
    );
    let mut seen_events = 0;
    while !stop.load(Ordering::SeqCst) {
        if let Some((p, g)) = emu.wait_new_port(gen, Duration::from_millis(200)) {
            gen = g;
            println!("{}", p.display());
        }
        let log = emu.log();
        for e in &log.events[seen_events..] {
            eprintln!("emulator: {e}");
        }
        seen_events = log.events.len();
        if let Some(f) = emu.failure() {
            bail!("emulator stopped: {f}");
        }
    }
    let log = emu.log();
    eprintln!(
        "received {} lines, executed {} motion pieces, {} receive-buffer overflows",
        log.received.len(),
        log.executed.len(),
        log.rx_overflows
    );
    Ok(())
}
