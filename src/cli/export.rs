//! `brdfmill export`: a job's BRDFs (target, design tile, simulated milled surface) as RGL `.bsdf` files and
//! MERL tables.

use anyhow::Result;
use std::path::PathBuf;

/// Arguments of `brdfmill export`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The job's output folder (from `brdfmill run`: its job.toml, ndf-design.json and ndf-milled.json)
    pub job: PathBuf,
    /// Output folder (default: the job's folder): target.bsdf, design.bsdf, milled.bsdf, target.binary,
    /// design.binary, milled.binary
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Run `brdfmill export`.
pub fn run(a: &Args) -> Result<()> {
    let out = a.out.clone().unwrap_or_else(|| a.job.clone());
    super::check_out_dir("--out", &out)?;
    for (path, what) in brdfmill::job::export::export(&a.job, &out)? {
        println!("{}: {what}", path.display());
    }
    Ok(())
}
