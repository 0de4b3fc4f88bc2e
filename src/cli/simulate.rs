//! `brdfmill simulate`: any G-code program → the milled heightfield (sim.npy, sim.png, sim.json, optional
//! sim.stl) and, given the design, its deviation map.

use anyhow::{anyhow, bail, Context, Result};
use brdfmill::cut::machine::Machine;
use brdfmill::stages::facets::TileFile;
use brdfmill::stages::simulate::{self, Shape, SimulateConfig};
use std::path::PathBuf;

/// Arguments of `brdfmill simulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The G-code program (any source: the subset of docs/DESIGN.md §5; anything else is refused with line and
    /// column); several programs run one after another on the same stock (GRBL's program-1.nc, program-2.nc, …)
    #[arg(required = true, num_args = 1..)]
    pub program: Vec<PathBuf>,
    /// The bit: ball:D, flat:D or bull:D:R (diameter and corner radius, mm)
    #[arg(long)]
    pub tool: String,
    /// Stock grid pitch (µm)
    #[arg(long, default_value_t = 5.0)]
    pub pitch_um: f64,
    /// Stock bounds x0,y0,x1,y1 (mm); default: the program's cutting extents plus the tool radius
    #[arg(long)]
    pub bounds: Option<String>,
    /// Height of the stock top (mm)
    #[arg(long, default_value_t = 0.0)]
    pub stock_top_mm: f64,
    /// Largest chord sagitta when arcs are linearised (µm)
    #[arg(long, default_value_t = 0.1)]
    pub arc_tolerance_um: f64,
    /// Flute length (mm): refuse a program whose tip goes deeper below the stock top; default: not checked
    #[arg(long)]
    pub flute_length_mm: Option<f64>,
    /// Largest stock grid, cells (8 bytes each; at most 1e9)
    #[arg(long, default_value_t = 250_000_000)]
    pub max_cells: usize,
    /// Machine profile (a path or a shipped name such as grbl-3018): the cut follows its `[accuracy]`
    /// (backlash, runout, step grid) and the time estimate its limits; default: a perfect machine with
    /// machines/linuxcnc-mill.toml's limits
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// Cut as a perfect machine would, ignoring the profile's `[accuracy]`
    #[arg(long)]
    pub ideal: bool,
    /// The design (tile.json from `brdfmill facets`, tile.npy beside it), repeated from the work origin:
    /// writes deviation.png, design-vs-cut.png and the over-/under-cut figures
    #[arg(long)]
    pub design: Option<PathBuf>,
    /// Also write sim.stl (a closed solid through at most --stl-side samples per side)
    #[arg(long)]
    pub stl: bool,
    /// Samples per side of sim.stl at most
    #[arg(long, default_value_t = 1000)]
    pub stl_side: usize,
    /// Output folder
    #[arg(long)]
    pub out: PathBuf,
}

/// Parse `x0,y0,x1,y1`.
fn parse_bounds(s: &str) -> Result<[f64; 4]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| anyhow!("--bounds `{s}`: expected four numbers x0,y0,x1,y1 in mm"))?;
    match v[..] {
        [a, b, c, d] => Ok([a, b, c, d]),
        _ => bail!("--bounds `{s}`: expected four numbers x0,y0,x1,y1 in mm"),
    }
}

/// Build the configuration from the arguments.
pub fn config(a: &Args) -> Result<SimulateConfig> {
    let machine = match &a.machine {
        Some(p) => Some(Machine::find(&p.to_string_lossy(), std::path::Path::new(""))?.1),
        None => None,
    };
    Ok(SimulateConfig {
        tool: Shape::parse(&a.tool).map_err(|e| anyhow!("--tool: {e}"))?,
        pitch_um: a.pitch_um,
        bounds_mm: a.bounds.as_deref().map(parse_bounds).transpose()?,
        stock_top_mm: a.stock_top_mm,
        arc_tolerance_um: a.arc_tolerance_um,
        max_cells: a.max_cells,
        flute_length_mm: a.flute_length_mm.unwrap_or(0.0),
        // each tool number of the program swept with the profile's shape for it (`--tool` for the rest)
        tools: machine.as_ref().map(simulate::tool_table).unwrap_or_default(),
        machine,
        ideal: a.ideal,
        // the gouge check per tool needs each tool's own cut
        tool_cuts: a.design.is_some(),
        ..Default::default()
    })
}

/// Run the subcommand.
pub fn run(a: &Args) -> Result<()> {
    super::check_out_dir("--out", &a.out)?;
    let cfg = config(a)?;
    let texts = a
        .program
        .iter()
        .map(|p| std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display())))
        .collect::<Result<Vec<String>>>()?;
    let names = a
        .program
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" + ");
    let design = match &a.design {
        Some(p) => {
            let t = TileFile::read(p)?;
            Some(t.load_heightfield(p)?)
        }
        None => None,
    };
    let t0 = std::time::Instant::now();
    let refs: Vec<&str> = texts.iter().map(String::as_str).collect();
    let sim = simulate::run_files(&refs, &cfg).map_err(|e| anyhow!("{names}: {e}"))?;
    let t_sim = t0.elapsed().as_secs_f64();
    let dev = design.as_ref().map(|d| simulate::deviation(&sim, d, &cfg.tool));
    // the gouge check covers each tool: its own cut against the design
    if let Some(d) = &design {
        for c in &sim.tool_cuts {
            let g = simulate::deviation(&sim.of_tool(c), d, &cfg.tool).max_under_um;
            println!(
                "tool T{} ({}): {} segments, deepest {g:.3} µm below the design",
                c.number, c.shape, c.segments
            );
        }
    }
    let t_dev = t0.elapsed().as_secs_f64() - t_sim;

    // everything computed; encode, then write
    let s = &sim.stats;
    let relief = sim
        .heightfield
        .relief_png(&format!("simulated cut, {} at {} um", cfg.tool, cfg.pitch_um), 1024)
        .to_png();
    let dev_png = dev.as_ref().map(|d| {
        d.to_png("simulated - design (µm); grey: unreachable or edge band", 1024)
            .0
            .to_png()
    });
    // the design and the cut side by side (absent when no window was assessed)
    let pair_png = dev
        .as_ref()
        .and_then(|d| simulate::side_by_side(&sim, d, simulate::side_by_side::WINDOW_MM))
        .map(|s| s.canvas.to_png());
    let stl = a.stl.then(|| {
        let tris = simulate::solid(&sim, a.stl_side, 1.0);
        brdfmill::base::stl::to_binary_stl(&tris, "brdfmill simulated cut")
    });
    let json = simulate::SimFile::new(
        &sim,
        &cfg,
        &names,
        dev.as_ref(),
        a.design.as_ref().map(|p| p.display().to_string()),
    )
    .to_json();
    sim.heightfield.write_npy(&a.out.join("sim.npy"))?;
    brdfmill::base::io::write_atomic(&a.out.join("sim.png"), &relief)?;
    if let Some(b) = &dev_png {
        brdfmill::base::io::write_atomic(&a.out.join("deviation.png"), b)?;
    }
    if let Some(b) = &pair_png {
        brdfmill::base::io::write_atomic(&a.out.join("design-vs-cut.png"), b)?;
    }
    if let Some(b) = &stl {
        brdfmill::base::io::write_atomic(&a.out.join("sim.stl"), b)?;
    }
    brdfmill::base::io::write_atomic(&a.out.join("sim.json"), json.as_bytes())?;

    println!(
        "program   {} lines, {} moves ({} arcs → {} segments, {} reach the stock){}",
        s.lines,
        s.moves,
        s.arcs,
        s.segments,
        s.cutting_segments,
        if s.inch { ", inches converted to mm" } else { "" }
    );
    println!(
        "stock     {} × {} cells at {} µm over X {:.3}..{:.3} Y {:.3}..{:.3} mm, top z = {} mm",
        s.cells[0],
        s.cells[1],
        cfg.pitch_um,
        s.bounds_mm[0],
        s.bounds_mm[2],
        s.bounds_mm[1],
        s.bounds_mm[3],
        cfg.stock_top_mm
    );
    println!(
        "removed   {:.4} mm³, deepest z {:.4} mm",
        s.removed_volume_mm3, s.min_z_mm
    );
    println!(
        "time      {} estimated ({}), {:.1} mm cutting, {:.1} mm rapid",
        brdfmill::stages::toolpath::hms(s.estimated_s),
        s.machine,
        s.feed_length_mm,
        s.rapid_length_mm
    );
    if s.rapid_cuts > 0 {
        println!(
            "WARNING   {} rapid (G0) moves remove material, first at lines {:?}",
            s.rapid_cuts, s.rapid_cut_lines
        );
    }
    println!(
        "sweep     {:.3e} cells swept in {:.2} s ({:.0} M cells/s)",
        s.swept_cells as f64,
        t_sim,
        s.swept_cells as f64 / t_sim / 1e6
    );
    if let Some(d) = &dev {
        println!(
            "design    interior {} cells ({:.3} mm from the edge); unreachable {:.2}% (opening > design + {} µm)",
            d.interior_cells,
            d.interior_margin_mm,
            100.0 * d.unreachable_fraction,
            d.reach_tolerance_um
        );
        println!(
            "over      {:.3} µm at ({:.4}, {:.4}) mm; where reachable {:.3} µm at ({:.4}, {:.4}) mm",
            d.max_over_um,
            d.max_over_at_mm[0],
            d.max_over_at_mm[1],
            d.max_over_reachable_um,
            d.max_over_reachable_at_mm[0],
            d.max_over_reachable_at_mm[1]
        );
        println!(
            "under     {:.3} µm at ({:.4}, {:.4}) mm (gouge when > 0); rms where reachable {:.3} µm",
            d.max_under_um, d.max_under_at_mm[0], d.max_under_at_mm[1], d.rms_reachable_um
        );
        println!("deviation computed in {t_dev:.2} s");
    }
    println!(
        "wrote     {}/sim.npy, sim.png, sim.json{}{}",
        a.out.display(),
        match (dev.is_some(), pair_png.is_some()) {
            (true, true) => ", deviation.png, design-vs-cut.png",
            (true, false) => ", deviation.png",
            _ => "",
        },
        if a.stl { ", sim.stl" } else { "" }
    );
    Ok(())
}
