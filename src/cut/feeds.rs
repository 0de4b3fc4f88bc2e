//! Cutting data from a tool × stock table: the spindle speed, feed, plunge and depth of cut a tool gets in a
//! stock on *this* machine when its profile gives none, and what is wrong with the data a tool runs at
//! (given or derived) — each finding with what would work. docs/MACHINE.md §6 gives the table's sources and
//! the derivation.
//!
//! For a carbide end mill of diameter `D` mm with `z` flutes in a stock whose [`Row`] gives a surface speed
//! range `[v₀, v₁]` m/min and a chip load range `[k₀, k₁]·D` µm per tooth:
//!
//! - spindle speed `n = clamp(1000·v₁ / (π·D), n_min, n_max)` rev/min: as fast as the table allows, within
//!   the spindle's range (a desktop spindle never reaches `v₁` with a small bit);
//! - chip load `f_z = clamp(max((k₀+k₁)/2·D, TIR), k₀·D, k₁·D)` µm: the middle of the range, raised to the
//!   runout (TIR) so every flute cuts (below it the longest flute takes the whole chip and the others
//!   rub), never above the tool's `k₁·D` (the load that breaks a small bit), which wins when the two meet;
//! - feed `F = n·z·f_z / 1000` mm/min, within `[1, limits.max_feed_mm_min]`; plunge `F/3`;
//! - depth of cut `a_p = d·D` with the row's fraction `d`.
//!
//! The surface speed is `v = π·D·n / 1000` at the full diameter; a ball cutting a near-flat facet cuts near
//! its tip, where it is lower still. The figures are starting points from tooling makers' charts, not
//! measurements of this machine: a profile that gives a tool's data (`aluminium = { … }`) keeps them, and
//! they are checked against the same table.

use super::machine::{CuttingData, Machine, Stock, Tool};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// One stock's row of the table, for carbide end mills (two or more flutes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// The stock.
    pub stock: Stock,
    /// Surface speed range, m/min (`[0, …]`: no lower limit worth a warning).
    pub surface_m_min: [f64; 2],
    /// Chip load per tooth range per mm of diameter, µm/mm.
    pub chip_um_per_mm: [f64; 2],
    /// Largest depth of cut as a fraction of the diameter.
    pub depth_per_diameter: f64,
    /// What to do about chips and heat.
    pub coolant: &'static str,
    /// Coolant (mist or air) is needed, not only advised.
    pub coolant_needed: bool,
}

/// Carbide in aluminium alloys (6061, 7075): 90–600 m/min, 0.5–1.2% of the diameter per tooth, a tenth of
/// the diameter deep on a light router; mist or air is needed (aluminium welds to a small bit).
pub const ALUMINIUM: Row = Row {
    stock: Stock::Aluminium,
    surface_m_min: [90.0, 600.0],
    chip_um_per_mm: [5.0, 12.0],
    depth_per_diameter: 0.1,
    coolant: "mist or an air blast to clear the chips (aluminium welds to a small bit)",
    coolant_needed: true,
};

/// Carbide in machining wax and plastics: no surface-speed floor worth a warning (the chips melt when the
/// bit rubs, so the chip load matters), 1–4% of the diameter per tooth, half the diameter deep.
pub const WAX: Row = Row {
    stock: Stock::Wax,
    surface_m_min: [0.0, 300.0],
    chip_um_per_mm: [10.0, 40.0],
    depth_per_diameter: 0.5,
    coolant: "none; a vacuum or an air blast to clear the chips",
    coolant_needed: false,
};

/// The table's row for a stock.
pub fn row(stock: Stock) -> &'static Row {
    match stock {
        Stock::Aluminium => &ALUMINIUM,
        Stock::Wax => &WAX,
    }
}

/// Plunge feed as a fraction of the cutting feed.
pub const PLUNGE_FRACTION: f64 = 1.0 / 3.0;

/// The slowest feed a program writes, mm/min.
const MIN_FEED_MM_MIN: f64 = 1.0;

/// The machine's figures the derivation is limited by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Spindle range, rev/min.
    pub rpm: [f64; 2],
    /// Highest cutting feed, mm/min.
    pub max_feed_mm_min: f64,
    /// Runout at the tool (TIR), µm.
    pub runout_um: f64,
    /// Coolant is on while cutting.
    pub coolant_on: bool,
}

impl Limits {
    /// A machine profile's limits.
    pub fn of(m: &Machine) -> Limits {
        Limits {
            rpm: [m.spindle.min_rpm, m.spindle.max_rpm],
            max_feed_mm_min: m.limits.max_feed_mm_min,
            runout_um: m.accuracy().runout_um,
            coolant_on: m.program.coolant != super::machine::Coolant::Off,
        }
    }
}

/// Cutting data for a tool of `diameter_mm` with `flutes` in `stock`, from the table and within `lim`.
pub fn derive(diameter_mm: f64, flutes: u32, stock: Stock, lim: &Limits) -> CuttingData {
    let r = row(stock);
    let d = diameter_mm;
    // rounded as a machinist writes them (speeds to 100 rpm, feeds to 1 mm/min, depths to 1 µm, all down),
    // the feed from the speed as written
    let rpm = round_to(
        (1000.0 * r.surface_m_min[1] / (PI * d)).clamp(lim.rpm[0], lim.rpm[1]),
        100.0,
    )
    .clamp(lim.rpm[0], lim.rpm[1]);
    let [lo, hi] = r.chip_um_per_mm.map(|k| k * d);
    let chip_um = (0.5 * (lo + hi)).max(lim.runout_um).clamp(lo, hi);
    let feed = (rpm * flutes.max(1) as f64 * chip_um / 1000.0).clamp(MIN_FEED_MM_MIN, lim.max_feed_mm_min);
    CuttingData {
        feed_mm_min: round_to(feed, 1.0),
        plunge_mm_min: round_to(feed * PLUNGE_FRACTION, 1.0).max(MIN_FEED_MM_MIN),
        spindle_rpm: rpm,
        max_depth_of_cut_mm: round_to(r.depth_per_diameter * d, 0.001),
    }
}

/// `x` rounded down to a multiple of `step` (at least one step): what a machinist writes.
fn round_to(x: f64, step: f64) -> f64 {
    ((x / step + 1e-9).floor() * step).max(step)
}

/// What is wrong with a tool's cutting data in a stock on a machine, in the units a machinist checks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Finding {
    /// The surface speed at the full diameter is below the table's floor.
    SurfaceSpeedLow {
        /// At the full diameter, m/min.
        surface_m_min: f64,
        /// The table's floor, m/min.
        min_m_min: f64,
        /// The spindle speed that would reach the floor, rev/min.
        rpm_needed: f64,
        /// The spindle's top speed, rev/min.
        max_rpm: f64,
        /// The smallest diameter that reaches the floor at the top speed, mm.
        diameter_needed_mm: f64,
    },
    /// The chip load is below the runout: one flute cuts, the others rub.
    ChipBelowRunout {
        /// Chip load, µm/tooth.
        chip_um: f64,
        /// Runout (TIR), µm.
        runout_um: f64,
        /// The most this tool takes, µm/tooth.
        tool_max_um: f64,
    },
    /// The chip load is below the table's range: the edge rubs and heats instead of cutting.
    ChipLow {
        /// Chip load, µm/tooth.
        chip_um: f64,
        /// The table's range, µm/tooth.
        range_um: [f64; 2],
    },
    /// The chip load is above the table's range: a small bit breaks.
    ChipHigh {
        /// Chip load, µm/tooth.
        chip_um: f64,
        /// The table's range, µm/tooth.
        range_um: [f64; 2],
    },
    /// The depth of cut is above the table's.
    DepthHigh {
        /// Depth of cut, mm.
        depth_mm: f64,
        /// The table's, mm.
        max_mm: f64,
    },
    /// The stock needs coolant or air and the profile has it off.
    NoCoolant {
        /// What to use.
        advice: String,
    },
}

impl Finding {
    /// The finding in plain words, with what would work.
    pub fn text(&self) -> String {
        match self {
            Finding::SurfaceSpeedLow {
                surface_m_min,
                min_m_min,
                rpm_needed,
                max_rpm,
                diameter_needed_mm,
            } => format!(
                "{surface_m_min:.1} m/min of surface speed at the full diameter (less near a ball's tip, which \
                 cuts the near-flat facets) is below carbide's {min_m_min:.0} m/min in aluminium: it takes \
                 {rpm_needed:.0} rpm (this spindle reaches {max_rpm:.0}); what suits this spindle: machining wax, \
                 or a bit of at least {diameter_needed_mm:.1} mm"
            ),
            Finding::ChipBelowRunout {
                chip_um,
                runout_um,
                tool_max_um,
            } => {
                if runout_um > tool_max_um {
                    format!(
                        "{chip_um:.1} µm/tooth is below the machine's {runout_um} µm runout, and a chip above the \
                         runout would overload this bit (at most {tool_max_um:.1} µm): one flute does the cutting \
                         and the others rub; a collet with under {tool_max_um:.1} µm of runout, or a larger bit"
                    )
                } else {
                    format!(
                        "{chip_um:.1} µm/tooth is below the machine's {runout_um} µm runout: one flute does the \
                         cutting and the others rub; a feed for {runout_um} µm/tooth or more shares the cut"
                    )
                }
            }
            Finding::ChipLow { chip_um, range_um } => format!(
                "{chip_um:.1} µm/tooth is below the {:.1}–{:.1} µm this bit wants: it rubs and heats; a higher \
                 feed or a lower spindle speed",
                range_um[0], range_um[1]
            ),
            Finding::ChipHigh { chip_um, range_um } => format!(
                "{chip_um:.1} µm/tooth is above the {:.1}–{:.1} µm this bit takes: a small bit breaks; a lower \
                 feed or a higher spindle speed",
                range_um[0], range_um[1]
            ),
            Finding::DepthHigh { depth_mm, max_mm } => format!(
                "{depth_mm} mm depth of cut is above the {max_mm:.3} mm this bit takes in this stock on a light \
                 machine; shallower layers"
            ),
            Finding::NoCoolant { advice } => format!("the profile's coolant is off: {advice}"),
        }
    }
}

/// How a tool's data compare with the table: the figures and what is wrong.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Assessment {
    /// Chip load, µm/tooth: `1000·F / (n·z)`.
    pub chip_um: f64,
    /// Surface speed at the full diameter, m/min: `π·D·n / 1000`.
    pub surface_m_min: f64,
    /// The table's chip load range for this bit, µm/tooth.
    pub chip_range_um: [f64; 2],
    /// What is wrong, with what would work (empty: the data suit the bit on this machine).
    pub findings: Vec<Finding>,
}

/// Check a tool's data (at `feed_mm_min`, which may be a job's override) against the table and the machine.
pub fn assess(tool: &Tool, data: &CuttingData, feed_mm_min: f64, stock: Stock, lim: &Limits) -> Assessment {
    let r = row(stock);
    let d = tool.diameter_mm();
    let chip_um = tool.chip_load_um(feed_mm_min, data.spindle_rpm);
    let surface_m_min = tool.surface_speed_m_min(data.spindle_rpm);
    let range = r.chip_um_per_mm.map(|k| k * d);
    let tol = 1.0 + 1e-6;
    let mut findings = vec![];
    if surface_m_min * tol < r.surface_m_min[0] {
        findings.push(Finding::SurfaceSpeedLow {
            surface_m_min,
            min_m_min: r.surface_m_min[0],
            rpm_needed: 1000.0 * r.surface_m_min[0] / (PI * d),
            max_rpm: lim.rpm[1],
            diameter_needed_mm: 1000.0 * r.surface_m_min[0] / (PI * lim.rpm[1]),
        });
    }
    if tool.flutes > 1 && chip_um * tol < lim.runout_um {
        findings.push(Finding::ChipBelowRunout {
            chip_um,
            runout_um: lim.runout_um,
            tool_max_um: range[1],
        });
    } else if chip_um * tol < range[0] {
        findings.push(Finding::ChipLow {
            chip_um,
            range_um: range,
        });
    }
    if chip_um > range[1] * tol {
        findings.push(Finding::ChipHigh {
            chip_um,
            range_um: range,
        });
    }
    let max_depth = r.depth_per_diameter * d;
    if data.max_depth_of_cut_mm > max_depth * tol + 1e-9 {
        findings.push(Finding::DepthHigh {
            depth_mm: data.max_depth_of_cut_mm,
            max_mm: max_depth,
        });
    }
    if r.coolant_needed && !lim.coolant_on {
        findings.push(Finding::NoCoolant {
            advice: r.coolant.to_string(),
        });
    }
    Assessment {
        chip_um,
        surface_m_min,
        chip_range_um: range,
        findings,
    }
}

/// A tool's cutting data as a program uses them, with where they came from and how they compare with the
/// table (`program.json`'s `cutting`, the setup sheet's tool rows).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ToolData {
    /// The tool's id in the profile.
    pub id: String,
    /// `true`: the table's data for this machine; `false`: the profile's.
    pub from_table: bool,
    /// The data (the feed is the job's override where it gives one).
    #[serde(flatten)]
    pub data: CuttingData,
    /// The comparison with the table.
    #[serde(flatten)]
    pub assessment: Assessment,
}

/// A tool's data in `stock` on a machine, at `feed_mm_min` (the data's own feed, or a job's override).
pub fn tool_data(tool: &Tool, stock: Stock, feed_mm_min: f64, lim: &Limits) -> ToolData {
    let mut data = *tool.cutting(stock);
    data.feed_mm_min = feed_mm_min;
    ToolData {
        id: tool.id.clone(),
        from_table: !tool.data_given(stock),
        data,
        assessment: assess(tool, &data, feed_mm_min, stock, lim),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lim(max_rpm: f64, runout_um: f64) -> Limits {
        Limits {
            rpm: [0.0, max_rpm],
            max_feed_mm_min: 1000.0,
            runout_um,
            coolant_on: true,
        }
    }

    /// On a spindle fast enough, the derived data sit at the table's top surface speed and the middle chip
    /// load, and the check finds nothing: `n = 1000·v / (π·D)`, `F = n·z·f_z`.
    #[test]
    fn a_fast_spindle_gets_the_tables_data_and_no_finding() {
        let l = Limits {
            rpm: [0.0, 100_000.0],
            max_feed_mm_min: 100_000.0,
            runout_um: 0.0,
            coolant_on: true,
        };
        let d = 6.0;
        let c = derive(d, 2, Stock::Aluminium, &l);
        let n = 1000.0 * 600.0 / (PI * d);
        assert!((c.spindle_rpm - n).abs() <= 100.0, "{} vs {n}", c.spindle_rpm);
        let fz = 8.5 * d;
        assert!((c.feed_mm_min - c.spindle_rpm * 2.0 * fz / 1000.0).abs() <= 1.0);
        assert!((c.max_depth_of_cut_mm - 0.6).abs() < 1e-9);
        let tool = crate::cut::machine::Tool::for_test("flat6", crate::cut::tool::Shape::Flat { diameter_mm: d });
        let a = assess(&tool, &c, c.feed_mm_min, Stock::Aluminium, &l);
        assert!(a.findings.is_empty(), "{:?}", a.findings);
    }

    /// A 0.5 mm ball in aluminium on a 10,000 rpm spindle with 15 µm of runout: the spindle tops out, the chip
    /// load stops at the bit's limit below the runout, and the check names the speed it would take, the
    /// diameter that suits the spindle, and the runout.
    #[test]
    fn a_small_ball_on_a_slow_spindle_is_named_with_what_would_work() {
        let l = lim(10_000.0, 15.0);
        let c = derive(0.5, 2, Stock::Aluminium, &l);
        assert_eq!(c.spindle_rpm, 10_000.0);
        assert!((c.feed_mm_min - 10_000.0 * 2.0 * 6.0 / 1000.0).abs() <= 1.0); // 12·0.5 µm, the top
        let tool = crate::cut::machine::Tool::for_test("b", crate::cut::tool::Shape::Ball { diameter_mm: 0.5 });
        let a = assess(&tool, &c, c.feed_mm_min, Stock::Aluminium, &l);
        let speed = a.findings.iter().find_map(|f| match f {
            Finding::SurfaceSpeedLow {
                rpm_needed,
                diameter_needed_mm,
                ..
            } => Some((*rpm_needed, *diameter_needed_mm)),
            _ => None,
        });
        let (rpm, dia) = speed.expect("surface speed named");
        assert!((rpm - 90_000.0 / (PI * 0.5)).abs() < 1e-6);
        assert!((dia - 9.0 / PI).abs() < 1e-9); // 1000·90 / (π·10,000)
        assert!(a
            .findings
            .iter()
            .any(|f| matches!(f, Finding::ChipBelowRunout { tool_max_um, .. } if (*tool_max_um - 6.0).abs() < 1e-12)));
        assert!(!a.findings.iter().any(|f| matches!(f, Finding::ChipHigh { .. })));
    }

    /// Where the runout fits under the bit's limit, the derived chip load rises to it, so the check finds
    /// no rubbing flute.
    #[test]
    fn the_chip_load_rises_to_the_runout_when_the_bit_takes_it() {
        let l = lim(24_000.0, 15.0);
        let c = derive(2.0, 2, Stock::Aluminium, &l); // range 10–24 µm, middle 17
        let chip = 1000.0 * c.feed_mm_min / (c.spindle_rpm * 2.0);
        assert!((16.9..=17.0).contains(&chip), "{chip}");
        let c = derive(1.5, 2, Stock::Aluminium, &l); // range 7.5–18, middle 12.75 < 15
        let chip = 1000.0 * c.feed_mm_min / (c.spindle_rpm * 2.0);
        assert!((14.9..=15.0).contains(&chip), "{chip}");
    }

    /// The feed never exceeds the machine's, nor the spindle its range.
    #[test]
    fn derived_data_stay_within_the_machine() {
        let l = Limits {
            rpm: [6000.0, 24_000.0],
            max_feed_mm_min: 500.0,
            runout_um: 5.0,
            coolant_on: false,
        };
        for d in [0.2, 0.5, 1.0, 3.0, 6.0, 12.0, 25.0] {
            for s in [Stock::Aluminium, Stock::Wax] {
                let c = derive(d, 4, s, &l);
                assert!(c.feed_mm_min <= 500.0 && c.feed_mm_min >= 1.0);
                assert!((6000.0..=24_000.0).contains(&c.spindle_rpm));
                assert!(c.plunge_mm_min <= c.feed_mm_min);
            }
        }
    }
}
