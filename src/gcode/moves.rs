//! The machine-independent form of a program: a list of moves in work coordinates (mm, z = 0 the stock top),
//! which the checker, the time estimator and the G-code emitter all read.

use serde::{Deserialize, Serialize};

/// A point in work coordinates, mm.
pub type P3 = [f64; 3];

/// One step of a program.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Move {
    /// `G0` to a point.
    Rapid(P3),
    /// `G1` to a point at a feed, mm/min.
    Feed(P3, f64),
    /// Spindle on clockwise (`M3`) at rev/min.
    SpindleOn(f64),
    /// Spindle off (`M5`).
    SpindleOff,
    /// `G4` dwell, s.
    Dwell(f64),
    /// A comment line.
    Comment(&'static str),
    /// A tool change to the tool numbered `number` (a `kind` bit of `diameter_mm`), written per dialect by
    /// `crate::gcode::emit`: LinuxCNC `T M6 G43 H`, GRBL an `M0` pause with the instruction. The move list
    /// around it already holds the `M5` and the retract before it, and the spindle start after it.
    ToolChange {
        /// Tool number in the machine's table (the `T`/`H` word).
        number: u32,
        /// Diameter, mm (for the operator's message).
        diameter_mm: f64,
        /// `ball`, `flat` or `bull` (for the operator's message).
        kind: &'static str,
    },
    /// Coolant on (`M7` mist, `M8` flood) or off (`M9`).
    Coolant(Coolant),
}

/// Coolant commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Coolant {
    /// `M9`.
    Off,
    /// `M7`.
    Mist,
    /// `M8`.
    Flood,
}

/// Path length split by kind, mm.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Lengths {
    /// Cutting (G1) length.
    pub feed_mm: f64,
    /// Rapid (G0) length.
    pub rapid_mm: f64,
}

/// Lengths of a move list starting from `start`.
pub fn lengths(moves: &[Move], start: P3) -> Lengths {
    let mut at = start;
    let mut l = Lengths::default();
    for m in moves {
        match *m {
            Move::Rapid(p) => {
                l.rapid_mm += dist(at, p);
                at = p;
            }
            Move::Feed(p, _) => {
                l.feed_mm += dist(at, p);
                at = p;
            }
            _ => {}
        }
    }
    l
}

/// Euclidean distance.
#[inline]
pub fn dist(a: P3, b: P3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Bounding box `(min, max)` of all motion end points (and `start`).
pub fn bounds(moves: &[Move], start: P3) -> (P3, P3) {
    let mut lo = start;
    let mut hi = start;
    for m in moves {
        if let Move::Rapid(p) | Move::Feed(p, _) = m {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    (lo, hi)
}
