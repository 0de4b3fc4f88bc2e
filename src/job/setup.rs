//! The setup sheet ("To mill this"): what a machinist needs before the first cut — the stock with its
//! margins, the work zero and the touch-off pad, the tools in order with their stick-out and cutting data
//! (and where those data do not suit the tool), the programs in order with their times, and how to check and
//! run them on *this* machine's controller — then the program's numbers.
//!
//! **Stock.** The cut spans the program's tool-tip extents widened by the largest tool's radius. Around that
//! the sheet asks for [`EDGE_MM`] of stock on every side (so the cut never meets the stock's edge), a
//! [`PAD_MM`] square touch-off pad on the −X side that no program goes near (uncut stock at the stock's top,
//! where every tool's Z zero is taken: after the first tool the top of the work is cut away), and
//! [`CLAMP_MM`] on every side for clamps; a vise gripping below the top or tape needs no clamp margin.

use super::Ready;
use crate::cut::feeds::ToolData;
use crate::cut::machine::Tool;
use crate::gcode::Dialect;
use crate::stages::simulate::{Deviation, SimStats};
use crate::stages::toolpath::{self, Summary};

/// Stock beyond the cut on every side, mm.
pub const EDGE_MM: f64 = 1.0;
/// Side of the touch-off pad, mm.
pub const PAD_MM: f64 = 10.0;
/// Stock for clamps on every side, mm.
pub const CLAMP_MM: f64 = 10.0;
/// Stick-out beyond the cut's depth, mm: the collet and the shank clear the stock top by this much.
pub const STICKOUT_CLEARANCE_MM: f64 = 2.0;
/// Stock left under the deepest cut, mm.
pub const FLOOR_MM: f64 = 2.0;

/// The stock rectangle `[x0, y0, x1, y1]` in work mm and the pad's centre, for a cut whose tip extents are
/// `lo`, `hi` with tools of largest radius `r`.
pub fn stock_rect(lo: [f64; 3], hi: [f64; 3], r: f64) -> ([f64; 4], [f64; 2]) {
    let (cx0, cy0, cx1, cy1) = (lo[0] - r, lo[1] - r, hi[0] + r, hi[1] + r);
    let pad = [cx0 - EDGE_MM - PAD_MM / 2.0, 0.5 * (cy0 + cy1)];
    (
        [
            cx0 - EDGE_MM - PAD_MM - CLAMP_MM,
            cy0 - EDGE_MM - CLAMP_MM,
            cx1 + EDGE_MM + CLAMP_MM,
            cy1 + EDGE_MM + CLAMP_MM,
        ],
        pad,
    )
}

/// One tool's line — shape, stick-out, cutting data and where they came from — and what is wrong with its
/// data on this machine, each with what would work.
fn tool_line(tool: &Tool, c: &ToolData, depth_mm: f64) -> (String, Vec<String>) {
    let a = &c.assessment;
    let line = format!(
        "T{} {}: {} {:.3} mm, {} flutes; stick-out at least {:.1} mm (the cut's {:.3} mm depth and {STICKOUT_CLEARANCE_MM} mm \
         for the collet over the stock); {} mm/min, plunge {} mm/min, {} rpm, {} mm depth of cut ({}): {:.1} µm/tooth \
         (this bit takes {:.1}–{:.1}), {:.1} m/min",
        tool.number,
        tool.id,
        tool.shape.kind(),
        tool.diameter_mm(),
        tool.flutes,
        depth_mm + STICKOUT_CLEARANCE_MM,
        depth_mm,
        c.data.feed_mm_min,
        c.data.plunge_mm_min,
        c.data.spindle_rpm,
        c.data.max_depth_of_cut_mm,
        if c.from_table {
            "the tool × stock table's for this machine"
        } else {
            "the profile's"
        },
        a.chip_um,
        a.chip_range_um[0],
        a.chip_range_um[1],
        a.surface_m_min,
    );
    (line, a.findings.iter().map(|f| f.text()).collect())
}

/// The sheet's rows (the report's "To mill this" table).
pub(super) fn sheet(
    ready: &Ready,
    s: &Summary,
    relief_mm: f64,
    dev: &Deviation,
    sim: &SimStats,
) -> Vec<(String, String)> {
    let t = &ready.job.toolpath;
    // the tools in the order the programs use them, with their data as the programs use them
    let tools: Vec<(&Tool, &ToolData)> = s
        .cutting
        .iter()
        .filter_map(|c| Some((ready.machine.tool(&c.id).ok()?, c)))
        .collect();
    let r = tools.iter().map(|(t, _)| t.radius_mm()).fold(0.0, f64::max);
    let [lo, hi] = s.extents_mm;
    let ([x0, y0, x1, y1], pad) = stock_rect(lo, hi, r);
    let depth = -lo[2];
    let dialect = ready.machine.dialect;
    let programs = s
        .files
        .iter()
        .map(|f| format!("{} ({}, {})", f.file, f.tools.join(", "), toolpath::hms(f.estimated_s)))
        .collect::<Vec<_>>()
        .join(", then ");
    let mut rows = vec![
        (
            "programs, in order".to_string(),
            if dialect == Dialect::Linuxcnc {
                format!("{programs}, with its tool table tool.tbl (summary in program.json)")
            } else {
                format!("{programs} (summary in program.json)")
            },
        ),
        (
            "estimated time".into(),
            format!(
                "{} in all: {} in rapids{}",
                toolpath::hms(s.estimated_s),
                toolpath::hms(s.rapid_s),
                s.air_feed_s
                    .map(|a| format!(", {} feeding through air (simulated)", toolpath::hms(a)))
                    .unwrap_or_default()
            ),
        ),
        (
            "stock".into(),
            format!(
                "{}, at least {:.1} × {:.1} mm and {:.1} mm thick: the cut spans X {:.2} to {:.2}, Y {:.2} to {:.2} mm \
                 (the area {} × {} mm and the tool's radius), {EDGE_MM} mm beyond it on every side, a {PAD_MM} mm \
                 touch-off pad on the −X side and {CLAMP_MM} mm on every side for clamps (not needed with a vise \
                 gripping below the top, or tape)",
                t.stock.name(),
                x1 - x0,
                y1 - y0,
                depth + FLOOR_MM,
                lo[0] - r,
                hi[0] + r,
                lo[1] - r,
                hi[1] + r,
                t.area_mm[0],
                t.area_mm[1],
            ),
        ),
        (
            "work zero".into(),
            format!(
                "X0 Y0 at the area's lower-left corner, {:.1} mm from the stock's left edge and {:.1} mm from its \
                 front edge; Z0 on the stock top, touched off on the pad at X {:.1} Y {:.1} (no program goes there, \
                 so it stays uncut for every tool)",
                -x0, -y0, pad[0], pad[1]
            ),
        ),
    ];
    // a row per tool in the order the programs use them, and what to check about its cutting data
    for (k, (tool, c)) in tools.iter().enumerate() {
        let (line, findings) = tool_line(tool, c, depth);
        let key = if tools.len() > 1 {
            format!("tool {} of {}", k + 1, tools.len())
        } else {
            "tool".into()
        };
        rows.push((key, line));
        if !findings.is_empty() {
            rows.push((format!("T{} cutting data", tool.number), findings.join("; ")));
        }
    }
    if let Some(row) = arc_advice(ready, sim) {
        rows.push(row);
    }
    rows.extend([
        ("check, then run".into(), run_advice(dialect, s)),
        (
            "relief".into(),
            format!(
                "{relief_mm:.3} mm deep (the design); the program cuts to {:.3} mm",
                s.depth_mm
            ),
        ),
    ]);
    rows.extend(numbers(s, dev));
    rows
}

/// What a GRBL controller does to the programs' arcs, and which `$12` the verdict assumed (docs/MACHINE.md §3.1):
/// GRBL cuts an arc as `⌊½θr/√(t(2r−t))⌋` chords at its arc tolerance `t` (`$12`), so every chord sags by at
/// least `t`; the simulation cut the arcs so. Read from the simulated cut's own record (`sim`: the programs'
/// `G2`/`G3` blocks as it read them, and the chord tolerance it cut them with). None when the controller
/// follows arcs exactly, or there are none.
fn arc_advice(ready: &Ready, sim: &SimStats) -> Option<(String, String)> {
    let m = &ready.machine;
    let profile_mm = m.limits.arc_chord_mm(m.dialect)?;
    let arcs = sim.arcs;
    if arcs == 0 {
        return None;
    }
    let simulated_mm = sim.arc_tolerance_um * 1e-3;
    let assumed = if (simulated_mm - profile_mm).abs() <= 1e-12 {
        format!("`$12` = {profile_mm} mm, the profile's")
    } else {
        format!("chords of {simulated_mm} mm (`simulate.arc_tolerance_um`; the profile's `$12` is {profile_mm} mm)")
    };
    Some((
        "arcs".into(),
        format!(
            "{arcs} arcs (G2/G3): GRBL cuts each as chords that stand at least its `$12` inside the arc (below \
             it over a crest), and the simulated cut the verdict measured assumed {assumed}. Set `$12` to {profile_mm} mm on the \
             controller before running (`$12={profile_mm}`; `$$` lists it): coarser, it cuts the arcs further from the design \
             than the verdict saw, and `brdfmill stream` refuses to start (the programs' header says what they were simulated \
             with; `--accept-coarser-arcs` overrides)"
        ),
    ))
}

/// How to check and run the programs on the dialect's controller.
fn run_advice(dialect: Dialect, s: &Summary) -> String {
    match dialect {
        Dialect::Grbl => {
            let each = s
                .files
                .iter()
                .map(|f| format!("brdfmill stream {} --port PORT --check", f.file))
                .collect::<Vec<_>>()
                .join(", then ");
            format!(
                "{each}: GRBL's check mode ($C) runs every line first without moving, and each program streams only \
                 if none errs (docs/MILLING.md){}",
                if s.files.len() > 1 {
                    ". GRBL cannot change tools: between programs mount the next tool, keep X and Y, and zero Z on the \
                     pad (jog down to it, then `G10 L20 P1 Z0` or your sender's zero Z)"
                } else {
                    ""
                }
            )
        }
        Dialect::Linuxcnc => "load tool.tbl as the machine's tool table ([EMCIO] TOOL_TABLE) and set each tool's \
                             length on the pad (Touch Off, or G10 L10); check the program with `rs274 -t tool.tbl -g \
                             program.nc` or LinuxCNC's preview; it changes tools itself (G53 G0 Z up, M6, G43)"
            .into(),
    }
}

/// The program's numbers after the setup.
fn numbers(s: &Summary, dev: &Deviation) -> Vec<(String, String)> {
    vec![
        ("lines".into(), s.lines.to_string()),
        (
            "stepover".into(),
            format!("{:.1} µm (scallop {:.3} µm)", 1000.0 * s.stepover_mm, s.scallop_um),
        ),
        (
            "passes".into(),
            format!(
                "{} finishing, {} roughing layers",
                s.finishing_passes, s.roughing_layers
            ),
        ),
        (
            "path".into(),
            format!(
                "{:.1} mm cutting{}, {:.1} mm rapid",
                s.feed_length_mm,
                s.air_feed_mm
                    .map(|a| format!(" ({a:.1} mm of it through air)"))
                    .unwrap_or_default(),
                s.rapid_length_mm
            ),
        ),
        (
            "gouge (simulated)".into(),
            format!(
                "{:.2} µm at most below the design in the simulated cut (the figure under Deviation from the design)",
                dev.max_under_um.max(0.0)
            ),
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stock holds the cut widened by the tool's radius, the edge on every side, the pad on −X and the
    /// clamps on every side; the pad lies on stock outside the cut.
    #[test]
    fn the_stock_holds_the_cut_the_pad_and_the_clamps() {
        let (lo, hi, r) = ([0.0, 0.0, -0.8], [13.2, 13.2, 10.0], 0.25);
        let ([x0, y0, x1, y1], pad) = stock_rect(lo, hi, r);
        assert!((x1 - x0 - (13.2 + 2.0 * r + 2.0 * EDGE_MM + PAD_MM + 2.0 * CLAMP_MM)).abs() < 1e-12);
        assert!((y1 - y0 - (13.2 + 2.0 * r + 2.0 * EDGE_MM + 2.0 * CLAMP_MM)).abs() < 1e-12);
        // the pad: beyond the cut's edge, inside the clamp margin
        assert!(pad[0] + PAD_MM / 2.0 <= -r - EDGE_MM + 1e-12);
        assert!(pad[0] - PAD_MM / 2.0 >= x0 + CLAMP_MM - 1e-12);
        assert!(pad[1] > 0.0 && pad[1] < 13.2);
    }
}
