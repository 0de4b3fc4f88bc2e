//! `brdfmill compare`: a scan of the milled part (X3P or .npy) against the job that made it, registered to
//! the simulated cut and measured as the verdict measures the cut.

use anyhow::Result;
use brdfmill::job::compare::{self, CompareConfig};
use std::path::PathBuf;

/// Arguments of `brdfmill compare`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scan of the milled part: an X3P file (ISO 25178-72) or a .npy heightfield in mm (NaN: missing)
    pub scan: PathBuf,
    /// The job's output folder (from `brdfmill run`: its job.toml, run.json and sim.x3p)
    #[arg(long)]
    pub job: PathBuf,
    /// Sample pitch of a .npy scan (µm)
    #[arg(long)]
    pub pitch_um: Option<f64>,
    /// The least agreement of the scan's slopes with the simulated cut's at which it is taken to be of this part
    #[arg(long, default_value_t = 0.95)]
    pub min_correlation: f64,
    /// Output folder: compare.json, compare.html, difference.png, ndf-scan.json
    #[arg(long)]
    pub out: PathBuf,
}

/// Run `brdfmill compare`: 0 when the scan registers and passes, 3 when it falls short.
pub fn run(a: &Args) -> Result<i32> {
    super::check_out_dir("--out", &a.out)?;
    if !(a.min_correlation > 0.0 && a.min_correlation < 1.0) {
        anyhow::bail!("--min-correlation {}: expected a number in (0, 1)", a.min_correlation);
    }
    let cfg = CompareConfig {
        min_correlation: a.min_correlation,
        pitch_um: a.pitch_um,
    };
    let c = compare::compare(&a.scan, &a.job, &a.out, &cfg)?;
    let r = &c.registration;
    println!(
        "registration: rotation {:.3}°, shift ({:.4}, {:.4}) mm, tilt {:.3}°; slopes agree {:.4}, heights correlate {:.4}, residual {:.2} µm rms, {:.1}% of the cut covered",
        r.rotation_deg,
        r.shift_mm[0],
        r.shift_mm[1],
        r.tilt_deg,
        r.slope_correlation,
        r.correlation,
        r.residual_rms_um,
        r.coverage * 100.0
    );
    if let (Some(scan), Some(sim)) = (&c.scan, &c.simulated) {
        println!(
            "scan vs target: L1 {:.4}, correlation {:.4}, variance ratios {:.3}/{:.3} (simulated cut in the same window: L1 {:.4}, correlation {:.4}, {:.3}/{:.3})",
            scan.ndf_l1,
            scan.ndf_corr,
            scan.cov_ratio[0],
            scan.cov_ratio[1],
            sim.ndf_l1,
            sim.ndf_corr,
            sim.cov_ratio[0],
            sim.cov_ratio[1]
        );
    }
    for reason in &c.reasons {
        eprintln!("{reason}");
    }
    println!(
        "{}; report: {}",
        if c.pass { "pass" } else { "falls short" },
        a.out.join("compare.html").display()
    );
    Ok(if c.pass { 0 } else { 3 })
}
