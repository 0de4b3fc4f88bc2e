//! `brdfmill ndf`: BRDF → ndf.json (+ PNG).

use anyhow::{Context, Result};
use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::ndf::{self, HalfAngleConfig, NdfConfig, NdfFile};
use std::path::PathBuf;

/// Arguments of `brdfmill ndf`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Target BRDF: beckmann:alpha=A | ggx:alpha=A | ggx:ax=A,ay=B | ward:ax=A,ay=B | blinn:n=N |
    /// merl:PATH | rgl:PATH | csv:PATH | highlight:PNG[,extent_deg=E], optionally followed by ,material=NAME
    /// or ,eta=E,k=K
    #[arg(long, required_unless_present = "highlight", conflicts_with = "highlight")]
    pub brdf: Option<String>,
    /// A drawn highlight (PNG) as the target instead of --brdf: the light a collimated light along the
    /// normal throws onto a screen parallel to the part, seen from above (docs/DESIGN.md §2.1)
    #[arg(long)]
    pub highlight: Option<PathBuf>,
    /// With --highlight: the angle of reflection at the ends of the image's longer axis (degrees, at most 40)
    #[arg(long, default_value_t = 30.0, requires = "highlight")]
    pub highlight_extent_deg: f64,
    /// With --highlight: the part's material (a preset name)
    #[arg(long, requires = "highlight")]
    pub material: Option<String>,
    /// Base material lobe to deconvolve (a BRDF spec), or `none`
    #[arg(long, default_value = "none")]
    pub base: String,
    /// Slope grid resolution per axis (cells)
    #[arg(long, default_value_t = 256)]
    pub res: usize,
    /// Half-width of the slope grid as a polar angle (degrees): |p|, |q| ≤ tan(angle)
    #[arg(long, default_value_t = 60.0)]
    pub max_angle_deg: f64,
    /// Lucy–Richardson iteration limit
    #[arg(long, default_value_t = 200)]
    pub iters: usize,
    /// Stop Lucy–Richardson when an iteration changes the estimate by less than this (relative L1; 0 = never)
    #[arg(long, default_value_t = 1e-5)]
    pub tol: f64,
    /// Difference angle of the near-retro configuration the half-angle distribution is read at (degrees)
    #[arg(long, default_value_t = 0.5)]
    pub theta_d_deg: f64,
    /// Output ndf.json
    #[arg(long)]
    pub out: PathBuf,
    /// Also draw the target NDF (and the observed one beside it) as a PNG
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    super::check_out_file("--out", &a.out)?;
    if let Some(p) = &a.png {
        super::check_out_file("--png", p)?;
    }
    let cfg = NdfConfig {
        res: a.res,
        max_angle_deg: a.max_angle_deg,
        iterations: a.iters,
        tolerance: a.tol,
        half_angle: HalfAngleConfig {
            theta_d_deg: a.theta_d_deg,
            ..Default::default()
        },
    };
    cfg.validate()?;
    let brdf = match (&a.brdf, &a.highlight) {
        (Some(spec), _) => Brdf::parse(spec).context("--brdf")?,
        (None, Some(path)) => {
            let spec = brdfmill::stages::brdf::highlight::spec(
                &path.display().to_string(),
                Some(a.highlight_extent_deg),
                a.material.as_deref(),
            )
            .map_err(|e| anyhow::anyhow!("--highlight: {e}"))?;
            Brdf::parse(&spec).context("--highlight")?
        }
        (None, None) => anyhow::bail!("give --brdf SPEC or --highlight PNG"),
    };
    let base = match a.base.trim() {
        "none" | "" => None,
        s => Some(Brdf::parse(s).context("--base")?),
    };
    let t0 = std::time::Instant::now();
    let n = ndf::run(&cfg, &brdf, base.as_ref())?;
    let file = NdfFile::from(&n);
    // Render everything before writing anything, so an error leaves no partial output.
    let png = a.png.as_ref().map(|_| ndf::render_pair_png(&n).to_png());
    file.write(&a.out)?;
    if let (Some(path), Some(bytes)) = (&a.png, png) {
        brdfmill::base::io::write_atomic(path, &bytes)?;
    }
    let s = &n.stats;
    let o = &n.observed_stats;
    println!("brdf      {}", n.brdf_spec);
    println!("base      {}", n.base_spec.as_deref().unwrap_or("none"));
    println!(
        "source    {:?}, grid {}×{} over |p|,|q| ≤ {:.4}",
        n.source,
        cfg.res,
        cfg.res,
        cfg.domain().p_max
    );
    println!(
        "observed  mass {:.6}  cov [[{:.6}, {:.6}], [{:.6}, {:.6}]]",
        o.mass, o.cov[0][0], o.cov[0][1], o.cov[1][0], o.cov[1][1]
    );
    println!(
        "target    mass {:.6}  mean [{:.2e}, {:.2e}]  cov [[{:.6}, {:.6}], [{:.6}, {:.6}]]",
        s.mass, s.mean[0], s.mean[1], s.cov[0][0], s.cov[0][1], s.cov[1][0], s.cov[1][1]
    );
    println!(
        "tilt      removed p {:.3e}, q {:.3e} ({:.4}°)",
        n.tilt.p, n.tilt.q, n.tilt.deg
    );
    if let Some(w) = ndf::grid_warning(&n) {
        println!("warning   {w}");
    }
    let d = &n.deconvolution;
    println!(
        "deconv    {} — {} of {} iterations, stopped by {:?}, last change {:.2e}",
        d.method, d.iterations, d.max_iterations, d.stopped_by, d.last_change
    );
    println!(
        "wrote     {}{}",
        a.out.display(),
        a.png.as_ref().map(|p| format!(", {}", p.display())).unwrap_or_default()
    );
    println!("time      {:.2} s", t0.elapsed().as_secs_f64());
    Ok(())
}
