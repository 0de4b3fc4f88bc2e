//! `brdfmill run JOB.toml --out DIR`: the whole pipeline.

use anyhow::Result;
use brdfmill::job::{self, Job, Stage};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `brdfmill run`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The job file (TOML; see examples/ and `brdfmill::job`)
    pub job: PathBuf,
    /// Output folder for every artifact and the report
    #[arg(long)]
    pub out: PathBuf,
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    let t0 = std::time::Instant::now();
    let ready = Job::load(&a.job)?;
    // the output folder before any work: an existing file there, or a folder that cannot be made, would
    // otherwise fail only after the first stage
    if a.out.exists() && !a.out.is_dir() {
        anyhow::bail!("--out {}: exists and is not a folder", a.out.display());
    }
    std::fs::create_dir_all(&a.out)
        .map_err(|e| anyhow::anyhow!("--out {}: cannot create the folder: {e}", a.out.display()))?;
    println!("job       {} ({})", ready.job.name, a.job.display());
    let style = ProgressStyle::with_template("{spinner} {prefix:>9}  {msg} {elapsed}").unwrap();
    let mut bar: Option<ProgressBar> = None;
    let mut progress = |stage: Stage, started: bool| {
        if started {
            let b = ProgressBar::new_spinner()
                .with_style(style.clone())
                .with_prefix(stage.name())
                .with_message(match stage {
                    Stage::Ndf => "BRDF → observed distribution, Lucy–Richardson",
                    Stage::Facets => "CVT sampling, annealing, Poisson integration",
                    Stage::Toolpath => "drop-cutter, roughing, raster finishing, G-code",
                    Stage::Simulate => "material removal on the stock",
                    Stage::Verify => "NDFs, metrics, figures, report",
                });
            b.enable_steady_tick(Duration::from_millis(120));
            bar = Some(b);
        } else if let Some(b) = bar.take() {
            b.finish_with_message("done in");
        }
    };
    let outcome = job::run(&ready, &a.out, &mut progress)?;
    let m = &outcome.metrics;
    println!();
    for (stage, s) in &outcome.timings {
        println!("{:>9}  {:6.2} s", stage.name(), s);
    }
    println!(
        "design    NDF corr {:.4}, L1 {:.4}, JS {:.4}, variance ratio [{:.3}, {:.3}]",
        m.design.ndf_corr, m.design.ndf_l1, m.design.ndf_js, m.design.cov_ratio[0], m.design.cov_ratio[1]
    );
    println!(
        "milled    NDF corr {:.4}, L1 {:.4}, JS {:.4}, variance ratio [{:.3}, {:.3}]",
        m.milled.ndf_corr, m.milled.ndf_l1, m.milled.ndf_js, m.milled.cov_ratio[0], m.milled.cov_ratio[1]
    );
    println!(
        "verdict   {}",
        if m.pass {
            "PASS: the milled surface meets every tolerance"
        } else {
            "FALLS SHORT (see the report's \"Why\")"
        }
    );
    for n in &m.notes {
        println!("          - {n}");
    }
    println!("wrote     {} files to {}", outcome.artifacts.len(), a.out.display());
    println!("report    {}", outcome.report.display());
    println!("total     {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}
