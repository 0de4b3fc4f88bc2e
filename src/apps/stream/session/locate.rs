//! Which lines ran, from where motion stopped. After a stop (or, on resume, after a disconnect) the
//! streamer knows the lines that *may* have run — execution is a prefix of them — and the position the
//! controller reports; [`locate`] finds the prefix whose path ends at, or passes through, that position.
//! It refuses, rather than guesses, when the position lies on the path more than once.

use crate::apps::stream::program::{words, Line, MotionMode, Program};
use crate::base::Invalid;
use crate::gcode::interp::{Interpreter, Motion};
use crate::gcode::moves::Arc;
use crate::gcode::Dialect;

/// Which of the candidate lines ran, from where motion stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// Candidates that executed completely, in order.
    pub executed: Vec<usize>,
    /// The candidate cut mid-way and the stop point (work coordinates, mm).
    pub partial: Option<(usize, [f64; 3])>,
    /// Why the answer is only the earliest consistent one (the position lies on the path more than once):
    /// the resume then starts at the earliest line that may not have run.
    pub ambiguous: Option<String>,
}

/// What is known about where motion stopped: the evidence [`locate`] decides from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evidence {
    /// The line the controller reported executing when motion stopped (`Ln`), if the build reports it.
    pub ln: Option<u32>,
    /// The stop position, work mm.
    pub position: [f64; 3],
    /// Where the tool was before the first candidate, when the program model cannot know it (the
    /// position reported at the start of a fresh run, before anything moved).
    pub origin: Option<[f64; 3]>,
    /// GRBL's arc tolerance `$12`, mm: how far inside an arc the chords it runs may pass (a stop inside an
    /// arc lies on a chord).
    pub arc_tolerance_mm: f64,
    /// The controller is idle with nothing left to run (after a disconnect it finished what it had):
    /// motion ended at the end of a block, so a stop inside a line is no explanation.
    pub at_rest: bool,
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A position whose three axes are all known.
pub(super) fn known(p: [Option<f64>; 3]) -> Option<[f64; 3]> {
    Some([p[0]?, p[1]?, p[2]?])
}

/// Where `p` projects on the line through `a` and `b`: the parameter `t` (0 at `a`, 1 at `b`) and the
/// projected point.
fn project(a: [f64; 3], b: [f64; 3], p: [f64; 3]) -> (f64, [f64; 3]) {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    let t = ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1] + (p[2] - a[2]) * d[2]) / len2;
    let q = [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]];
    (t, q)
}

/// The arc line `l` draws from `start` (work mm): the line read again by the one interpreter as GRBL 1.1h
/// reads it, from `start` in the modal state before it — its centre from the `R` word
/// ([`Arc::center_from_radius`]) or from the `I J K` offsets. `None` for anything but an arc, and for a
/// block GRBL would refuse (`R` with offsets, a chord longer than the diameter).
pub(super) fn arc_of(l: &Line, start: [f64; 3]) -> Option<Arc> {
    if !l.motion?.is_arc() {
        return None;
    }
    let ws = words(&l.block).ok()?;
    let mut interp = Interpreter::new(Dialect::Grbl, l.before, start);
    match interp.block(&ws).ok()?.motion? {
        Motion::Arc { arc, .. } => Some(arc),
        _ => None,
    }
}

/// GRBL's default `$12`, mm.
pub const DEFAULT_ARC_TOLERANCE_MM: f64 = 0.002;

/// How far inside `arc` (from `from`) the chords GRBL's `mc_arc` runs it with pass at most, mm: `n` chords
/// ([`Arc::grbl_chords`], one when that is 0) of angle `θ/n`, each missing the arc by `r(1 − cos(θ/2n))` —
/// at least `tol` once `n` ≥ 1 (the floor makes the chords longer), up to 4× it.
pub fn chord_sagitta_mm(arc: &Arc, from: [f64; 3], tol: f64) -> f64 {
    let theta = arc.sweep(from).1.abs();
    let n = arc.grbl_chords(from, tol).max(1) as f64;
    arc.radius(from) * (1.0 - (theta / (2.0 * n)).min(std::f64::consts::PI).cos())
}

/// Where `p` lies along moving line `l` from `a` to `b`: the fraction of the way, the point of the path
/// there (for a straight line the projection, unclamped; for an arc its angle, `None` outside it), and how
/// far from that point the controller may be on it (for an arc the chords' sagitta, `arc_tol` being `$12`).
fn along(l: &Line, a: [f64; 3], b: [f64; 3], p: [f64; 3], arc_tol: f64) -> Option<(f64, [f64; 3], f64)> {
    match l.motion {
        Some(MotionMode::Rapid | MotionMode::Linear) => {
            let (t, q) = project(a, b, p);
            Some((t, q, 0.0))
        }
        Some(MotionMode::ArcCw | MotionMode::ArcCcw) => {
            let arc = arc_of(l, a)?;
            let (t, q) = arc.project(a, p)?;
            Some((t, q, chord_sagitta_mm(&arc, a, arc_tol)))
        }
        _ => None,
    }
}

/// Given the lines that may have run (`candidates`, in order; execution is a prefix of them) and the
/// evidence of where motion stopped, find which candidates ran completely and which one was cut, and where.
///
/// With `Ln` the controller names the line. Otherwise every point along the candidates' path within `tol`
/// of the position is a consistent explanation; the furthest is taken when only non-moving lines separate
/// them. When a moving line separates two explanations the position alone cannot tell them apart: the
/// earliest is taken — the resume then starts at the earliest line that may not have run — and
/// [`Located::ambiguous`] says why. `Err` when the position lies on none of the candidates' path.
pub fn locate(program: &Program, candidates: &[usize], ev: &Evidence, tol: f64) -> Result<Located, Invalid> {
    match ev.ln.map(|l| l as usize).filter(|l| candidates.contains(l)) {
        Some(ln) => locate_named(program, candidates, ln, ev, tol),
        None => locate_by_position(program, candidates, ev, tol),
    }
}

/// The controller names the line: every candidate before it ran; where on it motion stopped decides
/// between complete, not started and cut (which needs no known start point).
fn locate_named(program: &Program, cands: &[usize], ln: usize, ev: &Evidence, tol: f64) -> Result<Located, Invalid> {
    let p = ev.position;
    let mut executed: Vec<usize> = cands.iter().copied().filter(|&n| n < ln).collect();
    let l = program
        .line(ln)
        .ok_or_else(|| format!("line {ln} is not in the program"))?;
    let (start, end) = (known(l.start_mm), known(l.end_mm));
    if !l.moves || end.is_some_and(|b| dist(b, p) <= tol) {
        executed.push(ln);
        return Ok(Located {
            executed,
            partial: None,
            ambiguous: None,
        });
    }
    if start.is_some_and(|a| dist(a, p) <= tol) {
        return Ok(Located {
            executed,
            partial: None,
            ambiguous: None,
        });
    }
    let mut at = p;
    if let (Some(a), Some(b)) = (start, end) {
        match along(l, a, b, p, ev.arc_tolerance_mm) {
            Some((t, q, slack)) if dist(q, p) <= tol + slack && (0.0..=1.0).contains(&t) => {
                // inside an arc the resume continues from the arc's own point (the stop lies on a chord)
                if l.motion != Some(MotionMode::Rapid) && l.motion != Some(MotionMode::Linear) {
                    at = q;
                }
            }
            _ => {
                return Err(Invalid(format!(
                "the controller reports line {ln} executing but the stop position ({:.3}, {:.3}, {:.3}) is not on it",
                p[0], p[1], p[2]
            )))
            }
        }
    }
    Ok(Located {
        executed,
        partial: Some((ln, at)),
        ambiguous: None,
    })
}

/// No line named: every point of the candidates' path within `tol` of the position is an explanation;
/// take the furthest, or the earliest (saying why) when a moving line separates two of them.
fn locate_by_position(program: &Program, cands: &[usize], ev: &Evidence, tol: f64) -> Result<Located, Invalid> {
    let p = ev.position;
    let consistent = explanations(program, cands, ev, tol)?;
    if cands.is_empty() {
        return Ok(Located {
            executed: Vec::new(),
            partial: None,
            ambiguous: None,
        });
    }
    if consistent.is_empty() {
        return Err(Invalid(format!(
            "the stop position ({:.3}, {:.3}, {:.3}) lies on none of lines {:?}",
            p[0],
            p[1],
            p[2],
            &cands[..cands.len().min(8)]
        )));
    }
    let cmp = |x: &(usize, f64, [f64; 3]), y: &(usize, f64, [f64; 3])| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1));
    let lo = *consistent.iter().min_by(|x, y| cmp(x, y)).expect("non-empty");
    let hi = *consistent.iter().max_by(|x, y| cmp(x, y)).expect("non-empty");
    let spans_motion = (lo.0..hi.0).any(|i| program.line(cands[i]).is_some_and(|l| l.moves));
    let (take, ambiguous) = if spans_motion {
        let why = format!(
            "the stop position ({:.3}, {:.3}, {:.3}) is on the path more than once (lines {} and {}): taking \
             the earlier, so the resume starts at the earliest line that may not have run",
            p[0],
            p[1],
            p[2],
            cands[lo.0.min(cands.len() - 1)],
            cands[hi.0.min(cands.len() - 1)]
        );
        (lo, Some(why))
    } else {
        (hi, None)
    };
    let executed = cands[..take.0.min(cands.len())].to_vec();
    let partial = (take.1 > 0.0 && take.0 < cands.len()).then(|| (cands[take.0], take.2));
    Ok(Located {
        executed,
        partial,
        ambiguous,
    })
}

/// Every progress `(index, fraction, point)` consistent with the evidence: `cands[..index]` complete and
/// `cands[index]` done up to `fraction`, where the resume would continue from `point` (the stop position,
/// or inside an arc the arc's point at its angle). A candidate whose start the program model does not know
/// starts at the evidence's origin as long as no moving candidate precedes it.
fn explanations(
    program: &Program,
    cands: &[usize],
    ev: &Evidence,
    tol: f64,
) -> Result<Vec<(usize, f64, [f64; 3])>, String> {
    let p = ev.position;
    let mut consistent: Vec<(usize, f64, [f64; 3])> = Vec::new();
    let mut moved = false;
    for (i, &n) in cands.iter().enumerate() {
        let l = program
            .line(n)
            .ok_or_else(|| format!("line {n} is not in the program"))?;
        let start = known(l.start_mm).or(if moved { None } else { ev.origin });
        if !l.moves {
            if let Some(s) = start {
                if dist(s, p) <= tol {
                    consistent.push((i, 0.0, p));
                    consistent.push((i + 1, 0.0, p));
                }
            } else if i == 0 && cands.len() == 1 {
                consistent.push((1, 0.0, p));
            }
            continue;
        }
        moved = true;
        let Some(b) = known(l.end_mm) else {
            return Err(format!("line {n}'s end position is unknown to the program model"));
        };
        if dist(b, p) <= tol {
            consistent.push((i + 1, 0.0, p));
        }
        // From an unknown start only the end can be recognised.
        let Some(a) = start else { continue };
        if dist(a, p) <= tol {
            consistent.push((i, 0.0, p));
        }
        if ev.at_rest || dist(a, p) <= tol || dist(b, p) <= tol {
            continue;
        }
        if let Some((t, q, slack)) = along(l, a, b, p, ev.arc_tolerance_mm) {
            if t > 0.0 && t < 1.0 && dist(q, p) <= tol + slack {
                let arc = !matches!(l.motion, Some(MotionMode::Rapid | MotionMode::Linear));
                consistent.push((i, t, if arc { q } else { p }));
            }
        }
    }
    Ok(consistent)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn prog(text: &str) -> Program {
        Program::parse(Path::new("t.nc"), text, 1, true).unwrap()
    }

    const SQUARE: &str = "G21G90\nG0X0Y0Z1\nM3S1000\nG1Z-1F100\nG1X10\nG1Y10\nG1X0\nG1Y0\nG0Z1\n";

    fn ev(ln: Option<u32>, position: [f64; 3]) -> Evidence {
        Evidence {
            ln,
            position,
            origin: None,
            arc_tolerance_mm: DEFAULT_ARC_TOLERANCE_MM,
            at_rest: false,
        }
    }

    #[test]
    fn locates_a_stop_inside_a_line() {
        let p = prog(SQUARE);
        let c: Vec<usize> = (4..=9).collect();
        let loc = locate(&p, &c, &ev(None, [10.0, 4.0, -1.0]), 0.005).unwrap();
        assert_eq!(loc.executed, vec![4, 5]);
        assert_eq!(loc.partial, Some((6, [10.0, 4.0, -1.0])));
        // With Ln the line is named by the controller.
        let loc = locate(&p, &c, &ev(Some(6), [10.0, 4.0, -1.0]), 0.005).unwrap();
        assert_eq!(loc.executed, vec![4, 5]);
        // At a corner: the line ending there is complete, the next not started.
        let loc = locate(&p, &c, &ev(None, [10.0, 10.0, -1.0]), 0.005).unwrap();
        assert_eq!((loc.executed, loc.partial), (vec![4, 5, 6], None));
    }

    #[test]
    fn an_ambiguous_position_takes_the_earliest_and_says_why() {
        let p = prog(SQUARE);
        let c: Vec<usize> = (4..=9).collect();
        // (0,0,-1) is both where line 5 starts and where line 8 ends: a full square apart.
        let loc = locate(&p, &c, &ev(None, [0.0, 0.0, -1.0]), 0.005).unwrap();
        assert_eq!((loc.executed, loc.partial), (vec![4], None));
        assert!(loc.ambiguous.unwrap().contains("more than once"));
        assert!(locate(&p, &c, &ev(None, [3.0, 3.0, 3.0]), 0.005)
            .unwrap_err()
            .contains("none of"));
    }

    /// A stop inside an arc is located by the arc's angle, by position and by `Ln` alike, and the resume
    /// point is the arc's own point there (the controller stopped on a chord, inside the arc by its sagitta).
    #[test]
    fn locates_a_stop_inside_an_arc() {
        // a half circle of radius 5 about (5, 0) from (0, 0) to (10, 0), clockwise: over the top
        let p = prog("G21G90\nG0X0Y0Z0\nG2X10Y0I5J0F300\nG1X12\n");
        let c = vec![3, 4];
        let on_chord = [5.0 - 5.0 * 0.8_f64.cos() * 0.9996, 5.0 * 0.8_f64.sin() * 0.9996, 0.0];
        for ln in [None, Some(3)] {
            let loc = locate(&p, &c, &ev(ln, on_chord), 0.005).unwrap();
            assert!(loc.executed.is_empty(), "{loc:?}");
            let (n, at) = loc.partial.unwrap();
            assert_eq!(n, 3);
            let r = (at[0] - 5.0).hypot(at[1]);
            assert!((r - 5.0).abs() < 1e-9, "on the arc: {at:?}");
            assert!(dist(at, on_chord) < 0.005);
        }
        // the mirror point below the axis is not on this arc (it turns over the top)
        let below = [on_chord[0], -on_chord[1], 0.0];
        assert!(locate(&p, &c, &ev(None, below), 0.005).is_err());
    }

    /// A stop inside an arc in radius form is located on the circle GRBL draws: the half turn `G2 X10 R5`
    /// from (0,0) over the top (centre (5,0)), and back the long way, `G3 X0 R-5.5`: counter-clockwise
    /// from (10,0) to (0,0) about (5, √5.25), over the top again; `R` with offsets is a block GRBL refuses,
    /// so no arc.
    #[test]
    fn a_stop_inside_an_arc_in_radius_form_is_located_on_its_circle() {
        let p = prog("G21G90\nG0X0Y0Z0\nG2X10Y0R5F300\nG3X0Y0R-5.5\nG2X10Y0R5I5\n");
        let top = [5.0 - 5.0 * 0.6, 5.0 * 0.8, 0.0];
        let loc = locate(&p, &[3, 4], &ev(None, top), 0.005).unwrap();
        let (n, at) = loc.partial.unwrap();
        assert!(n == 3 && dist(at, top) < 1e-12, "{loc:?}");
        let arc = arc_of(p.line(3).unwrap(), [0.0; 3]).unwrap();
        assert!(dist(arc.center, [5.0, 0.0, 0.0]) < 1e-12, "{:?}", arc.center);
        let cy = (5.5f64 * 5.5 - 25.0).sqrt();
        let long = arc_of(p.line(4).unwrap(), [10.0, 0.0, 0.0]).unwrap();
        assert!(dist(long.center, [5.0, cy, 0.0]) < 1e-12, "{:?}", long.center);
        // its highest point, halfway along its 229°
        let high = [5.0, cy + 5.5, 0.0];
        let loc = locate(&p, &[4], &ev(None, high), 0.005).unwrap();
        assert_eq!(loc.partial.map(|x| x.0), Some(4), "{loc:?}");
        assert!(arc_of(p.line(5).unwrap(), [0.0; 3]).is_none());
    }

    /// A short arc GRBL runs as one chord (θ = 0.11 rad at r = 5: ⌊0.275 / √(0.002·9.998)⌋ = 1) passes
    /// r(1 − cos(θ/2)) = 7.6 µm inside the arc at its middle, beyond the 5 µm position tolerance: the
    /// chord's sagitta is allowed for, so a stop there is located; as far off a straight line it is not.
    #[test]
    fn a_stop_on_a_long_chord_of_a_short_arc_is_located() {
        let (c, s) = (5.0 * 0.11_f64.cos(), 5.0 * 0.11_f64.sin());
        let p = prog(&format!("G21G90\nG0X5Y0Z0\nG3X{c:.6}Y{s:.6}I-5J0F300\nG1X0\n"));
        let arc = arc_of(p.line(3).unwrap(), [5.0, 0.0, 0.0]).unwrap();
        let sag = chord_sagitta_mm(&arc, [5.0, 0.0, 0.0], DEFAULT_ARC_TOLERANCE_MM);
        assert!((sag - 5.0 * (1.0 - 0.055_f64.cos())).abs() < 1e-6, "{sag}");
        let mid = [(5.0 + c) / 2.0, s / 2.0, 0.0];
        let loc = locate(&p, &[3, 4], &ev(None, mid), 0.005).unwrap();
        assert_eq!(loc.partial.map(|x| x.0), Some(3), "{loc:?}");
        // the same distance beside line 4 (from the arc's end to X0) is no stop on it
        let beside = [2.0, s + sag, 0.0];
        assert!(locate(&p, &[4], &ev(None, beside), 0.005).is_err());
    }

    /// Issue 14's CI flake (seed 60): the link dropped before line 2 arrived, so the tool never left the
    /// origin (0,0,0) — which also lies on line 4's plunge from Z2 to Z-0.5. With the origin known and the
    /// controller at rest, nothing but line 1 can have run.
    #[test]
    fn the_origin_and_rest_rule_out_a_plunge_through_the_start_point() {
        let p = prog("G21G90\nG0X0Y0Z2\nM3S1000\nG1Z-0.5F100\nG1X10\n");
        let c: Vec<usize> = (1..=5).collect();
        let mut e = ev(None, [0.0, 0.0, 0.0]);
        // Without the evidence, the plunge explains the position: the old, wrong answer.
        let old = locate(&p, &c, &e, 0.005).unwrap();
        assert_eq!(old.executed, vec![1, 2, 3]);
        e.origin = Some([0.0, 0.0, 0.0]);
        e.at_rest = true;
        let loc = locate(&p, &c, &e, 0.005).unwrap();
        assert_eq!((loc.executed, loc.partial, loc.ambiguous), (vec![1], None, None));
    }
}
