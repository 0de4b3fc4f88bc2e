//! `brdfmill` — the command line. A thin layer over the library: it parses arguments, reads and writes
//! files, draws progress and maps errors to exit codes: 0 success, 1 an error or a refused input (the message
//! names the file and the field), 2 a bad command line, 3 a `run` that completed but falls short of its
//! tolerances (`--allow-shortfall` makes that 0), or a `compare` whose scan falls short.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod cli;

/// Turn a target reflectance (BRDF) into a millable microgeometry.
#[derive(Parser, Debug)]
#[command(name = "brdfmill", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run every stage of a job file (BRDF → NDF → facets → toolpath → simulation → verification) and
    /// write every artifact and an HTML report to DIR.
    Run(cli::run::Args),
    /// BRDF → target NDF in slope space (half-angle distribution, Lucy–Richardson deconvolution of the base
    /// lobe, mean tilt removed). Writes ndf.json and optionally a PNG.
    Ndf(cli::ndf::Args),
    /// Target NDF → a tileable facet heightfield: CVT sampling, annealed arrangement, periodic Poisson
    /// integration. Writes DIR/tile.json, tile.npy, tile.png and tile.stl.
    Facets(cli::facets::Args),
    /// Tile → G-code: ball-nose drop-cutter, roughing layers and raster finishing over the work area, checked
    /// against the machine profile before anything is written.
    Toolpath(cli::toolpath::Args),
    /// Any G-code program → the heightfield the bit cuts (material removal on a stock heightfield), with
    /// deviation from the design when given.
    Simulate(cli::simulate::Args),
    /// Stream a G-code program to a GRBL 1.1 controller over a serial port (character counting, journal,
    /// resume, check mode, feed hold on Ctrl-C).
    Stream(cli::stream::Args),
    /// Run a virtual GRBL 1.1 controller on a pseudo-terminal and print its port path (for tests and dry runs).
    Emulate(cli::emulate::Args),
    /// A measured (X3P) or simulated (.npy) surface → NDF and BRDF, geometric and wave optics, with a report
    /// in DIR.
    Analyze(cli::analyze::Args),
    /// A scan of the milled part (X3P or .npy) against the job that made it: registered to the simulated cut
    /// (quarter turns, small angles, translation, tilt), measured as the verdict measures the cut, with the
    /// difference map. Writes DIR/compare.json, compare.html, difference.png, ndf-scan.json.
    Compare(cli::compare::Args),
    /// A job's BRDFs for other tools: the target's, the design tile's and the simulated milled surface's as
    /// MERL .binary tables (target.binary, design.binary, milled.binary) in DIR (default: the job's folder).
    Export(cli::export::Args),
    /// Machine profile → a calibration coupon (program, reading sheet, dimensions) whose slots measure the
    /// profile's backlash, runout and steps per mm with calipers. Writes DIR/calibrate.nc, calibrate.md,
    /// calibrate.json (and tool.tbl for LinuxCNC).
    Calibrate(cli::calibrate::Args),
}

fn main() {
    let cli = Cli::parse();
    let ok = |r: Result<()>| r.map(|()| 0);
    let result: Result<i32> = match cli.command {
        Command::Run(a) => cli::run::run(&a),
        Command::Ndf(a) => ok(cli::ndf::run(&a)),
        Command::Facets(a) => ok(cli::facets::run(&a)),
        Command::Toolpath(a) => ok(cli::toolpath::run(&a)),
        Command::Simulate(a) => ok(cli::simulate::run(&a)),
        Command::Stream(a) => ok(cli::stream::run(&a)),
        Command::Emulate(a) => ok(cli::emulate::run(&a)),
        Command::Analyze(a) => ok(cli::analyze::run(&a)),
        Command::Calibrate(a) => ok(cli::calibrate::run(&a)),
        Command::Compare(a) => cli::compare::run(&a),
        Command::Export(a) => ok(cli::export::run(&a)),
    };
    match result {
        Ok(0) => {}
        Ok(code) => std::process::exit(code),
        Err(e) => {
            // not `eprintln!`, which panics when standard error is closed
            use std::io::Write as _;
            let _ = writeln!(std::io::stderr(), "error: {e:#}");
            std::process::exit(1);
        }
    }
}
