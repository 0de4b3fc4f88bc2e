//! `brdfmill facets`: ndf.json → DIR/tile.json, tile.npy, tile.png, tile.stl.

use anyhow::{bail, Result};
use brdfmill::stages::facets::{self, format::Source, FacetsConfig, SteepPolicy, TileFile};
use brdfmill::stages::ndf::NdfFile;
use std::path::PathBuf;

/// Arguments of `brdfmill facets`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The target NDF (ndf.json from `brdfmill ndf`)
    #[arg(long)]
    pub ndf: PathBuf,
    /// Facets per tile, W x H
    #[arg(long, default_value = "32x32")]
    pub facets: String,
    /// Side of one facet (mm)
    #[arg(long, default_value_t = 1.0)]
    pub facet_mm: f64,
    /// Heightfield sample spacing (µm); must divide the facet side
    #[arg(long, default_value_t = 10.0)]
    pub pitch_um: f64,
    /// Seed of every random choice
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Machinable limit: steepest facet (degrees from the normal)
    #[arg(long, default_value_t = 45.0)]
    pub max_slope_deg: f64,
    /// Steeper slopes: truncate (drop from the distribution) or clamp (onto the limit)
    #[arg(long, default_value = "truncate")]
    pub steep: String,
    /// Annealing sweeps (one sweep = W·H proposed swaps)
    #[arg(long, default_value_t = 20000)]
    pub sweeps: usize,
    /// Output folder
    #[arg(long)]
    pub out: PathBuf,
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    super::check_out_dir("--out", &a.out)?;
    let (w, h) = super::parse_pair::<usize>(&a.facets, "--facets", "WxH, e.g. 32x32")?;
    let steep = match a.steep.as_str() {
        "truncate" => SteepPolicy::Truncate,
        "clamp" => SteepPolicy::Clamp,
        s => bail!("--steep `{s}`: expected `truncate` or `clamp`"),
    };
    let mut cfg = FacetsConfig {
        facets_x: w,
        facets_y: h,
        facet_mm: a.facet_mm,
        pitch_um: a.pitch_um,
        seed: a.seed,
        max_slope_deg: a.max_slope_deg,
        steep,
        ..Default::default()
    };
    cfg.anneal.sweeps = a.sweeps;
    cfg.validate()?;
    let ndf = NdfFile::read(&a.ndf)?;
    let t0 = std::time::Instant::now();
    let tile = facets::run(&cfg, &ndf.target())?;
    let file = TileFile::new(
        &tile,
        Source {
            ndf: a.ndf.display().to_string(),
            brdf: ndf.brdf.clone(),
            base: ndf.base.clone(),
        },
        "tile.npy",
    );
    // Everything is computed before anything is written.
    let stl = tile.stl();
    let png = tile.relief_png().to_png();
    let json = file.to_json();
    brdfmill::base::io::write_atomic(&a.out.join("tile.stl"), &stl)?;
    brdfmill::base::io::write_atomic(&a.out.join("tile.png"), &png)?;
    tile.heightfield.write_npy(&a.out.join("tile.npy"))?;
    brdfmill::base::io::write_atomic(&a.out.join("tile.json"), json.as_bytes())?;

    let s = &file.stats;
    let sm = &s.sampling;
    println!(
        "facets    {w}×{h} of {} mm, heightfield {}×{} at {} µm",
        cfg.facet_mm, tile.heightfield.nx, tile.heightfield.ny, cfg.pitch_um
    );
    println!(
        "slopes    cov [[{:.5}, {:.5}], [{:.5}, {:.5}]]  (ndf: [[{:.5}, {:.5}], [{:.5}, {:.5}]])",
        s.cov[0][0],
        s.cov[0][1],
        s.cov[1][0],
        s.cov[1][1],
        ndf.stats.cov[0][0],
        ndf.stats.cov[0][1],
        ndf.stats.cov[1][0],
        ndf.stats.cov[1][1]
    );
    println!(
        "steep     {:.4}% of the NDF's mass lies beyond {}° ({})",
        sm.steep_mass * 100.0,
        cfg.max_slope_deg,
        if steep == SteepPolicy::Truncate {
            "dropped"
        } else {
            "clamped onto the limit"
        }
    );
    println!(
        "sampling  2D KS distance: i.i.d. {:.4}, Halton {:.4}, CVT {:.4}; energy test vs NDF p = {:.3} ({})",
        sm.ks_random,
        sm.ks_halton,
        sm.ks_cvt,
        sm.energy_p_value,
        if sm.energy_p_value >= 0.05 { "pass" } else { "FAIL" }
    );
    let (e, r) = (&s.energy, &s.energy_random);
    println!(
        "energy    C {:.4} I {:.4} V {:.4} valleys {} — random C {:.3} I {:.3} V {:.3} valleys {:.0} — total {:.2}% of random",
        e.C, e.I, e.V, e.valleys, r.C, r.I, r.V, r.valleys, 100.0 * e.total() / r.total()
    );
    println!(
        "seams     max step interior {:.2} µm, at the tile seam {:.2} µm, rms {:.2} µm",
        s.seams.max_interior_um, s.seams.max_seam_um, s.seams.rms_um
    );
    println!("relief    {:.1} µm", s.relief_mm * 1000.0);
    println!("wrote     {}/tile.json, tile.npy, tile.png, tile.stl", a.out.display());
    println!("time      {:.2} s", t0.elapsed().as_secs_f64());
    Ok(())
}
