//! Which lines ran, from where motion stopped. After a stop (or, on resume, after a disconnect) the
//! streamer knows the lines that *may* have run — execution is a prefix of them — and the position the
//! controller reports; [`locate`] finds the prefix whose path ends at, or passes through, that position.
//! It refuses, rather than guesses, when the position lies on the path more than once.

use crate::stream::program::{MotionMode, Program};

/// Which of the candidate lines ran, from where motion stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// Candidates that executed completely, in order.
    pub executed: Vec<usize>,
    /// The candidate cut mid-way and the stop point (work coordinates, mm).
    pub partial: Option<(usize, [f64; 3])>,
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

/// Given the lines that may have run (`candidates`, in order; execution is a prefix of them), the line
/// reported executing when motion stopped (`ln`, if the controller reports `Ln`) and the stop position
/// `p` (work mm), find which candidates ran completely and which one was cut, and where.
///
/// Every point along the candidates' path that lies within `tol` of `p` is a consistent explanation; if
/// two of them are separated by a moving line, the answer is ambiguous and an error is returned rather
/// than a guess. Otherwise the furthest explanation is taken (the lines between are non-moving ones).
pub fn locate(
    program: &Program,
    candidates: &[usize],
    ln: Option<u32>,
    p: [f64; 3],
    tol: f64,
) -> Result<Located, String> {
    match ln.map(|l| l as usize).filter(|l| candidates.contains(l)) {
        Some(ln) => locate_named(program, candidates, ln, p, tol),
        None => locate_by_position(program, candidates, p, tol),
    }
}

/// The controller names the line: every candidate before it ran; where on it motion stopped decides
/// between complete, not started and cut (which needs no known start point).
fn locate_named(program: &Program, cands: &[usize], ln: usize, p: [f64; 3], tol: f64) -> Result<Located, String> {
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
        });
    }
    if start.is_some_and(|a| dist(a, p) <= tol) {
        return Ok(Located {
            executed,
            partial: None,
        });
    }
    if let (Some(a), Some(b)) = (start, end) {
        let (t, q) = project(a, b, p);
        if dist(q, p) > tol || !(0.0..=1.0).contains(&t) {
            return Err(format!(
                "the controller reports line {ln} executing but the stop position ({:.3}, {:.3}, {:.3}) is not on it",
                p[0], p[1], p[2]
            ));
        }
    }
    Ok(Located {
        executed,
        partial: Some((ln, p)),
    })
}

/// No line named: every point of the candidates' path within `tol` of `p` is an explanation; take the
/// furthest, unless a moving line separates two of them.
fn locate_by_position(program: &Program, cands: &[usize], p: [f64; 3], tol: f64) -> Result<Located, String> {
    let consistent = explanations(program, cands, p, tol)?;
    if cands.is_empty() {
        return Ok(Located {
            executed: Vec::new(),
            partial: None,
        });
    }
    if consistent.is_empty() {
        // Nothing ran yet: the position is where the first candidate starts.
        return Err(format!(
            "the stop position ({:.3}, {:.3}, {:.3}) lies on none of lines {:?}",
            p[0],
            p[1],
            p[2],
            &cands[..cands.len().min(8)]
        ));
    }
    let cmp = |x: &(usize, f64), y: &(usize, f64)| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1));
    let lo = *consistent.iter().min_by(|x, y| cmp(x, y)).expect("non-empty");
    let hi = *consistent.iter().max_by(|x, y| cmp(x, y)).expect("non-empty");
    let spans_motion = (lo.0..hi.0).any(|i| program.line(cands[i]).is_some_and(|l| l.moves));
    if spans_motion {
        return Err(format!(
            "the stop position ({:.3}, {:.3}, {:.3}) is on the path more than once (lines {} and {})",
            p[0],
            p[1],
            p[2],
            cands[lo.0],
            cands[(hi.0).min(cands.len() - 1)]
        ));
    }
    let executed = cands[..hi.0.min(cands.len())].to_vec();
    let partial = (hi.1 > 0.0 && hi.0 < cands.len()).then(|| (cands[hi.0], p));
    Ok(Located { executed, partial })
}

/// Every progress `(index, fraction)` consistent with the position `p`: `cands[..index]` complete and
/// `cands[index]` done up to `fraction`.
fn explanations(program: &Program, cands: &[usize], p: [f64; 3], tol: f64) -> Result<Vec<(usize, f64)>, String> {
    let mut consistent: Vec<(usize, f64)> = Vec::new();
    for (i, &n) in cands.iter().enumerate() {
        let l = program
            .line(n)
            .ok_or_else(|| format!("line {n} is not in the program"))?;
        if !l.moves {
            if let Some(s) = known(l.start_mm) {
                if dist(s, p) <= tol {
                    consistent.push((i, 0.0));
                    consistent.push((i + 1, 0.0));
                }
            } else if i == 0 && cands.len() == 1 {
                consistent.push((1, 0.0));
            }
            continue;
        }
        let Some(b) = known(l.end_mm) else {
            return Err(format!("line {n}'s end position is unknown to the program model"));
        };
        if dist(b, p) <= tol {
            consistent.push((i + 1, 0.0));
        }
        // From an unknown start only the end can be recognised.
        let Some(a) = known(l.start_mm) else { continue };
        if dist(a, p) <= tol {
            consistent.push((i, 0.0));
        }
        if matches!(l.motion, Some(MotionMode::Rapid | MotionMode::Linear)) {
            let (t, q) = project(a, b, p);
            if t > 0.0 && t < 1.0 && dist(q, p) <= tol && dist(a, p) > tol && dist(b, p) > tol {
                consistent.push((i, t));
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

    #[test]
    fn locates_a_stop_inside_a_line() {
        let p = prog(SQUARE);
        let c: Vec<usize> = (4..=9).collect();
        let loc = locate(&p, &c, None, [10.0, 4.0, -1.0], 0.005).unwrap();
        assert_eq!(loc.executed, vec![4, 5]);
        assert_eq!(loc.partial, Some((6, [10.0, 4.0, -1.0])));
        // With Ln the line is named by the controller.
        let loc = locate(&p, &c, Some(6), [10.0, 4.0, -1.0], 0.005).unwrap();
        assert_eq!(loc.executed, vec![4, 5]);
        // At a corner: the line ending there is complete, the next not started.
        let loc = locate(&p, &c, None, [10.0, 10.0, -1.0], 0.005).unwrap();
        assert_eq!((loc.executed, loc.partial), (vec![4, 5, 6], None));
    }

    #[test]
    fn refuses_ambiguous_and_unknown_positions() {
        let p = prog(SQUARE);
        let c: Vec<usize> = (4..=9).collect();
        // (0,0,-1) is both where line 5 starts and where line 8 ends: a full square apart.
        assert!(locate(&p, &c, None, [0.0, 0.0, -1.0], 0.005)
            .unwrap_err()
            .contains("more than once"));
        assert!(locate(&p, &c, None, [3.0, 3.0, 3.0], 0.005)
            .unwrap_err()
            .contains("none of"));
    }
}
