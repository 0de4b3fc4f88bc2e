//! A toolpath configuration checked against a machine, once: [`ToolpathConfig::check`] returns the
//! [`ToolpathPlan`] — the tools, the stepover, the feed and the raster strategy — that [`ToolpathPlan::run`]
//! builds the program from, so nothing is checked or worked out twice. Everything that needs no tile is
//! checked here, with the work bounded before it starts (issue 13: a stepover of 1e-7 mm or a tool the size
//! of the machine would run for hours or ask for terabytes); each refusal names the field.

use super::{raster, rough, Strategy, ToolpathConfig, ToolpathError};
use crate::base::heightfield::Heightfield;
use crate::cut::machine::{self, Machine, Tool};
use crate::cut::tool::Shape;

/// The largest design grid the raster may sample, cells (8 bytes each: 3.2 GB).
pub const MAX_GRID_CELLS: f64 = 4e8;

/// The most finishing CL points a program may have (24 bytes each before simplification: 2.4 GB).
pub const MAX_CL_POINTS: f64 = 1e8;

/// The most finishing passes a program may have (a 1 µm scallop with a 0.5 mm ball is 45 µm apart: 2,700
/// passes over 120 mm).
pub const MAX_PASSES: f64 = 200_000.0;

/// The least cutting feed override, mm/min: feeds are written to 0.1 mm/min and the reduced ones (entries,
/// engagement) are fractions of the cutting feed, so a smaller one would be written as `F0`.
pub const MIN_FEED_MM_MIN: f64 = 1.0;

/// The fewest motor steps a finishing stepover may span: rounded to steps, passes of `n` steps are spaced
/// within `1/(2n)` of the stepover asked for (12% at 4).
pub const MIN_STEPOVER_STEPS: f64 = 4.0;

/// The largest collinear-point tolerance, µm (a quarter of a millimetre would flatten the facets).
pub const MAX_TOLERANCE_UM: f64 = 250.0;

/// A toolpath configuration checked against its machine for a design grid of `pitch_mm`.
#[derive(Clone, Debug)]
pub struct ToolpathPlan {
    /// The configuration.
    pub cfg: ToolpathConfig,
    /// The machine.
    pub machine: Machine,
    /// The finishing tool (a ball-nose).
    pub tool: Tool,
    /// The roughing tool (the finishing tool when none is named).
    pub rough: Tool,
    /// The finishing stepover, mm: `stepover_mm`, or the one that leaves `scallop_um`.
    pub stepover_mm: f64,
    /// The cutting feed, mm/min: the override, or the finishing tool's cutting data for the stock.
    pub feed_mm_min: f64,
    /// The raster strategy (`auto` resolved: one-way where the machine's axes have backlash).
    pub strategy: Strategy,
    /// The design grid's pitch the work was bounded for, mm.
    pub pitch_mm: f64,
    /// What the check changed or warns of, in plain words (a tolerance raised to the machine's step grid,
    /// zigzag finishing on an axis with backlash).
    pub notes: Vec<String>,
}

/// The tool a job roughs with when it names none: the profile's `program.roughing_tool` when it is larger
/// than the finishing tool (a smaller one gains nothing), else the finishing tool. It cuts only when the
/// relief is deeper than the finishing tool's depth of cut.
fn default_rough<'a>(machine: &'a Machine, tool: &'a Tool) -> &'a Tool {
    machine
        .program
        .roughing_tool
        .as_deref()
        .and_then(|id| machine.tool(id).ok())
        .filter(|r| r.diameter_mm() > tool.diameter_mm())
        .unwrap_or(tool)
}

/// `ToolpathError::Limit` naming the field and the estimate.
pub(super) fn limit(field: &str, what: String) -> ToolpathError {
    ToolpathError::Limit {
        field: field.to_string(),
        estimate: what,
    }
}

impl ToolpathConfig {
    /// Check what needs no tile — the tools, the area within travel, the tolerance, the raster, the feed, the
    /// job name for the header — and the work its area and stepover ask for on a design grid of `pitch_mm`;
    /// return the plan [`ToolpathPlan::run`] builds programs from.
    pub fn check(&self, machine: &Machine, pitch_mm: f64) -> Result<ToolpathPlan, ToolpathError> {
        let bad = |s: String| Err(ToolpathError::Config(s));
        machine::program_text("job", &self.job).map_err(ToolpathError::Profile)?;
        let tool = machine
            .tool(&self.tool)
            .map_err(|e| ToolpathError::Config(format!("`tool`: {e}")))?;
        if !matches!(tool.shape, Shape::Ball { .. }) {
            return bad(format!(
                "`tool`: finishing needs a ball-nose; `{}` is {:?}",
                tool.id,
                tool.shape.kind()
            ));
        }
        let rough = if self.rough_tool.is_empty() {
            default_rough(machine, tool)
        } else {
            machine
                .tool(&self.rough_tool)
                .map_err(|e| ToolpathError::Config(format!("`rough_tool`: {e}")))?
        };
        let [ax, ay] = self.area_mm;
        if !(ax > 0.0 && ay > 0.0 && ax.is_finite() && ay.is_finite()) {
            return bad(format!("`area_mm` must be positive, got [{ax}, {ay}]"));
        }
        if !(self.max_hours > 0.0 && self.max_hours.is_finite()) {
            return bad(format!(
                "`max_hours` must be a positive number of hours, got {}",
                self.max_hours
            ));
        }
        if ax > machine.travel.x_mm || ay > machine.travel.y_mm {
            return Err(ToolpathError::Machine(format!(
                "impossible combination: `area_mm` = [{ax}, {ay}] is larger than the machine's travel {}×{} mm \
                 (travel.x_mm × travel.y_mm of `{}`)",
                machine.travel.x_mm, machine.travel.y_mm, machine.name
            )));
        }
        if !(0.0..=MAX_TOLERANCE_UM).contains(&self.tolerance_um) {
            return bad(format!(
                "`tolerance_um` must be in [0, {MAX_TOLERANCE_UM}] µm, got {}",
                self.tolerance_um
            ));
        }
        if !self.angle_deg.is_finite() {
            return bad(format!("`angle_deg` must be a finite angle, got {}", self.angle_deg));
        }
        let f = self.feed_mm_min;
        if f != 0.0 && !(f >= MIN_FEED_MM_MIN && f <= machine.limits.max_feed_mm_min) {
            return bad(format!(
                "`feed_mm_min` must be 0 (the tool's cutting data) or in [{MIN_FEED_MM_MIN}, {}] mm/min (limits.max_feed_mm_min), got {f}",
                machine.limits.max_feed_mm_min
            ));
        }
        let stepover_mm = self.stepover_of(tool.radius_mm())?;
        if !(pitch_mm.is_finite() && pitch_mm > 0.0) {
            return bad(format!("the design grid's pitch must be positive, got {pitch_mm} mm"));
        }
        self.bound_grid(tool, rough, stepover_mm, pitch_mm)?;
        let feed_mm_min = if f > 0.0 {
            f
        } else {
            tool.cutting(self.stock).feed_mm_min
        };
        let strategy = match self.strategy {
            Strategy::Auto if machine.has_backlash() => Strategy::Oneway,
            Strategy::Auto => Strategy::Zigzag,
            s => s,
        };
        let mut cfg = self.clone();
        let notes = self.check_resolution(machine, stepover_mm, strategy, &mut cfg)?;
        Ok(ToolpathPlan {
            cfg,
            notes,
            machine: machine.clone(),
            tool: tool.clone(),
            rough: rough.clone(),
            stepover_mm,
            feed_mm_min,
            strategy,
            pitch_mm,
        })
    }

    /// The finishing stepover, mm: `stepover_mm` when given, else the one that leaves `scallop_um` with a ball
    /// of radius `r_mm`.
    fn stepover_of(&self, r_mm: f64) -> Result<f64, ToolpathError> {
        let bad = |s: String| Err(ToolpathError::Config(s));
        if self.stepover_mm > 0.0 && self.stepover_mm.is_finite() {
            Ok(self.stepover_mm)
        } else if self.stepover_mm != 0.0 {
            bad(format!(
                "`stepover_mm` must be a positive length (or 0: from the scallop), got {}",
                self.stepover_mm
            ))
        } else if self.scallop_um > 0.0 && self.scallop_um * 1e-3 < r_mm {
            Ok(raster::stepover_for_scallop(r_mm, self.scallop_um * 1e-3))
        } else {
            bad(format!(
                "`scallop_um` must be in (0, {}) µm for the {} mm ball, got {}",
                r_mm * 1000.0,
                2.0 * r_mm,
                self.scallop_um
            ))
        }
    }

    /// What the machine resolves (`accuracy.steps_per_mm`, else `limits.resolution_mm`): a scallop below half
    /// a Z step or a stepover of fewer than [`MIN_STEPOVER_STEPS`] steps is refused, naming the key and the
    /// machine's figure; a simplification tolerance below half a step is raised to it (the writer rounds to
    /// the grid anyway), said in the notes; zigzag finishing on an axis with backlash is warned of.
    fn check_resolution(
        &self,
        machine: &Machine,
        stepover_mm: f64,
        strategy: Strategy,
        cfg: &mut ToolpathConfig,
    ) -> Result<Vec<String>, ToolpathError> {
        let acc = machine.accuracy();
        let (step, source) = match acc.step_mm() {
            Some(s) => (s, "accuracy.steps_per_mm"),
            None => ([machine.limits.resolution_mm; 3], "limits.resolution_mm"),
        };
        let um = |mm: f64| format!("{:.4} µm", mm * 1000.0);
        if self.stepover_mm == 0.0 && self.scallop_um * 1e-3 < step[2] / 2.0 {
            return Err(ToolpathError::Config(format!(
                "`scallop_um` = {} µm is below half of the Z step {} of `{}` ({source}): the controller rounds every Z to a step, so the scallops would be rounding, not cut; use at least {}",
                self.scallop_um,
                um(step[2]),
                machine.name,
                um(step[2] / 2.0)
            )));
        }
        let xy = step[0].max(step[1]);
        if stepover_mm < MIN_STEPOVER_STEPS * xy {
            let key = if self.stepover_mm > 0.0 {
                "stepover_mm"
            } else {
                "scallop_um"
            };
            return Err(ToolpathError::Config(format!(
                "`{key}` gives a stepover of {} = {:.1} steps of {} ({source} of `{}`): rounded to steps the passes would be unevenly spaced; a stepover of at least {MIN_STEPOVER_STEPS} steps ({}) is needed",
                um(stepover_mm),
                stepover_mm / xy,
                um(xy),
                machine.name,
                um(MIN_STEPOVER_STEPS * xy)
            )));
        }
        let mut notes = vec![];
        let half = machine.write_resolution_mm() / 2.0;
        if self.tolerance_um > 0.0 && self.tolerance_um * 1e-3 < half {
            cfg.tolerance_um = half * 1000.0;
            notes.push(format!(
                "`toolpath.tolerance_um` {} µm raised to {}: half the {} grid `{}` writes coordinates on ({source}), finer than any point can be placed",
                self.tolerance_um,
                um(half),
                um(2.0 * half),
                machine.name
            ));
        }
        if strategy == Strategy::Zigzag && acc.has_backlash_xy() {
            notes.push(format!(
                "Finishing zigzag on `{}`, whose axes have {} / {} µm of backlash (accuracy.backlash_um): every other pass is shifted by the backlash along the passes, so a facet of slope p gets steps of p × b between neighbouring passes; `strategy = \"auto\"` finishes one-way. The milled figures below are on this machine, `milled_ideal` on a perfect one.",
                machine.name, acc.backlash_um[0], acc.backlash_um[1]
            ));
        }
        Ok(notes)
    }

    /// The design grid the raster samples (the area's diagonal plus the larger tool's radius on each side),
    /// the finishing passes and their CL points, against [`MAX_GRID_CELLS`], [`MAX_PASSES`] and
    /// [`MAX_CL_POINTS`].
    fn bound_grid(&self, tool: &Tool, rough: &Tool, stepover: f64, pitch_mm: f64) -> Result<(), ToolpathError> {
        let [ax, ay] = self.area_mm;
        let radius = tool.radius_mm().max(rough.radius_mm());
        let margin = radius + 3.0 * pitch_mm;
        let diag = ax.hypot(ay);
        let side = (diag + 2.0 * margin) / pitch_mm + 2.0;
        if side * side > MAX_GRID_CELLS {
            return Err(limit(
                "tools.diameter_mm / area_mm",
                format!(
                    "the design grid would be about {:.3e} cells (area plus the tool radius {radius} mm on each side, at {pitch_mm} mm), above {MAX_GRID_CELLS:.0e}",
                    side * side,
                ),
            ));
        }
        let field = if self.stepover_mm > 0.0 {
            "stepover_mm"
        } else {
            "scallop_um"
        };
        let passes = diag / stepover + 1.0;
        if passes > MAX_PASSES || passes * side > MAX_CL_POINTS {
            return Err(limit(
                field,
                format!(
                    "stepover {stepover:.3e} mm gives about {passes:.3e} passes over {ax}×{ay} mm and {:.3e} CL points, above {MAX_PASSES:.0e} passes or {MAX_CL_POINTS:.0e} points",
                    passes * side
                ),
            ));
        }
        Ok(())
    }
}

impl ToolpathPlan {
    /// The finishing tool as this machine cuts with it: its runout envelope ([`crate::cut::accuracy`]), the
    /// shape the design loop, the scallop lobe and the simulation all use.
    pub fn cutting_shape(&self) -> Shape {
        self.machine.accuracy().envelope(self.tool.shape)
    }

    /// The tile must be periodic (it repeats over the area) and on the grid the plan was checked for; the
    /// layers of each tool, from the tile's relief and the profile, are bounded ([`rough::MAX_LAYERS`]).
    pub(super) fn check_tile(&self, tile: &Heightfield) -> Result<(), ToolpathError> {
        if !tile.periodic {
            return Err(ToolpathError::Config(
                "the design heightfield must be periodic (a tile) to repeat over the area".into(),
            ));
        }
        if (tile.pitch_mm - self.pitch_mm).abs() > 1e-12 * self.pitch_mm {
            return Err(ToolpathError::Config(format!(
                "the design's pitch {} mm is not the {} mm the plan was checked for",
                tile.pitch_mm, self.pitch_mm
            )));
        }
        let relief = -tile.z_mm.iter().copied().fold(0.0, f64::min);
        for t in [&self.rough, &self.tool] {
            let doc = t.cutting(self.cfg.stock).max_depth_of_cut_mm;
            let layers = relief / doc;
            if layers > rough::MAX_LAYERS as f64 {
                return Err(limit(
                    &format!("tools ({}).{:?}.max_depth_of_cut_mm", t.id, self.cfg.stock).to_lowercase(),
                    format!(
                        "a relief of {relief:.4} mm at {doc:e} mm per cut is about {layers:.3e} layers, above {}",
                        rough::MAX_LAYERS
                    ),
                ));
            }
        }
        Ok(())
    }
}
