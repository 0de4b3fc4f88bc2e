//! `brdfmill analyze`: a measured (X3P) or simulated (.npy) surface → NDF and BRDF, geometric and wave,
//! with a report.

use anyhow::Result;
use brdfmill::apps::analyze::{self, Config};
use std::path::PathBuf;

/// Arguments of `brdfmill analyze`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The surface: an X3P file (ISO 25178-72) or a .npy heightfield in mm
    pub surface: PathBuf,
    /// Sample pitch of a .npy heightfield (µm)
    #[arg(long)]
    pub pitch_um: Option<f64>,
    /// Wavelength of the wave-optics BRDF (µm)
    #[arg(long, default_value_t = 0.55)]
    pub wavelength_um: f64,
    /// Standard deviation of the Gaussian coherence kernel (µm)
    #[arg(long, default_value_t = 10.0)]
    pub sigma_um: f64,
    /// Coherence windows per axis averaged by the wave slice
    #[arg(long, default_value_t = 3)]
    pub windows: usize,
    /// Output folder: ndf.png, brdf_slices.png, surface.png, analysis.json, report.html
    #[arg(long)]
    pub out: PathBuf,
}

/// Run `brdfmill analyze`.
pub fn run(a: &Args) -> Result<()> {
    super::check_out_dir("--out", &a.out)?;
    let cfg = Config {
        pitch_um: a.pitch_um,
        wavelength_um: a.wavelength_um,
        sigma_um: a.sigma_um,
        windows: a.windows,
    };
    // every error of the analysis names the file and the field
    let r = analyze::run(&cfg, &a.surface, &a.out)?;
    println!(
        "{}: {}×{} at {:.3} µm, {} missing points; slope covariance [[{:.3e}, {:.3e}], [{:.3e}, {:.3e}]]",
        r.source,
        r.size[0],
        r.size[1],
        r.pitch_um,
        r.missing_points,
        r.slope_cov[0][0],
        r.slope_cov[0][1],
        r.slope_cov[1][0],
        r.slope_cov[1][1]
    );
    println!(
        "wave vs geometric slope marginals: L1 {:.3} / {:.3}, variance ratio {:.3} / {:.3}; FFT vs Gabor L2 {:.4}",
        r.wave_vs_geometric_l1[0],
        r.wave_vs_geometric_l1[1],
        r.wave_vs_geometric_variance_ratio[0],
        r.wave_vs_geometric_variance_ratio[1],
        r.fft_vs_gabor_l2
    );
    for n in r.notes.iter().filter(|n| n.starts_with("Warning")) {
        eprintln!("{n}");
    }
    println!("report: {}", a.out.join("report.html").display());
    Ok(())
}
