//! Fifty seeded faults against the **real GRBL 1.1h firmware** (the grbl-sim kit, `../shared/grbl-sim`
//! or `$BRDFMILL_GRBL_SIM`), ten of each kind — a reset, a soft-limit alarm, a disconnect, a disconnect
//! with a restart of the board, a line GRBL rejects — each at a random line, each followed by what the stop
//! message tells the user to do, until the job completes; the firmware's own step trace must show every
//! motion line exactly once. The test suite runs ten (`tests/grbl_firmware.rs`); this is the long run,
//! with its wall time, for docs/STREAM.md.
//!
//! `cargo build --release && cargo run --release --example bench_grbl_faults [TRIALS [FIRST]]`
//! (`BRDFMILL_KEEP_FAILED_SIM=1` keeps a failing trial's wire log, trace and journal)

#[path = "../tests/grbl_harness/mod.rs"]
mod grbl_harness;

use grbl_harness::*;
use std::time::Instant;

fn main() {
    let trials: u64 = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(50);
    // the first trial's index, to repeat one trial (its seed is 5000 + index, its kind index mod 5)
    let first: u64 = std::env::args().nth(2).and_then(|a| a.parse().ok()).unwrap_or(0);
    let Some((kit, exe)) = kit_or_skip("bench_grbl_faults") else {
        eprintln!("no grbl-sim kit: nothing measured");
        std::process::exit(1);
    };
    let t0 = Instant::now();
    let mut failed = vec![];
    for k in first..first + trials {
        let (seed, kind) = (5000 + k, Kind::ALL[(k % 5) as usize]);
        let t = Instant::now();
        let r = std::panic::catch_unwind(|| trial(&kit, &exe, seed, kind));
        let ok = r.is_ok();
        println!(
            "trial {:>3} seed {seed} {kind:?}: {} ({:.1} s)",
            k + 1,
            if ok { "every line exactly once" } else { "FAILED" },
            t.elapsed().as_secs_f64()
        );
        if !ok {
            failed.push(format!("seed {seed} {kind:?}"));
        }
    }
    println!(
        "{} of {trials} trials with every motion line exactly once by the firmware's step trace, in {:.0} s{}",
        trials as usize - failed.len(),
        t0.elapsed().as_secs_f64(),
        if failed.is_empty() {
            String::new()
        } else {
            format!("; failed: {}", failed.join(", "))
        }
    );
    if !failed.is_empty() {
        std::process::exit(1);
    }
}
