//! The move-list builder: feeds capped by the machine's Z limit, safe approaches, and the sequence that
//! starts, changes and stops a tool.
//!
//! **Start of a tool** ([`Builder::start_tool`]): the tool change (LinuxCNC `T M6 G43 H`, GRBL a named
//! first tool or an `M0` pause, written by [`crate::gcode::emit`]), a Z-only retract to the clearance
//! height (the emitter writes it before any X/Y word because the position is unknown then), *then* the
//! spindle at the tool's own speed with its dwell, then the coolant. **Stop of a tool**
//! ([`Builder::stop_tool`]): feed up to the lead height, rapid to the clearance height, park at the
//! profile's park position if it has one, `M5`, `M9`. The program's end is a stop without a following start.

use super::machine::{CuttingData, Machine, Tool};
use crate::gcode::moves::{self, Coolant, Move, P3};

/// Clearance above the stock where lead-ins start and lead-outs end, mm.
pub const LEAD_MM: f64 = super::check::RAPID_FLOOR_MM;

/// A move list under construction, with the tool's position and the current tool's limits.
pub struct Builder<'m> {
    /// The moves so far.
    pub moves: Vec<Move>,
    /// The tool tip's position, mm.
    pub at: P3,
    /// The machine.
    pub machine: &'m Machine,
    /// Plunge feed of the current tool, mm/min.
    pub plunge_mm_min: f64,
}

impl<'m> Builder<'m> {
    /// An empty program on `machine`, the tip assumed at `start`.
    pub fn new(machine: &'m Machine, start: P3) -> Self {
        Self {
            moves: vec![],
            at: start,
            machine,
            plunge_mm_min: 1.0,
        }
    }

    /// Safe z, mm.
    pub fn safe_z(&self) -> f64 {
        self.machine.program.safe_z_mm
    }

    /// A rapid move.
    pub fn rapid(&mut self, p: P3) {
        self.moves.push(Move::Rapid(p));
        self.at = p;
    }

    /// A feed move whose Z component respects the machine's Z feed limit and, going down, the tool's
    /// plunge feed: a descent steeper than the cut's own direction is capped so that its vertical speed
    /// `f·|dz|/d` is at most the plunge feed.
    pub fn feed(&mut self, p: P3, f: f64) {
        let d = moves::dist(self.at, p);
        let dz = p[2] - self.at[2];
        let zcap = if dz < 0.0 {
            self.machine.limits.max_feed_z_mm_min.min(self.plunge_mm_min)
        } else {
            self.machine.limits.max_feed_z_mm_min
        };
        let f = if d > 0.0 && f * dz.abs() / d > zcap {
            (zcap * d / dz.abs()).min(f)
        } else {
            f
        };
        self.moves.push(Move::Feed(p, f));
        self.at = p;
    }

    /// Retract to safe z, travel at safe z, rapid down to the lead height, plunge to `p` at the plunge feed.
    pub fn approach(&mut self, p: P3) {
        let safe = self.safe_z();
        if self.at[2] < safe {
            self.rapid([self.at[0], self.at[1], safe]);
        }
        self.rapid([p[0], p[1], safe]);
        self.rapid([p[0], p[1], LEAD_MM.max(p[2])]);
        let plunge = self.plunge_mm_min;
        self.feed(p, plunge);
    }

    /// Feed along `pts` at `f`.
    pub fn path(&mut self, pts: &[P3], f: f64) {
        for p in pts {
            self.feed(*p, f);
        }
    }

    /// Mount `tool` and start its spindle: tool change, Z retract, spindle on at the tool's speed, dwell,
    /// coolant (see the module documentation).
    pub fn start_tool(&mut self, tool: &Tool, cut: &CuttingData) {
        self.moves.push(Move::ToolChange {
            number: tool.number,
            diameter_mm: tool.diameter_mm(),
            kind: tool.shape.kind(),
        });
        let clear = self.machine.program.clearance_z();
        self.rapid([self.at[0], self.at[1], clear]);
        self.moves.push(Move::SpindleOn(cut.spindle_rpm));
        self.moves.push(Move::Dwell(self.machine.program.spindle_dwell_s));
        let coolant = self.machine.program.coolant;
        if coolant != Coolant::Off {
            self.moves.push(Move::Coolant(coolant));
        }
        self.plunge_mm_min = cut.plunge_mm_min;
    }

    /// Lift out of the cut, retract to the clearance height, park, spindle and coolant off.
    pub fn stop_tool(&mut self) {
        if self.at[2] < LEAD_MM {
            let up = [self.at[0], self.at[1], LEAD_MM];
            let f = self.machine.limits.max_feed_z_mm_min;
            self.feed(up, f);
        }
        let clear = self.machine.program.clearance_z();
        self.rapid([self.at[0], self.at[1], clear]);
        if let Some([x, y]) = self.machine.program.park_xy_mm {
            self.rapid([x, y, clear]);
        }
        self.moves.push(Move::SpindleOff);
        if self.machine.program.coolant != Coolant::Off {
            self.moves.push(Move::Coolant(Coolant::Off));
        }
    }
}
