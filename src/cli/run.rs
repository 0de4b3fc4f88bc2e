//! `brdfmill run JOB.toml --out DIR`: the whole pipeline.
//!
//! Exit codes: 0 when the verdict passes (or the run stopped at `--until` before verification, or
//! `--allow-shortfall` was given), [`EXIT_SHORTFALL`] (3) when the run completed and the milled surface falls
//! short of a tolerance, 1 for a refused job or a failed stage, 2 for a bad command line.

use anyhow::Result;
use brdfmill::job::{self, Job, Progress, Stage};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Duration;

/// Exit code of a completed run whose milled surface falls short of its tolerances.
pub const EXIT_SHORTFALL: i32 = 3;

/// Arguments of `brdfmill run`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The job file (TOML; every key in docs/JOB.md)
    pub job: PathBuf,
    /// Output folder for every artifact and the report
    #[arg(long)]
    pub out: PathBuf,
    /// Stop after this stage: ndf, facets, toolpath (G-code only: no simulation or verification), simulate
    #[arg(long, value_parser = ["ndf", "facets", "toolpath", "simulate", "verify"], default_value = "verify")]
    pub until: String,
    /// Override a job key, e.g. --set facets.seed=3 --set toolpath.scallop_um=0.5 (TOML values; repeatable)
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
    /// Exit 0 even when the milled surface falls short (the artifacts are written either way)
    #[arg(long)]
    pub allow_shortfall: bool,
}

/// Run the subcommand; returns the exit code.
pub fn run(a: &Args) -> Result<i32> {
    let t0 = std::time::Instant::now();
    let until = Stage::parse(&a.until).unwrap_or(Stage::Verify);
    let ready = Job::load_with(&a.job, &a.set)?;
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
    let mut progress = |event: Progress| match event {
        Progress::Arrangement(round) | Progress::Round(round) => {
            let what = match event {
                Progress::Arrangement(_) => format!("seed {:>20}", round.seed),
                _ => format!("round {}", round.round),
            };
            let highlight = round
                .highlight_corr
                .map(|c| format!(", highlight {c:.4}"))
                .unwrap_or_default();
            let steps = if round.refined {
                "refined surface".to_string()
            } else {
                format!("steps {:.1} µm rms", round.rms_step_um)
            };
            let line = format!(
                "   {what}  as-milled model: corr {:.4}, L1 {:.4}, variance ratio [{:.3}, {:.3}]{highlight}, relief {:.3} mm, {steps}",
                round.ndf_corr, round.ndf_l1, round.cov_ratio[0], round.cov_ratio[1], round.relief_mm
            );
            match &bar {
                Some(b) => b.suspend(|| println!("{line}")),
                None => println!("{line}"),
            }
        }
        Progress::Started(stage) => {
            let b = ProgressBar::new_spinner()
                .with_style(style.clone())
                .with_prefix(stage.name())
                .with_message(match stage {
                    Stage::Ndf => "BRDF → observed distribution, Lucy–Richardson",
                    Stage::Facets => "design rounds: CVT sampling, annealing, Poisson integration, as-milled model",
                    Stage::Toolpath => "drop-cutter, roughing, raster finishing, G-code",
                    Stage::Simulate => "material removal on the stock",
                    Stage::Verify => "NDFs, metrics, figures, report",
                });
            b.enable_steady_tick(Duration::from_millis(120));
            bar = Some(b);
        }
        Progress::Prepared(what) => println!("input     {what}"),
        Progress::Region(name) => {
            let line = format!("   region `{name}`");
            match &bar {
                Some(b) => b.suspend(|| println!("{line}")),
                None => println!("{line}"),
            }
        }
        Progress::Finished(_) => {
            if let Some(b) = bar.take() {
                b.finish_with_message("done in");
            }
        }
    };
    let outcome = job::run(&ready, &a.out, until, &mut progress)?;
    Ok(summary(a, &ready.job.toolpath, &outcome, t0.elapsed().as_secs_f64()))
}

/// The closing summary; returns the exit code.
fn summary(a: &Args, t: &brdfmill::stages::toolpath::ToolpathConfig, outcome: &job::Outcome, total_s: f64) -> i32 {
    println!();
    for (stage, s) in &outcome.timings {
        println!("{:>9}  {:6.2} s", stage.name(), s);
    }
    for w in &outcome.warnings {
        println!("warning   {w}");
    }
    let (rounds, chosen) = &outcome.rounds;
    if let Some(c) = rounds.get(*chosen) {
        println!(
            "design    {} round{}, round {} chosen: as-milled model corr {:.4}, L1 {:.4}, variance ratio [{:.3}, {:.3}]{}",
            rounds.len(),
            if rounds.len() == 1 { "" } else { "s" },
            c.round,
            c.ndf_corr,
            c.ndf_l1,
            c.cov_ratio[0],
            c.cov_ratio[1],
            c.highlight_corr
                .map(|h| format!(", highlight corr {h:.4}"))
                .unwrap_or_default()
        );
        println!(
            "slopes    steepest facet {:.1}°, from {}",
            outcome.slope_cap.0, outcome.slope_cap.1
        );
    }
    if let Some(r) = outcome.relief_mm {
        println!("relief    {r:.3} mm (the design, highest to lowest point)");
    }
    if let Some(p) = &outcome.program {
        let hms = brdfmill::stages::toolpath::hms;
        println!(
            "program   {} — {} lines, estimated {} of machining ({} in rapids{}), cuts to {:.3} mm; tools: {}",
            p.file_names()
                .iter()
                .map(|f| a.out.join(f).display().to_string())
                .collect::<Vec<_>>()
                .join(", then "),
            p.lines,
            hms(p.estimated_s),
            hms(p.rapid_s),
            p.air_feed_s
                .map(|s| format!(", {} feeding through air", hms(s)))
                .unwrap_or_default(),
            p.depth_mm,
            t.tools_in_order(&p.roughing_tool)
        );
    }
    for c in outcome.program.iter().flat_map(|p| &p.cutting) {
        let a = &c.assessment;
        println!(
            "cutting   {}: {} mm/min, {} rpm, {} mm deep ({}): {:.1} µm/tooth, {:.1} m/min{}",
            c.id,
            c.data.feed_mm_min,
            c.data.spindle_rpm,
            c.data.max_depth_of_cut_mm,
            if c.from_table { "table" } else { "profile" },
            a.chip_um,
            a.surface_m_min,
            a.findings
                .iter()
                .map(|f| format!("\n          check: {}", f.text()))
                .collect::<String>()
        );
    }
    for (k, v) in &outcome.setup {
        if matches!(k.as_str(), "stock" | "work zero" | "arcs" | "check, then run") {
            println!("{:<9} {v}", k.split(',').next().unwrap_or(k));
        }
    }
    let code = match (&outcome.metrics, &outcome.regions) {
        (Some(m), _) => verdict(m, a.allow_shortfall),
        (None, Some(m)) => region_verdict(m, a.allow_shortfall),
        (None, None) => {
            println!("verdict   none: stopped after `{}` (--until)", a.until);
            0
        }
    };
    println!(
        "wrote     {} files, {:.1} MB, to {}",
        outcome.artifacts.len(),
        outcome.bytes_written as f64 / 1e6,
        a.out.display()
    );
    if let Some(r) = &outcome.report {
        println!("report    {}", r.display());
    }
    println!("total     {total_s:.1} s");
    code
}

/// Print each region's figures and the verdict of a job with `[svbrdf]`; the exit code.
fn region_verdict(m: &brdfmill::stages::verify::RegionsMetrics, allow_shortfall: bool) -> i32 {
    for r in &m.regions {
        println!(
            "region    `{}`: milled NDF corr {:.4}, L1 {:.4}, variance ratio [{:.3}, {:.3}], border {:.2} mm, {}",
            r.name,
            r.milled.ndf_corr,
            r.milled.ndf_l1,
            r.milled.cov_ratio[0],
            r.milled.cov_ratio[1],
            r.border_mm,
            if r.pass { "passes" } else { "falls short" }
        );
    }
    verdict_line(m.pass, "every region meets every tolerance", &m.notes, allow_shortfall)
}

/// The verdict line and its reasons; the exit code.
fn verdict_line(pass: bool, what_passes: &str, notes: &[String], allow_shortfall: bool) -> i32 {
    if pass {
        println!("verdict   PASS: {what_passes}");
    } else {
        println!("verdict   FALLS SHORT (see the report's \"Why\")");
    }
    for n in notes {
        println!("          - {n}");
    }
    if pass || allow_shortfall {
        0
    } else {
        EXIT_SHORTFALL
    }
}

/// Print the figures and the verdict; the exit code.
fn verdict(m: &brdfmill::stages::verify::Metrics, allow_shortfall: bool) -> i32 {
    println!(
        "tile      NDF corr {:.4}, L1 {:.4}, JS {:.4}, variance ratio [{:.3}, {:.3}] (design tile ⊛ base lobe)",
        m.design.ndf_corr, m.design.ndf_l1, m.design.ndf_js, m.design.cov_ratio[0], m.design.cov_ratio[1]
    );
    // a drawn highlight's verdict is its correlation with the image: it goes on the milled line with its bound
    let highlight = m
        .highlight_corr
        .map(|c| format!(", highlight corr {c:.4} (at least {})", m.tolerances.highlight_corr_min))
        .unwrap_or_default();
    println!(
        "milled    NDF corr {:.4}, L1 {:.4}, JS {:.4}, variance ratio [{:.3}, {:.3}]{highlight}",
        m.milled.ndf_corr, m.milled.ndf_l1, m.milled.ndf_js, m.milled.cov_ratio[0], m.milled.cov_ratio[1]
    );
    verdict_line(
        m.pass,
        "the milled surface meets every tolerance",
        &m.notes,
        allow_shortfall,
    )
}
