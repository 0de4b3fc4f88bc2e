//! The simulator's reader: any program (LinuxCNC, GRBL, CAM post-processors), not only ours, read through
//! the crate's one G-code interpreter ([`crate::gcode::interp`]) the way the machine it is for reads it
//! ([`ParseOptions::dialect`]), into straight segments for the sweep and the move list of the time estimate.
//! What it does not understand is refused with the line and column of the offending character; nothing is
//! skipped silently.
//!
//! **Understood.** Comments `( … )` (not nested) and `;` to the end of the line; `N` line numbers; `%` alone on
//! a line (the second one ends the program); upper or lower case; spaces anywhere outside comments, also
//! inside numbers (as LinuxCNC reads them). Words:
//!
//! | word | meaning |
//! | --- | --- |
//! | `G0 G1 G2 G3` | rapid, feed, clockwise / counter-clockwise arc (in the plane of `G17`, `G18` or `G19`; `I J`, `K I`, `J K` or `R` form; LinuxCNC: `P` full turns) |
//! | `G4 P` | dwell, seconds |
//! | `G17 G18 G19` | arc plane XY, ZX, YZ (clockwise as seen from the positive end of Z, Y, X) |
//! | `G20 G21` | inch / mm; everything is converted to mm on reading |
//! | `G90 G91`, `G90.1 G91.1` | absolute / incremental X Y Z, and arc centres (default `G91.1`, relative to the start; `G90.1` LinuxCNC only) |
//! | `G40 G49 G54 G61 G61.1 G64 [P Q] G80 G94` | states the simulation is already in, or path blending, which the simulation does not model: it follows the programmed path exactly (`G61.1 G64` LinuxCNC only) |
//! | `M0 M1` | pauses (no effect); `M2 M30` end the program (later lines are not read) |
//! | `M3 M4 M5`, `S` | spindle; `M7 M8 M9` coolant (no effect) |
//! | `T`, `M6` | tool select and change (`T… M0` on one line is a manual change, as GRBL has no `M6`; a `T` before the first move is the mounted tool): every later segment carries the tool's number ([`Segment::tool`]), so the simulation sweeps each tool with its own shape |
//! | `G43 H` | tool length offset from the table (LinuxCNC): the simulation works in tip coordinates and takes the offset as measured; an `H` other than the tool in the spindle is refused (the classic crash) |
//! | `F` | feed, units per minute (`G94`) |
//! | `X Y Z I J K R` | coordinates, arc centre offsets (the two of the plane), arc radius (negative: the long way round) |
//!
//! Anything else is an error: what neither dialect reads (other G and M codes, `A B C U V W` axes, `#`
//! parameters, `[ ]` expressions, `O` words, block delete `/`, two words of one modal group or two of one letter
//! on a line, a feed move without a feed rate, an arc whose end radius differs from its start radius beyond
//! the dialect's tolerance), and what a controller reads but the simulation does not model: work offsets
//! (`G10`, `G92`, `G55`–`G59`, `G43.1`), machine coordinates (`G53`, but for `G53 G0 Z…` alone: a tool
//! change's retract, read as straight up to at least the start height), stored positions (`G28`, `G30`),
//! probing (`G38.x`) and inverse-time feed (`G93`).
//!
//! The program's own positions are work coordinates; the tool starts at [`ParseOptions::start_mm`] (LinuxCNC's
//! standalone interpreter starts at the origin, with no motion mode in force; GRBL in `G0`). Arcs are
//! linearised into chords whose sagitta (the largest distance between a chord and the arc it replaces) is at
//! most `arc_tolerance_mm`: the chords lie inside the arc, so the swept tool centre is within that tolerance
//! of the programmed one.

pub use crate::cut::sweep::{Segment, SegmentKind};
use crate::gcode::block::{NonModal, Parsed, ToolLength};
use crate::gcode::interp::{self, Interpreter, Step};
use crate::gcode::lex::{lex, Block};
use crate::gcode::modal::{Modal, MotionMode, Spindle};
use crate::gcode::moves::{Move, P3};
use crate::gcode::Dialect;

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
    /// How the controller the program is for reads it (the machine profile's dialect).
    pub dialect: Dialect,
}

impl Default for ParseOptions {
    fn default() -> Self {
        Self {
            arc_tolerance_mm: 1e-4,
            start_mm: [0.0; 3],
            max_segments: 20_000_000,
            dialect: Dialect::Linuxcnc,
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
    /// `crate::cut::estimate::estimate_s`.
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

/// The reader's state between lines: the interpreter and the tool-change rule.
struct State {
    interp: Interpreter,
    /// The tool selected by the last `T` word.
    selected: u32,
    /// The tool in the spindle.
    tool: u32,
}

/// An error at a 0-based column of line `lineno`.
fn at(lineno: usize, col: usize, message: impl Into<String>) -> GcodeError {
    GcodeError {
        line: lineno,
        column: col + 1,
        message: message.into(),
    }
}

/// Read a whole program.
pub fn parse(text: &str, opt: &ParseOptions) -> Result<Motion, GcodeError> {
    // LinuxCNC's standalone interpreter starts with no motion mode: coordinates before a G0/G1/G2/G3 are an
    // error, not a rapid. GRBL starts in G0.
    let modal = match opt.dialect {
        Dialect::Linuxcnc => Modal {
            motion: MotionMode::Cancel,
            ..Modal::default()
        },
        Dialect::Grbl => Modal::default(),
    };
    let mut st = State {
        interp: Interpreter::new(opt.dialect, modal, opt.start_mm),
        selected: 0,
        tool: 0,
    };
    let mut prog = Motion::default();
    let mut percents = 0;
    let mut seen_content = false;
    for (n, raw) in text.lines().enumerate() {
        let lineno = n + 1;
        prog.lines = lineno;
        let lexed = lex(raw).map_err(|e| at(lineno, e.column, e.kind.to_string()))?;
        match lexed {
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
                let step = st.interp.block(&w).map_err(|e| at(lineno, e.column, e.message))?;
                if block(&step, lineno, &mut st, &mut prog, opt)? {
                    prog.end_line = Some(lineno);
                    break;
                }
            }
        }
    }
    if prog.segments.len() > opt.max_segments {
        return Err(at(
            prog.lines,
            0,
            format!("more than {} linear segments", opt.max_segments),
        ));
    }
    prog.end_mm = st.interp.pos;
    Ok(prog)
}

/// `G53 G0 Z…` alone: the retract in machine coordinates a LinuxCNC tool change starts with.
fn machine_retract(p: &Parsed) -> bool {
    matches!(p.non_modal, Some((NonModal::Machine, _)))
        && matches!(p.motion, Some((MotionMode::Rapid, _)))
        && p.get('Z').is_some()
        && p.get('X').is_none()
        && p.get('Y').is_none()
}

/// Read the programs of a job that run one after another on the same stock (GRBL's one program per tool),
/// each from [`ParseOptions::start_mm`] with the tool its first `T` word names: their motion in order, line
/// numbers counted on through the files (an error names the program too).
pub fn parse_all(texts: &[&str], opt: &ParseOptions) -> Result<Motion, GcodeError> {
    let mut all = Motion::default();
    let n = texts.len();
    for (k, text) in texts.iter().enumerate() {
        let mut p = parse(text, opt).map_err(|e| GcodeError {
            message: if n > 1 {
                format!("program {} of {n}: {}", k + 1, e.message)
            } else {
                e.message
            },
            line: e.line,
            column: e.column,
        })?;
        let offset = all.lines as u32;
        p.segments.iter_mut().for_each(|s| s.line += offset);
        all.segments.append(&mut p.segments);
        all.moves.append(&mut p.moves);
        all.end_line = p.end_line.map(|l| l + all.lines);
        all.lines += p.lines;
        all.motions += p.motions;
        all.arcs += p.arcs;
        all.inch |= p.inch;
        all.end_mm = p.end_mm;
        if all.segments.len() > opt.max_segments {
            return Err(at(
                all.lines,
                0,
                format!("more than {} linear segments", opt.max_segments),
            ));
        }
    }
    Ok(all)
}

/// What a controller reads but the simulation does not model, refused at its word.
fn not_simulated(p: &Parsed, lineno: usize) -> Result<(), GcodeError> {
    let refuse = |col: usize, m: &str| Err(at(lineno, col, m));
    if let Some((n, col)) = p.non_modal.filter(|_| !machine_retract(p)) {
        return refuse(
            col,
            match n {
                NonModal::GoStored(_) | NonModal::SetStored(_) => {
                    "home positions (G28/G30) are machine-specific and not simulated"
                }
                NonModal::Machine => "machine coordinates (G53) are supported only as `G53 G0 Z…` alone, a retract",
                NonModal::SetOffset | NonModal::ClearOffset => "coordinate offsets (G92) are not supported",
                NonModal::SetCoord => "coordinate system offsets (G10) are not supported",
            },
        );
    }
    if let Some((k, col)) = p.coord_select {
        if k != 0 {
            return refuse(col, "only the G54 work coordinate system is supported");
        }
    }
    if let Some((ToolLength::Dynamic, col)) = p.tool_length {
        return refuse(col, "only the tool table's length offset (G43 H) is supported");
    }
    if let Some((true, col)) = p.feed_mode {
        return refuse(col, "only units-per-minute feed (G94) is supported");
    }
    if let Some((MotionMode::Probe { .. }, col)) = p.motion {
        return refuse(col, "probing (G38.x) is not simulated");
    }
    Ok(())
}

/// One block's effect on the program's motion, in the order of RS274/NGC (F, S, T, M6, spindle, coolant,
/// dwell, modes, motion, stop). Returns true when the block ends the program.
fn block(
    step: &Step,
    lineno: usize,
    st: &mut State,
    prog: &mut Motion,
    opt: &ParseOptions,
) -> Result<bool, GcodeError> {
    let p = &step.parsed;
    not_simulated(p, lineno)?;
    tools(p, lineno, st, prog)?;
    if step.modal.units.mm() != 1.0 {
        prog.inch = true;
    }
    if let Some(s) = p.spindle_word {
        prog.moves.push(match s {
            Spindle::Off => Move::SpindleOff,
            _ => Move::SpindleOn(step.modal.spindle_rpm),
        });
    }
    if let Some(s) = step.dwell_s {
        prog.moves.push(Move::Dwell(s));
    }
    let Some(motion) = step.motion else {
        return Ok(p.program_end);
    };
    let col = p
        .motion
        .map(|m| m.1)
        .or_else(|| p.first_column(&['X', 'Y', 'Z']))
        .unwrap_or(0);
    for (k, l) in ['X', 'Y', 'Z'].into_iter().enumerate() {
        if let Some((_, c)) = p.get(l) {
            let v = motion.end()[k];
            if !v.is_finite() || v.abs() > MAX_COORDINATE_MM {
                let msg = format!("{l} reaches {v:e} mm, beyond any machine (|coordinate| ≤ {MAX_COORDINATE_MM:e} mm)");
                return Err(at(lineno, c, msg));
            }
        }
    }
    let before = prog.segments.len();
    if machine_retract(p) {
        // where machine Z is in work coordinates the simulation cannot know; a retract to it goes up on a
        // machine homed at the top of its travel: straight up to the start height at least
        let to = [step.from[0], step.from[1], step.from[2].max(opt.start_mm[2])];
        push_line(prog, st.tool, step.from, to, SegmentKind::Rapid, lineno, None);
        st.interp.pos = to;
        if prog.segments.len() > before {
            prog.motions += 1;
        }
        return Ok(p.program_end);
    }
    match motion {
        interp::Motion::Line { mode, to, feed_mm_min } => {
            let (kind, feed) = match mode {
                MotionMode::Rapid => (SegmentKind::Rapid, None),
                _ => (SegmentKind::Feed, Some(feed_mm_min)),
            };
            push_line(prog, st.tool, step.from, to, kind, lineno, feed);
        }
        interp::Motion::Arc { arc, turns } => {
            linearise(prog, st.tool, step.from, &arc, turns, lineno, opt).map_err(|m| at(lineno, col, m))?;
            prog.arcs += 1;
        }
        interp::Motion::Stored { .. } => unreachable!("refused by not_simulated"),
    }
    if prog.segments.len() > before {
        prog.motions += 1;
    }
    if prog.segments.len() > opt.max_segments {
        let msg = format!(
            "the program expands to more than {} linear segments (arcs are split within the arc tolerance)",
            opt.max_segments
        );
        return Err(at(lineno, col, msg));
    }
    Ok(p.program_end)
}

/// T, M6 (and `T… M0`), and G43 H against the tool in the spindle.
fn tools(p: &Parsed, lineno: usize, st: &mut State, prog: &Motion) -> Result<(), GcodeError> {
    if let Some((t, _)) = p.get('T') {
        st.selected = t as u32;
        // a tool named before the first move is the one mounted (GRBL has no M6)
        if prog.segments.is_empty() {
            st.tool = st.selected;
        }
    }
    // M6 changes to the selected tool; `T… M0` on one line is a manual change (GRBL's pause)
    if p.tool_change.is_some() || (p.program_pause && p.get('T').is_some()) {
        st.tool = st.selected;
    }
    if let (Some((ToolLength::Table, _)), Some((h, col))) = (p.tool_length, p.get('H')) {
        if h != st.tool as f64 {
            let msg = format!("G43 H{h} takes another tool's length than the spindle's (T{})", st.tool);
            return Err(at(lineno, col, msg));
        }
    }
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
        feed_mm_min: feed.unwrap_or(0.0),
    });
    prog.moves.push(match feed {
        None => Move::Rapid(to),
        Some(f) => Move::Feed(to, f),
    });
}

/// GRBL's `N_ARC_CORRECTION` (its `config.h`): an arc's radius vector is set exactly every this many turns.
const GRBL_N_ARC_CORRECTION: usize = 12;

/// Linearise an arc (centre and end from the interpreter) from `from` into chords of sagitta ≤ the tolerance,
/// with `turns` extra full turns. The radius varies linearly from start to end (LinuxCNC accepts a small
/// difference); the normal coordinate varies linearly with the angle (a helix).
///
/// For GRBL the chords are the controller's own (`mc_arc` in its `motion_control.c`): with `θ` the sweep,
/// `r` the start's radius and `t` the tolerance (its `$12`), `⌊½·θ·r / √(t(2r − t))⌋` segments (at least
/// one) of equal angle, the last ending at the end point; the vertices are the start's radius vector turned
/// by the controller's third-order rotation (`cos ≈ 1 − θ²/2`, `sin ≈ θ − θ³/6`), set exactly every 12th,
/// so they drift inside the circle as the controller's do (by `r·θ⁴/24` a turn: 2 µm on a 5 mm radius at
/// `$12` = 0.05 mm; at most 43 nm, on a 0.25 mm radius, at the default 0.002). The floor lets a chord's
/// sagitta pass `t` slightly, as the controller's does.
#[allow(clippy::too_many_arguments)]
fn linearise(
    prog: &mut Motion,
    tool: u32,
    from: P3,
    arc: &crate::gcode::moves::Arc,
    turns: u32,
    lineno: usize,
    opt: &ParseOptions,
) -> Result<(), String> {
    use std::f64::consts::TAU;
    // the plane's (first, second, normal) axes; below, x/y/z name them
    let (fa, sa, na) = arc.plane.axes();
    let (x0, y0, z0) = (from[fa], from[sa], from[na]);
    let (x1, y1, z1) = (arc.to[fa], arc.to[sa], arc.to[na]);
    let (cx, cy) = (arc.center[fa], arc.center[sa]);
    let world = |p: [f64; 3]| {
        let mut w = [0.0; 3];
        w[fa] = p[0];
        w[sa] = p[1];
        w[na] = p[2];
        w
    };
    let full = (x1 - x0).abs() < 1e-9 && (y1 - y0).abs() < 1e-9;
    let r0 = ((x0 - cx).powi(2) + (y0 - cy).powi(2)).sqrt();
    let r1 = ((x1 - cx).powi(2) + (y1 - cy).powi(2)).sqrt();
    let a0 = (y0 - cy).atan2(x0 - cx);
    let a1 = (y1 - cy).atan2(x1 - cx);
    let cw = arc.cw;
    let mut sweep = if cw { a0 - a1 } else { a1 - a0 };
    sweep = sweep.rem_euclid(TAU);
    if full || sweep < 1e-12 {
        sweep = TAU;
    }
    sweep += TAU * f64::from(turns);
    let rmax = r0.max(r1);
    let tol = opt.arc_tolerance_mm;
    let dmax = if tol >= rmax {
        std::f64::consts::FRAC_PI_2
    } else {
        (2.0 * (1.0 - tol / rmax).acos()).min(std::f64::consts::FRAC_PI_2)
    };
    let n = match opt.dialect {
        Dialect::Grbl if tol < 2.0 * r0 => (0.5 * sweep * r0 / (tol * (2.0 * r0 - tol)).sqrt()).floor().max(1.0),
        Dialect::Grbl => 1.0,
        Dialect::Linuxcnc => (sweep / dmax).ceil().max(1.0),
    };
    // estimated before a chord is allocated: the program's segments so far plus this arc's
    if prog.segments.len() as f64 + n > opt.max_segments as f64 {
        return Err(format!(
            "the arc needs {n} chords; with the program's {} segments so far that passes the limit of {} \
             segments (max_segments, about 100 bytes each)",
            prog.segments.len(),
            opt.max_segments
        ));
    }
    let n = n as usize;
    let dir = if cw { -1.0 } else { 1.0 };
    // GRBL's vertices: the start's radius vector turned by θ/n at a time with its third-order small-angle
    // rotation, set exactly every N_ARC_CORRECTION turns (mc_arc)
    let theta = dir * sweep / n as f64;
    let (cos_t, sin_t) = {
        let c = 2.0 - theta * theta;
        (0.5 * c, theta * (c + 4.0) / 6.0)
    };
    let (rx, ry) = (x0 - cx, y0 - cy);
    let (mut ra, mut rb, mut count) = (rx, ry, 0);
    let mut at = from;
    for k in 1..=n {
        let p = if k == n {
            arc.to
        } else {
            let f = k as f64 / n as f64;
            match opt.dialect {
                Dialect::Grbl => {
                    if count < GRBL_N_ARC_CORRECTION {
                        (ra, rb) = (ra * cos_t - rb * sin_t, ra * sin_t + rb * cos_t);
                        count += 1;
                    } else {
                        let (c, s) = ((k as f64 * theta).cos(), (k as f64 * theta).sin());
                        (ra, rb) = (rx * c - ry * s, rx * s + ry * c);
                        count = 0;
                    }
                    world([cx + ra, cy + rb, z0 + (z1 - z0) * f])
                }
                Dialect::Linuxcnc => {
                    let a = a0 + dir * sweep * f;
                    let rr = r0 + (r1 - r0) * f;
                    world([cx + rr * a.cos(), cy + rr * a.sin(), z0 + (z1 - z0) * f])
                }
            }
        };
        push_line(prog, tool, at, p, SegmentKind::Arc, lineno, Some(arc.feed_mm_min));
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

    /// `G53 G0 Z…` alone is a retract straight up to at least the start height; any other use of G53 is
    /// refused at its word.
    #[test]
    fn a_machine_coordinate_retract_goes_straight_up() {
        let opt = ParseOptions {
            start_mm: [0.0, 0.0, 5.0],
            ..Default::default()
        };
        let g = parse("G0 X1 Y2 Z-0.5\nG53 G0 Z0\nT2 M6\nG0 Z5\n", &opt).unwrap();
        assert_eq!(g.segments[1].from, [1.0, 2.0, -0.5]);
        assert_eq!(g.segments[1].to, [1.0, 2.0, 5.0]);
        assert_eq!(g.segments[1].kind, SegmentKind::Rapid);
        assert_eq!(g.segments.len(), 2, "already at the start height: no move");
        for bad in ["G53 G0 X1 Z0\n", "G53 G1 Z0 F100\n", "G0 G53 Y3\n"] {
            let e = parse(bad, &opt).unwrap_err();
            assert!(e.message.contains("G53"), "{bad}: {e}");
        }
    }

    /// Programs read one after another continue on one stock, each from the start with its own tool, and an
    /// error names the program.
    #[test]
    fn programs_in_sequence() {
        let opt = ParseOptions {
            start_mm: [0.0, 0.0, 5.0],
            ..Default::default()
        };
        let g = parse_all(
            &["T3\nG0 Z5\nG1 Z-1 F10\nM30\n", "T1\nG0 Z5\nX1\nG1 Z-2 F10\nM30\n"],
            &opt,
        )
        .unwrap();
        let tools: Vec<u32> = g.segments.iter().map(|s| s.tool).collect();
        assert_eq!(tools, [3, 1, 1]);
        assert_eq!(
            g.segments[1].from,
            [0.0, 0.0, 5.0],
            "the second program starts from the start"
        );
        assert_eq!(g.segments[2].line, 4 + 4, "lines count on through the files");
        let e = parse_all(&["G0 Z5\n", "G0 Z5\nG1 X1\n"], &opt).unwrap_err();
        assert!(e.message.starts_with("program 2 of 2") && e.line == 2, "{e}");
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
