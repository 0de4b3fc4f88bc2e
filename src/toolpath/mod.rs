//! Stage 4 — toolpath: a heightfield (typically the periodic facet tile) to a G-code program.
//!
//! - [`machine`]: versioned machine profiles (`machines/*.toml`) with their tools.
//! - [`dropcutter`]: the exact cutter-location surface of a ball, flat or bull-nose bit ([`crate::tool::Shape`]) over a heightfield.
//! - [`raster`]: raster passes at any angle over the tile repeated across the work area.
//! - [`simplify`]: one-sided removal of collinear points within a stated tolerance.
//! - [`check`], [`estimate`]: the machine check and the run-time estimate; the program is written by [`crate::gcode::emit`].
//!
//! The program cuts roughing layers first when the design is deeper than the tool's depth of cut
//! (z = max(layer, CL_rough + leave)), then the finishing raster at the stepover of the target scallop.

pub mod check;
pub mod dropcutter;
pub(crate) mod estimate;
pub mod machine;
pub(crate) mod raster;
pub(crate) mod simplify;

use crate::gcode::emit;
use crate::gcode::moves::{self, Move, P3};
use crate::heightfield::Heightfield;
use crate::tool::Shape;
use machine::{Machine, Stock, Tool};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Raster strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// Alternate directions, linked along the area's edge at the CL surface.
    Zigzag,
    /// Every pass in the same direction (climb for an `M3` spindle), retracting between passes.
    Oneway,
}

/// Configuration of the toolpath stage. Lengths carry their unit in the name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ToolpathConfig {
    /// Finishing tool id in the machine profile (a ball-nose).
    pub tool: String,
    /// Roughing tool id (ball or flat); the finishing tool when empty.
    pub rough_tool: String,
    /// Stock material, selects the cutting data.
    pub stock: Stock,
    /// Work area `[x, y]`, mm, covered by the tile repeated.
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
            strategy: Strategy::Zigzag,
            tolerance_um: 0.5,
            feed_mm_min: 0.0,
            job: "brdfmill tile".into(),
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
}

/// What the program does, in numbers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Lines of G-code.
    pub lines: usize,
    /// Cutting path length, mm.
    pub feed_length_mm: f64,
    /// Rapid path length, mm.
    pub rapid_length_mm: f64,
    /// Estimated run time, s (feeds, acceleration, junction deviation).
    pub estimated_s: f64,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
    /// Scallop height of that stepover, µm.
    pub scallop_um: f64,
    /// Finishing passes.
    pub finishing_passes: usize,
    /// Roughing layers (0 when the design is within one depth of cut).
    pub roughing_layers: usize,
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
}

/// A finished program.
pub struct Toolpath {
    /// The moves.
    pub moves: Vec<Move>,
    /// The G-code text.
    pub gcode: String,
    /// Its numbers.
    pub summary: Summary,
}

/// Clearance above the stock where lead-ins start and lead-outs end, mm.
const LEAD_MM: f64 = check::RAPID_FLOOR_MM;

struct Builder {
    moves: Vec<Move>,
    at: P3,
    safe_z: f64,
    plunge: f64,
    max_feed_z: f64,
}

impl Builder {
    fn rapid(&mut self, p: P3) {
        self.moves.push(Move::Rapid(p));
        self.at = p;
    }

    /// A feed move whose Z component respects the machine's Z feed limit.
    fn feed(&mut self, p: P3, f: f64) {
        let d = moves::dist(self.at, p);
        let dz = (p[2] - self.at[2]).abs();
        let f = if d > 0.0 && f * dz / d > self.max_feed_z {
            self.max_feed_z * d / dz
        } else {
            f
        };
        self.moves.push(Move::Feed(p, f));
        self.at = p;
    }

    /// Retract to safe z, travel at safe z, rapid down to the lead height, plunge to `p`.
    fn approach(&mut self, p: P3) {
        if self.at[2] < self.safe_z {
            self.rapid([self.at[0], self.at[1], self.safe_z]);
        }
        self.rapid([p[0], p[1], self.safe_z]);
        self.rapid([p[0], p[1], LEAD_MM.max(p[2])]);
        let plunge = self.plunge;
        self.feed(p, plunge);
    }

    fn path(&mut self, pts: &[P3], f: f64) {
        for p in pts {
            self.feed(*p, f);
        }
    }
}

/// The checked inputs of one program.
struct Plan<'a> {
    tool: &'a Tool,
    rough: &'a Tool,
    area: (f64, f64),
    stepover: f64,
    feed: f64,
}

/// Check the configuration against the machine and the tile; choose the tools and the stepover.
fn plan<'a>(cfg: &ToolpathConfig, tile: &Heightfield, machine: &'a Machine) -> Result<Plan<'a>, ToolpathError> {
    let bad = |s: String| Err(ToolpathError::Config(s));
    let tool = machine.tool(&cfg.tool)?;
    if !matches!(tool.shape, Shape::Ball { .. }) {
        return bad(format!(
            "finishing needs a ball-nose tool; `{}` is {:?}",
            tool.id,
            tool.shape.kind()
        ));
    }
    let rough = if cfg.rough_tool.is_empty() {
        tool
    } else {
        machine.tool(&cfg.rough_tool)?
    };
    let [ax, ay] = cfg.area_mm;
    if !(ax > 0.0 && ay > 0.0 && ax.is_finite() && ay.is_finite()) {
        return bad(format!("area_mm must be positive, got {ax}×{ay}"));
    }
    if ax > machine.travel.x_mm || ay > machine.travel.y_mm {
        return Err(ToolpathError::Machine(format!(
            "area {ax}×{ay} mm is larger than the machine's travel.x_mm × travel.y_mm = {}×{} mm",
            machine.travel.x_mm, machine.travel.y_mm
        )));
    }
    if cfg.tolerance_um.is_nan() || cfg.tolerance_um < 0.0 || !cfg.angle_deg.is_finite() {
        return bad("tolerance_um must be ≥ 0 and angle_deg finite".into());
    }
    if !tile.periodic {
        return bad("the design heightfield must be periodic (a tile) to repeat over the area".into());
    }
    let r = tool.radius_mm();
    let stepover = if cfg.stepover_mm > 0.0 {
        cfg.stepover_mm
    } else if cfg.scallop_um > 0.0 && cfg.scallop_um * 1e-3 < r {
        raster::stepover_for_scallop(r, cfg.scallop_um * 1e-3)
    } else {
        return bad(format!(
            "scallop_um must be in (0, {}) for this tool, got {}",
            r * 1000.0,
            cfg.scallop_um
        ));
    };
    let cut = tool.cutting(cfg.stock);
    let feed = if cfg.feed_mm_min > 0.0 {
        cfg.feed_mm_min
    } else {
        cut.feed_mm_min
    };
    Ok(Plan {
        tool,
        rough,
        area: (ax, ay),
        stepover,
        feed,
    })
}

/// The finishing CL passes (in parallel), simplified one-sidedly, with the depth of the raw CL surface and
/// the independent gouge check by direct summation: `(passes, depth_mm, checked points, max gouge mm)`.
fn finishing_passes(
    design: &raster::RotatedDesign,
    dc: &dropcutter::DropCutter,
    stepover: f64,
    tol: f64,
) -> (Vec<Vec<P3>>, f64, usize, f64) {
    let (vmin, vmax) = design.v_range();
    let vs = raster::pass_positions(vmin, vmax, stepover);
    let raw: Vec<Vec<P3>> = vs.par_iter().map(|v| design.pass(dc, *v, |z| z)).collect();
    let depth = -raw.iter().flatten().map(|p| p[2]).fold(f64::INFINITY, f64::min);
    let finishing: Vec<Vec<P3>> = raw.par_iter().map(|pts| simplify::simplify(pts, tol)).collect();
    // Every point up to 50,000, an even stride through them beyond.
    let all: Vec<P3> = finishing.iter().flatten().copied().collect();
    let stride = all.len().div_ceil(50_000).max(1);
    let checked: Vec<P3> = all.iter().step_by(stride).copied().collect();
    let max_gouge = checked
        .par_iter()
        .map(|p| design.cl_at(dc, p[0], p[1]) - p[2])
        .reduce(|| f64::NEG_INFINITY, f64::max);
    (finishing, depth, checked.len(), max_gouge)
}

/// Roughing layers at the roughing tool's depth of cut while the design is deeper than one cut; returns
/// the number of layers.
fn roughing(
    b: &mut Builder,
    design: &raster::RotatedDesign,
    rough: &Tool,
    rough_cut: &machine::CuttingData,
    depth: f64,
    tol: f64,
) -> usize {
    let mut layers = 0;
    if depth <= rough_cut.max_depth_of_cut_mm {
        return 0;
    }
    let (vmin, vmax) = design.v_range();
    let leave = rough_cut.max_depth_of_cut_mm / 3.0;
    let rough_cutter = rough.shape.normalized();
    let rs = match rough_cutter {
        Shape::Ball { diameter_mm } => raster::stepover_for_scallop(diameter_mm / 2.0, leave).min(0.8 * diameter_mm),
        Shape::Flat { diameter_mm } => diameter_mm / 2.0,
        // the flat part overlaps, the corners leave a ball's scallop between them
        Shape::Bull {
            diameter_mm,
            corner_radius_mm: rc,
        } => (diameter_mm - 2.0 * rc + raster::stepover_for_scallop(rc, leave)).min(0.8 * diameter_mm),
    };
    let rdc = design.cutter(rough_cutter);
    let rvs = raster::pass_positions(vmin, vmax, rs);
    let rows: Vec<Vec<P3>> = rvs.par_iter().map(|v| design.pass(&rdc, *v, |z| z + leave)).collect();
    let floor = rows.iter().flatten().map(|p| p[2]).fold(f64::INFINITY, f64::min);
    let mut z_layer = 0.0;
    while z_layer > floor {
        z_layer -= rough_cut.max_depth_of_cut_mm;
        layers += 1;
        b.moves.push(Move::Comment("roughing layer"));
        let zl = z_layer;
        let mut first = true;
        for (k, row) in rows.iter().enumerate() {
            let mut pts: Vec<P3> = row.iter().map(|p| [p[0], p[1], p[2].max(zl)]).collect();
            if k % 2 == 1 {
                pts.reverse();
            }
            let pts = simplify::simplify(&pts, tol);
            if pts.is_empty() {
                continue; // a pass that misses the area (corners of a rotated raster)
            }
            if first {
                b.approach(pts[0]);
                first = false;
            } else {
                let link = link_points(design, &rdc, b.at, pts[0], |z| (z + leave).max(zl));
                b.path(&simplify::simplify(&link, tol), rough_cut.feed_mm_min);
            }
            b.path(&pts[1..], rough_cut.feed_mm_min);
        }
    }
    layers
}

/// The finishing raster, then the retract to safe z and the spindle off.
#[allow(clippy::too_many_arguments)]
fn finishing(
    b: &mut Builder,
    design: &raster::RotatedDesign,
    dc: &dropcutter::DropCutter,
    passes: &[Vec<P3>],
    strategy: Strategy,
    feed: f64,
    tol: f64,
) {
    b.moves.push(Move::Comment("finishing"));
    let mut first = true;
    for (k, pass) in passes.iter().enumerate() {
        if pass.is_empty() {
            continue;
        }
        let pts: Vec<P3> = match strategy {
            Strategy::Zigzag if k % 2 == 1 => pass.iter().rev().copied().collect(),
            Strategy::Zigzag => pass.clone(),
            // one-way passes run in −u so that the uncut side (+v) is on the right: climb for M3
            Strategy::Oneway => pass.iter().rev().copied().collect(),
        };
        if first || strategy == Strategy::Oneway {
            b.approach(pts[0]);
            first = false;
        } else {
            let link = link_points(design, dc, b.at, pts[0], |z| z);
            b.path(&simplify::simplify(&link, tol), feed);
        }
        b.path(&pts[1..], feed);
        if strategy == Strategy::Oneway {
            let up = [b.at[0], b.at[1], LEAD_MM.max(b.at[2])];
            let f = b.plunge;
            b.feed(up, f);
        }
    }
    let up = [b.at[0], b.at[1], LEAD_MM.max(b.at[2])];
    let f = b.plunge;
    b.feed(up, f);
    b.rapid([b.at[0], b.at[1], b.safe_z]);
    b.moves.push(Move::SpindleOff);
}

/// Build the program for `tile` (periodic, repeated over the area) on `machine`.
pub fn run(cfg: &ToolpathConfig, tile: &Heightfield, machine: &Machine) -> Result<Toolpath, ToolpathError> {
    let Plan {
        tool,
        rough,
        area: (ax, ay),
        stepover,
        feed,
    } = plan(cfg, tile, machine)?;
    let r = tool.radius_mm();
    let cut = tool.cutting(cfg.stock);
    let rough_cut = rough.cutting(cfg.stock);
    let margin = r.max(rough.radius_mm()) + 3.0 * tile.pitch_mm;
    let design = raster::RotatedDesign::new(tile, (ax, ay), cfg.angle_deg, margin);
    let tol = cfg.tolerance_um * 1e-3;
    let dc = design.cutter(tool.shape);
    let (passes, depth, checked_points, max_gouge) = finishing_passes(&design, &dc, stepover, tol);

    let mut b = Builder {
        moves: vec![],
        at: [0.0, 0.0, machine.program.safe_z_mm],
        safe_z: machine.program.safe_z_mm,
        plunge: cut.plunge_mm_min,
        max_feed_z: machine.limits.max_feed_z_mm_min,
    };
    let start = b.at;
    b.moves
        .push(Move::SpindleOn(cut.spindle_rpm.max(rough_cut.spindle_rpm)));
    b.moves.push(Move::Dwell(machine.program.spindle_dwell_s));
    b.rapid(start);
    let layers = roughing(&mut b, &design, rough, rough_cut, depth, tol);
    finishing(&mut b, &design, &dc, &passes, cfg.strategy, feed, tol);
    let moves = b.moves;

    check::check(&moves, start, machine, rough).map_err(ToolpathError::Machine)?;
    check::check(&moves, start, machine, tool).map_err(ToolpathError::Machine)?;
    let est = estimate::estimate_s(&moves, start, machine);
    let len = moves::lengths(&moves, start);
    let (lo, hi) = moves::bounds(&moves, start);
    let scallop = raster::scallop_for_stepover(r, stepover) * 1000.0;
    let header = vec![
        format!("brdfmill {} - {}", env!("CARGO_PKG_VERSION"), cfg.job),
        format!("machine: {} [{:?}]", machine.name, machine.dialect),
        format!(
            "tool: {} {:?} D{} mm, stock {:?}",
            tool.id,
            tool.shape.kind(),
            tool.diameter_mm(),
            cfg.stock
        ),
        format!(
            "finishing: stepover {:.4} mm, scallop {scallop:.3} um, angle {} deg, {:?}",
            stepover, cfg.angle_deg, cfg.strategy
        ),
        format!(
            "feed {feed} mm/min, plunge {} mm/min, spindle {} rpm",
            cut.plunge_mm_min, cut.spindle_rpm
        ),
        format!(
            "roughing: {layers} layers with {} at {} mm depth of cut",
            rough.id, rough_cut.max_depth_of_cut_mm
        ),
        format!("area {ax} x {ay} mm, origin at its lower-left corner, Z0 = stock top"),
        format!(
            "design depth {depth:.4} mm, simplification tolerance {} um [one-sided]",
            cfg.tolerance_um
        ),
        format!(
            "estimated run time {} [feeds, acceleration, junction deviation]",
            hms(est)
        ),
    ];
    let gcode = emit::emit(machine.dialect, &header, machine.limits.path_tolerance_mm, &moves);
    let summary = Summary {
        lines: gcode.lines().count(),
        feed_length_mm: len.feed_mm,
        rapid_length_mm: len.rapid_mm,
        estimated_s: est,
        stepover_mm: stepover,
        scallop_um: scallop,
        finishing_passes: passes.len(),
        roughing_layers: layers,
        depth_mm: depth,
        extents_mm: [lo, hi],
        checked_points,
        max_gouge_um: max_gouge * 1000.0,
        feed_mm_min: feed,
        spindle_rpm: cut.spindle_rpm,
    };
    Ok(Toolpath { moves, gcode, summary })
}

/// Points along the straight link from `a` to `b` every pitch, at the CL surface mapped by `zmap`, ending at
/// `b` (whose z is already right).
fn link_points(
    design: &raster::RotatedDesign,
    dc: &dropcutter::DropCutter,
    a: P3,
    b: P3,
    zmap: impl Fn(f64) -> f64,
) -> Vec<P3> {
    let d = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let n = (d / design.hf.pitch_mm).ceil().max(1.0) as usize;
    let mut pts: Vec<P3> = (1..n)
        .map(|k| {
            let t = k as f64 / n as f64;
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            [x, y, zmap(design.cl_at(dc, x, y))]
        })
        .collect();
    pts.insert(0, a);
    pts.push(b);
    pts
}

/// `h:mm:ss`.
pub fn hms(s: f64) -> String {
    let s = s.round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
}
