//! `brdfmill toolpath`: tile.json + machine profile → program.nc.

use anyhow::{bail, Result};
use brdfmill::cut::machine::{Machine, Stock};
use brdfmill::stages::facets::TileFile;
use brdfmill::stages::toolpath::{self, Strategy, ToolpathConfig};
use std::path::PathBuf;

/// Arguments of `brdfmill toolpath`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The tile to cut (tile.json from `brdfmill facets`; its tile.npy beside it)
    #[arg(long)]
    pub tile: PathBuf,
    /// Machine profile: a path, or a shipped profile's name (grbl-3018, grbl-router-6040, linuxcnc-mill)
    #[arg(long)]
    pub machine: PathBuf,
    /// Finishing tool id from the profile (a ball-nose)
    #[arg(long)]
    pub tool: String,
    /// Roughing tool id (ball or flat); default: the finishing tool
    #[arg(long, default_value = "")]
    pub rough_tool: String,
    /// Work area covered by the repeated tile, X x Y (mm)
    #[arg(long, default_value = "40x40")]
    pub area: String,
    /// Target scallop height of the finishing raster (µm)
    #[arg(long, default_value_t = 1.0)]
    pub scallop_um: f64,
    /// Finishing stepover (mm); overrides --scallop-um
    #[arg(long)]
    pub stepover_mm: Option<f64>,
    /// Raster direction (degrees from X)
    #[arg(long, default_value_t = 0.0)]
    pub angle_deg: f64,
    /// Raster strategy: auto (oneway where the profile has `limits.backlash`, else zigzag), zigzag or oneway (climb)
    #[arg(long, default_value = "auto")]
    pub strategy: String,
    /// Stock material for the cutting data: aluminium or wax
    #[arg(long, default_value = "aluminium")]
    pub stock: String,
    /// Collinear-point tolerance (µm, one-sided: never below the CL surface)
    #[arg(long, default_value_t = 0.5)]
    pub tolerance_um: f64,
    /// Cutting feed override (mm/min); default: the tool's cutting data
    #[arg(long)]
    pub feed_mm_min: Option<f64>,
    /// Write the finishing passes as straight blocks only (no G2/G3 arcs in the pass plane)
    #[arg(long)]
    pub no_arcs: bool,
    /// Refuse a program whose estimated run time is longer (hours)
    #[arg(long, default_value_t = 12.0)]
    pub max_hours: f64,
    /// Output G-code file
    #[arg(long)]
    pub out: PathBuf,
}

/// Build the configuration from the arguments.
pub fn config(a: &Args) -> Result<ToolpathConfig> {
    Ok(ToolpathConfig {
        tool: a.tool.clone(),
        rough_tool: a.rough_tool.clone(),
        stock: match a.stock.as_str() {
            "aluminium" | "aluminum" => Stock::Aluminium,
            "wax" => Stock::Wax,
            s => bail!("--stock `{s}`: expected aluminium or wax"),
        },
        area_mm: {
            let (x, y) = super::parse_pair::<f64>(&a.area, "--area", "XxY in mm, e.g. 40x40")?;
            [x, y]
        },
        scallop_um: a.scallop_um,
        stepover_mm: a.stepover_mm.unwrap_or(0.0),
        angle_deg: a.angle_deg,
        strategy: match a.strategy.as_str() {
            "auto" => Strategy::Auto,
            "zigzag" => Strategy::Zigzag,
            "oneway" => Strategy::Oneway,
            s => bail!("--strategy `{s}`: expected auto, zigzag or oneway"),
        },
        tolerance_um: a.tolerance_um,
        feed_mm_min: a.feed_mm_min.unwrap_or(0.0),
        job: format!("tile {}", a.tile.display()),
        arcs: !a.no_arcs,
        max_hours: a.max_hours,
    })
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    super::check_out_file("--out", &a.out)?;
    let cfg = config(a)?;
    let (_, machine) = Machine::find(&a.machine.to_string_lossy(), std::path::Path::new(""))?;
    let tile = TileFile::read(&a.tile)?;
    let hf = tile.load_heightfield(&a.tile)?;
    let t0 = std::time::Instant::now();
    let p = toolpath::run(&cfg, &hf, &machine)?;
    // one file, or GRBL's one per tool beside it: OUT-1.nc, OUT-2.nc, … in the order they run
    let n = p.files.len();
    for (k, f) in p.files.iter().enumerate() {
        let path = if n == 1 {
            a.out.clone()
        } else {
            let stem = a
                .out
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_default();
            let ext = a
                .out
                .extension()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_else(|| "nc".into());
            a.out.with_file_name(format!("{stem}-{}.{ext}", k + 1))
        };
        brdfmill::base::io::write_atomic(&path, f.gcode.as_bytes())?;
        if n > 1 {
            println!(
                "program   {} — tool {} (program {} of {n}: zero Z on the touch-off pad before it)",
                path.display(),
                f.summary.tools.join(", "),
                k + 1
            );
        }
    }
    if machine.dialect == brdfmill::gcode::Dialect::Linuxcnc {
        let table = a.out.with_file_name(brdfmill::gcode::TOOL_TABLE_FILE);
        brdfmill::base::io::write_atomic(&table, brdfmill::gcode::tool_table(&machine).as_bytes())?;
        println!(
            "tools     {} (LinuxCNC tool table: rs274 -t, or the machine's [EMCIO] TOOL_TABLE)",
            table.display()
        );
    }
    let s = &p.summary;
    println!("machine   {} ({:?}), tool {}", machine.name, machine.dialect, cfg.tool);
    println!(
        "raster    {} finishing passes at {:.4} mm stepover (scallop {:.3} µm), {} intermediate levels, design depth {:.3} mm",
        s.finishing_passes, s.stepover_mm, s.scallop_um, s.finishing_levels, s.depth_mm
    );
    if s.roughing_layers > 0 {
        println!(
            "roughing  {} layers with {}, {} tool change(s)",
            s.roughing_layers, s.roughing_tool, s.tool_changes
        );
    }
    println!(
        "lines     {} ({} motion blocks, {} of them G2/G3 arcs in the pass plane)",
        s.lines, s.blocks, s.arc_blocks
    );
    let limit = s
        .max_blocks_s
        .map_or("no limit".to_string(), |r| format!("limit {r} blocks/s"));
    println!("blocks    peak {:.0} blocks/s ({limit})", s.peak_blocks_s);
    println!(
        "path      {:.1} mm cutting, {:.1} mm rapid",
        s.feed_length_mm, s.rapid_length_mm
    );
    println!(
        "time      {} estimated (feeds, acceleration, junction deviation, block rate); {} without the block-rate limit; tool changes not counted",
        toolpath::hms(s.estimated_s),
        toolpath::hms(s.estimated_unlimited_s)
    );
    println!(
        "extents   X {:.3}..{:.3}  Y {:.3}..{:.3}  Z {:.4}..{:.3} mm",
        s.extents_mm[0][0],
        s.extents_mm[1][0],
        s.extents_mm[0][1],
        s.extents_mm[1][1],
        s.extents_mm[0][2],
        s.extents_mm[1][2]
    );
    println!(
        "gouge     {} CL points checked by direct summation, deepest {:.4} µm below the design",
        s.checked_points,
        s.max_gouge_um.max(0.0)
    );
    println!("wrote     {} in {:.1} s", a.out.display(), t0.elapsed().as_secs_f64());
    Ok(())
}
