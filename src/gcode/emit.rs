//! G-code emission: a modal-state writer that never emits a word the controller is already in.
//!
//! **Rounding budget.** Coordinates are written with 4 decimals (0.1 µm), feeds and speeds with 1. The
//! rounding moves a point by at most 0.05 µm per axis, an order below the default simplification
//! tolerance (0.5 µm) and the 1 µm scallop target; the two add to at most 0.6 µm between the CL surface and
//! the written path.
//!
//! **Dialects.** GRBL 1.1 has no `G64`: its junction deviation `$11` plays that role and is set on the
//! controller, so the program only notes it in the header. LinuxCNC gets `G64 P<tolerance>`. Both get
//! `G21 G90 G17 G94`, `M3 S…` then a `G4` dwell before the first cut, a retract to safe z, `M5` and `M2`.

use super::moves::{Move, P3};
use super::Dialect;
use std::fmt::Write;

/// Format a coordinate: 4 decimals, trailing zeros trimmed, no negative zero.
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

/// The modal state of the controller as far as the emitter knows it.
#[derive(Default)]
struct Modal {
    motion: Option<u8>,
    xyz: [Option<String>; 3],
    feed: Option<String>,
    spindle: Option<String>,
}

/// Write a program: `header` comment lines, the preamble for `dialect`, then `moves`.
pub fn emit(dialect: Dialect, header: &[String], path_tolerance_mm: f64, moves: &[Move]) -> String {
    let mut out = String::with_capacity(moves.len() * 24 + 1024);
    for h in header {
        // GRBL and LinuxCNC both end a comment at ')' and GRBL limits lines to 80 characters.
        let clean: String = h
            .chars()
            .map(|c| if c == '(' || c == ')' { '[' } else { c })
            .filter(|c| c.is_ascii())
            .collect();
        let mut line = format!("({clean})");
        line.truncate(78);
        if !line.ends_with(')') {
            line.pop();
            line.push(')');
        }
        let _ = writeln!(out, "{line}");
    }
    let _ = writeln!(out, "G21 G90 G17 G94");
    if dialect == Dialect::Linuxcnc {
        let _ = writeln!(out, "G64 P{}", num(path_tolerance_mm, 4));
    }
    let mut m = Modal::default();
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
                let _ = writeln!(out, "({c})");
            }
        }
    }
    let _ = writeln!(out, "M2");
    out
}

fn motion(out: &mut String, m: &mut Modal, g: u8, p: P3, feed: Option<f64>) {
    let mut line = String::new();
    if m.motion != Some(g) {
        line.push_str(if g == 0 { "G0" } else { "G1" });
        m.motion = Some(g);
    }
    for (k, axis) in ['X', 'Y', 'Z'].iter().enumerate() {
        let s = num(p[k], 4);
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

    #[test]
    fn numbers_are_compact() {
        assert_eq!(num(1.5, 4), "1.5");
        assert_eq!(num(-0.00001, 4), "0");
        assert_eq!(num(12.0, 4), "12");
        assert_eq!(num(-0.12345, 4), "-0.1235");
    }

    #[test]
    fn no_redundant_words() {
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
        let g = emit(Dialect::Grbl, &["job".into()], 0.01, &moves);
        let body: Vec<&str> = g.lines().collect();
        assert_eq!(
            body,
            [
                "(job)",
                "G21 G90 G17 G94",
                "M3 S10000",
                "G4 P2",
                "G0 X0 Y0 Z5",
                "X1",
                "G1 Z-0.1 F100",
                "X2 F300",
                "X3",
                "G0 Z5",
                "M5",
                "M2"
            ]
        );
        let l = emit(Dialect::Linuxcnc, &[], 0.001, &moves);
        assert!(l.contains("G64 P0.001"));
        assert!(!g.contains("G64"));
    }

    #[test]
    fn comments_are_safe_for_both_controllers() {
        let g = emit(
            Dialect::Grbl,
            &["a (nested) comment with µ and a very long tail ".repeat(4)],
            0.01,
            &[],
        );
        let first = g.lines().next().unwrap();
        assert!(first.len() <= 80 && first.starts_with('(') && first.ends_with(')'));
        assert_eq!(first.matches('(').count(), 1);
        assert!(first.is_ascii());
    }
}
