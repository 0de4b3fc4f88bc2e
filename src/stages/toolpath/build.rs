//! The move-list builder: feeds capped by the machine's Z limit, safe approaches with ramped entries, and
//! the sequence that starts, changes and stops a tool.
//!
//! **Entries** ([`Builder::approach`]): the first entry of a tool travels at safe z, every later one rises
//! only to the retract height (0.5 mm above the stock top, which nothing over the work stands above) and
//! travels there; a rapid down to that height over the start of the run, then straight down *through air*
//! at the machine's Z feed to the *entry height* `z₀ = z + 1.1·doc + 5 µm` (every level engages at most the
//! tool's depth of cut `doc` below the stock it meets — the roughing layers by construction, the finishing
//! levels by their stock check — so at the start `p` of a run no stock stands above the tool's lower
//! surface placed at `z₀`: for any cell at offset `d`, `before ≤ after + doc ≤ ball_p(d) + doc`; a roughing
//! layer lowers that to the layer before it plus the ridges its tool leaves between paths — the stock the
//! earlier layers left — which the acceptance tests check against the simulated stock; the finishing levels
//! and the final raster, whose stock the builder has swept, lower it to 5 µm above the stock's own cutter
//! location at `p`), then
//! ramp into the material along the run itself at the tool's `max_ramp_deg` θ at most: back and forth over
//! its first `a = Δ/(2m·tanθ)` mm in `m` legs until `Δ = z₀ − z` is descended, never below the run's own
//! cutter locations (so never below the design). A run too short for 50 legs is entered by a straight
//! plunge at the plunge feed, and counted. A pass ends with a rapid straight up to the retract height.
//!
//! **Start of a tool** ([`Builder::start_tool`]): the tool change (LinuxCNC `G53 G0 Z`, `T M6`, `G43 H`;
//! GRBL the start of the tool's own program, written by [`crate::gcode::emit`] and split by `super::files`), a Z-only retract to the clearance
//! height (the emitter writes it before any X/Y word because the position is unknown then), *then* the
//! spindle at the tool's own speed with its dwell, then the coolant. **Stop of a tool**
//! ([`Builder::stop_tool`]): feed up to the lead height, rapid to the clearance height, park at the
//! profile's park position if it has one, `M5`, `M9`. The program's end is a stop without a following start.

use crate::cut::machine::{CuttingData, Machine, Tool};
use crate::gcode::moves::{self, Coolant, Move, P3};

/// Clearance above the stock where lead-ins start and lead-outs end, mm.
pub const LEAD_MM: f64 = super::check::RAPID_FLOOR_MM;

/// The entry height above a run's start is this many depths of cut plus [`ENTRY_MARGIN_MM`]: the levels
/// hold their depth of cut within the 5% the simulated stock resolves it to, and a little more.
pub const ENTRY_DOC_FACTOR: f64 = 1.1;

/// See [`ENTRY_DOC_FACTOR`], mm.
pub const ENTRY_MARGIN_MM: f64 = 0.005;

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
    /// Cutting feed of the current tool, mm/min (the ramps').
    pub feed_mm_min: f64,
    /// `tan` of the current tool's steepest entry ([`Tool::max_ramp_deg`]); infinite when it may plunge.
    pub ramp_tan: f64,
    /// Height above a run's start from which its entry ramps (see the module documentation), mm.
    pub entry_mm: f64,
    /// Highest the stock can stand during the current level, mm (a roughing layer's: the layer before it
    /// plus the allowance; infinite when only the depth of cut bounds it). Entries ramp from no higher.
    pub entry_ceiling_z: f64,
    /// Entries ramped so far.
    pub ramped_entries: usize,
    /// Entries plunged straight (the tool may plunge, or the run is too short for a ramp).
    pub plunged_entries: usize,
    /// The current tool has entered the work since it started: later approaches travel at the retract
    /// height [`LEAD_MM`] over the stock, not at the clearance height.
    pub in_work: bool,
}

/// Most back-and-forth legs of one ramp; a run shorter than that needs is plunged into instead.
pub const MAX_RAMP_LEGS: usize = 50;

impl<'m> Builder<'m> {
    /// An empty program on `machine`, the tip assumed at `start`.
    pub fn new(machine: &'m Machine, start: P3) -> Self {
        Self {
            moves: vec![],
            at: start,
            machine,
            plunge_mm_min: 1.0,
            feed_mm_min: 1.0,
            ramp_tan: f64::INFINITY,
            entry_mm: 0.0,
            entry_ceiling_z: f64::INFINITY,
            ramped_entries: 0,
            plunged_entries: 0,
            in_work: false,
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
        let f = if d > 0.0 {
            self.z_capped(f, (p[2] - self.at[2]) / d)
        } else {
            f
        };
        self.moves.push(Move::Feed(p, f));
        self.at = p;
    }

    /// `f` lowered so that the vertical speed `f·|dz/ds|` is at most the machine's Z feed and, going down
    /// (`dz/ds < 0`), the tool's plunge feed: the cap [`Self::feed`] and [`Self::arc`] share.
    fn z_capped(&self, f: f64, dz_ds: f64) -> f64 {
        let zmax = self.machine.limits.max_feed_z_mm_min;
        let cap = if dz_ds < 0.0 {
            zmax.min(self.plunge_mm_min)
        } else {
            zmax
        };
        let steep = dz_ds.abs().min(1.0);
        if f * steep > cap {
            cap / steep
        } else {
            f
        }
    }

    /// Travel over the start of `run`, descend through air to the entry height and ramp into the material
    /// along `run` (see the module documentation). The first approach of a tool travels at safe z; later
    /// ones rise only to the retract height [`LEAD_MM`] above the stock top (nothing stands higher over the
    /// work) and travel there. The descent from there to the entry height is air by construction and runs at
    /// the machine's Z feed; `stock_cl`, where the caller knows it, is the lowest the tip can sit at `run[0]`
    /// without touching the stock as it stands, which lowers the entry height to just above it. The tool
    /// ends at `run[0]`; the caller then cuts `run[1..]`.
    pub fn approach(&mut self, run: &[P3], stock_cl: Option<f64>) {
        let Some(&p) = run.first() else {
            return;
        };
        let travel = if self.in_work { LEAD_MM } else { self.safe_z() };
        if self.at[2] < travel {
            self.rapid([self.at[0], self.at[1], travel]);
        }
        self.rapid([p[0], p[1], self.at[2].max(travel)]);
        self.rapid([p[0], p[1], LEAD_MM.max(p[2])]);
        self.in_work = true;
        let plunge = self.plunge_mm_min;
        let mut top = (p[2] + self.entry_mm).min(self.entry_ceiling_z).min(LEAD_MM);
        if let Some(s) = stock_cl {
            top = top.min(s.min(0.0) + ENTRY_MARGIN_MM);
        }
        // never below the run's start (a layer's ceiling can be lower than a run that starts on the allowance)
        let top = top.max(p[2]);
        self.air_down(top);
        // within the margin there is nothing to ramp through
        if top <= p[2] + ENTRY_MARGIN_MM + 1e-9 {
            self.feed(p, plunge);
            return;
        }
        let legs = ramp_legs(run, top - p[2], self.ramp_tan);
        let Some(points) = legs else {
            self.plunged_entries += 1;
            self.feed(p, plunge);
            return;
        };
        let f = self.feed_mm_min;
        for q in points {
            self.feed(q, f);
        }
        self.ramped_entries += 1;
    }

    /// Straight down through air to `z` at the machine's Z feed (nothing when already there or below).
    fn air_down(&mut self, z: f64) {
        if z < self.at[2] - 1e-12 {
            let f = self.machine.limits.max_feed_z_mm_min;
            self.moves.push(Move::Feed([self.at[0], self.at[1], z], f));
            self.at = [self.at[0], self.at[1], z];
        }
    }

    /// Straight up out of the cut to the retract height [`LEAD_MM`], as a rapid.
    pub fn retract(&mut self) {
        if self.at[2] < LEAD_MM {
            self.rapid([self.at[0], self.at[1], LEAD_MM]);
        }
    }

    /// An arc at feed `f`, capped like [`Self::feed`]: its vertical speed `f·|dz/ds|` at most the machine's Z
    /// feed, and where it descends at most the plunge feed. An arc in a vertical plane under a half turn with
    /// no vertical tangent is steepest, rising or falling, at an end, where `|dz/ds| = |h − c_h| / r` and the
    /// sign of `dz/ds` is the tangent's (`G2` turns clockwise in the plane's axes): so each end is capped
    /// by its own direction — an arc climbing to a crest is not slowed to the plunge feed. An arc in the XY
    /// plane keeps the stricter cap at its larger `|x − c_x| / r` (its Z is helical, not in the plane).
    pub fn arc(&mut self, mut a: moves::Arc, f: f64) {
        let (p, q, _) = a.plane.axes();
        let r = (self.at[p] - a.center[p]).hypot(self.at[q] - a.center[q]);
        // dz/ds at one end
        let end = |at: P3| -> f64 {
            let (rp, rq) = (at[p] - a.center[p], at[q] - a.center[q]);
            // the unit tangent in the plane's axes: counter-clockwise (−rq, rp), clockwise (rq, −rp)
            let (tp, tq) = if a.cw { (rq, -rp) } else { (-rq, rp) };
            match (p, q) {
                (2, _) => tp / r,
                (_, 2) => tq / r,
                // XY: no vertical tangent in the plane; the old, stricter reading, as a descent
                _ => -(rp.abs() / r),
            }
        };
        a.feed_mm_min = self.z_capped(self.z_capped(f, end(self.at)), end(a.to));
        self.moves.push(Move::Arc(a));
        self.at = a.to;
    }

    /// The blocks of a fitted run ([`super::arcs::fit`]) at feed `f`: lines by [`Self::feed`], arcs by
    /// [`Self::arc`].
    pub fn pieces(&mut self, pieces: &[super::arcs::Piece], f: f64) {
        for pc in pieces {
            match *pc {
                super::arcs::Piece::Line(p) => self.feed(p, f),
                super::arcs::Piece::Arc(a) => self.arc(a, f),
            }
        }
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
        self.feed_mm_min = cut.feed_mm_min;
        self.ramp_tan = if tool.max_ramp_deg >= 90.0 {
            f64::INFINITY
        } else {
            tool.max_ramp_deg.to_radians().tan()
        };
        self.entry_mm = ENTRY_DOC_FACTOR * cut.max_depth_of_cut_mm + ENTRY_MARGIN_MM;
        self.in_work = false;
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
        self.in_work = false;
        self.moves.push(Move::SpindleOff);
        if self.machine.program.coolant != Coolant::Off {
            self.moves.push(Move::Coolant(Coolant::Off));
        }
    }
}

/// The points of a ramp descending `depth` mm into the start of `run` at slope `tan` at most: `m` legs back
/// and forth over the run's first `a` mm (`2·m·a·tan = depth`, `a` no longer than the run), each point's z
/// the straight descent by the distance travelled, never below the run's own z at that point, the last
/// point the run's start. `None` when the tool may plunge (`tan` infinite), or the run would need more than
/// [`MAX_RAMP_LEGS`] legs.
pub fn ramp_legs(run: &[P3], depth: f64, tan: f64) -> Option<Vec<P3>> {
    if !tan.is_finite() || run.len() < 2 {
        return None;
    }
    // the run's arc length in x, y at each point
    let mut s = vec![0.0];
    for w in run.windows(2) {
        s.push(s[s.len() - 1] + (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]));
    }
    let avail = s[s.len() - 1];
    let total = depth / tan;
    let m = (total / (2.0 * avail)).ceil().max(1.0) as usize;
    if avail <= 0.0 || m > MAX_RAMP_LEGS {
        return None;
    }
    let a = total / (2 * m) as f64;
    // the run at arc length t (t ≤ avail)
    let at = |t: f64| -> P3 {
        let k = s.partition_point(|v| *v < t).clamp(1, run.len() - 1);
        let (s0, s1) = (s[k - 1], s[k]);
        let f = if s1 > s0 {
            ((t - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let (p, q) = (run[k - 1], run[k]);
        [
            p[0] + f * (q[0] - p[0]),
            p[1] + f * (q[1] - p[1]),
            p[2] + f * (q[2] - p[2]),
        ]
    };
    // the run's own vertices within the leg, then its end
    let inner: Vec<f64> = s.iter().copied().filter(|v| *v > 0.0 && *v < a).collect();
    let top = run[0][2] + depth;
    let mut out = vec![];
    let mut travelled = 0.0;
    let mut pos = 0.0;
    for leg in 0..2 * m {
        let forward = leg % 2 == 0;
        let stops: Vec<f64> = if forward {
            inner.iter().copied().chain(std::iter::once(a)).collect()
        } else {
            inner.iter().rev().copied().chain(std::iter::once(0.0)).collect()
        };
        for t in stops {
            travelled += (t - pos).abs();
            pos = t;
            let q = at(t);
            out.push([q[0], q[1], (top - tan * travelled).max(q[2])]);
        }
    }
    if let Some(last) = out.last_mut() {
        *last = run[0];
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ramp into a flat run: 2m legs, every segment at the ramp slope (within rounding), ending at the
    /// run's start; on a run that rises, never below it.
    #[test]
    fn ramps_descend_at_the_angle_and_end_at_the_run() {
        let run: Vec<P3> = (0..=100).map(|i| [i as f64 * 0.01, 0.5, -0.3]).collect();
        let tan = 3f64.to_radians().tan();
        let pts = ramp_legs(&run, 0.2, tan).unwrap();
        let mut prev = [0.0, 0.5, -0.1];
        let mut horizontal = 0.0;
        for q in &pts {
            let d = (q[0] - prev[0]).hypot(q[1] - prev[1]);
            horizontal += d;
            if d > 1e-9 {
                let slope = (prev[2] - q[2]) / d;
                assert!(slope <= tan * (1.0 + 1e-9) && slope >= 0.0, "slope {slope} at {q:?}");
            }
            prev = *q;
        }
        assert_eq!(*pts.last().unwrap(), run[0]);
        assert!(
            (horizontal - 0.2 / tan).abs() < 1e-9,
            "{horizontal} against {}",
            0.2 / tan
        );
        assert!(pts.iter().all(|q| q[0] <= 1.0 + 1e-12 && q[0] >= 0.0));
        // a rising run: the ramp rides on it where it is higher than the descent
        let rising: Vec<P3> = (0..=100)
            .map(|i| [i as f64 * 0.01, 0.0, -0.3 + 0.5 * i as f64 * 0.01])
            .collect();
        let pts = ramp_legs(&rising, 0.2, tan).unwrap();
        for q in &pts {
            assert!(q[2] >= -0.3 + 0.5 * q[0] - 1e-12, "{q:?} below the run");
        }
        // plunging allowed, or a run too short for 50 legs: no ramp
        assert!(ramp_legs(&run, 0.2, f64::INFINITY).is_none());
        assert!(ramp_legs(&run[..2], 0.2, tan).is_none());
    }

    /// An arc's feed is capped by the direction at each end: a quarter circle of a 0.25 mm ball rolling up
    /// to a crest (in −X, `G2` in ZX, as a one-way raster runs) keeps the cutting feed when the machine's Z
    /// feed allows it, its mirror rolling down from the crest is held to the plunge feed at its vertical
    /// end, and the sign of `dz/ds` each end reads agrees with a finite difference along the arc.
    #[test]
    fn arcs_are_capped_by_the_plunge_feed_only_where_they_descend() {
        let m =
            Machine::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/grbl-3018.toml")).unwrap();
        let (r, f, plunge) = (0.25, 120.0, 40.0);
        let c = [1.0, 0.0, -1.0];
        // (start, end, G2?) in the XZ plane: up from 45° to the crest, and down from the crest
        let s = std::f64::consts::FRAC_1_SQRT_2 * r;
        let cases = [
            // rising to the crest moving −X: from (c + s, c_z + s) to (c_x, c_z + r), clockwise in (Z, X)
            ([c[0] + s, 0.0, c[2] + s], [c[0], 0.0, c[2] + r], true),
            // falling from the crest moving −X to the vertical tangent's side: (c_x, c_z + r) to (c_x − r, c_z)
            ([c[0], 0.0, c[2] + r], [c[0] - r, 0.0, c[2]], true),
        ];
        let mut feeds = vec![];
        for (from, to, cw) in cases {
            let mut b = Builder::new(&m, from);
            b.plunge_mm_min = plunge;
            let a = moves::Arc {
                to,
                center: c,
                plane: moves::Plane::Zx,
                cw,
                feed_mm_min: 0.0,
            };
            // the direction of travel at the start, by a finite difference along the arc
            let pts = a.points(from, 1e-6);
            let dz0 = pts[0][2] - from[2];
            b.arc(a, f);
            let Some(Move::Arc(out)) = b.moves.last() else { panic!() };
            feeds.push((dz0, out.feed_mm_min));
        }
        let zmax = m.limits.max_feed_z_mm_min;
        // rising: capped only by the Z feed at its steeper end (|dz/ds| = 1/√2 there)
        assert!(feeds[0].0 > 0.0, "{feeds:?}");
        let want = f.min(zmax * std::f64::consts::SQRT_2);
        assert!((feeds[0].1 - want).abs() < 1e-9, "{feeds:?}");
        // falling to a vertical tangent: the plunge feed
        assert!(feeds[1].0 < 0.0, "{feeds:?}");
        assert!((feeds[1].1 - plunge.min(zmax)).abs() < 1e-9, "{feeds:?}");
    }
}
