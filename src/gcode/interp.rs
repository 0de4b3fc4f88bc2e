//! The crate's one G-code interpreter: a block's words (`gcode::lex`), sorted and checked on their own
//! ([`Parsed`]), then checked together and executed against the controller's state — modal state, parser
//! position, work offsets — into what the block does ([`Step`]), in the order and with the error codes of
//! GRBL 1.1h's `gc_execute_line`, with a [`Dialect`] policy where LinuxCNC reads a block differently.
//!
//! Its three readers: the simulator (`stages::simulate::gcode`, any program → swept segments), the virtual
//! controller (`apps::stream::emulator`, GRBL's replies and planner blocks) and the streamer's program model
//! ([`super::program`], the modal state and position before and after each line). They read a program the
//! same way because they read it through this code.
//!
//! **Coordinates.** Positions are machine coordinates, mm; work coordinates are `machine − WCO` with
//! `WCO = G54…G59 + G92 + TLO (z)` ([`Offsets`]). A reader that does not know the controller's frame (the
//! streamer's model, before the controller has said where it is) starts with every axis unknown
//! ([`Interpreter::known`]) and the offsets unknown ([`Interpreter::frame_known`]): it measures from the work
//! origin in force at the start, so a block that moves in machine coordinates, goes to a stored position,
//! probes, or changes the offsets absolutely leaves the position unknown until an absolute move sets it.

use super::block::{fail, BlockError, NonModal, Parsed, ToolLength};
use super::lex::Word;
use super::modal::{Distance, Modal, MotionMode};
use super::moves::{Arc, Plane, P3};
use super::Dialect;

/// The message of GRBL's `error:33` for an `R` arc with no travel in its plane (a helix along the normal
/// alone), which GRBL itself does not catch: it plans a NaN centre. The virtual controller logs it as not
/// modelled.
pub const R_ARC_WITHOUT_TRAVEL: &str = "an `R` arc with no travel in its plane";

/// The work offsets a controller keeps (GRBL's `$#`): `WPos = MPos − WCO`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Offsets {
    /// G54–G59 origins, machine mm.
    pub coord: [[f64; 3]; 6],
    /// The system in force (0 = G54).
    pub select: usize,
    /// The G92 offset, mm.
    pub g92: [f64; 3],
    /// The tool length offset along z (G43.1), mm.
    pub tlo: f64,
    /// G28 and G30 positions, machine mm.
    pub stored: [[f64; 3]; 2],
}

impl Offsets {
    /// The `WCO` of system `select` with this G92 offset and tool length offset.
    #[must_use]
    pub fn wco_of(&self, select: usize, g92: [f64; 3], tlo: f64) -> P3 {
        let c = self.coord[select];
        [c[0] + g92[0], c[1] + g92[1], c[2] + g92[2] + tlo]
    }

    /// The `WCO` in force.
    #[must_use]
    pub fn wco(&self) -> P3 {
        self.wco_of(self.select, self.g92, self.tlo)
    }
}

/// A block's motion, machine mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// G0, G1 or G38.x: straight to `to` (G38.x stops where the probe touches), at `feed_mm_min` (0 for G0;
    /// for G93 the feed the block's time gives).
    Line {
        /// G0, G1 or G38.x.
        mode: MotionMode,
        /// The end.
        to: P3,
        /// Feed, mm/min.
        feed_mm_min: f64,
    },
    /// G2/G3 from the parser position; its `feed_mm_min` is the block's feed, and `turns` the extra full turns
    /// (LinuxCNC's `P` − 1).
    Arc {
        /// The arc.
        arc: Arc,
        /// Extra full turns.
        turns: u32,
    },
    /// G28/G30: a rapid to `via`, then to `to`.
    Stored {
        /// The intermediate point (the start when the block names no axis).
        via: P3,
        /// The stored position, on the axes the block names (all when it names none).
        to: P3,
    },
}

impl Motion {
    /// Where it ends.
    #[must_use]
    pub fn end(&self) -> P3 {
        match self {
            Motion::Line { to, .. } | Motion::Stored { to, .. } => *to,
            Motion::Arc { arc, .. } => arc.to,
        }
    }
}

/// What one block does.
#[derive(Clone, Debug)]
pub struct Step {
    /// Its words, sorted (columns for messages).
    pub parsed: Parsed,
    /// The modal state the block runs in (after its modal words, before a program end resets them).
    pub modal: Modal,
    /// The parser position before it, machine mm.
    pub from: P3,
    /// Which axes of `from` were known.
    pub from_known: [bool; 3],
    /// Its motion (`None`: none, or a move to where the tool is already is still `Some`).
    pub motion: Option<Motion>,
    /// The motion's geometry is known: its start (for an arc, in the plane) and its target.
    pub geometry_known: bool,
    /// G4's dwell, seconds.
    pub dwell_s: Option<f64>,
}

/// The interpreter's state between blocks.
#[derive(Clone, Debug)]
pub struct Interpreter {
    /// How blocks are read.
    pub dialect: Dialect,
    /// A GRBL build with `ENABLE_M7` (mist coolant).
    pub m7: bool,
    /// The modal state.
    pub modal: Modal,
    /// The parser position, machine mm (where the last block left the tool).
    pub pos: P3,
    /// Which axes of `pos` are known.
    pub known: [bool; 3],
    /// The work offsets.
    pub offsets: Offsets,
    /// The offsets are the controller's own (false: relative to the frame in force at the start).
    pub frame_known: bool,
    /// G93 inverse-time feed in force.
    pub inverse_time: bool,
}

impl Interpreter {
    /// An interpreter that knows where the tool is (`pos`, machine mm) and the controller's offsets (zero):
    /// the simulator's and the virtual controller's.
    #[must_use]
    pub fn new(dialect: Dialect, modal: Modal, pos: P3) -> Interpreter {
        Interpreter {
            dialect,
            m7: false,
            modal,
            pos,
            known: [true; 3],
            offsets: Offsets::default(),
            frame_known: true,
            inverse_time: false,
        }
    }

    /// An interpreter for a program whose start position and offsets are not known (the streamer's model):
    /// positions are work coordinates of the system in force at the start, `start` where known.
    #[must_use]
    pub fn unknown_frame(dialect: Dialect, start: [Option<f64>; 3]) -> Interpreter {
        Interpreter {
            known: start.map(|v| v.is_some()),
            frame_known: false,
            ..Interpreter::new(dialect, Modal::default(), start.map(|v| v.unwrap_or(0.0)))
        }
    }

    /// The parser position in work coordinates, `None` on unknown axes.
    #[must_use]
    pub fn work_position(&self) -> [Option<f64>; 3] {
        let wco = self.offsets.wco();
        std::array::from_fn(|i| self.known[i].then(|| self.pos[i] - wco[i]))
    }

    /// Run one block: check it as the dialect does and, when it is valid, apply it to the state and say what
    /// it does. A refused block changes nothing.
    pub fn block(&mut self, words: &[Word]) -> Result<Step, BlockError> {
        let mut m = self.modal;
        let p = Parsed::new(words, self.dialect, self.m7, &mut m)?;
        let k = m.units.mm();
        let f = p.value('F');
        let inverse = p.feed_mode.map_or(self.inverse_time, |f| f.0);
        if inverse {
            // G93: F is this block's 1/minutes; the feed is undefined after it unless the next block gives one
            // (GRBL zeroes it before and after every inverse-time block)
            m.feed_mm_min = f;
        } else if self.inverse_time {
            // back to G94: the last feed is not carried over
            m.feed_mm_min = f.map(|f| f * k);
        } else if let Some(f) = f {
            m.feed_mm_min = Some(f * k);
        }
        if let Some(s) = p.value('S') {
            m.spindle_rpm = s;
        }
        if let Some((mm, _)) = p.motion {
            m.motion = mm;
        }
        // GRBL checks G93's F word first, for any motion-mode axis command, G0 included
        let consumes = self.consumes_axes(&p);
        let motion_axis_command = p.has_axis() && !consumes && !matches!(p.non_modal, Some((NonModal::GoStored(_), _)));
        if inverse && motion_axis_command && f.is_none() {
            return fail(command_column(&p), 22, "G93 (inverse time) needs `F` on every move");
        }
        self.check(&p, &m)?;
        let select = p.coord_select.map_or(self.offsets.select, |c| c.0);
        let offsets = self.offsets_after(&p, select, k);
        // the axis words as a target: machine mm for G53, else work coordinates through the block's system
        // (a G10 that changes the table uses up the block's axis words, so the old table serves the target)
        let machine = matches!(p.non_modal, Some((NonModal::Machine, _)));
        let wco = self.offsets.wco_of(select, offsets.g92, offsets.tlo);
        let (target, target_known) = self.axis_target(&p, k, machine, m.distance, wco);
        let motion = if consumes {
            None
        } else if let Some((NonModal::GoStored(w), _)) = p.non_modal {
            Some(Motion::Stored {
                via: target,
                to: self.stored_target(&p, offsets.stored[w]),
            })
        } else {
            self.motion(&p, &m, target, target_known, k, inverse)?
        };
        self.unused_words(&p, &m)?;
        let step = Step {
            dwell_s: p.dwell.map(|_| p.value('P').unwrap_or(0.0)),
            modal: m,
            from: self.pos,
            from_known: self.known,
            geometry_known: motion.is_some() && self.geometry_known(&p, &m, target_known),
            motion,
            parsed: p,
        };
        self.commit(&step, offsets, inverse, target_known);
        Ok(step)
    }

    /// The block's axis words are used up by a command that is not a move (G10, G92, GRBL's G43.1 and G49,
    /// LinuxCNC's G43.1).
    fn consumes_axes(&self, p: &Parsed) -> bool {
        let tool_length = matches!(
            (p.tool_length, self.dialect),
            (Some((ToolLength::Dynamic, _)), _) | (Some((ToolLength::Cancel, _)), Dialect::Grbl)
        );
        tool_length || matches!(p.non_modal, Some((NonModal::SetCoord | NonModal::SetOffset, _)))
    }

    /// The checks across words (GRBL's step 3), once the block's modal state `m` is known.
    fn check(&self, p: &Parsed, m: &Modal) -> Result<(), BlockError> {
        let has_axis = p.has_axis();
        if let Some(col) = p.dwell {
            if p.get('P').is_none() {
                return fail(col, 28, "G4 needs `P` (seconds)");
            }
        }
        self.check_non_modal(p, m, has_axis)?;
        let g10 = matches!(p.non_modal, Some((NonModal::SetCoord, _)));
        if let Some((_, col)) = p.get('P') {
            let linuxcnc = self.dialect == Dialect::Linuxcnc;
            let arc = m.motion.is_arc();
            if !(p.dwell.is_some() || g10 || (linuxcnc && (p.blend || arc))) {
                let what = if linuxcnc {
                    "`P` is only understood with G4 (dwell), G64 or an arc (turns)"
                } else {
                    "`P` is only understood with G4 (dwell) or G10 (the coordinate system)"
                };
                return fail(col, 36, what);
            }
        }
        if let Some((_, col)) = p.get('L') {
            if !g10 {
                return fail(col, 36, "`L` is only understood with G10");
            }
        }
        if let Some((_, col)) = p.get('Q') {
            if !p.blend {
                return fail(col, 36, "`Q` is only understood with G64");
            }
        }
        match (p.tool_length, p.get('H')) {
            (Some((ToolLength::Table, _)), Some(_)) => {}
            (_, Some((_, col))) => return fail(col, 36, "`H` is only understood with G43"),
            (Some((ToolLength::Table, col)), None) => {
                return fail(col, 20, "G43 without `H`: name the tool table entry")
            }
            _ => {}
        }
        if let Some((ToolLength::Dynamic, col)) = p.tool_length {
            // G43.1 takes exactly the Z word (GRBL's TOOL_LENGTH_OFFSET_AXIS)
            let [x, y, z] = p.axes();
            if z.is_none() || x.is_some() || y.is_some() {
                return fail(col, 37, "G43.1 takes the Z word alone");
            }
        }
        if self.consumes_axes(p) {
            return Ok(());
        }
        if has_axis && m.motion == MotionMode::Cancel {
            let col = p.first_column(&['X', 'Y', 'Z']).unwrap_or(0);
            return fail(col, 31, "coordinates without an active motion mode (G0/G1/G2/G3)");
        }
        Ok(())
    }

    /// G10's words (GRBL's order: no axis words 26, `P` or `L` missing 28, `P` beyond G59 29, `L` not 2 or 20:
    /// 20), G92 without axis words (26) and G53 with a motion other than G0/G1 (30).
    fn check_non_modal(&self, p: &Parsed, m: &Modal, has_axis: bool) -> Result<(), BlockError> {
        match p.non_modal {
            Some((NonModal::SetCoord, col)) => {
                if !has_axis {
                    return fail(col, 26, "G10 needs axis words");
                }
                let (Some(pv), Some(l)) = (p.value('P'), p.value('L')) else {
                    return fail(col, 28, "G10 needs `L` and `P`");
                };
                if pv.trunc() > 6.0 {
                    return fail(
                        col,
                        29,
                        format!("G10 P{pv}: there are six systems, P1 to P6 (P0: the one in force)"),
                    );
                }
                if l != 2.0 && l != 20.0 {
                    return fail(col, 20, format!("G10 L{l} is not supported (L2 or L20)"));
                }
            }
            Some((NonModal::SetOffset, col)) if !has_axis => return fail(col, 26, "G92 needs axis words"),
            Some((NonModal::Machine, col)) if !matches!(m.motion, MotionMode::Rapid | MotionMode::Linear) => {
                return fail(col, 30, "G53 moves with G0 or G1 only")
            }
            _ => {}
        }
        Ok(())
    }

    /// GRBL's last check (step 3, "non-specific"), after the motion's own: offsets or a radius that no arc
    /// used are unused words (an arc in radius form with offsets too fails it in [`Interpreter::arc`]).
    fn unused_words(&self, p: &Parsed, m: &Modal) -> Result<(), BlockError> {
        let arc_words = p.offsets().iter().any(Option::is_some) || p.get('R').is_some();
        let full_circle = self.dialect == Dialect::Linuxcnc && p.get('R').is_none();
        let arc = m.motion.is_arc() && (p.has_axis() || full_circle);
        if arc_words && !arc {
            let col = p.first_column(&['I', 'J', 'K', 'R']).unwrap_or(0);
            return fail(col, 36, "`I`, `J`, `K` or `R` without an arc (G2/G3)");
        }
        Ok(())
    }

    /// The offsets after this block's G10, G92/G92.1, G28.1/G30.1 and G43.1/G49, in GRBL's relations
    /// `WPos = MPos − WCS − G92 − TLO` (L20: `WCS = MPos − G92 − TLO − value`; G92:
    /// `G92 = MPos − WCS − TLO − value`), with the system `select` in force.
    fn offsets_after(&self, p: &Parsed, select: usize, k: f64) -> Offsets {
        let mut o = self.offsets;
        let z_tlo = |i: usize| if i == 2 { self.offsets.tlo } else { 0.0 };
        let pos = self.pos;
        let axes = p.axes();
        match p.non_modal.map(|n| n.0) {
            Some(NonModal::SetCoord) => {
                let pv = p.value('P').unwrap_or(0.0).trunc() as usize;
                let idx = if pv > 0 { pv - 1 } else { select };
                for i in 0..3 {
                    if let Some(v) = axes[i] {
                        o.coord[idx][i] = if p.value('L') == Some(20.0) {
                            pos[i] - self.offsets.g92[i] - z_tlo(i) - v * k
                        } else {
                            v * k
                        };
                    }
                }
            }
            Some(NonModal::SetOffset) => {
                for i in 0..3 {
                    if let Some(v) = axes[i] {
                        o.g92[i] = pos[i] - self.offsets.coord[select][i] - z_tlo(i) - v * k;
                    }
                }
            }
            Some(NonModal::ClearOffset) => o.g92 = [0.0; 3],
            Some(NonModal::SetStored(w)) => o.stored[w] = pos,
            _ => {}
        }
        match p.tool_length {
            Some((ToolLength::Dynamic, _)) => o.tlo = axes[2].unwrap_or(0.0) * k,
            Some((ToolLength::Cancel, _)) => o.tlo = 0.0,
            _ => {}
        }
        o.select = select;
        o
    }

    /// The machine target of the block's axis words (an axis without a word stays), mm once scaled by `k`:
    /// machine coordinates for G53, else relative to the parser position in G91, else work coordinates
    /// through `wco`; and which of its axes are known.
    fn axis_target(&self, p: &Parsed, k: f64, machine: bool, d: Distance, wco: P3) -> (P3, [bool; 3]) {
        let (mut target, mut known) = (self.pos, self.known);
        for (i, a) in p.axes().iter().enumerate() {
            if let Some(v) = a {
                target[i] = if machine {
                    v * k
                } else if d == Distance::Incremental {
                    target[i] + v * k
                } else {
                    v * k + wco[i]
                };
                known[i] = if machine {
                    self.frame_known
                } else {
                    d == Distance::Absolute || known[i]
                };
            }
        }
        (target, known)
    }

    /// Where G28/G30 ends: the stored position, only on the axes the block names when it names any (GRBL
    /// 1.1: "move only the axes specified in secondary move").
    fn stored_target(&self, p: &Parsed, stored: P3) -> P3 {
        let mut home = stored;
        if p.has_axis() {
            for (i, (h, a)) in home.iter_mut().zip(p.axes()).enumerate() {
                if a.is_none() {
                    *h = self.pos[i];
                }
            }
        }
        home
    }

    /// The block's move to `target` (machine mm; `k` converts the block's units to mm), checked (`None`: no
    /// motion). In inverse time the feed is `F` per minute of the block: its feed in mm/min is its length · F.
    fn motion(
        &self,
        p: &Parsed,
        m: &Modal,
        target: P3,
        target_known: [bool; 3],
        k: f64,
        inverse: bool,
    ) -> Result<Option<Motion>, BlockError> {
        let probe = matches!(m.motion, MotionMode::Probe { .. });
        let arc_mode = m.motion.is_arc();
        let feed = m.feed_mm_min.unwrap_or(0.0);
        let col = command_column(p);
        let full_circle = self.dialect == Dialect::Linuxcnc
            && arc_mode
            && p.get('R').is_none()
            && p.offsets().iter().any(Option::is_some);
        if !p.has_axis() && !full_circle {
            // GRBL: a G2, G3 or G38.x word without axis words needs a feed (22), then is an error (26); a modal
            // motion without axis words, or G0/G1 alone, just stays
            let needs_axes = self.dialect == Dialect::Grbl && (probe || arc_mode) && p.motion.is_some();
            return match (needs_axes, feed > 0.0) {
                (false, _) => Ok(None),
                (true, false) => fail(col, 22, format!("{} without a feed rate (F)", m.motion.name())),
                (true, true) => fail(col, 26, format!("{} without axis words", m.motion.name())),
            };
        }
        if m.motion == MotionMode::Cancel {
            return Ok(None);
        }
        if m.motion != MotionMode::Rapid && feed <= 0.0 {
            return fail(col, 22, format!("{} without a feed rate (F)", m.motion.name()));
        }
        if probe && self.known == [true; 3] && (0..3).all(|i| (target[i] - self.pos[i]).abs() < 1e-9) {
            return fail(col, 33, "a probe to where the tool already is");
        }
        if arc_mode {
            let (mut arc, turns) = self.arc(p, m, target, target_known, k)?;
            if inverse {
                arc.feed_mm_min = arc.length_mm(self.pos) * feed;
            }
            return Ok(Some(Motion::Arc { arc, turns }));
        }
        let feed_mm_min = match m.motion {
            MotionMode::Rapid => 0.0,
            _ if inverse => (0..3).map(|i| (target[i] - self.pos[i]).powi(2)).sum::<f64>().sqrt() * feed,
            _ => feed,
        };
        Ok(Some(Motion::Line {
            mode: m.motion,
            to: target,
            feed_mm_min,
        }))
    }

    /// An arc in the block's plane from the parser position to `target`, with GRBL 1.1's arc errors
    /// (`gc_execute_line`): 32 without an in-plane axis word. In radius form (`R`, [`Arc::center_from_radius`]):
    /// 33 when the end is the start, 34 when the chord is longer than the diameter, then 36 when offsets came
    /// too. In offset form (`I J` in G17, `K I` in G18, `J K` in G19): 35 without an in-plane offset, 33 when
    /// the end radius differs from the start's by more than 0.005 mm and either 0.5 mm or 0.1%. LinuxCNC reads
    /// absolute centres (G90.1), extra turns (`P`) and full circles without axis words, tolerates a radius
    /// short of half the chord by a micrometre, refuses an offset normal to the plane and a radius difference
    /// over max(0.002 mm, 0.1%). Positions not yet known skip the checks that need them.
    fn arc(
        &self,
        p: &Parsed,
        m: &Modal,
        target: P3,
        target_known: [bool; 3],
        k: f64,
    ) -> Result<(Arc, u32), BlockError> {
        let linuxcnc = self.dialect == Dialect::Linuxcnc;
        let plane = Plane::from_g(m.plane);
        let (a, b, n) = plane.axes();
        let col = command_column(p);
        let axes = p.axes();
        let ijk = p.offsets();
        let letter = |i: usize| ['I', 'J', 'K'][i];
        if linuxcnc {
            if let Some((_, c)) = p.get(letter(n)) {
                return fail(
                    c,
                    20,
                    format!("`{}` is not an offset in the G{} plane", letter(n), m.plane),
                );
            }
        }
        let turns = match p.get('P') {
            Some((pv, c)) if linuxcnc => {
                if pv < 1.0 || pv.fract() != 0.0 || pv > 1e6 {
                    return fail(c, 20, format!("arc turns P{pv} must be a positive whole number"));
                }
                pv as u32 - 1
            }
            _ => 0,
        };
        let radius = p.get('R');
        if let (true, Some((_, c)), true) = (linuxcnc, radius, ijk[a].is_some() || ijk[b].is_some()) {
            return fail(c, 20, "an arc takes `R` or `I`/`J`, not both");
        }
        let in_plane_axis = axes[a].is_some() || axes[b].is_some();
        if !in_plane_axis && (!linuxcnc || radius.is_some()) {
            let c = radius.map_or(col, |r| r.1);
            return fail(
                c,
                32,
                "an arc needs an axis word in its plane (a full circle needs I/J)",
            );
        }
        let cw = m.motion == MotionMode::ArcCw;
        let from = self.pos;
        let known = |t: &[bool; 3]| t[a] && t[b];
        let positions_known = known(&self.known) && known(&target_known);
        let center = match radius {
            Some((r, c)) => {
                let d = (target[a] - from[a]).hypot(target[b] - from[b]);
                if positions_known && (target == from || (linuxcnc && d < 1e-9)) {
                    return fail(c, 33, "an `R` arc whose end is its start (a full circle needs I/J)");
                }
                let center = match Arc::center_from_radius(from, target, plane, r * k, cw) {
                    Some(center) => center,
                    None if !positions_known => from,
                    None if d == 0.0 => return fail(c, 33, R_ARC_WITHOUT_TRAVEL),
                    // LinuxCNC tolerates a radius a micrometre short of half the chord: the centre is its middle
                    None if linuxcnc && r.abs() * k >= d / 2.0 - 1e-6_f64.max(1e-6 * d) => {
                        let mut c = from;
                        c[a] = (from[a] + target[a]) / 2.0;
                        c[b] = (from[b] + target[b]) / 2.0;
                        c
                    }
                    None => {
                        let msg = format!(
                            "radius {} mm is less than half the chord, {:.6} mm",
                            r.abs() * k,
                            d / 2.0
                        );
                        return fail(c, 34, msg);
                    }
                };
                if ijk.iter().any(Option::is_some) {
                    return fail(c, 36, "an arc takes `R` or `I`/`J`, not both");
                }
                center
            }
            None => {
                if ijk[a].is_none() && ijk[b].is_none() {
                    return fail(col, 35, "G2/G3 needs `I`/`J` (centre) or `R` (radius)");
                }
                let off = |i: usize| ijk[i].unwrap_or(0.0) * k;
                let mut center = from;
                if m.arc_distance == Distance::Absolute {
                    let wco = self.offsets.wco();
                    (center[a], center[b]) = (off(a) + wco[a], off(b) + wco[b]);
                } else {
                    (center[a], center[b]) = (from[a] + off(a), from[b] + off(b));
                }
                if positions_known {
                    self.check_radius(from, target, center, plane, col)?;
                }
                center
            }
        };
        let arc = Arc {
            to: target,
            center,
            plane,
            cw,
            feed_mm_min: m.feed_mm_min.unwrap_or(0.0),
        };
        Ok((arc, turns))
    }

    /// The end's radius against the start's (offset form): GRBL's `error:33` beyond 0.005 mm and either 0.5 mm
    /// or 0.1% of the radius; LinuxCNC's beyond max(0.002 mm, 0.1%), and no arc of zero radius.
    fn check_radius(&self, from: P3, to: P3, center: P3, plane: Plane, col: usize) -> Result<(), BlockError> {
        let (a, b, _) = plane.axes();
        let r0 = (from[a] - center[a]).hypot(from[b] - center[b]);
        let r1 = (to[a] - center[a]).hypot(to[b] - center[b]);
        let dr = (r1 - r0).abs();
        let too_far = match self.dialect {
            Dialect::Grbl => dr > 0.005 && (dr > 0.5 || dr > 0.001 * r0),
            Dialect::Linuxcnc => {
                if r0 < 1e-9 {
                    return fail(col, 33, "arc of zero radius (the centre is the start point)");
                }
                dr > 0.002_f64.max(1e-3 * r0)
            }
        };
        if too_far {
            let tol = match self.dialect {
                Dialect::Grbl => "0.005 mm and either 0.5 mm or 0.1%",
                Dialect::Linuxcnc => "max(0.002 mm, 0.1%)",
            };
            return fail(
                col,
                33,
                format!(
                    "radius to the end ({r1:.6} mm) differs from radius to the start ({r0:.6} mm) by more than {tol}"
                ),
            );
        }
        Ok(())
    }

    /// The motion's geometry is known: its target and, for an arc, its start in the plane.
    fn geometry_known(&self, p: &Parsed, m: &Modal, target_known: [bool; 3]) -> bool {
        if matches!(p.non_modal, Some((NonModal::GoStored(_), _))) {
            return self.frame_known && target_known == [true; 3];
        }
        let (a, b, _) = Plane::from_g(m.plane).axes();
        let start = !m.motion.is_arc() || (self.known[a] && self.known[b]);
        start && target_known == [true; 3]
    }

    /// Apply a valid block: offsets, feed mode, modal state (a program end resets part of it, as GRBL 1.1h
    /// does: G1, G17, G90, G94, G54, M5, M9) and the parser position.
    fn commit(&mut self, step: &Step, offsets: Offsets, inverse: bool, target_known: [bool; 3]) {
        let p = &step.parsed;
        let select_before = self.offsets.select;
        self.offsets = offsets;
        self.inverse_time = inverse && !p.program_end;
        self.modal = step.modal;
        if p.program_end {
            self.offsets.select = 0;
            self.modal = Modal {
                units: step.modal.units,
                feed_mm_min: step.modal.feed_mm_min,
                spindle_rpm: step.modal.spindle_rpm,
                motion: MotionMode::Linear,
                ..Modal::default()
            };
        }
        if let Some(mo) = &step.motion {
            self.pos = mo.end();
            self.known = match mo {
                Motion::Stored { .. } => [self.frame_known; 3],
                Motion::Arc { .. } if !step.geometry_known => [false; 3],
                _ => target_known,
            };
        }
        if !self.frame_known {
            self.follow_offsets(p, select_before);
        }
    }

    /// Without the controller's frame, which axes of the work position survive the block's offset changes:
    /// G92 and G10 L20 on the system in force set the work position to the axis words (known from then on);
    /// an absolute G10 L2 of the system in force, a switch of system, G92.1, a tool length offset and a
    /// program end (back to G54) move the work origin by what the model cannot know.
    fn follow_offsets(&mut self, p: &Parsed, select_before: usize) {
        let given = p.axes().map(|a| a.is_some());
        let in_force = |pv: Option<f64>| {
            pv.unwrap_or(0.0).trunc() as usize == 0 || pv.map(|v| v as usize - 1) == Some(select_before)
        };
        match p.non_modal.map(|n| n.0) {
            Some(NonModal::SetOffset) => (0..3).for_each(|i| self.known[i] |= given[i]),
            Some(NonModal::SetCoord) if in_force(p.value('P')) => {
                let relative = p.value('L') == Some(20.0);
                (0..3).filter(|&i| given[i]).for_each(|i| self.known[i] = relative);
            }
            Some(NonModal::ClearOffset) => self.known = [false; 3],
            _ => {}
        }
        if self.offsets.select != select_before {
            self.known = [false; 3];
        }
        if matches!(p.tool_length, Some((ToolLength::Dynamic | ToolLength::Cancel, _))) {
            self.known[2] = false;
        }
    }
}

/// The column a block-level error points at: the block's motion word, else its first axis word, else its
/// first arc word, else the start.
fn command_column(p: &Parsed) -> usize {
    p.motion
        .map(|m| m.1)
        .or_else(|| p.first_column(&['X', 'Y', 'Z']))
        .or_else(|| p.first_column(&['I', 'J', 'K', 'R']))
        .unwrap_or(0)
}
