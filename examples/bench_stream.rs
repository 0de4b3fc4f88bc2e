//! Streaming throughput against the virtual GRBL 1.1h controller on a pseudo-terminal: 10,000 short moves
//! at 115200 baud with motion simulated 10⁴× faster than real time, so the link is the bottleneck. Prints
//! bytes per second and the fraction of the baud limit. A figure, not a test: timing depends on the machine
//! and its load, so no test asserts it (`cargo run --release --example bench_stream`).

use std::sync::atomic::AtomicBool;

use brdfmill::stream::emulator::{Emulator, EmulatorConfig};
use brdfmill::stream::program::Program;
use brdfmill::stream::serial::SerialLink;
use brdfmill::stream::session::{self, Config, Mode, Outcome, Silent};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = tempfile::tempdir()?;
    let mut text = String::from("G21G90\nG1F3000\n");
    for i in 0..9_998 {
        let a = f64::from(i) * 0.01;
        text += &format!("X{:.3}Y{:.3}\n", 10.0 * a.cos(), 10.0 * a.sin());
    }
    let path = dir.path().join("bench.nc");
    std::fs::write(&path, text)?;
    let prog = Program::read(&path, true)?;
    let baud = 115_200;
    let emu = Emulator::start(EmulatorConfig {
        baud,
        time_scale: 1e4,
        settings: vec![(10, 3.0)],
        ..EmulatorConfig::default()
    })?;
    let port = emu.port_path().ok_or("the emulator has no port")?;
    let mut link = SerialLink::open(&port, baud)?;
    let outcome = session::run(
        &mut link,
        &prog,
        &Config::default(),
        &dir.path().join("bench.journal.jsonl"),
        Mode::Fresh,
        &mut Silent,
        &AtomicBool::new(false),
    )?;
    let Outcome::Completed(stats) = outcome else {
        return Err(format!("the job stopped: {outcome:?}").into());
    };
    let limit = f64::from(baud) / 10.0;
    let secs = stats.streaming_time.as_secs_f64().max(1e-9);
    let bps = stats.bytes_sent as f64 / secs;
    println!(
        "{} lines, {} bytes in {secs:.2} s = {bps:.0} bytes/s, {:.1}% of the {baud}-baud limit ({limit:.0} bytes/s); \
         at most {} bytes in flight; {} receive-buffer overflows",
        stats.lines_sent,
        stats.bytes_sent,
        100.0 * bps / limit,
        stats.max_in_flight,
        emu.log().rx_overflows
    );
    Ok(())
}
