//! `brdfmill calibrate`: machine profile → DIR/calibrate.nc, calibrate.md, calibrate.json (and tool.tbl for
//! LinuxCNC): a coupon that measures the profile's `[accuracy]`.

use anyhow::{bail, Context, Result};
use brdfmill::apps::calibrate::{self, CalibrateConfig};
use brdfmill::cut::machine::{Machine, Stock};
use brdfmill::stages::toolpath::hms;
use std::path::PathBuf;

/// Arguments of `brdfmill calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Machine profile: a path, or a shipped profile's name (grbl-3018, grbl-router-6040, linuxcnc-mill)
    #[arg(long)]
    pub machine: PathBuf,
    /// Output folder (made when missing)
    #[arg(long)]
    pub out: PathBuf,
    /// Stock material for the cutting data: wax or aluminium
    #[arg(long, default_value = "wax")]
    pub stock: String,
    /// Tool id from the profile; default: its smallest flat end mill, else its smallest ball-nose
    #[arg(long)]
    pub tool: Option<String>,
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    super::check_out_dir("--out", &a.out)?;
    let stock = match a.stock.as_str() {
        "aluminium" | "aluminum" => Stock::Aluminium,
        "wax" => Stock::Wax,
        s => bail!("--stock `{s}`: expected wax or aluminium"),
    };
    let (from, machine) = Machine::find(&a.machine.to_string_lossy(), std::path::Path::new(""))?;
    let cfg = CalibrateConfig {
        stock,
        tool: a.tool.clone(),
        profile: from.display().to_string(),
    };
    let c = calibrate::coupon(&machine, &cfg).with_context(|| format!("machine {}", from.display()))?;
    let written = c.write(&a.out)?;
    let s = &c.spec;
    println!("machine   {} ({:?}), {}", machine.name, machine.dialect, from.display());
    println!(
        "tool      {} (T{}, {} D{} mm) in {}: F{} S{}, {} level(s) of {} mm",
        s.tool.id,
        s.tool.number,
        s.tool.kind,
        s.tool.diameter_mm,
        calibrate::stock_name(s.stock),
        s.feed_mm_min,
        s.spindle_rpm,
        s.levels,
        s.depth_mm / s.levels as f64
    );
    println!(
        "coupon    block ≥ {} × {} × {} mm, X0 Y0 its front-left corner, Z0 its top",
        s.stock_mm[0], s.stock_mm[1], s.stock_mm[2]
    );
    for f in [&s.x, &s.y] {
        println!(
            "{} slots   at {:?} mm (approached {:?}): lands {:?} mm, P = {} mm",
            f.axis, f.centres_mm, f.approach, f.lands_mm, f.pitch_mm
        );
    }
    println!(
        "time      {} estimated ({} at the block rate), {} blocks",
        hms(s.estimated_s),
        hms(s.estimated_block_limited_s),
        s.blocks
    );
    for p in written {
        println!("wrote     {}", p.display());
    }
    println!("next      cut it, then follow calibrate.md to read it and set accuracy.* in the profile");
    Ok(())
}
