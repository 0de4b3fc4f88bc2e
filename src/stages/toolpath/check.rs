//! The machine check: before a byte of G-code is written, the move list is checked against the machine
//! profile and the tool. A violation names the limit, its value and the offending value.

use crate::base::Invalid;
use crate::cut::machine::{Machine, Tool};
use crate::gcode::moves::{bounds, chords, Move, P3};

/// Clearance above the stock top (z = 0) below which a rapid may not go, mm.
pub const RAPID_FLOOR_MM: f64 = 0.5;

/// Check `moves` (starting at `start`) against `machine` and `tool`; `Err` names the first violation. Rapids
/// across X/Y run at `program.safe_z_mm` or above.
pub fn check(moves: &[Move], start: P3, machine: &Machine, tool: &Tool) -> Result<(), Invalid> {
    check_in(moves, start, machine, tool, None)
}

/// [`check`], where rapids across X/Y may also run at the retract height ([`RAPID_FLOOR_MM`] above the
/// stock top) or above while both their ends lie over the work `[x0, y0, x1, y1]` (mm): over the stock,
/// whose top nothing stands above; clamps and the touch-off pad lie outside it.
pub fn check_in(
    moves: &[Move],
    start: P3,
    machine: &Machine,
    tool: &Tool,
    work: Option<[f64; 4]>,
) -> Result<(), Invalid> {
    // extents and feeds of arcs by their chords (both lie on them)
    let (lo, hi) = bounds(moves, start);
    let t = &machine.travel;
    for (k, (axis, travel)) in [("X", t.x_mm), ("Y", t.y_mm), ("Z", t.z_mm)].iter().enumerate() {
        let extent = hi[k] - lo[k];
        if extent > *travel + 1e-9 {
            return Err(Invalid(format!(
                "the program spans {extent:.3} mm in {axis} ({:.3} to {:.3}), more than the machine's travel.{}_mm = {travel} mm",
                lo[k],
                hi[k],
                axis.to_lowercase()
            )));
        }
    }
    let depth = -lo[2];
    if depth > tool.flute_length_mm + 1e-9 {
        return Err(Invalid(format!(
            "the program cuts {depth:.3} mm below the stock top, deeper than tool `{}`'s flute_length_mm = {} mm",
            tool.id, tool.flute_length_mm
        )));
    }
    let l = &machine.limits;
    let safe = machine.program.safe_z_mm;
    let mut at = start;
    // `n`: the move a chord came from, so a violation names the move list's own index
    for &(n, ref m) in &chords(moves, start) {
        match *m {
            Move::Feed(p, f) => {
                let dxy = ((p[0] - at[0]).powi(2) + (p[1] - at[1]).powi(2)).sqrt();
                let dz = (p[2] - at[2]).abs();
                // feeds are written to 0.1 mm/min: below half of that the block would read `F0` (GRBL:
                // error:22, or a stall)
                if f.is_nan() || f < 0.05 {
                    return Err(Invalid(format!(
                        "move {n}: feed {f} mm/min would be written as F0 (feeds are written to 0.1 mm/min)"
                    )));
                }
                if dxy > 1e-12 && f > l.max_feed_mm_min + 1e-9 {
                    return Err(Invalid(format!(
                        "move {n}: feed {f} mm/min exceeds limits.max_feed_mm_min = {} mm/min",
                        l.max_feed_mm_min
                    )));
                }
                // the Z component of the feed must respect the Z limit
                let len = (dxy * dxy + dz * dz).sqrt();
                if len > 1e-12 && f * dz / len > l.max_feed_z_mm_min + 1e-9 {
                    return Err(Invalid(format!(
                        "move {n}: Z feed {:.1} mm/min exceeds limits.max_feed_z_mm_min = {} mm/min",
                        f * dz / len,
                        l.max_feed_z_mm_min
                    )));
                }
                at = p;
            }
            Move::Rapid(p) => {
                let moves_xy = (p[0] - at[0]).abs() > 1e-12 || (p[1] - at[1]).abs() > 1e-12;
                let over_work =
                    |q: P3| work.is_some_and(|[x0, y0, x1, y1]| q[0] >= x0 && q[0] <= x1 && q[1] >= y0 && q[1] <= y1);
                let low = p[2].min(at[2]);
                let allowed = if over_work(p) && over_work(at) {
                    RAPID_FLOOR_MM
                } else {
                    safe
                };
                if moves_xy && low < allowed - 1e-9 {
                    return Err(Invalid(format!(
                        "move {n}: rapid across X/Y at z = {low:.3} mm, below {} over the stock",
                        if allowed == safe {
                            format!("program.safe_z_mm = {safe} mm")
                        } else {
                            format!("the retract height {RAPID_FLOOR_MM} mm")
                        }
                    )));
                }
                if p[2] < RAPID_FLOOR_MM - 1e-9 {
                    return Err(Invalid(format!(
                        "move {n}: rapid down to z = {:.3} mm, into the stock (rapids stop {RAPID_FLOOR_MM} mm above its top)",
                        p[2]
                    )));
                }
                at = p;
            }
            Move::SpindleOn(rpm) if rpm < machine.spindle.min_rpm || rpm > machine.spindle.max_rpm => {
                return Err(Invalid(format!(
                    "spindle speed {rpm} rev/min is outside spindle.min_rpm..max_rpm = {}..{} rev/min",
                    machine.spindle.min_rpm, machine.spindle.max_rpm
                )));
            }
            _ => {}
        }
    }
    Ok(())
}
