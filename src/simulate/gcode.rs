//! A G-code reader for the subset of DESIGN.md §5, for programs from anywhere (LinuxCNC, GRBL, CAM
//! post-processors), not only ours. What it does not understand is refused with the line and column of the
//! offending character; nothing is skipped silently.
//!
//! **Understood.** Comments `( … )` (not nested) and `;` to the end of the line; `N` line numbers; `%` alone on
//! a line (the second one ends the program); upper or lower case; spaces anywhere outside comments, also
//! inside numbers (as LinuxCNC reads them). Words:
//!
//! | word | meaning |
//! | --- | --- |
//! | `G0 G1 G2 G3` | rapid, feed, clockwise / counter-clockwise arc (in the plane of `G17`, `G18` or `G19`; `I J`, `K I`, `J K` or `R` form; `P` full turns) |
//! | `G4 P` | dwell, seconds |
//! | `G17 G18 G19` | arc plane XY, ZX, YZ (clockwise as seen from the positive end of Z, Y, X) |
//! | `G20 G21` | inch / mm; everything is converted to mm on reading |
//! | `G90 G91`, `G90.1 G91.1` | absolute / incremental X Y Z, and arc centres (default `G91.1`, relative to the start) |
//! | `G40 G49 G54 G61 G61.1 G64 [P Q] G80 G94` | states the simulation is already in, or path blending, which the simulation does not model: it follows the programmed path exactly |
//! | `M0 M1` | pauses (no effect); `M2 M30` end the program (later lines are not read) |
//! | `M3 M4 M5`, `S` | spindle; `M7 M8 M9` coolant (no effect) |
//! | `T`, `M6` | tool select and change (`T… M0` on one line is a manual change, as GRBL has no `M6`; a `T` before the first move is the mounted tool): every later segment carries the tool's number ([`Segment::tool`]), so the simulation sweeps each tool with its own shape |
//! | `G43 H` | tool length offset from the table: the simulation works in tip coordinates and takes the offset as measured; an `H` other than the tool in the spindle is refused (the classic crash) |
//! | `F` | feed, units per minute (`G94`) |
//! | `X Y Z I J K R` | coordinates, arc centre offsets (the two of the plane), arc radius (negative: the long way round) |
//!
//! Anything else — other G and M codes, `A B C U V W` axes, an arc offset normal to its plane (`K` in G17), `#` parameters, `[ ]`
//! expressions, `O` words, block delete `/`, two words of one modal group or two of one letter on a line, a feed
//! move without a feed rate, an arc whose end radius differs from its start radius by more than max(0.002 mm,
//! 0.1%) — is an error.
//!
//! The program's own positions are work coordinates; the tool starts at [`ParseOptions::start_mm`] (LinuxCNC's
//! standalone interpreter starts at the origin). Arcs are linearised into chords whose sagitta (the largest
//! distance between a chord and the arc it replaces) is at most `arc_tolerance_mm`: the chords lie inside the
//! arc, so the swept tool centre is within that tolerance of the programmed one.

use crate::gcode::lex::{g_name as gname, lex, tenths, Block, Word};
use crate::gcode::modal::{Distance, Modal, MotionMode, Units};
use crate::gcode::moves::{Move, Plane, P3};
use serde::{Deserialize, Serialize};

/// A program that cannot be simulated: where and why. Line and column count from 1 (columns in characters).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct GcodeError {
    /// Line, from 1.
    pub line: usize,
    /// Column in characters, from 1.
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

/// What a linear segment of the swept path comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentKind {
    /// `G0`.
    Rapid,
    /// `G1`.
    Feed,
    /// A chord of a `G2`/`G3` arc.
    Arc,
}

/// One straight piece of the tool-tip path, mm, in work coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Start of the tip.
    pub from: P3,
    /// End of the tip.
    pub to: P3,
    /// Where it comes from.
    pub kind: SegmentKind,
    /// The program line, from 1.
    pub line: u32,
    /// The tool in the spindle (the number of the last `T… M6`; 0 before any).
    #[serde(default)]
    pub tool: u32,
}

/// The largest coordinate the reader accepts, mm (1 km): beyond it a number is a typo or an attack, and
/// the volume and time figures computed from it would be meaningless.
pub const MAX_COORDINATE_MM: f64 = 1e6;

/// Options of the reader.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParseOptions {
    /// Largest chord sagitta when arcs are linearised, mm.
    pub arc_tolerance_mm: f64,
    /// Tool-tip position before the first move, mm.
    pub start_mm: P3,
    /// Refuse a program that expands to more linear segments than this (arcs at a fine tolerance). A segment
    /// and its move take about 100 bytes, so the default 20 M bounds the program's memory near 2 GB; an arc
    /// is refused *before* its chords are allocated when they would pass the limit.
    pub max_segments: usize,
}

impl Default for ParseOptions {
    fn default() -> Self {
        Self {
            arc_tolerance_mm: 1e-4,
            start_mm: [0.0; 3],
            max_segments: 20_000_000,
        }
    }
}

/// A program read into its motion: linear segments (mm) for the sweep and the machine-independent move list
/// of the time estimator.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Motion {
    /// Every motion as straight segments, in program order (zero-length moves dropped).
    pub segments: Vec<Segment>,
    /// The same motion (arcs as their chords) with feeds in mm/min, spindle and dwell commands, for
    /// `crate::toolpath::estimate::estimate_s`.
    pub moves: Vec<Move>,
    /// Lines read (up to and including the end of the program).
    pub lines: usize,
    /// Motion commands that moved (G0/G1/G2/G3 blocks).
    pub motions: usize,
    /// Arc commands among them.
    pub arcs: usize,
    /// Whether any `G20` (inch) was read.
    pub inch: bool,
    /// The line of the `M2`/`M30` or closing `%` that ended the program, if any.
    pub end_line: Option<usize>,
    /// The tip's position at the end, mm.
    pub end_mm: P3,
}

/// Modal group of a supported G code (tenths), or the reason it is refused.
fn g_group(t: i64) -> Result<u8, String> {
    Ok(match t {
        0 | 10 | 20 | 30 | 800 => 1,
        40 => 0,
        170 | 180 | 190 => 2,
        200 | 210 => 6,
        900 | 910 => 3,
        901 | 911 => 4,
        940 => 5,
        400 => 7,
        490 => 8,
        540 => 12,
        610 | 611 | 640 => 13,
        280 | 281 | 300 | 301 => return Err("home positions (G28/G30) are machine-specific and not simulated".into()),
        410 | 411 | 420 | 421 => return Err("cutter radius compensation is not supported".into()),
        430 => 8,
        431 | 432 => return Err("only the tool table's length offset (G43 H) is supported".into()),
        530 => return Err("machine coordinates (G53) are not supported".into()),
        550..=593 => return Err("only the G54 work coordinate system is supported".into()),
        730 | 760 | 810..=890 => return Err("canned cycles are not supported".into()),
        920..=923 => return Err("coordinate offsets (G92) are not supported".into()),
        930 | 950 => return Err("only units-per-minute feed (G94) is supported".into()),
        _ => {
            return Err(format!(
                "{} is not supported (understood: G0 G1 G2 G3 G4 G17 G18 G19 G20 G21 G40 G43 G49 G54 G61 G61.1 G64 G80 G90 \
                 G90.1 G91 G91.1 G94)",
                gname(t)
            ))
        }
    })
}

/// Modal group of a supported M code.
fn m_group(m: i64) -> Result<u8, String> {
    Ok(match m {
        0 | 1 | 2 | 30 => 4,
        6 => 6,
        3..=5 => 7,
        7..=9 => 8,
        _ => {
            return Err(format!(
                "M{m} is not supported (understood: M0 M1 M2 M3 M4 M5 M6 M7 M8 M9 M30)"
            ))
        }
    })
}

/// The reader's state between lines: the crate's one modal state, the position and the tool-change rule.
struct State {
    pos: P3,
    modal: Modal,
    /// The tool selected by the last `T` word.
    selected: u32,
    /// The tool in the spindle.
    tool: u32,
}

/// A lexed line, or the reader's error for it.
fn tokenize(raw: &str, lineno: usize) -> Result<Block, GcodeError> {
    lex(raw).map_err(|e| GcodeError {
        line: lineno,
        column: e.column + 1,
        message: e.kind.to_string(),
    })
}

/// Read a whole program.
pub fn parse(text: &str, opt: &ParseOptions) -> Result<Motion, GcodeError> {
    let mut st = State {
        pos: opt.start_mm,
        // LinuxCNC's standalone interpreter starts with no motion mode: coordinates before a G0/G1/G2/G3
        // are an error, not a rapid.
        modal: Modal {
            motion: MotionMode::Cancel,
            ..Modal::default()
        },
        selected: 0,
        tool: 0,
    };
    let mut prog = Motion::default();
    let mut percents = 0;
    let mut seen_content = false;
    for (n, raw) in text.lines().enumerate() {
        let lineno = n + 1;
        prog.lines = lineno;
        match tokenize(raw, lineno)? {
            Block::Percent => {
                percents += 1;
                if percents == 2 || seen_content {
                    prog.end_line = Some(lineno);
                    break;
                }
            }
            Block::Words(w) => {
                if w.is_empty() {
                    continue;
                }
                seen_content = true;
                if block(&w, lineno, &mut st, &mut prog, opt)? {
                    prog.end_line = Some(lineno);
                    break;
                }
            }
        }
    }
    if prog.segments.len() > opt.max_segments {
        return Err(GcodeError {
            line: prog.lines,
            column: 1,
            message: format!("more than {} linear segments", opt.max_segments),
        });
    }
    prog.end_mm = st.pos;
    Ok(prog)
}

/// The words of one block, sorted by kind, each with its 0-based column.
struct Words {
    /// G codes in tenths.
    gs: Vec<(i64, usize)>,
    /// M codes.
    ms: Vec<(i64, usize)>,
    /// Value words by letter (`A` = 0).
    val: [Option<(f64, usize)>; 26],
}

impl Words {
    fn get(&self, l: char) -> Option<(f64, usize)> {
        self.val[(l as u8 - b'A') as usize]
    }
    fn has_g(&self, t: i64) -> bool {
        self.gs.iter().any(|g| g.0 == t)
    }
    fn has_m(&self, m: i64) -> bool {
        self.ms.iter().any(|g| g.0 == m)
    }
}

/// An error at a 0-based column of line `lineno`.
fn at(lineno: usize, col: usize, message: String) -> GcodeError {
    GcodeError {
        line: lineno,
        column: col + 1,
        message,
    }
}

/// Sort a block's words, refusing unknown codes, two codes of one modal group and repeated letters.
fn sort_words(w: &[Word], lineno: usize) -> Result<Words, GcodeError> {
    let err = |col: usize, message: String| at(lineno, col, message);
    let mut out = Words {
        gs: vec![],
        ms: vec![],
        val: [None; 26],
    };
    let mut g_groups: Vec<u8> = vec![];
    let mut m_groups: Vec<u8> = vec![];
    for (k, wd) in w.iter().enumerate() {
        match wd.letter {
            'G' => {
                let t = tenths(wd.value).ok_or_else(|| err(wd.column, format!("G{} is not supported", wd.value)))?;
                let g = g_group(t).map_err(|m| err(wd.column, m))?;
                if g != 0 && g_groups.contains(&g) {
                    return Err(err(
                        wd.column,
                        format!("{} conflicts with another G code of its group on this line", gname(t)),
                    ));
                }
                g_groups.push(g);
                out.gs.push((t, wd.column));
            }
            'M' => {
                let m = match tenths(wd.value) {
                    Some(t) if t % 10 == 0 => t / 10,
                    _ => return Err(err(wd.column, format!("M{} is not supported", wd.value))),
                };
                let g = m_group(m).map_err(|e| err(wd.column, e))?;
                if g != 8 && m_groups.contains(&g) {
                    return Err(err(
                        wd.column,
                        format!("M{m} conflicts with another M code of its group on this line"),
                    ));
                }
                m_groups.push(g);
                out.ms.push((m, wd.column));
            }
            'N' => {
                if k != 0 {
                    return Err(err(wd.column, "a line number `N` must come first on the line".into()));
                }
            }
            'X' | 'Y' | 'Z' | 'I' | 'J' | 'K' | 'R' | 'F' | 'S' | 'P' | 'Q' | 'T' | 'H' => {
                let slot = &mut out.val[(wd.letter as u8 - b'A') as usize];
                if slot.is_some() {
                    return Err(err(wd.column, format!("`{}` appears twice on this line", wd.letter)));
                }
                *slot = Some((wd.value, wd.column));
            }
            'A' | 'B' | 'C' | 'U' | 'V' | 'W' => {
                return Err(err(
                    wd.column,
                    format!("axis `{}`: only X, Y and Z are simulated (3-axis)", wd.letter),
                ))
            }
            l => return Err(err(wd.column, format!("word `{l}` is not supported"))),
        }
    }
    Ok(out)
}

/// Execute one block in the order of RS274/NGC (F, S, T, M6, spindle, coolant, dwell, modes, motion, stop).
/// Returns true when the block ends the program.
fn block(w: &[Word], lineno: usize, st: &mut State, prog: &mut Motion, opt: &ParseOptions) -> Result<bool, GcodeError> {
    let w = sort_words(w, lineno)?;
    feeds_and_tools(&w, lineno, st, prog)?;
    dwell(&w, lineno, st, prog)?;
    modes(&w, st, prog);
    motion(&w, lineno, st, prog, opt)?;
    Ok(w.has_m(2) || w.has_m(30))
}

/// F, S, T and M6, spindle on/off.
fn feeds_and_tools(w: &Words, lineno: usize, st: &mut State, prog: &mut Motion) -> Result<(), GcodeError> {
    let err = |col: usize, message: String| at(lineno, col, message);
    if let Some((f, col)) = w.get('F') {
        if f < 0.0 {
            return Err(err(col, format!("negative feed F{f}")));
        }
        // units are those in force when F is read; a G20/G21 on the same line applies first
        let units = if w.has_g(200) {
            Units::Inch
        } else if w.has_g(210) {
            Units::Mm
        } else {
            st.modal.units
        };
        st.modal.feed_mm_min = Some(f * units.mm());
    }
    if let Some((s, col)) = w.get('S') {
        if s < 0.0 {
            return Err(err(col, format!("negative spindle speed S{s}")));
        }
        st.modal.spindle_rpm = s;
    }
    if let Some((t, col)) = w.get('T') {
        if !(t >= 0.0 && t.fract() == 0.0 && t < 1e6) {
            return Err(err(col, format!("tool number T{t} must be a whole number ≥ 0")));
        }
        st.selected = t as u32;
        // a tool named before the first move is the one mounted (GRBL has no M6)
        if prog.segments.is_empty() {
            st.tool = st.selected;
        }
    }
    // M6 changes to the selected tool; `T… M0` on one line is a manual change (GRBL's pause)
    if w.has_m(6) || (w.has_m(0) && w.get('T').is_some()) {
        st.tool = st.selected;
    }
    if let Some((h, col)) = w.get('H') {
        if !w.has_g(430) {
            return Err(err(col, "`H` is only understood with G43".into()));
        }
        if h != st.tool as f64 {
            let msg = format!("G43 H{h} takes another tool's length than the spindle's (T{})", st.tool);
            return Err(err(col, msg));
        }
    } else if let Some(&(_, col)) = w.gs.iter().find(|g| g.0 == 430) {
        return Err(err(col, "G43 without `H`: name the tool table entry".into()));
    }
    if w.has_m(3) || w.has_m(4) {
        prog.moves.push(Move::SpindleOn(st.modal.spindle_rpm));
    }
    if w.has_m(5) {
        prog.moves.push(Move::SpindleOff);
    }
    Ok(())
}

/// `P` and `Q` belong to G4, G64 or an arc; G4 dwells.
fn dwell(w: &Words, lineno: usize, st: &State, prog: &mut Motion) -> Result<(), GcodeError> {
    let err = |col: usize, message: String| at(lineno, col, message);
    let motion_here =
        w.gs.iter()
            .find_map(|g| MotionMode::from_tenths(g.0))
            .unwrap_or(st.modal.motion);
    if let Some((_, col)) = w.get('P') {
        if !(w.has_g(40) || w.has_g(640) || motion_here.is_arc()) {
            return Err(err(
                col,
                "`P` is only understood with G4 (dwell), G64 or an arc (turns)".into(),
            ));
        }
    }
    if let Some((_, col)) = w.get('Q') {
        if !w.has_g(640) {
            return Err(err(col, "`Q` is only understood with G64".into()));
        }
    }
    if w.has_g(40) {
        let (p, col) = w.get('P').ok_or_else(|| {
            err(
                w.gs.iter().find(|g| g.0 == 40).map_or(0, |g| g.1),
                "G4 needs `P` (seconds)".into(),
            )
        })?;
        if p < 0.0 {
            return Err(err(col, format!("negative dwell P{p}")));
        }
        prog.moves.push(Move::Dwell(p));
    }
    Ok(())
}

/// Units and distance modes.
fn modes(w: &Words, st: &mut State, prog: &mut Motion) {
    let m = &mut st.modal;
    for &(t, _) in &w.gs {
        match t {
            200 => {
                m.units = Units::Inch;
                prog.inch = true;
            }
            210 => m.units = Units::Mm,
            170 => m.plane = 17,
            180 => m.plane = 18,
            190 => m.plane = 19,
            900 => m.distance = Distance::Absolute,
            910 => m.distance = Distance::Incremental,
            901 => m.arc_distance = Distance::Absolute,
            911 => m.arc_distance = Distance::Incremental,
            _ => {}
        }
    }
}

/// The block's motion, if it has coordinates.
fn motion(w: &Words, lineno: usize, st: &mut State, prog: &mut Motion, opt: &ParseOptions) -> Result<(), GcodeError> {
    let err = |col: usize, message: String| at(lineno, col, message);
    let mut motion_col = None;
    for &(t, col) in &w.gs {
        if let Some(m) = MotionMode::from_tenths(t) {
            st.modal.motion = m;
            motion_col = Some(col);
        }
    }
    let axis_col = ['X', 'Y', 'Z'].iter().filter_map(|l| w.get(*l).map(|v| v.1)).min();
    let arc_col = ['I', 'J', 'K', 'R'].iter().filter_map(|l| w.get(*l).map(|v| v.1)).min();
    if axis_col.is_none() && arc_col.is_none() {
        return Ok(());
    }
    let col = motion_col.or(axis_col).or(arc_col).unwrap_or(0);
    let motion = st.modal.motion;
    if motion == MotionMode::Cancel {
        return Err(err(
            axis_col.or(arc_col).unwrap_or(0),
            "coordinates without an active motion mode (G0/G1/G2/G3)".into(),
        ));
    }
    if !motion.is_arc() {
        if let Some(c) = arc_col {
            return Err(err(c, "`I`, `J`, `K` or `R` without an arc (G2/G3)".into()));
        }
    }
    let u = st.modal.units.mm();
    let mut target = st.pos;
    for (k, l) in ['X', 'Y', 'Z'].iter().enumerate() {
        if let Some((v, c)) = w.get(*l) {
            target[k] = match st.modal.distance {
                Distance::Incremental => st.pos[k] + v * u,
                Distance::Absolute => v * u,
            };
            if !target[k].is_finite() || target[k].abs() > MAX_COORDINATE_MM {
                return Err(err(
                    c,
                    format!(
                        "{l} reaches {:e} mm, beyond any machine (|coordinate| ≤ {MAX_COORDINATE_MM:e} mm)",
                        target[k]
                    ),
                ));
            }
        }
    }
    let feed = st.modal.feed_mm_min.unwrap_or(0.0);
    if motion != MotionMode::Rapid && feed <= 0.0 {
        return Err(err(col, format!("{} without a feed rate (F)", motion.name())));
    }
    let from = st.pos;
    let before = prog.segments.len();
    match motion {
        MotionMode::Rapid => push_line(prog, st.tool, from, target, SegmentKind::Rapid, lineno, None),
        MotionMode::Linear => push_line(prog, st.tool, from, target, SegmentKind::Feed, lineno, Some(feed)),
        _ => {
            let get = |l: char| w.get(l);
            arc(prog, st, &get, target, motion == MotionMode::ArcCw, lineno, col, opt).map_err(|m| err(m.0, m.1))?;
            prog.arcs += 1;
        }
    }
    if prog.segments.len() > before {
        prog.motions += 1;
    }
    if prog.segments.len() > opt.max_segments {
        return Err(err(
            col,
            format!(
                "the program expands to more than {} linear segments (arcs are split within the arc tolerance)",
                opt.max_segments
            ),
        ));
    }
    st.pos = target;
    Ok(())
}

fn push_line(prog: &mut Motion, tool: u32, from: P3, to: P3, kind: SegmentKind, line: usize, feed: Option<f64>) {
    if from == to {
        return;
    }
    prog.segments.push(Segment {
        from,
        to,
        kind,
        line: line as u32,
        tool,
    });
    prog.moves.push(match feed {
        None => Move::Rapid(to),
        Some(f) => Move::Feed(to, f),
    });
}

/// Linearise a G2 (`cw`) / G3 arc in the current plane (G17 X→Y with `I J`, G18 Z→X with `K I`, G19 Y→Z
/// with `J K`; clockwise seen from the positive end of the normal axis, so counter-clockwise for G3 in the
/// plane's own (first, second) axes) from the current position to `target` into chords of sagitta ≤ the
/// tolerance. The radius varies linearly from start to end (LinuxCNC accepts a small
/// difference); z varies linearly with the angle (a helix). Errors carry (0-based column, message).
#[allow(clippy::too_many_arguments)]
fn arc(
    prog: &mut Motion,
    st: &State,
    get: &dyn Fn(char) -> Option<(f64, usize)>,
    target: P3,
    cw: bool,
    lineno: usize,
    col: usize,
    opt: &ParseOptions,
) -> Result<(), (usize, String)> {
    use std::f64::consts::TAU;
    let u = st.modal.units.mm();
    // the plane's (first, second, normal) axes and their letters; below, x/y/z and I/J name them
    let (fa, sa, na) = Plane::from_g(st.modal.plane).axes();
    let (axis, off) = (['X', 'Y', 'Z'], ['I', 'J', 'K']);
    let normal_offset = off[na];
    if let Some((_, c)) = get(normal_offset) {
        return Err((
            c,
            format!(
                "`{normal_offset}` is not an offset in the G{} plane",
                st.modal.plane.max(17)
            ),
        ));
    }
    let get = |l: char| -> Option<(f64, usize)> {
        get(match l {
            'X' => axis[fa],
            'Y' => axis[sa],
            'I' => off[fa],
            'J' => off[sa],
            other => other,
        })
    };
    let (pos, tgt) = (st.pos, target);
    let [x0, y0, z0] = [pos[fa], pos[sa], pos[na]];
    let [x1, y1, z1] = [tgt[fa], tgt[sa], tgt[na]];
    let world = |p: [f64; 3]| {
        let mut w = [0.0; 3];
        w[fa] = p[0];
        w[sa] = p[1];
        w[na] = p[2];
        w
    };
    let turns = match get('P') {
        None => 0,
        Some((p, c)) => {
            if p < 1.0 || p.fract() != 0.0 || p > 1e6 {
                return Err((c, format!("arc turns P{p} must be a positive whole number")));
            }
            p as i64 - 1
        }
    };
    let (cx, cy, full) = match (get('R'), get('I').or(get('J'))) {
        (Some((_, c)), Some(_)) => return Err((c, "an arc takes `R` or `I`/`J`, not both".into())),
        (None, None) => return Err((col, "G2/G3 needs `I`/`J` (centre) or `R` (radius)".into())),
        (Some((r, c)), None) => {
            if get('X').is_none() && get('Y').is_none() {
                return Err((c, "an `R` arc needs X or Y (a full circle needs I/J)".into()));
            }
            let d = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
            let rad = r.abs() * u;
            if d < 1e-9 {
                return Err((c, "an `R` arc whose end is its start (a full circle needs I/J)".into()));
            }
            if rad < d / 2.0 - 1e-6_f64.max(1e-6 * d) {
                return Err((
                    c,
                    format!("radius {} mm is less than half the chord, {:.6} mm", rad, d / 2.0),
                ));
            }
            let h = (rad * rad - d * d / 4.0).max(0.0).sqrt();
            let (mx, my) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
            let (nx, ny) = (-(y1 - y0) / d, (x1 - x0) / d); // left of the chord
                                                            // G3 (ccw) with R > 0 turns left around a centre on the left; the long way (R < 0) flips it
            let s = if cw == (r > 0.0) { -1.0 } else { 1.0 };
            (mx + s * h * nx, my + s * h * ny, false)
        }
        (None, Some(_)) => {
            let i = get('I').map_or(0.0, |v| v.0) * u;
            let j = get('J').map_or(0.0, |v| v.0) * u;
            let (cx, cy) = match st.modal.arc_distance {
                Distance::Absolute => (i, j),
                Distance::Incremental => (x0 + i, y0 + j),
            };
            let r0 = ((x0 - cx).powi(2) + (y0 - cy).powi(2)).sqrt();
            let r1 = ((x1 - cx).powi(2) + (y1 - cy).powi(2)).sqrt();
            if r0 < 1e-9 {
                return Err((col, "arc of zero radius (the centre is the start point)".into()));
            }
            if (r1 - r0).abs() > 0.002_f64.max(1e-3 * r0) {
                return Err((
                    col,
                    format!(
                        "radius to the end ({r1:.6} mm) differs from radius to the start ({r0:.6} mm) by more than \
                         max(0.002 mm, 0.1%)"
                    ),
                ));
            }
            let full = (x1 - x0).abs() < 1e-9 && (y1 - y0).abs() < 1e-9;
            (cx, cy, full)
        }
    };
    let r0 = ((x0 - cx).powi(2) + (y0 - cy).powi(2)).sqrt();
    let r1 = ((x1 - cx).powi(2) + (y1 - cy).powi(2)).sqrt();
    let a0 = (y0 - cy).atan2(x0 - cx);
    let a1 = (y1 - cy).atan2(x1 - cx);
    let mut sweep = if cw { a0 - a1 } else { a1 - a0 };
    sweep = sweep.rem_euclid(TAU);
    if full || sweep < 1e-12 {
        sweep = TAU;
    }
    sweep += TAU * turns as f64;
    let rmax = r0.max(r1);
    let tol = opt.arc_tolerance_mm;
    let dmax = if tol >= rmax {
        std::f64::consts::FRAC_PI_2
    } else {
        (2.0 * (1.0 - tol / rmax).acos()).min(std::f64::consts::FRAC_PI_2)
    };
    let n = (sweep / dmax).ceil().max(1.0);
    // estimated before a chord is allocated: the program's segments so far plus this arc's
    if prog.segments.len() as f64 + n > opt.max_segments as f64 {
        return Err((
            col,
            format!(
                "the arc needs {n} chords; with the program's {} segments so far that passes the limit of {} \
                 segments (max_segments, about 100 bytes each)",
                prog.segments.len(),
                opt.max_segments
            ),
        ));
    }
    let n = n as usize;
    let dir = if cw { -1.0 } else { 1.0 };
    let mut at = st.pos;
    for k in 1..=n {
        let p = if k == n {
            target
        } else {
            let f = k as f64 / n as f64;
            let a = a0 + dir * sweep * f;
            let rr = r0 + (r1 - r0) * f;
            world([cx + rr * a.cos(), cy + rr * a.sin(), z0 + (z1 - z0) * f])
        };
        push_line(prog, st.tool, at, p, SegmentKind::Arc, lineno, st.modal.feed_mm_min);
        at = p;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(text: &str) -> Result<Motion, GcodeError> {
        parse(text, &ParseOptions::default())
    }

    #[test]
    fn words_comments_case_and_spaces() {
        let g = p("%\n(header)\nN10 g21g90 ; note\nG0X1 Y 2 . 5 z-0.5\nn20 G1 X 2 F100 (cut)\n%\nG0 X99\n").unwrap();
        assert_eq!(g.segments.len(), 2);
        assert_eq!(g.segments[0].to, [1.0, 2.5, -0.5]);
        assert_eq!(g.segments[1].to, [2.0, 2.5, -0.5]);
        assert_eq!(g.segments[1].line, 5);
        assert_eq!(g.end_line, Some(6), "the second % ends the program");
    }

    #[test]
    fn inch_and_incremental() {
        let g = p("G20 G91\nG1 X1 Y-1 F10\nX1\nG21 G90 G0 Z1\n").unwrap();
        let s = &g.segments;
        assert!((s[0].to[0] - 25.4).abs() < 1e-12 && (s[0].to[1] + 25.4).abs() < 1e-12);
        assert!((s[1].to[0] - 50.8).abs() < 1e-12);
        assert_eq!(s[2].to, [50.8, -25.4, 1.0]);
        assert!(matches!(g.moves[0], Move::Feed(_, f) if (f - 254.0).abs() < 1e-12));
        assert!(g.inch);
    }

    #[test]
    fn arcs_in_the_zx_and_yz_planes() {
        // G18 G2 from (0,0,0) to (2,0,0) about (1,0,0): clockwise seen from +Y, counter-clockwise with X
        // drawn right and Z up: under the chord (a cup), through z = -1 at x = 1
        let g = p("G1 X0 Y0 Z0 F100\nG18 G2 X2 Z0 I1 K0\n").unwrap();
        let mid = g
            .segments
            .iter()
            .map(|s| s.to)
            .min_by(|a, b| a[2].total_cmp(&b[2]))
            .unwrap();
        assert!(
            (mid[0] - 1.0).abs() < 1e-3 && (mid[2] + 1.0).abs() < 1e-6 && mid[1] == 0.0,
            "{mid:?}"
        );
        // G3 the other way: over the chord
        let g = p("G1 X0 Y0 Z0 F100\nG18 G3 X2 Z0 I1 K0\n").unwrap();
        assert!(g.segments.iter().all(|s| s.to[2] >= -1e-12) && g.segments.iter().any(|s| s.to[2] > 0.99));
        // G19 G2 from (0,0,0) to (0,2,0) about (0,1,0): clockwise seen from +X, Y right and Z up: over the chord
        let g = p("G1 X0 Y0 Z0 F100\nG19 G2 Y2 Z0 J1 K0\n").unwrap();
        assert!(g.segments.iter().all(|s| s.to[2] >= -1e-12 && s.to[0] == 0.0));
        assert!(g.segments.iter().any(|s| s.to[2] > 0.99));
    }

    #[test]
    fn refusals_carry_line_and_column() {
        for (text, line, col, what) in [
            ("G0 X1\nG1 X2\n", 2, 1, "feed"),
            (
                "G0 X1\nG18 G2 X2 Z0 I0.5 J0 F9\n",
                2,
                19,
                "not an offset in the G18 plane",
            ),
            ("G0 X1 A3\n", 1, 7, "axis"),
            ("#1 = 2\n", 1, 1, "parameters"),
            ("G1 X[1+2] F1\n", 1, 5, "parameter or expression"),
            ("O100 sub\n", 1, 1, "O-words"),
            ("G0 X1 (open\n", 1, 7, "not closed"),
            ("G0 G1 X1\n", 1, 4, "conflicts"),
            ("G0 X1 X2\n", 1, 7, "twice"),
            ("G81 X1 Z-1 R1\n", 1, 1, "canned"),
            ("M98\n", 1, 1, "M98"),
            ("G2 X1 Y1 F10\n", 1, 1, "I`/`J"),
            ("G1 X1 F10\nG2 X4 Y0 I1 J0\n", 2, 1, "differs"),
            ("G0 X1 Y2 $\n", 1, 10, "unexpected"),
            ("T2 M6\nG43 H1\n", 2, 5, "another tool"),
            ("G43\n", 1, 1, "without `H`"),
            ("G80 X1\n", 1, 5, "motion mode"),
            ("G0 X1 K1\n", 1, 7, "K"),
            ("G1 X\n", 1, 4, "needs a number"),
        ] {
            let e = p(text).expect_err(text);
            assert_eq!((e.line, e.column), (line, col), "{text:?}: {e}");
            assert!(e.message.contains(what), "{text:?}: {e}");
        }
    }

    #[test]
    fn arcs_ij_and_r_forms_agree() {
        let opt = ParseOptions {
            arc_tolerance_mm: 1e-4,
            ..Default::default()
        };
        // quarter circle ccw from (1,0) to (0,1) about the origin, three ways
        let texts = [
            "G0 X1 Y0\nG3 X0 Y1 I-1 J0 F100\n",
            "G0 X1 Y0\nG3 X0 Y1 R1 F100\n",
            "G0 X1 Y0\nG90.1 G3 X0 Y1 I0 J0 F100\n",
        ];
        for t in texts {
            let g = parse(t, &opt).unwrap();
            for s in &g.segments[1..] {
                let r = (s.to[0].powi(2) + s.to[1].powi(2)).sqrt();
                assert!((r - 1.0).abs() < 1e-12, "{t}: on the circle");
                assert!(s.to[0] >= -1e-12 && s.to[1] >= -1e-12, "{t}: first quadrant");
                let m = [(s.from[0] + s.to[0]) / 2.0, (s.from[1] + s.to[1]) / 2.0];
                let sag = 1.0 - (m[0] * m[0] + m[1] * m[1]).sqrt();
                assert!(sag <= 1e-4 + 1e-12, "{t}: sagitta {sag}");
            }
            assert_eq!(g.segments.last().unwrap().to, [0.0, 1.0, 0.0]);
        }
        // R < 0: the long way round (270°), cw full circle with P2 = two turns
        let g = parse("G0 X1 Y0\nG3 X0 Y1 R-1 F100\n", &opt).unwrap();
        assert!(
            g.segments[1..].iter().any(|s| s.to[0] > 1.99 && s.to[1] > 0.99),
            "the long arc about (1, 1) passes (2, 1)"
        );
        let one = parse("G0 X1 Y0\nG2 I-1 F100\n", &opt).unwrap().segments.len();
        let two = parse("G0 X1 Y0\nG2 I-1 P2 F100\n", &opt).unwrap().segments.len();
        assert!(two >= 2 * (one - 1) - 1, "{one} {two}");
    }

    #[test]
    fn helix_descends_linearly() {
        let g = p("G0 X1 Y0 Z0\nG2 I-1 Z-1 F100\n").unwrap();
        let last = g.segments.last().unwrap();
        assert_eq!(last.to, [1.0, 0.0, -1.0]);
        for s in &g.segments[1..] {
            let a = (-s.to[1]).atan2(s.to[0]).rem_euclid(std::f64::consts::TAU);
            let a = if a < 1e-9 { std::f64::consts::TAU } else { a };
            assert!((s.to[2] + a / std::f64::consts::TAU).abs() < 1e-9, "{s:?}");
        }
    }

    #[test]
    fn program_end_stops_reading() {
        let g = p("G0 X1\nM2\nthis is not g-code\n").unwrap();
        assert_eq!(g.end_line, Some(2));
        assert_eq!(g.segments.len(), 1);
    }
}
