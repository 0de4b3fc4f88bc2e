//! Stage 5 — simulate: any G-code program to the heightfield the bit really cuts (DESIGN.md §5).
//!
//! - [`gcode`]: the reader of §5, on the crate's one interpreter in the dialect of the program's machine; what
//!   it does not understand is refused with line and column. Arcs become chords within `arc_tolerance_um`
//!   (chord sagitta).
//! - The machining layer sweeps them: [`crate::cut::sweep`] (the lowest point of a ball, flat or bull bit
//!   swept along one straight segment, in closed form for ball and flat, a certified 1 pm bound for the
//!   bull) over `crate::cut::stock` (the stock heightfield in tiles, swept in parallel with rayon).
//! - [`deviation`](mod@deviation): the simulated surface against the design tile, and where the bit cannot reach.
//!
//! The stock is a non-periodic grid of `pitch_um` over the program's cutting extents plus the tool radius
//! (or given bounds), flat at `stock_top_mm`; every segment lowers it to `min(stock, sweep)` at each cell
//! centre, exactly for linear moves. The machining time comes from the machining layer's planner
//! (`crate::cut::estimate::estimate_s`) with the limits of a machine profile — by default those of
//! `machines/linuxcnc-mill.toml` (X/Y 500 mm/s², Z 300 mm/s², rapids 3000 / 1500 mm/min, junction deviation
//! 0.001 mm), said in [`SimStats::machine`].
//!
//! # Example
//! ```
//! use brdfmill::stages::simulate::{self, SimulateConfig, Shape};
//! let cfg = SimulateConfig { tool: Shape::parse("ball:1.0").unwrap(), pitch_um: 10.0, ..Default::default() };
//! let sim = simulate::run("G21 G90\nG0 X0 Y0.005 Z1\nG1 Z-0.2 F100\nX2\nG0 Z1\nM2\n", &cfg).unwrap();
//! // a 0.2 mm deep groove of a 1 mm ball (along a row of cell centres)
//! let (lo, _) = sim.heightfield.range();
//! assert!((lo + 0.2).abs() < 1e-12);
//! ```

mod air;
pub mod deviation;
pub mod gcode;
pub mod side_by_side;

pub use air::{air_feeds, cut_and_air_mm};
pub use deviation::{deviation, Deviation};
pub use side_by_side::{side_by_side, SideBySide};

use crate::base::heightfield::Heightfield;
use crate::cut::machine::{Accuracy, Machine};
use crate::cut::stock;
pub use crate::cut::tool::Shape;
use crate::gcode::moves::P3;
use gcode::{Motion, ParseOptions};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The tool table of a machine profile: tool number → shape.
pub fn tool_table(machine: &Machine) -> BTreeMap<u32, Shape> {
    machine.tools.iter().map(|t| (t.number, t.shape)).collect()
}

impl SimulateConfig {
    /// The bit of tool `number` as the machine cuts with it (its runout envelope).
    pub fn shape_of(&self, number: u32) -> Shape {
        self.accuracy()
            .envelope(self.tools.get(&number).copied().unwrap_or(self.tool))
    }

    /// The errors the cut follows: the machine's `[accuracy]`, or none when `ideal` or without a machine.
    pub fn accuracy(&self) -> Accuracy {
        match &self.machine {
            Some(m) if !self.ideal => m.accuracy(),
            _ => Accuracy::PERFECT,
        }
    }
}

/// One tool's own cut: its segments swept alone over the flat stock (the gouge check of each tool).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ToolCut {
    /// Tool number (`T`).
    pub number: u32,
    /// Its shape.
    pub shape: Shape,
    /// Heights its segments alone leave, mm, on the simulation's grid.
    #[serde(skip)]
    pub z_mm: Vec<f64>,
    /// Its segments.
    pub segments: usize,
}

/// The largest `max_cells` may be raised to: a stock of 10⁹ cells is 8 GB, and the deviation map, the
/// images and the files written from it hold as much again (a larger one failed its allocation and
/// aborted instead of being refused).
pub const MAX_CELLS_CEILING: usize = 1_000_000_000;

/// Configuration of the simulation. Lengths carry their unit in the name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateConfig {
    /// The bit (of every tool number not in `tools`).
    pub tool: Shape,
    /// The bit of each tool number (`T… M6`): each tool's segments are swept with its own shape. Empty: `tool`
    /// for all. [`tool_table`] reads it from a machine profile.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub tools: BTreeMap<u32, Shape>,
    /// Stock grid pitch, µm.
    pub pitch_um: f64,
    /// Stock bounds `[x0, y0, x1, y1]`, mm; None: the XY extents of the moves that reach below the stock top
    /// (of all moves when none does; of the start point when nothing moves), plus the tool radius, on
    /// multiples of the pitch.
    pub bounds_mm: Option<[f64; 4]>,
    /// Height of the stock top, mm (DESIGN.md: z = 0).
    pub stock_top_mm: f64,
    /// Largest chord sagitta when arcs are linearised, µm.
    pub arc_tolerance_um: f64,
    /// Tool-tip position before the first move, mm (LinuxCNC's interpreter starts at the origin).
    pub start_mm: [f64; 3],
    /// Refuse a stock grid of more cells than this (8 bytes each; 250 M cells is 2 GB).
    pub max_cells: usize,
    /// Refuse a program that expands to more linear segments than this.
    pub max_segments: usize,
    /// Flute length, mm: a move whose tip goes deeper than this below the stock top is refused (the shank
    /// would rub). 0: not checked.
    pub flute_length_mm: f64,
    /// The machine: its limits for the time estimate (None: `machines/linuxcnc-mill.toml`'s) and its
    /// `[accuracy]`, which the cut follows unless `ideal` (None: a perfect machine).
    pub machine: Option<Machine>,
    /// Cut as a perfect machine would, whatever `machine` declares (the `milled_ideal` figures).
    #[serde(default)]
    pub ideal: bool,
    /// Also cut each tool's program alone from the stock top ([`Simulation::tool_cuts`], for a gouge check
    /// per tool), when the program uses more than one tool: a second sweep of every tool but the first.
    #[serde(skip)]
    pub tool_cuts: bool,
    /// Only the milled surface: every tool's segments swept deepest first, the last tool first. The surface
    /// is the minimum over every sweep, whatever their order, so it is the same to the bit, and much cheaper
    /// (a roughing pass the finishing cut below is skipped after one compare per row); what needs program
    /// order is not measured (the air, the rapids that cut and the cutting segments are left at zero). For
    /// the job's comparison cuts (a perfect machine, each error alone), which are measured only by their
    /// surface.
    #[serde(skip)]
    pub surface_only: bool,
}

impl Default for SimulateConfig {
    fn default() -> Self {
        Self {
            tool: Shape::default(),
            tools: BTreeMap::new(),
            pitch_um: 5.0,
            bounds_mm: None,
            stock_top_mm: 0.0,
            arc_tolerance_um: 0.1,
            start_mm: [0.0; 3],
            max_cells: 250_000_000,
            max_segments: ParseOptions::default().max_segments,
            flute_length_mm: 0.0,
            machine: None,
            ideal: false,
            tool_cuts: false,
            surface_only: false,
        }
    }
}

impl SimulateConfig {
    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<(), SimulateError> {
        let bad = |s: String| Err(SimulateError::Config(s));
        self.tool
            .validate()
            .map_err(|e| SimulateError::Config(format!("tool {e}")))?;
        for (n, t) in &self.tools {
            t.validate()
                .map_err(|e| SimulateError::Config(format!("tool T{n} {e}")))?;
        }
        let p = self.pitch_um;
        if !(p.is_finite() && p > 0.0) {
            return bad(format!("`pitch_um` must be positive, got {p}"));
        }
        if self.tool.diameter_mm() < 2.0 * p * 1e-3 {
            return bad(format!(
                "the tool ({} mm) is smaller than two cells of pitch_um = {p}: the grid cannot resolve it",
                self.tool.diameter_mm()
            ));
        }
        if !(self.arc_tolerance_um.is_finite()
            && (MIN_ARC_TOLERANCE_UM..=MAX_ARC_TOLERANCE_UM).contains(&self.arc_tolerance_um))
        {
            return bad(format!(
                "`arc_tolerance_um` must be in [{MIN_ARC_TOLERANCE_UM}, {MAX_ARC_TOLERANCE_UM}] µm, got {}",
                self.arc_tolerance_um
            ));
        }
        if !self.stock_top_mm.is_finite() || self.start_mm.iter().any(|v| !v.is_finite()) {
            return bad("stock_top_mm and start_mm must be finite".into());
        }
        if let Some([x0, y0, x1, y1]) = self.bounds_mm {
            if !([x0, y0, x1, y1].iter().all(|v| v.is_finite()) && x1 > x0 && y1 > y0) {
                return bad(format!(
                    "bounds_mm must be x0,y0,x1,y1 with x1 > x0 and y1 > y0, got {x0},{y0},{x1},{y1}"
                ));
            }
        }
        if self.flute_length_mm.is_nan() || self.flute_length_mm < 0.0 {
            return bad(format!("flute_length_mm must be ≥ 0, got {}", self.flute_length_mm));
        }
        if self.max_cells > MAX_CELLS_CEILING {
            return bad(format!(
                "max_cells may be raised to {MAX_CELLS_CEILING} at most (8 bytes each, and the deviation, \
                 images and files hold more), got {}",
                self.max_cells
            ));
        }
        Ok(())
    }
}

/// The finest arc linearisation, µm (a nanometre: finer chords only multiply the segments).
pub const MIN_ARC_TOLERANCE_UM: f64 = 1e-3;

/// The coarsest arc linearisation, µm (a tenth of a millimetre would cut visibly polygonal arcs).
pub const MAX_ARC_TOLERANCE_UM: f64 = 100.0;

impl SimulateConfig {
    /// Bound the stock before anything runs: a program over `area_mm` (plus the tool's diameter and a
    /// millimetre of margin) at `pitch_um` is about this many cells, refused above `max_cells` with the field
    /// and the estimate; every field checked as [`SimulateConfig::validate`] does.
    pub fn check_area(&self, area_mm: [f64; 2]) -> Result<(), SimulateError> {
        self.validate()?;
        let [ax, ay] = area_mm;
        let p = self.pitch_um;
        let margin_mm = self.tool.diameter_mm() + 1.0;
        let cells = ((ax + margin_mm) / (p * 1e-3)) * ((ay + margin_mm) / (p * 1e-3));
        if cells > self.max_cells as f64 {
            return Err(SimulateError::Limit(format!(
                "`pitch_um` = {p} over {ax}×{ay} mm is about {cells:.3e} stock cells, more than {:e} (`max_cells`, 8 bytes each)",
                self.max_cells as f64
            )));
        }
        Ok(())
    }
}

/// Errors of the simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// The program uses something the reader does not understand (with line and column).
    #[error("{0}")]
    Gcode(#[from] gcode::GcodeError),
    /// A configuration value is out of range.
    #[error("simulate config: {0}")]
    Config(String),
    /// A stock, tool or program limit would be exceeded.
    #[error("refused: {0}")]
    Limit(String),
}

/// The simulation in numbers.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SimStats {
    /// Material removed from the stock, mm³ (sum over cells of depth below the top × pitch²).
    pub removed_volume_mm3: f64,
    /// Estimated machining time, s (feeds, acceleration, junction deviation; see [`SimStats::machine`]).
    pub estimated_s: f64,
    /// The machine profile whose limits the estimate used.
    pub machine: String,
    /// Motion commands that moved (G0/G1/G2/G3 blocks).
    pub moves: usize,
    /// Arc commands among them.
    pub arcs: usize,
    /// Linear segments swept (arcs split into chords).
    pub segments: usize,
    /// Segments that reach below the stock top over the stock.
    pub cutting_segments: usize,
    /// (segment, cell) evaluations: the cells under each segment's footprint, summed.
    pub swept_cells: u64,
    /// Rapid (G0) moves that removed material — a crash on a real machine.
    pub rapid_cuts: usize,
    /// Program lines of the first few of those.
    pub rapid_cut_lines: Vec<usize>,
    /// Lines read.
    pub lines: usize,
    /// Whether the program used inches (converted to mm).
    pub inch: bool,
    /// Stock grid cells `[nx, ny]`.
    pub cells: [usize; 2],
    /// Stock grid pitch, mm.
    pub pitch_mm: f64,
    /// Stock bounds `[x0, y0, x1, y1]`, mm.
    pub bounds_mm: [f64; 4],
    /// Lowest point of the simulated surface, mm.
    pub min_z_mm: f64,
    /// Cutting (G1 and arc) path length, mm.
    pub feed_length_mm: f64,
    /// Rapid path length, mm.
    pub rapid_length_mm: f64,
    /// Feed path that removed nothing when it ran (air: approaches, links and retraces above the stock as it
    /// stood then; [`crate::cut::sweep::CUT_MM`]), mm.
    #[serde(default)]
    pub air_feed_mm: f64,
    /// The time of that path at its programmed feeds, s.
    #[serde(default)]
    pub air_feed_s: f64,
    /// Largest chord sagitta of the arcs' linearisation, µm.
    pub arc_tolerance_um: f64,
    /// The machine's errors the cut followed (backlash, runout, step grid); absent: a perfect machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<Accuracy>,
}

/// A simulated cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Simulation {
    /// The milled surface, mm (non-periodic).
    pub heightfield: Heightfield,
    /// Work x, y of the grid's lower-left corner, mm: cell `(i, j)` is centred at
    /// `origin + ((i + ½)·pitch, (j + ½)·pitch)`.
    pub origin_mm: [f64; 2],
    /// The numbers.
    pub stats: SimStats,
    /// Each tool's own cut, when the program uses more than one tool and [`SimulateConfig::tool_cuts`] asks
    /// for them.
    #[serde(default, skip)]
    pub tool_cuts: Vec<ToolCut>,
}

impl Simulation {
    /// The surface of one tool's cut as a simulation of its own (for `deviation` per tool).
    pub fn of_tool(&self, cut: &ToolCut) -> Simulation {
        Simulation {
            heightfield: Heightfield {
                z_mm: cut.z_mm.clone(),
                ..self.heightfield.clone()
            },
            origin_mm: self.origin_mm,
            stats: self.stats.clone(),
            tool_cuts: vec![],
        }
    }

    /// Work coordinates of the centre of cell `(i, j)`, mm.
    pub fn cell_xy(&self, i: usize, j: usize) -> [f64; 2] {
        let p = self.heightfield.pitch_mm;
        [
            self.origin_mm[0] + (i as f64 + 0.5) * p,
            self.origin_mm[1] + (j as f64 + 0.5) * p,
        ]
    }
}

/// `sim.json`, version 1: the one layout that `brdfmill simulate` and `brdfmill run` both write.
#[derive(Debug, Serialize)]
pub struct SimFile<'a> {
    /// `"brdfmill-sim"`.
    pub format: &'static str,
    /// 1.
    pub version: u32,
    /// The program simulated (its path as given).
    pub program: String,
    /// The heights file beside this one.
    pub npy: &'static str,
    /// Work x, y of the grid's lower-left corner, mm.
    pub origin_mm: [f64; 2],
    /// The configuration.
    pub config: &'a SimulateConfig,
    /// The numbers.
    pub stats: &'a SimStats,
    /// Deviation from the design, when one was given.
    pub deviation: Option<&'a Deviation>,
    /// The design compared against (its path as given).
    pub design: Option<String>,
}

impl<'a> SimFile<'a> {
    /// The file for a simulation of `program` (a path, for the record) under `config`.
    pub fn new(
        sim: &'a Simulation,
        config: &'a SimulateConfig,
        program: &str,
        deviation: Option<&'a Deviation>,
        design: Option<String>,
    ) -> Self {
        SimFile {
            format: "brdfmill-sim",
            version: 1,
            program: program.to_string(),
            npy: "sim.npy",
            origin_mm: sim.origin_mm,
            config,
            stats: &sim.stats,
            deviation,
            design,
        }
    }

    /// Pretty JSON.
    #[must_use]
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("sim.json holds only finite numbers and strings")
    }
}

/// The limits assumed when no machine profile is given.
pub fn default_machine() -> Option<Machine> {
    Machine::parse(include_str!("../../../machines/linuxcnc-mill.toml")).ok()
}

/// Parse options from a configuration: the program is read in the dialect of the machine it names (LinuxCNC's
/// without one, as the default limits are a LinuxCNC mill's).
pub fn parse_options(cfg: &SimulateConfig) -> ParseOptions {
    ParseOptions {
        arc_tolerance_mm: cfg.arc_tolerance_um * 1e-3,
        start_mm: cfg.start_mm,
        max_segments: cfg.max_segments,
        dialect: cfg
            .machine
            .as_ref()
            .map_or(crate::gcode::Dialect::Linuxcnc, |m| m.dialect),
    }
}

/// Parse and simulate a program held in memory.
pub fn run(program: &str, cfg: &SimulateConfig) -> Result<Simulation, SimulateError> {
    run_files(&[program], cfg)
}

/// Parse and simulate programs that run one after another on the same stock ([`gcode::parse_all`]).
pub fn run_files(programs: &[&str], cfg: &SimulateConfig) -> Result<Simulation, SimulateError> {
    cfg.validate()?;
    let prog = gcode::parse_all(programs, &parse_options(cfg))?;
    simulate(&prog, cfg)
}

/// The stock grid of a program under a configuration (bounds given, or the cutting extents plus the tool
/// radius on multiples of the pitch), checked against the cell limit.
pub fn stock_grid(prog: &Motion, cfg: &SimulateConfig) -> Result<stock::Grid, SimulateError> {
    let p = cfg.pitch_um * 1e-3;
    let r = prog
        .segments
        .iter()
        .map(|s| s.tool)
        .collect::<std::collections::BTreeSet<u32>>()
        .into_iter()
        .map(|n| cfg.shape_of(n).radius_mm())
        .fold(cfg.tool.radius_mm(), f64::max);
    let (x0, y0, x1, y1) = match cfg.bounds_mm {
        Some([a, b, c, d]) => (a, b, c, d),
        None => {
            let below: Vec<_> = prog
                .segments
                .iter()
                .filter(|s| s.from[2].min(s.to[2]) < cfg.stock_top_mm)
                .collect();
            let pick: Vec<_> = if below.is_empty() {
                prog.segments.iter().collect()
            } else {
                below
            };
            // a program that never moves leaves the stock under the tool at its start point
            let start = [cfg.start_mm, cfg.start_mm];
            let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
            let ends: Vec<[P3; 2]> = if pick.is_empty() {
                vec![start]
            } else {
                pick.iter().map(|s| [s.from, s.to]).collect()
            };
            for e in ends {
                for q in e {
                    b = [b[0].min(q[0]), b[1].min(q[1]), b[2].max(q[0]), b[3].max(q[1])];
                }
            }
            (
                ((b[0] - r) / p).floor() * p,
                ((b[1] - r) / p).floor() * p,
                ((b[2] + r) / p).ceil() * p,
                ((b[3] + r) / p).ceil() * p,
            )
        }
    };
    let nx = ((x1 - x0) / p - 1e-9).ceil().max(1.0);
    let ny = ((y1 - y0) / p - 1e-9).ceil().max(1.0);
    if nx * ny > cfg.max_cells as f64 {
        return Err(SimulateError::Limit(format!(
            "a stock of {:.3} × {:.3} mm at {} µm is {nx} × {ny} = {:.0} cells, above the limit of {} cells \
             (max_cells); use a coarser pitch or smaller bounds",
            x1 - x0,
            y1 - y0,
            cfg.pitch_um,
            nx * ny,
            cfg.max_cells
        )));
    }
    Ok(stock::Grid {
        x0,
        y0,
        pitch: p,
        nx: nx as usize,
        ny: ny as usize,
    })
}

/// Simulate a program already read.
pub fn simulate(prog: &Motion, cfg: &SimulateConfig) -> Result<Simulation, SimulateError> {
    cfg.validate()?;
    if cfg.flute_length_mm > 0.0 {
        let floor = cfg.stock_top_mm - cfg.flute_length_mm;
        if let Some(s) = prog.segments.iter().find(|s| s.from[2].min(s.to[2]) < floor - 1e-9) {
            return Err(SimulateError::Limit(format!(
                "line {}: the tip reaches {:.4} mm below the stock top, deeper than the flute length {} mm",
                s.line,
                cfg.stock_top_mm - s.from[2].min(s.to[2]),
                cfg.flute_length_mm
            )));
        }
    }
    let acc = cfg.accuracy();
    // the path the machine follows (the commanded one on a perfect machine)
    let actual;
    let path = if acc.is_perfect() {
        prog
    } else {
        actual = Motion {
            segments: acc.actual_path(&prog.segments, cfg.start_mm),
            ..Motion::default()
        };
        &actual
    };
    let grid = stock_grid(prog, cfg)?;
    let top = cfg.stock_top_mm;
    let (z, rep, tool_cuts) = sweep_tools(&grid, top, cfg, path);
    let air = air_feeds(&path.segments, &rep.cut_segments);
    let area = grid.pitch * grid.pitch;
    let removed: f64 = z.iter().map(|v| (top - v).max(0.0)).sum::<f64>() * area;
    let min_z = z.iter().copied().fold(f64::INFINITY, f64::min);
    let machine = cfg.machine.clone().or_else(default_machine);
    let (estimated_s, machine_name) = match &machine {
        Some(m) => (
            crate::cut::estimate::estimate_s(&prog.moves, cfg.start_mm, m),
            if cfg.machine.is_some() {
                m.name.clone()
            } else {
                format!("{} (machines/linuxcnc-mill.toml, assumed)", m.name)
            },
        ),
        None => (f64::NAN, "none".into()),
    };
    let len = crate::gcode::moves::lengths(&prog.moves, cfg.start_mm);
    let stats = SimStats {
        removed_volume_mm3: removed,
        estimated_s,
        machine: machine_name,
        moves: prog.motions,
        arcs: prog.arcs,
        segments: prog.segments.len(),
        cutting_segments: rep.cutting_segments,
        swept_cells: rep.swept_cells,
        rapid_cuts: rep.rapid_cuts.len(),
        rapid_cut_lines: rep.rapid_cuts.iter().take(10).copied().collect(),
        lines: prog.lines,
        inch: prog.inch,
        cells: [grid.nx, grid.ny],
        pitch_mm: grid.pitch,
        bounds_mm: [
            grid.x0,
            grid.y0,
            grid.x0 + grid.nx as f64 * grid.pitch,
            grid.y0 + grid.ny as f64 * grid.pitch,
        ],
        min_z_mm: min_z,
        feed_length_mm: len.feed_mm,
        rapid_length_mm: len.rapid_mm,
        air_feed_mm: air.0,
        air_feed_s: air.1,
        arc_tolerance_um: cfg.arc_tolerance_um,
        accuracy: (!acc.is_perfect()).then_some(acc),
    };
    Ok(Simulation {
        heightfield: Heightfield {
            nx: grid.nx,
            ny: grid.ny,
            pitch_mm: grid.pitch,
            periodic: false,
            z_mm: z,
        },
        origin_mm: [grid.x0, grid.y0],
        stats,
        tool_cuts,
    })
}

/// Sweep each tool's segments with its own shape, in program order, the stock carried from one tool to the
/// next. Returns the heights, a report whose `rapid_cuts` are program *lines* and whose `cut_segments` index
/// `prog.segments` (each measured against the stock as it stood when the segment ran), and, when
/// `cfg.tool_cuts` asks and there is more than one tool, each tool's own cut (the first tool's is the stock
/// it left; each later one's is swept again from the top, the one extra sweep this costs).
fn sweep_tools(
    grid: &stock::Grid,
    top: f64,
    cfg: &SimulateConfig,
    prog: &Motion,
) -> (Vec<f64>, stock::SweepReport, Vec<ToolCut>) {
    // tools in the order the program first uses them
    let mut numbers: Vec<u32> = vec![];
    for s in &prog.segments {
        if !numbers.contains(&s.tool) {
            numbers.push(s.tool);
        }
    }
    if cfg.surface_only {
        let mut z = vec![top; grid.nx * grid.ny];
        for &n in numbers.iter().rev() {
            let segs: Vec<gcode::Segment> = prog.segments.iter().filter(|s| s.tool == n).copied().collect();
            stock::sweep_into(
                grid,
                &mut z,
                top,
                cfg.shape_of(n),
                &segs,
                stock::Order::DeepestFirst,
                |_, _| {},
            );
        }
        return (z, stock::SweepReport::default(), vec![]);
    }
    if numbers.len() <= 1 {
        let n = numbers.first().copied().unwrap_or(0);
        let (z, mut rep) = stock::sweep(grid, top, cfg.shape_of(n), &prog.segments);
        rep.rapid_cuts = rep.rapid_cuts.iter().map(|&k| prog.segments[k].line as usize).collect();
        return (z, rep, vec![]);
    }
    let mut z = vec![top; grid.nx * grid.ny];
    let mut rep = stock::SweepReport::default();
    let mut cuts = vec![];
    for (t, n) in numbers.into_iter().enumerate() {
        let index: Vec<usize> = (0..prog.segments.len())
            .filter(|&k| prog.segments[k].tool == n)
            .collect();
        let segs: Vec<gcode::Segment> = index.iter().map(|&k| prog.segments[k]).collect();
        let shape = cfg.shape_of(n);
        let r = stock::sweep_into(grid, &mut z, top, shape, &segs, stock::Order::Program, |_, _| {});
        rep.swept_cells += r.swept_cells;
        rep.cutting_segments += r.cutting_segments;
        rep.rapid_cuts
            .extend(r.rapid_cuts.iter().map(|&k| segs[k].line as usize));
        rep.cut_segments.extend(r.cut_segments.iter().map(|&k| index[k]));
        if !cfg.tool_cuts {
            continue;
        }
        let own = if t == 0 {
            z.clone()
        } else {
            stock::sweep(grid, top, shape, &segs).0
        };
        cuts.push(ToolCut {
            number: n,
            shape,
            z_mm: own,
            segments: segs.len(),
        });
    }
    rep.rapid_cuts.sort_unstable();
    rep.cut_segments.sort_unstable();
    (z, rep, cuts)
}

/// The simulated surface as a closed solid for STL ([`crate::base::stl::heightfield_solid`] in work mm).
pub fn solid(sim: &Simulation, max_side: usize, base_mm: f64) -> Vec<crate::base::stl::Triangle> {
    crate::base::stl::heightfield_solid(&sim.heightfield, sim.origin_mm, max_side, base_mm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_are_refused_with_a_message() {
        let prog = "G0 X0 Y0 Z1\nG1 Z-1 F100\nX100 Y100\n";
        let cfg = SimulateConfig {
            pitch_um: 1.0,
            ..Default::default()
        };
        let e = run(prog, &cfg).unwrap_err();
        assert!(e.to_string().contains("max_cells"), "{e}");
        let cfg = SimulateConfig {
            pitch_um: 100.0,
            flute_length_mm: 0.5,
            ..Default::default()
        };
        let e = run(prog, &cfg).unwrap_err();
        assert!(
            e.to_string().contains("line 2") && e.to_string().contains("flute"),
            "{e}"
        );
        let e = run("G0 X0\nG1 X1\n", &SimulateConfig::default()).unwrap_err();
        assert!(e.to_string().starts_with("line 2, column 1"), "{e}");
    }

    #[test]
    fn moves_outside_the_stock_and_rapid_cuts() {
        let cfg = SimulateConfig {
            pitch_um: 20.0,
            bounds_mm: Some([0.0, 0.0, 2.0, 2.0]),
            ..Default::default()
        };
        // a feed far away, a rapid through the stock
        let s = run(
            "G0 X50 Y50 Z1\nG1 Z-1 F100\nX60\nG0 Z1\nX1.01 Y1.01\nG0 Z-0.1\nG0 Z1\n",
            &cfg,
        )
        .unwrap();
        assert_eq!(s.stats.rapid_cuts, 1);
        assert_eq!(s.stats.rapid_cut_lines, vec![6]);
        let (lo, _) = s.heightfield.range();
        assert!((lo + 0.1).abs() < 1e-12, "{lo} {:?}", s.stats);
        assert!(s.stats.estimated_s > 0.0 && s.stats.machine.contains("assumed"));
    }

    /// The surface alone (deepest first, the last tool first) is the program-order cut to the bit: a roughing
    /// ball, then a finishing ball with runout (a bull-nose envelope), on a machine with backlash.
    #[test]
    fn the_surface_alone_is_the_program_order_cut() {
        let mut machine = crate::cut::machine::Machine::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/grbl-3018.toml"),
        )
        .unwrap();
        machine.accuracy = Some(crate::cut::accuracy::Accuracy {
            backlash_um: [25.0, 25.0, 0.0],
            runout_um: 15.0,
            ..crate::cut::accuracy::Accuracy::PERFECT
        });
        // two programs, as a GRBL job has them (GRBL cannot change tools: `T` names the bit)
        let rough = "G21 G90\nT1\nG0 X0 Y0 Z1\nG1 Z-0.3 F300\nX2 Y0.2\nY1.2\nX0 Y1\nG0 Z1\n";
        let finish =
            "G21 G90\nT2\nG0 X0 Y0.1 Z1\nG1 Z-0.45 F100\nX2 Y0.3 Z-0.35\nG2 X2 Y1.1 I0 J0.4\nG1 X0.2 Y0.9 Z-0.5\nG0 Z1\n";
        let program = [rough, finish];
        let cfg = SimulateConfig {
            pitch_um: 10.0,
            bounds_mm: Some([-1.0, -1.0, 3.0, 2.5]),
            tools: [
                (1, Shape::Ball { diameter_mm: 2.0 }),
                (2, Shape::Ball { diameter_mm: 0.5 }),
            ]
            .into(),
            machine: Some(machine),
            ..Default::default()
        };
        let full = run_files(&program, &cfg).unwrap();
        assert!(full.stats.cutting_segments > 0);
        let alone = run_files(
            &program,
            &SimulateConfig {
                surface_only: true,
                ..cfg.clone()
            },
        )
        .unwrap();
        assert_eq!(full.heightfield.z_mm, alone.heightfield.z_mm);
        assert!(full.heightfield.range().0 < -0.4);
    }

    #[test]
    fn stl_solid_is_closed_with_the_right_volume() {
        let cfg = SimulateConfig {
            pitch_um: 20.0,
            ..Default::default()
        };
        let s = run("G0 X0 Y0 Z1\nG1 Z-0.3 F100\nX2 Y0.5\nG0 Z1\n", &cfg).unwrap();
        for max_side in [8, 1000] {
            let t = solid(&s, max_side, 1.0);
            let mut edges = std::collections::HashMap::<([i64; 3], [i64; 3]), i64>::new();
            let key = |v: &crate::base::geometry::Vec3| {
                [
                    (v.x * 1e7).round() as i64,
                    (v.y * 1e7).round() as i64,
                    (v.z * 1e7).round() as i64,
                ]
            };
            for tri in &t {
                for k in 0..3 {
                    *edges.entry((key(&tri[k]), key(&tri[(k + 1) % 3]))).or_default() += 1;
                    *edges.entry((key(&tri[(k + 1) % 3]), key(&tri[k]))).or_default() -= 1;
                }
            }
            assert!(edges.values().all(|c| *c == 0), "open mesh at max_side {max_side}");
            let v = crate::base::stl::volume(&t);
            assert!(v > 0.0);
            if max_side == 1000 {
                // full resolution: the volume of the cell-centre surface over the base
                let hf = &s.heightfield;
                let (lo, _) = hf.range();
                let zb = lo - 1.0;
                let p = hf.pitch_mm;
                let mut expect = 0.0;
                for j in 0..hf.ny - 1 {
                    for i in 0..hf.nx - 1 {
                        // two triangles: mean of their vertex heights
                        let t1 = (hf.at(i, j) + hf.at(i + 1, j) + hf.at(i + 1, j + 1)) / 3.0;
                        let t2 = (hf.at(i, j) + hf.at(i + 1, j + 1) + hf.at(i, j + 1)) / 3.0;
                        expect += p * p / 2.0 * (t1 + t2 - 2.0 * zb);
                    }
                }
                assert!((v - expect).abs() < 1e-9 * expect, "{v} vs {expect}");
            }
        }
    }
}
