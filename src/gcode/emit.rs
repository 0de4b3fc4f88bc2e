//! G-code emission: a modal-state writer that never emits a word the controller is already in.
//!
//! **Rounding budget.** Coordinates are written on the machine's resolution `q` (profile
//! `limits.resolution_mm`, default 0.1 µm) with the decimals it needs: X and Y rounded to the nearest step
//! (at most `q/2` off), Z rounded *up* (`⌈z/q⌉·q`, at most `q` above, never below), so rounding never takes
//! the tip below the cutter-location surface. Feeds and speeds carry 1 decimal.
//!
//! **Preamble.** Header comments, then the modal safety line `G17 G21 G40 G49 G54 G80 G90 G94` (XY plane,
//! mm, no cutter compensation, no tool-length offset, work system 1, no canned cycle, absolute, feed per
//! minute: every state the program relies on, set whatever the controller was left in; GRBL 1.1 accepts each
//! of these words), and for LinuxCNC `G64 P<tol>`. GRBL has no `G64`: its junction deviation `$11` plays that
//! role on the controller and is only noted in the header.
//!
//! **Safe first move.** While the tool's position is unknown (at the start, and after a tool change, where
//! the operator re-touches Z or `G43` changes the offset), a move that goes anywhere in X/Y is written as a
//! Z-only block first and the X/Y block second, so the tool rises before it travels. The retract is in work
//! coordinates (`G0 Z<safe>`), not `G53 G0 Z0`: machine Z0 is the top of travel only on a homed machine, and
//! many desktop GRBL routers run without homing; a job cannot run without its work Z0 set anyway.
//!
//! **Tool changes** ([`Move::ToolChange`]). LinuxCNC: `G53 G0 Z<profile>` (up in machine coordinates, the
//! only height that is safe whatever the work offset and the old tool's length), `T<n> M6`, then `G43 H<n>`
//! (the tool table written beside the program holds the length). GRBL 1.1 has no `M6` (it reads a `T` word
//! and ignores it): the first tool is named in a comment and a `T<n>` line (the operator mounts it and sets
//! Z0 before starting). A job with several tools is written as one GRBL program per tool
//! (`crate::stages::toolpath::files`), each starting with its first tool; only the joined text a job reads
//! back holds later tools, each as a `T<n> M0` manual change after a `(MSG,…)` comment, which `brdfmill
//! simulate` reads as that change.
//!
//! **Arcs** ([`Move::Arc`]). `G2`/`G3` with the plane word (`G18`, `G19`) written when it changes and
//! `G17` restored before `M30`; the end point and the centre come on the resolution already (the fitter
//! quantises with [`quantize`], the rounding written here, and checks the arc as it will be drawn), and the
//! centre is written as the in-plane offsets `I J K` from the position the previous block left.
//!
//! **End.** The move list ends with the retract, park, `M5` and `M9`; the writer closes with `M30`.
//!
//! **Comments.** Text reaches the program only through [`comment_text`]: control characters become spaces
//! (the profile loader refuses them in names and tool ids in the first place), `(` → `[`, `)` → `]`,
//! `;` → `,`, common non-ASCII letters are spelled out (α → alpha, µ → u, ° → deg, × → x) and any other
//! becomes `?`, so a header line is one comment of at most 78 characters on both controllers.

use super::moves::{Arc, Coolant, Move, Plane, P3};
use super::Dialect;
use std::fmt::Write;

/// Format a coordinate: `decimals` decimals, trailing zeros trimmed, no negative zero.
pub fn num(v: f64, decimals: usize) -> String {
    let s = format!("{:.*}", decimals, v);
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// Text made safe for a G-code comment (see the module documentation): ASCII, no delimiters, no control
/// characters.
pub fn comment_text(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '(' => out.push('['),
            ')' => out.push(']'),
            ';' => out.push(','),
            c if c.is_control() => out.push(' '),
            c if c.is_ascii() => out.push(c),
            'α' => out.push_str("alpha"),
            'β' => out.push_str("beta"),
            'σ' => out.push_str("sigma"),
            'θ' => out.push_str("theta"),
            'φ' => out.push_str("phi"),
            'λ' => out.push_str("lambda"),
            'µ' | 'μ' => out.push('u'),
            '°' => out.push_str("deg"),
            '×' => out.push('x'),
            '–' | '—' | '−' => out.push('-'),
            '²' => out.push('2'),
            '³' => out.push('3'),
            '≤' => out.push_str("<="),
            '≥' => out.push_str(">="),
            '·' => out.push('*'),
            _ => out.push('?'),
        }
    }
    out
}

/// The text as comment lines `(…)` of at most 78 characters (a controller's line buffer holds 80: GRBL's
/// would drop the rest), joined by newlines: a longer text goes on in the next lines, broken after a space
/// when one is within the line, so that no word is cut (a cut once read "82020 bloc").
fn comment_line(text: &str) -> String {
    let clean = comment_text(text);
    let mut rest = clean.trim();
    let mut lines = vec![];
    while rest.len() > 76 {
        // ASCII after `comment_text`: any byte index is a character boundary
        let cut = rest[..=76].rfind(' ').filter(|&k| k > 0).unwrap_or(76);
        lines.push(format!("({})", rest[..cut].trim_end()));
        rest = rest[cut..].trim_start();
    }
    lines.push(format!("({rest})"));
    lines.join("\n")
}

/// What the writer needs besides the moves.
#[derive(Clone, Copy, Debug)]
pub struct Setup<'a> {
    /// Controller dialect.
    pub dialect: Dialect,
    /// Header comment lines (made safe here).
    pub header: &'a [String],
    /// LinuxCNC's `G64 P`, mm.
    pub path_tolerance_mm: f64,
    /// The machine's resolution, mm: coordinates are written on multiples of it.
    pub resolution_mm: f64,
    /// LinuxCNC: the machine-coordinate Z a tool change retracts to first (`G53 G0 Z…`), mm.
    pub tool_change_machine_z_mm: f64,
}

/// The modal state of the controller as far as the emitter knows it.
#[derive(Default)]
struct Modal {
    motion: Option<u8>,
    xyz: [Option<String>; 3],
    feed: Option<String>,
    spindle: Option<String>,
    /// The tool's X/Y/Z are known (false at the start and after a tool change).
    known: bool,
    /// Tool changes written so far.
    tools: usize,
    /// Decimals and resolution of coordinates.
    decimals: usize,
    resolution_mm: f64,
    /// The arc plane, when not `G17`.
    plane: Option<Plane>,
}

/// The modal safety line written before any motion.
pub const SAFETY_LINE: &str = "G17 G21 G40 G49 G54 G80 G90 G94";

/// Write a program: header comments, the preamble for the dialect, then `moves`, then `M30`.
pub fn emit(setup: &Setup, moves: &[Move]) -> String {
    let mut out = String::with_capacity(moves.len() * 24 + 1024);
    for h in setup.header {
        let _ = writeln!(out, "{}", comment_line(h));
    }
    let _ = writeln!(out, "{SAFETY_LINE}");
    if setup.dialect == Dialect::Linuxcnc {
        let _ = writeln!(out, "G64 P{}", num(setup.path_tolerance_mm, 4));
    }
    let q = setup.resolution_mm;
    let mut m = Modal {
        decimals: decimals_for(q),
        resolution_mm: q,
        ..Default::default()
    };
    for mv in moves {
        match *mv {
            Move::Rapid(p) => motion(&mut out, &mut m, 0, p, None),
            Move::Feed(p, f) => motion(&mut out, &mut m, 1, p, Some(f)),
            Move::SpindleOn(rpm) => {
                let s = num(rpm, 1);
                if m.spindle.as_deref() != Some(&s) {
                    let _ = writeln!(out, "M3 S{s}");
                    m.spindle = Some(s);
                }
            }
            Move::SpindleOff => {
                let _ = writeln!(out, "M5");
                m.spindle = None;
            }
            Move::Dwell(s) => {
                let _ = writeln!(out, "G4 P{}", num(s, 3));
            }
            Move::Comment(c) => {
                let _ = writeln!(out, "{}", comment_line(c));
            }
            Move::Coolant(c) => {
                let _ = writeln!(
                    out,
                    "{}",
                    match c {
                        Coolant::Off => "M9",
                        Coolant::Mist => "M7",
                        Coolant::Flood => "M8",
                    }
                );
            }
            Move::ToolChange {
                number,
                diameter_mm,
                kind,
            } => tool_change(&mut out, &mut m, setup, number, diameter_mm, kind),
            Move::Arc(a) => arc(&mut out, &mut m, &a),
        }
    }
    if m.plane.is_some() {
        let _ = writeln!(out, "G17");
    }
    let _ = writeln!(out, "M30");
    out
}

/// A tool change per dialect (see the module documentation); the position is unknown afterwards.
fn tool_change(out: &mut String, m: &mut Modal, setup: &Setup, number: u32, diameter_mm: f64, kind: &str) {
    let d = num(diameter_mm, 3);
    match setup.dialect {
        Dialect::Linuxcnc => {
            let _ = writeln!(out, "{}", comment_line(&format!("tool T{number}: {kind} D{d} mm")));
            // up in machine coordinates first, wherever the work offset and the old tool's length put it
            let _ = writeln!(out, "G53 G0 Z{}", num(setup.tool_change_machine_z_mm, 3));
            let _ = writeln!(out, "T{number} M6");
            let _ = writeln!(out, "G43 H{number}");
        }
        Dialect::Grbl if m.tools == 0 => {
            let _ = writeln!(
                out,
                "{}",
                comment_line(&format!(
                    "tool T{number}: {kind} D{d} mm - mount it, set Z0 on the touch-off pad"
                ))
            );
            let _ = writeln!(out, "T{number}");
        }
        Dialect::Grbl => {
            let _ = writeln!(
                out,
                "{}",
                comment_line(&format!(
                    "MSG,Change to T{number} {kind} D{d}, re-touch Z0 on stock, cycle start"
                ))
            );
            // GRBL reads and ignores the T word; on the pause's line it tells the reader (and the simulator)
            // which tool the operator mounts
            let _ = writeln!(out, "T{number} M0");
        }
    }
    m.tools += 1;
    m.known = false;
    m.xyz = Default::default();
    m.motion = None;
    m.feed = None;
}

/// The file name the tool table is written under, beside its program.
pub const TOOL_TABLE_FILE: &str = "tool.tbl";

/// LinuxCNC's tool table for every tool of `machine` (`T<n> P<pocket> D<diameter> Z<length> ;comment`): the
/// lengths are 0, to be measured on the machine (`G43 H<n>` then applies what the operator set); the
/// comment names the profile's id, made safe for a comment. `rs274 -t` reads it.
pub fn tool_table(machine: &crate::cut::machine::Machine) -> String {
    let mut out = String::new();
    for t in &machine.tools {
        let _ = writeln!(
            out,
            "T{n} P{n} D{} Z0 ;{} {}",
            num(t.diameter_mm(), 4),
            comment_text(&t.id),
            t.shape.kind(),
            n = t.number
        );
    }
    out
}

/// The fewest decimals (at most 6) that write every multiple of the resolution `q` exactly: 3 for 0.001 mm,
/// 5 for one step of 800 steps/mm (0.00125 mm), 6 when none does (a grid of 1/3 µm is then written to 1 nm).
pub fn decimals_for(q: f64) -> usize {
    (0..=6)
        .find(|&d| {
            let v = q * 10f64.powi(d as i32);
            (v - v.round()).abs() < 1e-6 * v.max(1.0)
        })
        .unwrap_or(6)
}

/// A coordinate on the machine's resolution `q`: X/Y to the nearest step, Z up to the next (never below).
pub fn quantize(v: f64, axis: usize, q: f64) -> f64 {
    let steps = if axis == 2 {
        (v / q - 1e-6).ceil()
    } else {
        (v / q).round()
    };
    steps * q
}

/// A point on the resolution `q` as [`quantize`] writes each of its coordinates.
pub fn quantize_point(p: P3, q: f64) -> P3 {
    [0, 1, 2].map(|k| quantize(p[k], k, q))
}

/// [`quantize`], written.
fn coord(m: &Modal, axis: usize, v: f64) -> String {
    num(quantize(v, axis, m.resolution_mm), m.decimals)
}

/// A `G2`/`G3` block (see the module documentation). The position is known here: arcs only continue a
/// cut; were it not, the arc is written as feeds along its chords from the arc's start.
fn arc(out: &mut String, m: &mut Modal, a: &Arc) {
    let known: Option<Option<P3>> = m.known.then(|| {
        let v = |k: usize| m.xyz[k].as_deref().and_then(|s| s.parse().ok());
        match (v(0), v(1), v(2)) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            _ => None,
        }
    });
    let Some(Some(from)) = known else {
        debug_assert!(false, "an arc with no known start");
        return motion(out, m, 1, a.to, Some(a.feed_mm_min));
    };
    let mut line = String::new();
    if m.plane.unwrap_or(Plane::Xy) != a.plane {
        let _ = write!(line, "G{} ", a.plane.g());
        m.plane = (a.plane != Plane::Xy).then_some(a.plane);
    }
    let g = if a.cw { 2 } else { 3 };
    line.push_str(if g == 2 { "G2" } else { "G3" });
    m.motion = Some(g);
    for (k, axis) in ['X', 'Y', 'Z'].iter().enumerate() {
        let s = coord(m, k, a.to[k]);
        if m.xyz[k].as_deref() != Some(&s) {
            let _ = write!(line, " {axis}{s}");
            m.xyz[k] = Some(s);
        }
    }
    let (p, q, _) = a.plane.axes();
    let mut offs = [(p, a.center[p] - from[p]), (q, a.center[q] - from[q])];
    offs.sort_by_key(|o| o.0);
    for (k, d) in offs {
        let steps = (d / m.resolution_mm).round() * m.resolution_mm;
        let _ = write!(line, " {}{}", ['I', 'J', 'K'][k], num(steps, m.decimals));
    }
    let f = num(a.feed_mm_min, 1);
    if m.feed.as_deref() != Some(&f) {
        let _ = write!(line, " F{f}");
        m.feed = Some(f);
    }
    out.push_str(&line);
    out.push('\n');
}

fn motion(out: &mut String, m: &mut Modal, g: u8, p: P3, feed: Option<f64>) {
    if !m.known {
        // unknown position: rise (or descend) in Z alone first, then travel
        let z = coord(m, 2, p[2]);
        match feed {
            Some(f) => {
                let fs = num(f, 1);
                let _ = writeln!(out, "G1 Z{z} F{fs}");
                m.feed = Some(fs);
            }
            None => {
                let _ = writeln!(out, "G0 Z{z}");
            }
        }
        m.motion = Some(g);
        m.xyz[2] = Some(z);
        m.known = true;
    }
    let mut line = String::new();
    if m.motion != Some(g) {
        line.push_str(if g == 0 { "G0" } else { "G1" });
        m.motion = Some(g);
    }
    for (k, axis) in ['X', 'Y', 'Z'].iter().enumerate() {
        let s = coord(m, k, p[k]);
        if m.xyz[k].as_deref() != Some(&s) {
            if !line.is_empty() {
                line.push(' ');
            }
            line.push(*axis);
            line.push_str(&s);
            m.xyz[k] = Some(s);
        }
    }
    if let Some(f) = feed {
        let s = num(f, 1);
        if m.feed.as_deref() != Some(&s) {
            if !line.is_empty() {
                line.push(' ');
            }
            line.push('F');
            line.push_str(&s);
            m.feed = Some(s);
        }
    }
    // A move to where the tool already is (after rounding) writes nothing.
    if line.chars().any(|c| c == 'X' || c == 'Y' || c == 'Z') {
        out.push_str(&line);
        out.push('\n');
    } else if !line.is_empty() && !line.starts_with('G') {
        // only a feed change: keep it for the next move (feed is modal), nothing to write now
        m.feed = None;
    } else if line.starts_with('G') {
        // only a motion mode change without motion: let the next move carry it
        m.motion = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup(dialect: Dialect, header: &[String]) -> Setup<'_> {
        Setup {
            dialect,
            header,
            path_tolerance_mm: 0.001,
            resolution_mm: 1e-4,
            tool_change_machine_z_mm: 0.0,
        }
    }

    #[test]
    fn decimals_write_every_step_of_the_grid_exactly() {
        for (q, d) in [
            (0.001, 3),
            (1e-4, 4),
            (1.0 / 800.0, 5),
            (1.0 / 400.0, 4),
            (1.0 / 2000.0, 4),
            (1.0, 0),
        ] {
            assert_eq!(decimals_for(q), d, "{q}");
            // k steps written and read back are k steps
            for k in [1_i64, 7, 123, 9_999] {
                let x: f64 = num(k as f64 * q, d).parse().unwrap();
                assert_eq!((x / q).round() as i64, k);
                assert!((x - k as f64 * q).abs() < 1e-12);
            }
        }
        assert_eq!(decimals_for(1.0 / 3000.0), 6);
    }

    #[test]
    fn numbers_are_compact() {
        assert_eq!(num(1.5, 4), "1.5");
        assert_eq!(num(-0.00001, 4), "0");
        assert_eq!(num(12.0, 4), "12");
        assert_eq!(num(-0.12345, 4), "-0.1235");
    }

    #[test]
    fn no_redundant_words_and_z_first() {
        let moves = [
            Move::SpindleOn(10000.0),
            Move::Dwell(2.0),
            Move::Rapid([0.0, 0.0, 5.0]),
            Move::Rapid([1.0, 0.0, 5.0]),
            Move::Feed([1.0, 0.0, -0.1], 100.0),
            Move::Feed([2.0, 0.0, -0.1], 300.0),
            Move::Feed([3.0, 0.0, -0.1], 300.0),
            Move::Feed([3.0, 0.0, -0.1], 300.0),
            Move::Rapid([3.0, 0.0, 5.0]),
            Move::SpindleOff,
        ];
        let g = emit(&setup(Dialect::Grbl, &["job".into()]), &moves);
        let body: Vec<&str> = g.lines().collect();
        assert_eq!(
            body,
            [
                "(job)",
                SAFETY_LINE,
                "M3 S10000",
                "G4 P2",
                "G0 Z5",
                "X0 Y0",
                "X1",
                "G1 Z-0.1 F100",
                "X2 F300",
                "X3",
                "G0 Z5",
                "M5",
                "M30"
            ]
        );
        let l = emit(&setup(Dialect::Linuxcnc, &[]), &moves);
        assert!(l.contains("G64 P0.001"));
        assert!(!g.contains("G64"));
    }

    #[test]
    fn z_rounds_up_to_the_resolution_and_xy_to_nearest() {
        let s = Setup {
            resolution_mm: 0.001,
            ..setup(Dialect::Grbl, &[])
        };
        let g = emit(
            &s,
            &[
                Move::Rapid([0.0, 0.0, 1.0]),
                Move::Feed([1.23449, 0.0004, -0.10001], 100.0),
            ],
        );
        assert!(g.contains("G1 X1.234 Z-0.1 F100"), "Y stays 0 after rounding: {g}");
        let g = emit(&s, &[Move::Rapid([0.0, 0.0, 1.0]), Move::Feed([1.0, 0.0, 0.3], 100.0)]);
        assert!(g.contains("Z0.3 "), "no step up from float noise: {g}");
    }

    #[test]
    fn tool_changes_per_dialect() {
        let tc = Move::ToolChange {
            number: 3,
            diameter_mm: 3.175,
            kind: "flat",
        };
        let moves = [tc, Move::Rapid([1.0, 2.0, 5.0]), tc, Move::Rapid([1.0, 2.0, 5.0])];
        let l = emit(&setup(Dialect::Linuxcnc, &[]), &moves);
        assert_eq!(l.matches("G53 G0 Z0\nT3 M6\nG43 H3\nG0 Z5\nX1 Y2\n").count(), 2, "{l}");
        let g = emit(&setup(Dialect::Grbl, &[]), &moves);
        assert!(!g.contains("M6") && !g.contains("G43"), "{g}");
        assert_eq!(
            g.matches("T3 M0\n").count(),
            1,
            "the first tool is mounted before the start: {g}"
        );
        assert!(g.contains("(MSG,Change to T3 flat D3.175"), "{g}");
        assert_eq!(g.matches("G0 Z5\nX1 Y2\n").count(), 2, "{g}");
    }

    #[test]
    fn comments_are_safe_for_both_controllers() {
        let g = emit(
            &setup(
                Dialect::Grbl,
                &["a (nested) comment with µ α and a very long tail ".repeat(4)],
            ),
            &[],
        );
        let first = g.lines().next().unwrap();
        assert!(first.len() <= 78 && first.starts_with('(') && first.ends_with(')'));
        assert_eq!(first.matches('(').count(), 1);
        assert_eq!(first.matches(')').count(), 1);
        assert!(
            first.is_ascii() && first.contains("[nested]") && first.contains("u alpha"),
            "{first}"
        );
        assert_eq!(comment_text("router (GRBL 1.1)"), "router [GRBL 1.1]");
        // an injected newline stays inside one comment line
        let g = emit(&setup(Dialect::Grbl, &["evil\nG0 Z-40\nG1 X100 F5000\n;".into()]), &[]);
        assert_eq!(g.lines().next().unwrap(), "(evil G0 Z-40 G1 X100 F5000 ,)");
        assert!(!g.lines().any(|l| l.starts_with("G0 Z-40")));
    }

    /// A header line longer than a comment line goes on in the next, broken between words: every line
    /// within 78 characters, the words read back whole and in order.
    #[test]
    fn a_long_comment_wraps_between_words() {
        let text = "estimated run time 2:27:32 [2:27:45 at the planner's block rate], 82020 blocks of \
                    motion, and a word longer than any line: "
            .to_string()
            + &"x".repeat(100);
        let g = emit(&setup(Dialect::Grbl, std::slice::from_ref(&text)), &[]);
        let lines: Vec<&str> = g.lines().take_while(|l| l.starts_with('(')).collect();
        assert!(lines.len() >= 3, "{g}");
        assert!(lines.iter().all(|l| l.len() <= 78 && l.ends_with(')')), "{lines:?}");
        let words: Vec<&str> = lines
            .iter()
            .flat_map(|l| l.trim_start_matches('(').trim_end_matches(')').split_whitespace())
            .collect();
        let want: Vec<String> = comment_text(&text).split_whitespace().map(String::from).collect();
        // the over-long word alone is cut, at 76 characters
        assert_eq!(words[..words.len() - 2].join(" "), want[..want.len() - 1].join(" "));
        assert_eq!(words[words.len() - 2..].concat(), "x".repeat(100));
    }
}
