//! What a real machine does to a program: a profile's `[accuracy]` (backlash, spindle runout, the motor step
//! grid) and the path and envelope the tool really follows (docs/MACHINE.md derives each model).
//!
//! - **Step grid.** GRBL converts every target to whole motor steps, `n = lround(x · steps_per_mm)`
//!   (`planner.c`), so the tip stops at `n / steps_per_mm`. The work origin is taken on the grid (it is set by
//!   touching off at a machine position, which is a whole number of steps), so work coordinates are
//!   quantised the same way: no point moves more than half a step.
//! - **Backlash** `b` on an axis (the lost motion of a lead-screw nut): the carriage follows the commanded
//!   coordinate `c` through a dead band, `|c − a| ≤ b/2`, the classical play operator. While an axis keeps its
//!   direction the carriage lags by `b/2` behind the command; on a reversal it stands still for `b` of
//!   commanded travel. A straight segment therefore splits into at most four straight pieces (each axis either
//!   stands still or follows the command), so the sweep stays exact.
//! - **Runout** (total indicated runout `TIR` of the tool in its collet, what a dial indicator reads on the
//!   shank) offsets the cutting edge by `e = TIR/2` from the spindle axis. Spinning, an offset ball of radius
//!   `r` sweeps a torus: a bull-nose of diameter `2r + TIR` and corner radius `r`; a flat or bull-nose mill
//!   grows by `TIR` in diameter. A groove is `TIR` wider.
//!
//! Not modelled, said in the report: deflection (it needs the cutting force, which depends on the chip
//! thickness at each point of the edge) and wear.

use crate::cut::sweep::Segment;
use crate::cut::tool::Shape;
use crate::gcode::moves::P3;
use serde::{Deserialize, Serialize};

/// `[accuracy]` of a machine profile: each error of the machine, with its unit in the key.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Accuracy {
    /// Lost motion on a reversal of X, Y, Z, µm (a dial indicator against the spindle while jogging
    /// back and forth). Default 0.
    #[serde(default)]
    pub backlash_um: [f64; 3],
    /// Total indicated runout of the tool in the spindle with its collet, µm. Default 0.
    #[serde(default)]
    pub runout_um: f64,
    /// Motor steps per mm of X, Y, Z (GRBL's `$100`–`$102`, LinuxCNC's `SCALE`). Absent: positions are not
    /// quantised beyond `limits.resolution_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps_per_mm: Option<[f64; 3]>,
}

/// The largest backlash and runout a profile may declare, µm: more is a worn-out machine or a typo in mm.
pub const MAX_ERROR_UM: f64 = 500.0;

impl Default for Accuracy {
    fn default() -> Self {
        Self::PERFECT
    }
}

impl Accuracy {
    /// A machine without errors (what the simulation assumed before profiles declared them).
    pub const PERFECT: Accuracy = Accuracy {
        backlash_um: [0.0; 3],
        runout_um: 0.0,
        steps_per_mm: None,
    };

    /// Check every key; the error is `(key, expected, value)`.
    pub fn check(&self) -> Result<(), (String, String, String)> {
        let err = |k: &str, e: &str, v: f64| Err((format!("accuracy.{k}"), e.to_string(), v.to_string()));
        for (k, b) in self.backlash_um.iter().enumerate() {
            if !(b.is_finite() && (0.0..=MAX_ERROR_UM).contains(b)) {
                return err(&format!("backlash_um[{k}]"), "in [0, 500] µm", *b);
            }
        }
        if !(self.runout_um.is_finite() && (0.0..=MAX_ERROR_UM).contains(&self.runout_um)) {
            return err("runout_um", "in [0, 500] µm", self.runout_um);
        }
        if let Some(s) = self.steps_per_mm {
            for (k, v) in s.iter().enumerate() {
                if !(v.is_finite() && (1.0..=100_000.0).contains(v)) {
                    return err(&format!("steps_per_mm[{k}]"), "in [1, 100000] steps/mm", *v);
                }
            }
        }
        Ok(())
    }

    /// No error declared.
    pub fn is_perfect(&self) -> bool {
        self.backlash_um == [0.0; 3] && self.runout_um == 0.0 && self.steps_per_mm.is_none()
    }

    /// An axis (0 X, 1 Y) has backlash.
    pub fn has_backlash_xy(&self) -> bool {
        self.backlash_um[0] > 0.0 || self.backlash_um[1] > 0.0
    }

    /// In words: `backlash 25/25/0 µm, runout 15 µm TIR, 800/800/800 steps/mm`.
    pub fn describe(&self) -> String {
        let [bx, by, bz] = self.backlash_um;
        let mut s = format!("backlash {bx}/{by}/{bz} µm, runout {} µm TIR", self.runout_um);
        if let Some([x, y, z]) = self.steps_per_mm {
            s.push_str(&format!(", {x}/{y}/{z} steps/mm"));
        }
        s
    }

    /// The cuts that show what each declared error does, named `backlash`, `runout`, `steps`, with
    /// `alone`: backlash and the step grid on an otherwise perfect machine (`alone = true`); runout as the
    /// declared machine without it (`alone = false`), since a cut with runout sweeps a bull-nose envelope,
    /// ~10× the cost of a ball's closed form, and the declared cut already has it.
    pub fn each(&self) -> Vec<(&'static str, Accuracy, bool)> {
        let p = Accuracy::PERFECT;
        let mut v = vec![];
        if self.backlash_um != [0.0; 3] {
            v.push((
                "backlash",
                Accuracy {
                    backlash_um: self.backlash_um,
                    ..p
                },
                true,
            ));
        }
        if self.steps_per_mm.is_some() {
            v.push((
                "steps",
                Accuracy {
                    steps_per_mm: self.steps_per_mm,
                    ..p
                },
                true,
            ));
        }
        if self.runout_um > 0.0 {
            v.push((
                "runout",
                Accuracy {
                    runout_um: 0.0,
                    ..*self
                },
                false,
            ));
        }
        v
    }

    /// One motor step of each axis, mm (None: not declared).
    pub fn step_mm(&self) -> Option<[f64; 3]> {
        self.steps_per_mm.map(|s| s.map(|v| 1.0 / v))
    }

    /// The common step of all three axes, mm, when they are equal (a program can then be written on the
    /// step grid with one resolution).
    pub fn common_step_mm(&self) -> Option<f64> {
        let s = self.steps_per_mm?;
        (s[0] == s[1] && s[1] == s[2]).then(|| 1.0 / s[0])
    }

    /// A point as the motors reach it: each coordinate rounded to the nearest step (half away from zero,
    /// like C's `lround`).
    pub fn quantise(&self, p: P3) -> P3 {
        match self.steps_per_mm {
            None => p,
            Some(s) => [0, 1, 2].map(|k| (p[k] * s[k]).round() / s[k]),
        }
    }

    /// The envelope a spinning bit of `shape` cuts with this runout (see the module documentation).
    pub fn envelope(&self, shape: Shape) -> Shape {
        let tir_mm = self.runout_um * 1e-3;
        if tir_mm == 0.0 {
            return shape;
        }
        match shape.normalized() {
            Shape::Ball { diameter_mm } => Shape::Bull {
                diameter_mm: diameter_mm + tir_mm,
                corner_radius_mm: diameter_mm / 2.0,
            },
            Shape::Flat { diameter_mm } => Shape::Flat {
                diameter_mm: diameter_mm + tir_mm,
            },
            Shape::Bull {
                diameter_mm,
                corner_radius_mm,
            } => Shape::Bull {
                diameter_mm: diameter_mm + tir_mm,
                corner_radius_mm,
            },
        }
    }

    /// The path the tip really follows for the commanded `segments` starting from `start_mm`: endpoints on
    /// the step grid, then the play operator of each axis. The carriage starts centred in its dead band (the
    /// slack before the program is unknown), so the first move of each axis takes up half of it.
    pub fn actual_path(&self, segments: &[Segment], start_mm: P3) -> Vec<Segment> {
        let half = self.backlash_um.map(|b| b * 0.5e-3);
        let mut carriage = self.quantise(start_mm);
        let mut out = Vec::with_capacity(segments.len() + segments.len() / 8);
        for s in segments {
            let (c0, c1) = (self.quantise(s.from), self.quantise(s.to));
            // where along the segment each reversing axis has taken up its slack
            let mut breaks: Vec<f64> = Vec::with_capacity(5);
            breaks.push(0.0);
            for k in 0..3 {
                let d = c1[k] - c0[k];
                if d == 0.0 || half[k] == 0.0 {
                    continue;
                }
                // the command engages the carriage once it reaches carriage ± b/2
                let engage = carriage[k] + d.signum() * half[k];
                let t = (engage - c0[k]) / d;
                if t > 0.0 && t < 1.0 {
                    breaks.push(t);
                }
            }
            breaks.push(1.0);
            breaks.sort_by(f64::total_cmp);
            let mut from = carriage;
            for w in breaks.windows(2) {
                let t = w[1];
                let c = [0, 1, 2].map(|k| c0[k] + t * (c1[k] - c0[k]));
                let to = [0, 1, 2].map(|k| carriage[k].clamp(c[k] - half[k], c[k] + half[k]));
                if w[1] > w[0] && to != from {
                    out.push(Segment { from, to, ..*s });
                }
                carriage = to;
                from = to;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cut::sweep::SegmentKind;

    fn seg(from: P3, to: P3) -> Segment {
        Segment {
            from,
            to,
            kind: SegmentKind::Feed,
            line: 1,
            tool: 0,
            feed_mm_min: 100.0,
        }
    }

    fn backlash(b_um: [f64; 3]) -> Accuracy {
        Accuracy {
            backlash_um: b_um,
            ..Accuracy::PERFECT
        }
    }

    #[test]
    fn quantisation_moves_no_point_more_than_half_a_step() {
        let a = Accuracy {
            steps_per_mm: Some([800.0, 800.0, 400.0]),
            ..Accuracy::PERFECT
        };
        let mut x = 0.123_456_7_f64;
        for _ in 0..10_000 {
            x = (x * 9301.0 + 49297.0) % 233_280.0 / 1000.0 - 100.0;
            let p = [x, -x * 0.7, x * 0.01];
            let q = a.quantise(p);
            for k in 0..3 {
                let step = 1.0 / a.steps_per_mm.unwrap()[k];
                assert!((q[k] - p[k]).abs() <= step / 2.0 + 1e-12, "{p:?} → {q:?}");
                // on the grid
                let n = q[k] / step;
                assert!((n - n.round()).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn a_reversal_stands_still_for_the_backlash_then_lags_by_half_of_it() {
        let a = backlash([20.0, 0.0, 0.0]);
        let b = 0.020;
        // +x from 0 to 1 (takes up b/2), back to 0, forward again
        let path = a.actual_path(
            &[
                seg([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
                seg([1.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
                seg([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
            ],
            [0.0; 3],
        );
        let xs: Vec<(f64, f64)> = path.iter().map(|s| (s.from[0], s.to[0])).collect();
        // first move: stands still for b/2 (nothing emitted), then reaches 1 − b/2
        assert!(
            (xs[0].0 - 0.0).abs() < 1e-12 && (xs[0].1 - (1.0 - b / 2.0)).abs() < 1e-12,
            "{xs:?}"
        );
        // reversal: stands still for b, then follows to 0 + b/2
        assert!((xs[1].1 - b / 2.0).abs() < 1e-12, "{xs:?}");
        assert!((xs[2].1 - (1.0 - b / 2.0)).abs() < 1e-12, "{xs:?}");
        // the pieces are continuous
        for w in path.windows(2) {
            assert_eq!(w[0].to, w[1].from);
        }
    }

    #[test]
    fn a_diagonal_splits_where_the_reversing_axis_engages() {
        let a = backlash([0.0, 40.0, 0.0]);
        // y has been moving down (carriage at c + b/2), now a diagonal up and right
        let last = a.actual_path(
            &[
                seg([0.0, 1.0, 0.0], [0.0, 0.0, 0.0]),
                seg([0.0, 0.0, 0.0], [1.0, 1.0, 0.0]),
            ],
            [0.0, 1.0, 0.0],
        );
        // second commanded segment: x moves from the start while y stands still for b = 0.04 of its travel
        let diag: Vec<_> = last.iter().filter(|s| s.to[0] > 0.0).collect();
        assert_eq!(diag.len(), 2, "{last:?}");
        assert!((diag[0].to[0] - 0.04).abs() < 1e-12 && (diag[0].to[1] - diag[0].from[1]).abs() < 1e-12);
        assert!((diag[1].to[1] - (1.0 - 0.02)).abs() < 1e-12, "{diag:?}");
    }

    #[test]
    fn the_runout_envelope_is_wider_by_the_runout() {
        let a = Accuracy {
            runout_um: 30.0,
            ..Accuracy::PERFECT
        };
        let e = a.envelope(Shape::Ball { diameter_mm: 0.5 });
        assert!((e.diameter_mm() - 0.53).abs() < 1e-12);
        assert!((e.corner_radius_mm() - 0.25).abs() < 1e-12);
        // the tip and the sphere's profile are unchanged beyond the flat of radius e
        assert_eq!(e.profile(0.0), 0.0);
        assert!((e.profile(0.015 + 0.1) - Shape::Ball { diameter_mm: 0.5 }.profile(0.1)).abs() < 1e-12);
        assert_eq!(
            Accuracy::PERFECT.envelope(Shape::Ball { diameter_mm: 0.5 }),
            Shape::Ball { diameter_mm: 0.5 }
        );
    }

    #[test]
    fn bad_keys_are_named() {
        let mut a = Accuracy::PERFECT;
        a.backlash_um[1] = -1.0;
        assert_eq!(a.check().unwrap_err().0, "accuracy.backlash_um[1]");
        let a = Accuracy {
            steps_per_mm: Some([800.0, 0.0, 800.0]),
            ..Accuracy::PERFECT
        };
        assert_eq!(a.check().unwrap_err().0, "accuracy.steps_per_mm[1]");
    }
}
