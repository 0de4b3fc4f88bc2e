//! Stage 4 — toolpath: a heightfield (typically the periodic facet tile) to a G-code program.
//!
//! - The machining layer supplies the machine profiles ([`crate::cut::machine`]), the exact cutter-location
//!   surface ([`crate::cut::dropcutter`]) and the run-time planner (`crate::cut::estimate`).
//! - `raster`: raster passes at any angle over the tile repeated across the work area.
//! - `simplify`: one-sided removal of collinear points within a stated tolerance; `arcs`: `G2`/`G3` in the
//!   pass plane (`G18`, `G19`) where a run of blocks lies on one circle, one-sided within it.
//! - [`check`]: the machine check; the program is written by `crate::gcode::emit`.
//!
//! The program cuts roughing layers first when the design is deeper than the tool's depth of cut
//! (z = max(layer, CL_rough + leave)), then the finishing raster at the stepover of the target scallop.

pub(crate) mod arcs;
mod build;
pub mod check;
pub mod files;
mod plan;
pub(crate) mod raster;
pub(crate) mod rough;
pub(crate) mod simplify;
mod stock_side;

pub use plan::{ToolpathPlan, MAX_CL_POINTS, MAX_GRID_CELLS, MAX_PASSES, MAX_TOLERANCE_UM, MIN_FEED_MM_MIN};

use crate::base::heightfield::Heightfield;
use crate::cut::machine::{self, Machine, Stock, Tool};
use crate::cut::{dropcutter, estimate, feeds};
use crate::gcode::emit;
use crate::gcode::moves::{self, Move, P3};
use build::Builder;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Raster strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// One-way where the machine profile says its axes have backlash (`limits.backlash`), zigzag elsewhere.
    Auto,
    /// Alternate directions, linked along the area's edge at the CL surface.
    Zigzag,
    /// Every pass in the same direction (climb for an `M3` spindle), retracting between passes.
    Oneway,
}

impl Strategy {
    /// Whether row `k` of the raw CL rows (ascending u) runs reversed: every row one-way (−u, climb for
    /// `M3`), every other row zigzag. The final passes and the intermediate finishing levels share it, so
    /// that a machine's backlash shifts both alike.
    #[must_use]
    pub fn reverses(self, k: usize) -> bool {
        self == Strategy::Oneway || k % 2 == 1
    }
}

/// Configuration of the toolpath stage. Lengths carry their unit in the name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ToolpathConfig {
    /// Finishing tool id in the machine profile (a ball-nose).
    pub tool: String,
    /// Roughing tool id (ball or flat); when empty, the profile's `program.roughing_tool` if it is larger
    /// than the finishing tool, else the finishing tool.
    pub rough_tool: String,
    /// Stock material, selects the cutting data.
    pub stock: Stock,
    /// Work area `[x, y]`, mm, covered by the tile repeated.
    #[serde(deserialize_with = "crate::base::de::exact_pair")]
    pub area_mm: [f64; 2],
    /// Target scallop height of the finishing raster, µm.
    pub scallop_um: f64,
    /// Finishing stepover, mm; 0 derives it from `scallop_um`.
    pub stepover_mm: f64,
    /// Raster direction, degrees from x.
    pub angle_deg: f64,
    /// Zigzag or one-way.
    pub strategy: Strategy,
    /// Collinear-point tolerance, µm (one-sided: the path never goes below the CL surface).
    pub tolerance_um: f64,
    /// Cutting feed override, mm/min; 0 uses the tool's cutting data.
    pub feed_mm_min: f64,
    /// Job name for the header.
    pub job: String,
    /// Fit `G2`/`G3` arcs in the pass plane (`G18` at 0°, `G19` at 90°; passes at other angles stay lines).
    pub arcs: bool,
    /// The longest run the job may take, hours: a program whose estimate is longer is refused, naming what
    /// takes the time and what would shorten it.
    pub max_hours: f64,
}

impl Default for ToolpathConfig {
    fn default() -> Self {
        Self {
            tool: "ball1".into(),
            rough_tool: String::new(),
            stock: Stock::Aluminium,
            area_mm: [40.0, 40.0],
            scallop_um: 1.0,
            stepover_mm: 0.0,
            angle_deg: 0.0,
            strategy: Strategy::Auto,
            tolerance_um: 0.5,
            feed_mm_min: 0.0,
            job: "brdfmill tile".into(),
            arcs: true,
            max_hours: 12.0,
        }
    }
}

impl ToolpathConfig {
    /// The tools in the order the program uses them, for summaries, given the program's roughing tool
    /// ([`Summary::roughing_tool`]; empty without roughing): the finishing tool alone, or the roughing tool
    /// then the finishing tool.
    pub fn tools_in_order(&self, roughing_tool: &str) -> String {
        if roughing_tool.is_empty() || roughing_tool == self.tool {
            format!("`{}` for every pass", self.tool)
        } else {
            format!("`{roughing_tool}` (roughing), then `{}` (finishing)", self.tool)
        }
    }
}

/// Errors of the toolpath stage.
#[derive(Debug, thiserror::Error)]
pub enum ToolpathError {
    /// A configuration value is out of range or does not fit the machine.
    #[error("toolpath config: {0}")]
    Config(String),
    /// The program would violate a machine limit.
    #[error("refused: {0}")]
    Machine(String),
    /// The machine profile does not have what the configuration asks for.
    #[error("toolpath config: {0}")]
    Profile(#[from] machine::ProfileError),
    /// The work the configuration asks for is beyond a stated limit (an endless run or a memory bomb).
    #[error("refused: `{field}`: {estimate}")]
    Limit {
        /// The field that drives the estimate.
        field: String,
        /// The estimate and the limit.
        estimate: String,
    },
}

/// What the program does, in numbers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Lines of G-code, over all the program files.
    pub lines: usize,
    /// Motion blocks.
    pub blocks: usize,
    /// The most motion blocks in any one second of the run, blocks/s.
    pub peak_blocks_s: f64,
    /// The planner's block-rate limit of the machine, blocks/s (None: unlimited).
    pub max_blocks_s: Option<f64>,
    /// Cutting path length, mm.
    pub feed_length_mm: f64,
    /// Rapid path length, mm.
    pub rapid_length_mm: f64,
    /// Estimated run time, s (feeds, acceleration, junction deviation, and the planner's block rate).
    pub estimated_s: f64,
    /// Estimated run time without the block-rate limit, s.
    pub estimated_unlimited_s: f64,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
    /// Scallop height of that stepover, µm.
    pub scallop_um: f64,
    /// Finishing passes.
    pub finishing_passes: usize,
    /// Intermediate finishing levels (where the finishing tool would cut deeper than its depth of cut).
    pub finishing_levels: usize,
    /// Roughing layers (0 when the design is within the finishing tool's depth of cut).
    pub roughing_layers: usize,
    /// The roughing tool's id (empty without roughing).
    pub roughing_tool: String,
    /// Tool changes after the first tool.
    pub tool_changes: usize,
    /// Depth of the design's CL surface below the stock top, mm.
    pub depth_mm: f64,
    /// Program extents `[min, max]` of the tool tip, mm.
    pub extents_mm: [P3; 2],
    /// CL points checked against the design by direct summation (all up to 50,000, an even stride beyond).
    pub checked_points: usize,
    /// Largest dip of the tool below the design at those points, µm (≤ 0: none).
    pub max_gouge_um: f64,
    /// Cutting feed, mm/min.
    pub feed_mm_min: f64,
    /// Spindle speed, rev/min.
    pub spindle_rpm: f64,
    /// Entries into material that ramp down along their pass at the tool's `max_ramp_deg` at most.
    #[serde(default)]
    pub ramped_entries: usize,
    /// Entries plunged straight at the plunge feed (the tool's `max_ramp_deg` is 90, or the run was too
    /// short for a ramp).
    #[serde(default)]
    pub plunged_entries: usize,
    /// Finishing blocks written as `G2`/`G3` arcs in the pass plane.
    #[serde(default)]
    pub arc_blocks: usize,
    /// Of the estimate without the block-rate limit, the time in rapids, s.
    #[serde(default)]
    pub rapid_s: f64,
    /// Feed path that removes nothing (air), mm, as the simulation of the program measured it (`None` until
    /// a job simulates it: `brdfmill toolpath` alone does not).
    #[serde(default)]
    pub air_feed_mm: Option<f64>,
    /// The time of that path at its programmed feeds, s.
    #[serde(default)]
    pub air_feed_s: Option<f64>,
    /// The program files, in the order they run (one unless GRBL changes tools: one per tool).
    #[serde(default)]
    pub files: Vec<files::FileSummary>,
    /// The cutting data of each tool the program uses, in order, with where they came from (the profile or
    /// the tool × stock table) and what is wrong with them on this machine (`cut::feeds`).
    #[serde(default)]
    pub cutting: Vec<feeds::ToolData>,
}

/// A finished program.
pub struct Toolpath {
    /// The moves.
    pub moves: Vec<Move>,
    /// The whole job as one text, for reading back: the only program, or for GRBL with several tools the
    /// programs of [`Toolpath::files`] as one with each later tool's mount a manual change (`T<n> M0`,
    /// which the simulation reads as the operator changing the tool). Written as a file only when it is
    /// the one program.
    pub gcode: String,
    /// The program files to write and run, in order ([`files`]).
    pub files: Vec<files::ProgramFile>,
    /// Its numbers.
    pub summary: Summary,
}

impl Toolpath {
    /// The texts of the program files, in order.
    pub fn texts(&self) -> Vec<&str> {
        self.files.iter().map(|f| f.gcode.as_str()).collect()
    }
}

/// The finishing tool's CL rows (in parallel), raw (one point per grid column inside the area).
fn cl_rows(design: &raster::RotatedDesign, dc: &dropcutter::DropCutter, vs: &[f64]) -> Vec<Vec<P3>> {
    vs.par_iter().map(|v| design.pass(dc, *v, |z| z)).collect()
}

/// The independent gouge check by direct summation of the final finishing points: every point up to 50,000,
/// an even stride through them beyond; `(checked points, max gouge mm)`.
fn gouge_check(design: &raster::RotatedDesign, dc: &dropcutter::DropCutter, finishing: &[Vec<P3>]) -> (usize, f64) {
    let all: Vec<P3> = finishing.iter().flatten().copied().collect();
    let stride = all.len().div_ceil(50_000).max(1);
    let checked: Vec<P3> = all.iter().step_by(stride).copied().collect();
    let max_gouge = checked
        .par_iter()
        .map(|p| design.cl_at(dc, p[0], p[1]) - p[2])
        .reduce(|| f64::NEG_INFINITY, f64::max);
    (checked.len(), max_gouge)
}

/// Pass positions on the machine's resolution `q` when the raster runs along X or Y (there a pass's cross
/// coordinate is its `v`): the emitter would otherwise round the whole pass sideways by up to `q/2`, onto
/// CL the drop-cutter did not compute. The first and last move inward, the others to the nearest step.
fn on_resolution(design: &raster::RotatedDesign, vs: Vec<f64>, q: f64) -> Vec<f64> {
    let (c, s) = design.cos_sin();
    if (c != 0.0 && s != 0.0) || vs.len() < 2 {
        return vs;
    }
    let n = vs.len();
    vs.iter()
        .enumerate()
        .map(|(k, v)| {
            let steps = v / q;
            let steps = if k == 0 {
                (steps - 1e-9).ceil()
            } else if k + 1 == n {
                (steps + 1e-9).floor()
            } else {
                steps.round()
            };
            steps * q
        })
        .collect()
}

/// Raise each CL point of a pass by `(q/2)·|s|`, `s` the steeper of the CL slopes to its two neighbours: the
/// emitter rounds X/Y to the nearest step `q` (Z up), which moves a point along the pass by up to `q/2`, where
/// the CL surface stands up to `|s|·q/2` higher (0.47 µm on a 43° facet at 1 µm). Raised, no written point
/// lies below the CL surface (the gouge check reads the points as written).
fn lift_for_rounding(pass: &mut [P3], q: f64) {
    let n = pass.len();
    if n < 2 {
        return;
    }
    let slope = |a: P3, b: P3| {
        let d = (b[0] - a[0]).hypot(b[1] - a[1]);
        if d > 0.0 {
            ((b[2] - a[2]) / d).abs()
        } else {
            0.0
        }
    };
    let lifts: Vec<f64> = (0..n)
        .map(|i| {
            let l = if i > 0 { slope(pass[i - 1], pass[i]) } else { 0.0 };
            let r = if i + 1 < n { slope(pass[i], pass[i + 1]) } else { 0.0 };
            0.5 * q * l.max(r)
        })
        .collect();
    pass.iter_mut().zip(lifts).for_each(|(p, l)| p[2] += l);
}

/// A finishing pass in cutting order: its simplified points (the one-sided polyline an entry ramps along)
/// and its blocks (lines and arcs, [`arcs::fit`]).
struct Pass {
    pts: Vec<P3>,
    pieces: Vec<arcs::Piece>,
}

/// The finishing passes from the raw CL rows: each oriented for `strategy` (zigzag reverses every other
/// pass; one-way passes run in −u so that the uncut side (+v) is on the right: climb for M3), simplified,
/// and fitted with arcs in the pass plane on resolution `q` when `arcs_on`.
fn finishing_passes(raw: &[Vec<P3>], strategy: Strategy, tol: f64, q: f64, arcs_on: bool) -> Vec<Pass> {
    raw.par_iter()
        .enumerate()
        .map(|(k, pass)| {
            let mut raw: Vec<P3> = pass.clone();
            if strategy.reverses(k) {
                raw.reverse();
            }
            let plane = if arcs_on { arcs::pass_plane(&raw) } else { None };
            Pass {
                pts: simplify::simplify(&raw, tol),
                pieces: arcs::fit(&raw, tol, q, plane),
            }
        })
        .collect()
}

/// The points the independent gouge check reads for a pass, as the emitter writes them (on the resolution
/// `q`, Z rounded up): its simplified points and, along each arc, its points every 0.1 µm of chord error as
/// the controller draws it (from the quantised start).
fn check_points(pass: &Pass, q: f64) -> Vec<P3> {
    let mut out: Vec<P3> = pass.pts.iter().map(|p| emit::quantize_point(*p, q)).collect();
    let Some(&first) = pass.pts.first() else {
        return out;
    };
    let mut at = first;
    for pc in &pass.pieces {
        match pc {
            arcs::Piece::Line(p) => at = *p,
            arcs::Piece::Arc(a) => {
                let from = emit::quantize_point(at, q);
                out.extend(a.points(from, moves::CHORD_TOL_MM));
                at = a.to;
            }
        }
    }
    out
}

/// The final finishing raster at the CL surface.
/// `stock_cl[k]`: the cutter location over the stock the raster finds along raw pass `k`, whose first point
/// is the pass's start unless the pass runs reversed.
#[allow(clippy::too_many_arguments)]
fn finishing(
    b: &mut Builder,
    design: &raster::RotatedDesign,
    dc: &dropcutter::DropCutter,
    passes: &[Pass],
    stock_cl: &[Vec<f64>],
    strategy: Strategy,
    feed: f64,
    tol: f64,
) {
    b.moves.push(Move::Comment("finishing"));
    let mut first = true;
    for (k, pass) in passes.iter().enumerate() {
        if pass.pts.is_empty() {
            continue;
        }
        let reversed = strategy.reverses(k);
        let start_cl = stock_cl
            .get(k)
            .and_then(|s| if reversed { s.last() } else { s.first() })
            .copied();
        if first || strategy == Strategy::Oneway {
            b.approach(&pass.pts, start_cl);
            first = false;
        } else {
            let link = link_points(design, dc, b.at, pass.pts[0], |z| z);
            b.path(&simplify::simplify(&link, tol), feed);
        }
        b.pieces(&pass.pieces, feed);
        if strategy == Strategy::Oneway {
            b.retract();
        }
    }
}

/// Build the program for `tile` (periodic, repeated over the area) on `machine`: [`ToolpathConfig::check`]
/// for the tile's grid, then [`ToolpathPlan::run`].
pub fn run(cfg: &ToolpathConfig, tile: &Heightfield, machine: &Machine) -> Result<Toolpath, ToolpathError> {
    cfg.check(machine, tile.pitch_mm)?.run(tile)
}

impl ToolpathPlan {
    /// Build the program for `tile` (periodic, on the grid the plan was checked for, repeated over the area).
    pub fn run(&self, tile: &Heightfield) -> Result<Toolpath, ToolpathError> {
        self.check_tile(tile)?;
        program(self, tile)
    }
}

/// The program of a checked plan.
fn program(plan: &ToolpathPlan, tile: &Heightfield) -> Result<Toolpath, ToolpathError> {
    let (cfg, machine, tool, rough) = (&plan.cfg, &plan.machine, &plan.tool, &plan.rough);
    let [ax, ay] = cfg.area_mm;
    let (stepover, feed, strategy) = (plan.stepover_mm, plan.feed_mm_min, plan.strategy);
    let r = tool.radius_mm();
    let cut = tool.cutting(cfg.stock);
    let rough_cut = rough.cutting(cfg.stock);
    let margin = r.max(rough.radius_mm()) + 3.0 * tile.pitch_mm;
    let design = raster::RotatedDesign::new(tile, (ax, ay), cfg.angle_deg, margin);
    let tol = cfg.tolerance_um * 1e-3;
    let dc = design.cutter(tool.shape);
    let (vmin, vmax) = design.v_range();
    let q = machine.write_resolution_mm();
    let vs = on_resolution(&design, raster::pass_positions(vmin, vmax, stepover), q);
    let mut raw = cl_rows(&design, &dc, &vs);
    raw.par_iter_mut().for_each(|pass| lift_for_rounding(pass, q));
    let depth = -raw.iter().flatten().map(|p| p[2]).fold(f64::INFINITY, f64::min);
    let start = [0.0, 0.0, machine.program.clearance_z()];

    // the stock side (roughing, then the finishing levels the stock it leaves needs) and the finishing
    // raster's blocks with their gouge check depend only on the CL rows: built side by side
    let stock_side = || {
        stock_side::stock_side(&stock_side::StockSide {
            machine,
            design: &design,
            dc: &dc,
            tool,
            rough,
            cut,
            rough_cut,
            start,
            depth,
            vs: &vs,
            raw: &raw,
            stepover,
            feed,
            tol,
            arcs: cfg.arcs,
            strategy,
        })
    };
    let finish_side = || {
        let passes = finishing_passes(&raw, strategy, tol, q, cfg.arcs);
        let checked: Vec<Vec<P3>> = passes.par_iter().map(|p| check_points(p, q)).collect();
        let (checked_points, max_gouge) = gouge_check(&design, &dc, &checked);
        (passes, checked_points, max_gouge)
    };
    let (stock_built, (passes, checked_points, max_gouge)) = rayon::join(stock_side, finish_side);
    let stock_side::StockBuilt {
        builder: mut b,
        layers,
        levels,
        tool_changes,
        stock_cl,
    } = stock_built?;
    let arc_blocks = passes
        .iter()
        .flat_map(|p| &p.pieces)
        .filter(|pc| matches!(pc, arcs::Piece::Arc(_)))
        .count();
    finishing(&mut b, &design, &dc, &passes, &stock_cl, strategy, feed, tol);
    b.stop_tool();
    let (ramped_entries, plunged_entries) = (b.ramped_entries, b.plunged_entries);
    let moves = b.moves;

    // the work: the area and the tools' reach beyond it (every pass and link stays within the design's margin)
    let work = Some([-margin, -margin, ax + margin, ay + margin]);
    check::check_in(&moves, start, machine, rough, work).map_err(|e| ToolpathError::Machine(e.0))?;
    check::check_in(&moves, start, machine, tool, work).map_err(|e| ToolpathError::Machine(e.0))?;
    let est = estimate::estimate(&moves, start, machine, machine.block_rate_limit());
    over_budget(cfg, &moves, start, machine, &est, passes.len(), stepover)?;
    let len = moves::lengths(&moves, start);
    let (lo, hi) = moves::bounds(&moves, start);
    let scallop = raster::scallop_for_stepover(r, stepover) * 1000.0;
    let facts = HeaderFacts {
        tool,
        rough,
        cfg,
        machine,
        stepover,
        scallop,
        strategy,
        feed,
        layers,
        levels,
        depth,
        area: (ax, ay),
    };
    let header = header(&facts);
    let joined_header: Vec<String> = header.iter().cloned().chain([estimate_line(&est)]).collect();
    let setup = emit::Setup {
        dialect: machine.dialect,
        header: &joined_header,
        path_tolerance_mm: machine.limits.path_tolerance_mm,
        resolution_mm: q,
        tool_change_machine_z_mm: machine.program.tool_change_machine_z_mm,
    };
    let program_files = files::program_files(&setup, &header, &moves, start, machine, &est);
    // one file is the job; several are read back joined
    let gcode = match &program_files[..] {
        [one] => one.gcode.clone(),
        _ => emit::emit(&setup, &moves),
    };
    let summary = Summary {
        lines: program_files.iter().map(|f| f.summary.lines).sum(),
        blocks: est.blocks,
        peak_blocks_s: est.peak_blocks_s,
        max_blocks_s: machine.block_rate_limit(),
        feed_length_mm: len.feed_mm,
        rapid_length_mm: len.rapid_mm,
        estimated_s: est.block_limited_s,
        estimated_unlimited_s: est.s,
        stepover_mm: stepover,
        scallop_um: scallop,
        finishing_passes: passes.len(),
        finishing_levels: levels,
        roughing_layers: layers,
        roughing_tool: if layers > 0 { rough.id.clone() } else { String::new() },
        tool_changes: tool_changes.saturating_sub(1),
        depth_mm: depth,
        extents_mm: [lo, hi],
        checked_points,
        max_gouge_um: max_gouge * 1000.0,
        feed_mm_min: feed,
        spindle_rpm: cut.spindle_rpm,
        ramped_entries,
        plunged_entries,
        arc_blocks,
        rapid_s: est.rapid_s,
        air_feed_mm: None,
        air_feed_s: None,
        files: program_files.iter().map(|f| f.summary.clone()).collect(),
        cutting: {
            let lim = feeds::Limits::of(machine);
            let roughs = layers > 0 && rough.id != tool.id;
            let r = roughs.then(|| feeds::tool_data(rough, cfg.stock, rough.cutting(cfg.stock).feed_mm_min, &lim));
            r.into_iter()
                .chain([feeds::tool_data(tool, cfg.stock, feed, &lim)])
                .collect()
        },
    };
    Ok(Toolpath {
        moves,
        gcode,
        files: program_files,
        summary,
    })
}

/// Refuse a program whose estimate is over `toolpath.max_hours`, with the time of the final raster and of
/// what comes before it (roughing and intermediate levels), and what would shorten each.
fn over_budget(
    cfg: &ToolpathConfig,
    moves: &[Move],
    start: P3,
    machine: &Machine,
    est: &estimate::Estimate,
    passes: usize,
    stepover: f64,
) -> Result<(), ToolpathError> {
    if est.block_limited_s <= cfg.max_hours * 3600.0 {
        return Ok(());
    }
    let k = moves
        .iter()
        .position(|m| matches!(m, Move::Comment("finishing")))
        .unwrap_or(0);
    let finish = estimate::estimate(&moves[k..], start, machine, machine.block_rate_limit()).block_limited_s;
    let before = (est.block_limited_s - finish).max(0.0);
    Err(ToolpathError::Limit {
        field: "max_hours".into(),
        estimate: format!(
            "the program would run {} on this machine, more than toolpath.max_hours = {} h: the final raster's \
             {passes} passes at a {:.1} µm stepover take {} (a larger toolpath.scallop_um widens the stepover as \
             its square root; a smaller toolpath.area_mm shortens every pass), roughing and intermediate levels {} \
             (a roughing tool, toolpath.rough_tool, takes deeper layers); or raise toolpath.max_hours",
            hms(est.block_limited_s),
            cfg.max_hours,
            1000.0 * stepover,
            hms(finish),
            hms(before)
        ),
    })
}

/// What the header states.
struct HeaderFacts<'a> {
    tool: &'a Tool,
    rough: &'a Tool,
    cfg: &'a ToolpathConfig,
    machine: &'a Machine,
    stepover: f64,
    scallop: f64,
    strategy: Strategy,
    feed: f64,
    layers: usize,
    levels: usize,
    depth: f64,
    area: (f64, f64),
}

/// The header comment lines (made safe by the emitter).
fn header(f: &HeaderFacts) -> Vec<String> {
    let (cfg, tool, rough) = (f.cfg, f.tool, f.rough);
    let cut = tool.cutting(cfg.stock);
    let rc = rough.cutting(cfg.stock);
    let chip_um = tool.chip_load_um(f.feed, cut.spindle_rpm);
    let mut h = vec![
        format!("brdfmill {} - {}", env!("CARGO_PKG_VERSION"), cfg.job),
        format!("machine: {}, {} G-code", f.machine.name, f.machine.dialect.name()),
        format!(
            "finish T{} {}: {} D{} mm, stock {}",
            tool.number,
            tool.id,
            tool.shape.kind(),
            tool.diameter_mm(),
            cfg.stock.name()
        ),
        format!(
            "finish: stepover {:.1} um, scallop {:.3} um, angle {} deg, {}",
            1000.0 * f.stepover,
            f.scallop,
            cfg.angle_deg,
            match f.strategy {
                Strategy::Zigzag => "zigzag",
                _ => "one-way",
            }
        ),
        format!(
            "finish: F{} plunge {} S{} chip {chip_um:.2} um/tooth, doc {} mm",
            f.feed, cut.plunge_mm_min, cut.spindle_rpm, cut.max_depth_of_cut_mm
        ),
        format!("finish: {} intermediate levels before the final raster", f.levels),
    ];
    if f.layers > 0 {
        h.push(format!(
            "rough T{} {}: {} D{} mm, {} layers of {} mm, F{} plunge {} S{}",
            rough.number,
            rough.id,
            rough.shape.kind(),
            rough.diameter_mm(),
            f.layers,
            rc.max_depth_of_cut_mm,
            rc.feed_mm_min,
            rc.plunge_mm_min,
            rc.spindle_rpm
        ));
    }
    h.push(format!(
        "area {} x {} mm, origin at its lower-left corner, Z0 = stock top",
        f.area.0, f.area.1
    ));
    h.push(format!(
        "design depth {:.4} mm, simplification tolerance {} um (one-sided)",
        f.depth, cfg.tolerance_um
    ));
    if f.machine.dialect == crate::gcode::Dialect::Grbl {
        if let Some(t) = f.machine.limits.arc_chord_mm(f.machine.dialect) {
            h.push(format!(
                "{}{t} mm or finer (arc tolerance, as simulated)",
                crate::gcode::program::ARC_TOLERANCE_MARK
            ));
        }
    }
    h
}

/// The header's estimate line.
pub(crate) fn estimate_line(est: &estimate::Estimate) -> String {
    format!(
        "estimated run time {} ({} at the block rate), {} blocks",
        hms(est.s),
        hms(est.block_limited_s),
        est.blocks
    )
}

/// Points along the straight link from `a` to `b` every pitch, at the CL surface mapped by `zmap`, ending at
/// `b` (whose z is already right). The CL heights are direct summations (in parallel: links are emitted one
/// after another).
fn link_points(
    design: &raster::RotatedDesign,
    dc: &dropcutter::DropCutter,
    a: P3,
    b: P3,
    zmap: impl Fn(f64) -> f64,
) -> Vec<P3> {
    link_through(a, &link_cl(design, dc, a, b), b, zmap)
}

/// `a`, the link's interior CL points with their z mapped by `zmap`, then `b`.
fn link_through(a: P3, cl: &[P3], b: P3, zmap: impl Fn(f64) -> f64) -> Vec<P3> {
    let mut pts = Vec::with_capacity(cl.len() + 2);
    pts.push(a);
    pts.extend(cl.iter().map(|p| [p[0], p[1], zmap(p[2])]));
    pts.push(b);
    pts
}

/// The interior points of the link from `a` to `b` every pitch, at the CL surface.
fn link_cl(design: &raster::RotatedDesign, dc: &dropcutter::DropCutter, a: P3, b: P3) -> Vec<P3> {
    let d = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let n = (d / design.hf.pitch_mm).ceil().max(1.0) as usize;
    (1..n)
        .into_par_iter()
        .map(|k| {
            let t = k as f64 / n as f64;
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            [x, y, design.cl_at(dc, x, y)]
        })
        .collect()
}

/// [`link_points`] remembering each link's CL points by its ends' `(x, y)`: the roughing layers link the
/// same pass ends again and again, only their `zmap` (the layer) differs.
struct LinkMemo<'a> {
    design: &'a raster::RotatedDesign,
    dc: &'a dropcutter::DropCutter<'a>,
    seen: std::cell::RefCell<std::collections::HashMap<[u64; 4], Vec<P3>>>,
}

impl LinkMemo<'_> {
    fn points(&self, a: P3, b: P3, zmap: impl Fn(f64) -> f64) -> Vec<P3> {
        let key = [a[0].to_bits(), a[1].to_bits(), b[0].to_bits(), b[1].to_bits()];
        let mut seen = self.seen.borrow_mut();
        let cl = seen.entry(key).or_insert_with(|| link_cl(self.design, self.dc, a, b));
        link_through(a, cl, b, zmap)
    }
}

/// `h:mm:ss`.
pub fn hms(s: f64) -> String {
    let s = s.round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
}
