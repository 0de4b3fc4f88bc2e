//! `brdfmill calibrate`: a small coupon program whose features make each error of a profile's `[accuracy]`
//! (see [`crate::cut::accuracy`]) measurable with calipers, and the sheet that says how to read them.
//!
//! **The coupon.** Six straight full-width slots of the tool, [`DEPTH_MM`](crate::apps::calibrate::DEPTH_MM) deep, in a block of at least
//! [`STOCK_MM`](crate::apps::calibrate::STOCK_MM) (X × Y) with X0 Y0 on its front-left corner and Z0 on its top: three slots along Y at
//! `x = a, b, c` measure X, three along X at `y = a, b, c` measure Y, `b` halfway between `a` and `c`. Each
//! slot is entered from outside the block (beyond its left or front face, which the touch-off locates) and
//! runs out past the far face, so no tool ever plunges or ramps into material; each depth level is a
//! separate pass along the slot, so the measured axis does not move while the slot is cut.
//!
//! **What each feature reads.** Let `D` be the tool's diameter, `S` the width the spinning tool cuts, `k`
//! the axis's scale (travel per commanded mm) and `b` its backlash. The play operator of the accuracy model
//! puts the carriage `b/2` behind the command after a move in one direction, so a slot whose axis last
//! moved `+` sits at `k·c − b/2` and one approached moving `−` at `k·c + b/2`. Slots `a` and `c` are
//! approached moving `+`, slot `b` moving `−` (each after a take-up move of [`TAKE_UP_MM`](crate::apps::calibrate::TAKE_UP_MM) > b):
//!
//! - land A (between slots a and b): `A = k·(b − a) − S + b`; land B (b to c): `B = k·(c − b) − S − b`.
//!   With `b − a = c − b` the scale and the slot width cancel: **`backlash = (A − B)/2`** — twice as
//!   sensitive as a reference land against a reversal land, and no land is cut without a reversal.
//! - a slot: `S = D + TIR` (the runout envelope) → **`runout = S − D`**, `D` the tool's measured diameter.
//! - the inner span `I` (the faces of the material between slots a and c) and the outer span `O` (slot a's
//!   far wall to slot c's far wall): `I = k·P − S`, `O = k·P + S` with `P = c − a` (both slots approached
//!   alike, so backlash cancels): **`L = (O + I)/2 = k·P`** and `steps_new = steps_old · P / L`; and
//!   `S = (O − I)/2` again.
//!
//! Everything is computed and checked (the machine check of the toolpath stage, [`check::check`](crate::stages::toolpath::check::check)) before a
//! byte is written; the outputs are written atomically ([`crate::base::io`]).

use crate::base::io::{self, WriteError};
use crate::cut::estimate;
use crate::cut::machine::{Accuracy, Coolant, Dialect, Machine, ProfileError, Stock, Tool};
use crate::gcode::emit;
use crate::gcode::moves::{Move, P3};
use crate::stages::toolpath::{check, hms};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The least stock block, X × Y, mm (the coupon is laid out on it).
pub const STOCK_MM: [f64; 2] = [50.0, 30.0];
/// Depth of every slot, mm: enough for a caliper's jaws, shallow enough to cut in minutes.
pub const DEPTH_MM: f64 = 1.0;
/// Least stock thickness, mm: the slots' depth and material under them.
pub const STOCK_THICKNESS_MM: f64 = 3.0;
/// Material left between the outer slots and the block's faces, mm (at least).
pub const BORDER_MM: f64 = 3.0;
/// Take-up travel before each slot, mm: at least four times the largest backlash a profile may declare
/// ([`crate::cut::accuracy::MAX_ERROR_UM`]), so the slack is always taken up.
pub const TAKE_UP_MM: f64 = 2.0;
/// How far outside the block's faces each slot starts and ends, beyond the tool's radius, mm.
pub const ENTRY_CLEAR_MM: f64 = 1.5;
/// The narrowest land worth measuring, mm.
pub const MIN_LAND_MM: f64 = 2.0;
/// The least height of vertical wall a slot must have (depth less the tool's corner radius), mm.
pub const MIN_WALL_MM: f64 = 0.3;
/// Height above the stock where descents and climbs change between rapid and feed, mm.
const LEAD_MM: f64 = check::RAPID_FLOOR_MM;

/// What to cut the coupon with.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrateConfig {
    /// Stock material (selects the cutting data); wax by default.
    pub stock: Stock,
    /// Tool id; None: the profile's smallest flat end mill, else its smallest ball ([`default_tool`]).
    pub tool: Option<String>,
    /// Where the profile came from, for the sheet (a path, or `machines/NAME.toml (shipped)`).
    pub profile: String,
}

impl Default for CalibrateConfig {
    fn default() -> Self {
        Self {
            stock: Stock::Wax,
            tool: None,
            profile: String::new(),
        }
    }
}

/// Why no coupon can be made.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The tool asked for is not in the profile.
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// The profile has no flat end mill or ball-nose.
    #[error("machine `{0}` has no flat end mill or ball-nose to cut the coupon with; name a tool with --tool")]
    NoTool(String),
    /// The tool cannot cut measurable features on the coupon.
    #[error("tool `{id}` cannot cut the coupon: {why}")]
    Tool {
        /// The tool's id.
        id: String,
        /// What is wrong, with the figures.
        why: String,
    },
    /// The program would violate a machine limit (the toolpath stage's check).
    #[error("refused: {0}")]
    Machine(String),
    /// An output could not be written.
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// The three slots that measure one axis (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AxisFeatures {
    /// The axis they measure, `X` or `Y`; the slots run along the other one.
    pub axis: &'static str,
    /// Centres of slots a, b, c on that axis, mm (on the grid the program is written on).
    pub centres_mm: [f64; 3],
    /// The direction the axis last moves in before each slot is cut (+1 or −1).
    pub approach: [i8; 3],
    /// Where each slot starts and ends along the other axis, mm (outside the block's faces).
    pub run_mm: [f64; 2],
    /// `P = c − a`, mm: the length the scale is read over.
    pub pitch_mm: f64,
    /// Commanded widths of land A (a to b) and land B (b to c): centre distance less `D`, mm.
    pub lands_mm: [f64; 2],
    /// Commanded inner span `I = P − D`, mm.
    pub inner_span_mm: f64,
    /// Commanded outer span `O = P + D`, mm.
    pub outer_span_mm: f64,
}

/// The tool the coupon is cut with.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CouponTool {
    /// Id in the profile.
    pub id: String,
    /// Tool number (`T`).
    pub number: u32,
    /// `flat`, `ball` or `bull`.
    pub kind: &'static str,
    /// Nominal diameter, mm: the commanded slot width.
    pub diameter_mm: f64,
    /// Corner radius, mm.
    pub corner_radius_mm: f64,
}

/// `calibrate.json`: the commanded dimensions of the coupon and what each reading sets.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CouponSpec {
    /// `"brdfmill-calibrate"`.
    pub format: &'static str,
    /// 1.
    pub version: u32,
    /// The profile's name.
    pub machine: String,
    /// Where the profile came from.
    pub profile: String,
    /// Controller dialect.
    pub dialect: Dialect,
    /// The tool.
    pub tool: CouponTool,
    /// Stock material.
    pub stock: Stock,
    /// Least block, X × Y × thickness, mm.
    pub stock_mm: [f64; 3],
    /// Depth of every slot, mm.
    pub depth_mm: f64,
    /// Depth levels each slot is cut in (the tool's depth of cut).
    pub levels: usize,
    /// Cutting feed, mm/min.
    pub feed_mm_min: f64,
    /// Plunge feed (through air, outside the block), mm/min.
    pub plunge_mm_min: f64,
    /// Spindle speed, rev/min.
    pub spindle_rpm: f64,
    /// The features that measure X.
    pub x: AxisFeatures,
    /// The features that measure Y.
    pub y: AxisFeatures,
    /// The grid the program is written on, mm.
    pub write_resolution_mm: f64,
    /// What the profile declares now (perfect when it has no `[accuracy]`).
    pub declared: Accuracy,
    /// Estimated run time, s (feeds, acceleration, junction deviation).
    pub estimated_s: f64,
    /// The same at the planner's block rate, s.
    pub estimated_block_limited_s: f64,
    /// Motion blocks.
    pub blocks: usize,
    /// Each key the sheet sets and its formula (measurements in mm).
    pub keys: Vec<[&'static str; 2]>,
}

/// A coupon ready to write.
#[derive(Clone, Debug)]
pub struct Coupon {
    /// The move list.
    pub moves: Vec<Move>,
    /// Where the tip is before the first move, mm.
    pub start_mm: P3,
    /// The program.
    pub gcode: String,
    /// Its dimensions.
    pub spec: CouponSpec,
    /// `calibrate.md`.
    pub sheet: String,
    /// LinuxCNC's tool table (`tool.tbl`), None for GRBL.
    pub tool_table: Option<String>,
}

/// The program's file name in the output folder.
pub const PROGRAM_FILE: &str = "calibrate.nc";
/// The sheet's file name.
pub const SHEET_FILE: &str = "calibrate.md";
/// The dimensions' file name.
pub const SPEC_FILE: &str = "calibrate.json";
/// LinuxCNC's tool table's file name.
pub use crate::gcode::TOOL_TABLE_FILE;

impl Coupon {
    /// Write the program, the sheet, the dimensions and (LinuxCNC) the tool table into `dir`, each atomically;
    /// returns the paths written.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, CalibrateError> {
        let json = serde_json::to_string_pretty(&self.spec).expect("the spec holds only finite numbers and text");
        let mut files = vec![
            (PROGRAM_FILE, &self.gcode),
            (SHEET_FILE, &self.sheet),
            (SPEC_FILE, &json),
        ];
        files.extend(self.tool_table.as_ref().map(|t| (TOOL_TABLE_FILE, t)));
        let write = |(name, text): (&str, &String)| {
            let path = dir.join(name);
            io::write_atomic(&path, text.as_bytes()).map(|()| path)
        };
        Ok(files.into_iter().map(write).collect::<Result<_, _>>()?)
    }
}

/// The default tool: the smallest flat end mill of the profile, else its smallest ball-nose (a flat cuts
/// vertical walls from the slot's floor up; a ball's walls stand only above its equator).
pub fn default_tool(machine: &Machine) -> Option<&Tool> {
    let smallest = |kind: &str| {
        machine
            .tools
            .iter()
            .filter(|t| t.shape.normalized().kind() == kind)
            .min_by(|a, b| a.diameter_mm().total_cmp(&b.diameter_mm()))
    };
    smallest("flat").or_else(|| smallest("ball"))
}

/// The slot centres of one axis on a block `len_mm` long for a tool of diameter `d_mm`: the longest whole
/// millimetre pitch `P` that leaves [`BORDER_MM`] outside the outer slots, centred, `b` halfway (all on the
/// write grid `q`). None when the lands `P/2 − D` would be narrower than [`MIN_LAND_MM`].
pub fn centres(len_mm: f64, d_mm: f64, q: f64) -> Option<[f64; 3]> {
    let p = (len_mm - 2.0 * BORDER_MM - d_mm).floor();
    if p / 2.0 - d_mm < MIN_LAND_MM {
        return None;
    }
    let a = (len_mm - p) / 2.0;
    Some([a, a + p / 2.0, a + p].map(|c| emit::quantize(c, 0, q)))
}

/// The features of one axis (`k` 0 for X, 1 for Y) with slot centres `c` for a tool of diameter `d`, on a
/// block of [`STOCK_MM`].
fn axis_features(k: usize, c: [f64; 3], d: f64) -> AxisFeatures {
    let other = STOCK_MM[1 - k];
    let out = d / 2.0 + ENTRY_CLEAR_MM;
    let p = c[2] - c[0];
    AxisFeatures {
        axis: ["X", "Y"][k],
        centres_mm: c,
        approach: [1, -1, 1],
        run_mm: [-out, other + out],
        pitch_mm: p,
        lands_mm: [c[1] - c[0] - d, c[2] - c[1] - d],
        inner_span_mm: p - d,
        outer_span_mm: p + d,
    }
}

/// The move list under construction and the tip's position.
struct Path3<'m> {
    moves: Vec<Move>,
    at: P3,
    machine: &'m Machine,
}

impl Path3<'_> {
    fn rapid(&mut self, p: P3) {
        self.moves.push(Move::Rapid(p));
        self.at = p;
    }

    fn feed(&mut self, p: P3, f: f64) {
        self.moves.push(Move::Feed(p, f));
        self.at = p;
    }

    /// Out of the cut: feed up to the lead height, rapid to safe z.
    fn up(&mut self) {
        let m = self.machine;
        if self.at[2] < LEAD_MM {
            self.feed([self.at[0], self.at[1], LEAD_MM], m.limits.max_feed_z_mm_min);
        }
        if self.at[2] < m.program.safe_z_mm {
            self.rapid([self.at[0], self.at[1], m.program.safe_z_mm]);
        }
    }
}

/// Slot `i` (a, b, c) of axis `k` (0 X, 1 Y; the measured axis, which does not move while it is cut): a
/// take-up move of [`TAKE_UP_MM`] in the approach direction at safe z, then for each level a descent outside
/// the block (rapid to the lead height, feed down through air) and a straight cut along the other axis out
/// past the far face; between levels only the other axis moves back.
fn slot(path: &mut Path3, spec: &CouponSpec, k: usize, i: usize, levels: &[f64]) {
    let (f, o) = ([&spec.x, &spec.y][k], 1 - k);
    let (centre, run) = (f.centres_mm[i], f.run_mm);
    let safe = path.machine.program.safe_z_mm;
    path.moves.push(Move::Comment(LABELS[k][i]));
    path.up();
    let mut p = [0.0, 0.0, safe];
    p[k] = centre - f64::from(f.approach[i]) * TAKE_UP_MM;
    p[o] = run[0];
    path.rapid(p);
    p[k] = centre;
    path.rapid(p);
    for &z in levels {
        path.up();
        p[o] = run[0];
        path.rapid(p);
        path.rapid([p[0], p[1], LEAD_MM]);
        path.feed([p[0], p[1], z], spec.plunge_mm_min);
        let mut end = [p[0], p[1], z];
        end[o] = run[1];
        path.feed(end, spec.feed_mm_min);
    }
    path.up();
}

/// The comment before each slot (static: the move list's comments are).
const LABELS: [[&str; 3]; 2] = [
    [
        "X slot a: along Y, X approached moving +X",
        "X slot b: along Y, X approached moving -X",
        "X slot c: along Y, X approached moving +X",
    ],
    [
        "Y slot a: along X, Y approached moving +Y",
        "Y slot b: along X, Y approached moving -Y",
        "Y slot c: along X, Y approached moving +Y",
    ],
];

/// The whole move list: tool, spindle, the three X slots, the three Y slots, retract, park, stop.
fn program_moves(machine: &Machine, tool: &Tool, spec: &CouponSpec, levels: &[f64], start: P3) -> Vec<Move> {
    let mut path = Path3 {
        moves: vec![],
        at: start,
        machine,
    };
    path.moves.push(Move::ToolChange {
        number: tool.number,
        diameter_mm: tool.diameter_mm(),
        kind: tool.shape.kind(),
    });
    let clear = machine.program.clearance_z();
    path.rapid([start[0], start[1], clear]);
    path.moves.push(Move::SpindleOn(spec.spindle_rpm));
    path.moves.push(Move::Dwell(machine.program.spindle_dwell_s));
    if machine.program.coolant != Coolant::Off {
        path.moves.push(Move::Coolant(machine.program.coolant));
    }
    for k in 0..2 {
        for i in 0..3 {
            slot(&mut path, spec, k, i, levels);
        }
    }
    path.up();
    path.rapid([path.at[0], path.at[1], clear]);
    if let Some([x, y]) = machine.program.park_xy_mm {
        path.rapid([x, y, clear]);
    }
    path.moves.push(Move::SpindleOff);
    if machine.program.coolant != Coolant::Off {
        path.moves.push(Move::Coolant(Coolant::Off));
    }
    path.moves
}

/// The tool to cut with, checked: its flank must stand [`MIN_WALL_MM`] above the slot floor.
fn pick_tool<'m>(machine: &'m Machine, cfg: &CalibrateConfig) -> Result<&'m Tool, CalibrateError> {
    let tool = match &cfg.tool {
        Some(id) => machine.tool(id)?,
        None => default_tool(machine).ok_or_else(|| CalibrateError::NoTool(machine.name.clone()))?,
    };
    let corner = tool.shape.normalized().corner_radius_mm();
    if DEPTH_MM - corner < MIN_WALL_MM {
        return Err(CalibrateError::Tool {
            id: tool.id.clone(),
            why: format!(
                "its corner radius {corner} mm leaves {:.2} mm of vertical wall in a {DEPTH_MM} mm deep slot, \
                 less than {MIN_WALL_MM} mm to measure; use a flat end mill or a ball of at most {} mm",
                DEPTH_MM - corner,
                2.0 * (DEPTH_MM - MIN_WALL_MM)
            ),
        });
    }
    Ok(tool)
}

/// Build the coupon for `machine`: pick and check the tool, lay the slots out on the block, build the moves,
/// check them against the machine (before anything is written), write the program, the sheet and the spec.
pub fn coupon(machine: &Machine, cfg: &CalibrateConfig) -> Result<Coupon, CalibrateError> {
    let tool = pick_tool(machine, cfg)?;
    let d = tool.diameter_mm();
    let q = machine.write_resolution_mm();
    let fit = |len: f64| {
        centres(len, d, q).ok_or_else(|| CalibrateError::Tool {
            id: tool.id.clone(),
            why: format!(
                "at D = {d} mm the lands on a {len} mm side of the {} x {} mm block would be narrower than \
                 {MIN_LAND_MM} mm; use a tool of at most about {:.1} mm",
                STOCK_MM[0],
                STOCK_MM[1],
                (STOCK_MM[1] - 2.0 * BORDER_MM - 2.0 * MIN_LAND_MM) / 3.0
            ),
        })
    };
    let (cx, cy) = (fit(STOCK_MM[0])?, fit(STOCK_MM[1])?);
    let cut = tool.cutting(cfg.stock);
    let l = &machine.limits;
    let n = (DEPTH_MM / cut.max_depth_of_cut_mm - 1e-9).ceil().max(1.0) as usize;
    let levels: Vec<f64> = (1..=n).map(|i| -DEPTH_MM * i as f64 / n as f64).collect();
    let declared = machine.accuracy();
    let mut spec = CouponSpec {
        format: "brdfmill-calibrate",
        version: 1,
        machine: machine.name.clone(),
        profile: cfg.profile.clone(),
        dialect: machine.dialect,
        tool: CouponTool {
            id: tool.id.clone(),
            number: tool.number,
            kind: tool.shape.kind(),
            diameter_mm: d,
            corner_radius_mm: tool.shape.corner_radius_mm(),
        },
        stock: cfg.stock,
        stock_mm: [STOCK_MM[0], STOCK_MM[1], STOCK_THICKNESS_MM],
        depth_mm: DEPTH_MM,
        levels: n,
        feed_mm_min: cut.feed_mm_min.min(l.max_feed_mm_min),
        plunge_mm_min: cut.plunge_mm_min.min(l.max_feed_z_mm_min),
        spindle_rpm: cut.spindle_rpm,
        x: axis_features(0, cx, d),
        y: axis_features(1, cy, d),
        write_resolution_mm: q,
        declared,
        estimated_s: 0.0,
        estimated_block_limited_s: 0.0,
        blocks: 0,
        keys: keys(machine.dialect),
    };
    let start = [0.0, 0.0, machine.program.clearance_z()];
    let moves = program_moves(machine, tool, &spec, &levels, start);
    check::check(&moves, start, machine, tool).map_err(|e| CalibrateError::Machine(e.0))?;
    let est = estimate::estimate(&moves, start, machine, machine.block_rate_limit());
    spec.estimated_s = est.s;
    spec.estimated_block_limited_s = est.block_limited_s;
    spec.blocks = est.blocks;
    let header = header(&spec);
    let setup = emit::Setup {
        dialect: machine.dialect,
        header: &header,
        path_tolerance_mm: l.path_tolerance_mm,
        resolution_mm: q,
        tool_change_machine_z_mm: machine.program.tool_change_machine_z_mm,
    };
    let gcode = emit::emit(&setup, &moves);
    let sheet = sheet(&spec);
    let tool_table = (machine.dialect == Dialect::Linuxcnc).then(|| emit::tool_table(machine));
    Ok(Coupon {
        moves,
        start_mm: start,
        gcode,
        spec,
        sheet,
        tool_table,
    })
}

/// The program's header comments (made safe by the emitter).
fn header(s: &CouponSpec) -> Vec<String> {
    let t = &s.tool;
    let list = |f: &AxisFeatures| f.centres_mm.map(|c| emit::num(c, 4)).join(", ");
    vec![
        format!("brdfmill {} - calibration coupon", env!("CARGO_PKG_VERSION")),
        format!("machine: {} ({:?})", s.machine, s.dialect),
        format!(
            "tool T{} {}: {} D{} mm, stock {}, F{} plunge {} S{}",
            t.number,
            t.id,
            t.kind,
            t.diameter_mm,
            stock_name(s.stock),
            s.feed_mm_min,
            s.plunge_mm_min,
            s.spindle_rpm
        ),
        format!(
            "block at least {} x {} x {} mm: X0 Y0 its front-left corner, Z0 its top",
            s.stock_mm[0], s.stock_mm[1], s.stock_mm[2]
        ),
        format!("X slots along Y at x = {} mm", list(&s.x)),
        format!("Y slots along X at y = {} mm", list(&s.y)),
        format!(
            "every slot {} mm deep, cut in {} pass(es) from outside the block",
            s.depth_mm, s.levels
        ),
        "slots a and c approached moving +, slot b moving -: read calibrate.md".into(),
        format!(
            "estimated run time {} ({} at the block rate), {} blocks",
            hms(s.estimated_s),
            hms(s.estimated_block_limited_s),
            s.blocks
        ),
    ]
}

/// The keys the sheet sets and their formulas (measurements in mm), those of the profile and the controller's.
fn keys(dialect: Dialect) -> Vec<[&'static str; 2]> {
    let mut v = vec![
        ["accuracy.backlash_um[0]", "1000 * (A_x - B_x) / 2"],
        ["accuracy.backlash_um[1]", "1000 * (A_y - B_y) / 2"],
        ["accuracy.runout_um", "1000 * (S - D_measured), S the mean slot width"],
        ["accuracy.steps_per_mm[0]", "steps_old_x * P_x / ((O_x + I_x) / 2)"],
        ["accuracy.steps_per_mm[1]", "steps_old_y * P_y / ((O_y + I_y) / 2)"],
    ];
    v.extend(match dialect {
        Dialect::Grbl => [
            ["$100", "accuracy.steps_per_mm[0]"],
            ["$101", "accuracy.steps_per_mm[1]"],
        ],
        Dialect::Linuxcnc => [
            ["[JOINT_0] SCALE", "SCALE_old * P_x / ((O_x + I_x) / 2)"],
            ["[JOINT_1] SCALE", "SCALE_old * P_y / ((O_y + I_y) / 2)"],
        ],
    });
    v
}

/// The stock's name as the command line spells it.
pub fn stock_name(s: Stock) -> &'static str {
    match s {
        Stock::Wax => "wax",
        Stock::Aluminium => "aluminium",
    }
}

mod sheet;
pub use sheet::sheet;
