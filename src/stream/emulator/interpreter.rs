//! The G-code interpreter (GRBL's `gc_execute_line`, `gcode.c`) for the modelled subset: words from
//! [`program::words`](crate::stream::program::words), modal groups and GRBL's error codes, the modal state
//! as a [`program::Modal`](crate::stream::program::Modal), targets in absolute or incremental mm or inches,
//! arcs in G17, G18 and G19 (I J K offsets) checked for radius, soft limits, and the hand-over of the resulting motion to the
//! planner. Work coordinates as GRBL 1.1h keeps them: G54–G59 (set by G10 L2/L20), the G92 offset (G92.1
//! clears it), the G43.1 tool length offset (G49 cancels it), G53 machine moves, G28/G30 (stored by
//! G28.1/G30.1; with axis words through an intermediate point, and then only those axes). Words outside the
//! subset answer `error:20` and are logged as not modelled.

use std::collections::HashSet;

use super::controller::{Controller, State};
use super::line_reader::leading_line_number;
use super::planner::{BlockKind, Moves, Waiting};
use crate::gcode::moves::{Arc, Plane};
use crate::stream::program::{self, Distance, Modal, MotionMode, Spindle, Units, MAX_LINE_NUMBER};

/// The modal group of G90.1/G91.1 (GRBL's `MODAL_GROUP_G4`; the other ids here are GRBL's group numbers).
const GROUP_ARC_DISTANCE: u8 = 104;
/// G modal group 7 (cutter radius compensation), numbered apart from the M groups.
const GROUP_CUTTER_COMP: u8 = 107;
/// G modal group 8 (tool length offset), numbered apart from the M groups.
const GROUP_TOOL_LENGTH: u8 = 108;
/// G modal group 13 (path control mode), numbered apart from the M groups.
const GROUP_CONTROL_MODE: u8 = 113;

/// GRBL's non-modal commands of group 0 that the emulator models (G4 is `Parsed::dwell`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum NonModal {
    /// G10 (with L2 or L20): set a coordinate system's offset.
    SetCoord,
    /// G28 (`0`) or G30 (`1`): go to the stored position.
    GoStored(usize),
    /// G28.1 (`0`) or G30.1 (`1`): store the current position.
    SetStored(usize),
    /// G53: this block's move in machine coordinates.
    Machine,
    /// G92: set the offset so the current position reads as the axis words.
    SetOffset,
    /// G92.1: clear it.
    ClearOffset,
}

/// A block's words sorted by what they do, with the modal changes they make already applied to a copy of
/// the parser's modal state (GRBL's steps 1–2: parse, and check each word on its own).
#[derive(Debug, Default)]
struct Parsed {
    /// Group 1 motion word in this block.
    motion: Option<MotionMode>,
    /// G4.
    dwell: bool,
    /// A spindle or coolant change (GRBL runs them synchronised with the planner).
    sync: bool,
    /// M2 / M30.
    program_end: bool,
    /// M0: a program pause (M1, the optional stop, GRBL ignores).
    program_pause: bool,
    /// One of G0–G3 (GRBL's `AXIS_COMMAND_MOTION_MODE`).
    axis_command: bool,
    /// M7, which only a build with `ENABLE_M7` accepts.
    mist_word: bool,
    /// A group-0 command that uses or changes coordinates.
    non_modal: Option<NonModal>,
    /// G54–G59 (0–5).
    coord_select: Option<usize>,
    /// G43.1 (`Some(true)`) or G49 (`Some(false)`).
    tool_length: Option<bool>,
    /// G93 (`Some(true)`, inverse time) or G94 (`Some(false)`).
    feed_mode: Option<bool>,
    l: Option<f64>,
    axis: [Option<f64>; 3],
    ijk: [Option<f64>; 3],
    f: Option<f64>,
    s: Option<f64>,
    p: Option<f64>,
    /// An arc's radius (`R`, the radius form), in the block's units.
    r: Option<f64>,
    groups: HashSet<u8>,
    seen: HashSet<char>,
}

impl Parsed {
    /// Sort the block's `(letter, value)` words, applying modal words to `m`; `Err` is GRBL's error code
    /// for the first word that is wrong on its own.
    fn new(words: impl IntoIterator<Item = (char, f64)>, m: &mut Modal) -> Result<Parsed, u16> {
        let mut p = Parsed::default();
        for (letter, v) in words {
            let int = v.trunc();
            let mantissa = ((v - int) * 10.0).round() as i32;
            match letter {
                'G' => p.g_word(int as i32, mantissa, m)?,
                'M' => p.m_word(int as i32, mantissa, m)?,
                letter => p.value_word(letter, v)?,
            }
        }
        Ok(p)
    }

    /// Two words of one modal group in a block: `error:21`.
    fn group(&mut self, g: u8) -> Result<(), u16> {
        if self.groups.insert(g) {
            Ok(())
        } else {
            Err(21)
        }
    }

    fn g_word(&mut self, g: i32, mantissa: i32, m: &mut Modal) -> Result<(), u16> {
        match (g, mantissa) {
            (0..=3, 0) | (80, 0) => {
                // Two of G0–G3 (or one and G10/G28/G30/G92) want the axis words: GRBL's axis command
                // conflict comes first.
                if g <= 3 && self.axis_command {
                    return Err(24);
                }
                self.axis_command |= g <= 3;
                self.group(1)?;
                self.motion = Some(match g {
                    0 => MotionMode::Rapid,
                    1 => MotionMode::Linear,
                    2 => MotionMode::ArcCw,
                    3 => MotionMode::ArcCcw,
                    _ => MotionMode::Cancel,
                });
            }
            (4, 0) => {
                self.group(0)?;
                self.dwell = true;
            }
            (17..=19, 0) => {
                self.group(2)?;
                m.plane = g as u8;
            }
            (20 | 21, 0) => {
                self.group(6)?;
                m.units = if g == 20 { Units::Inch } else { Units::Mm };
            }
            (90 | 91, 0) => {
                self.group(3)?;
                m.distance = if g == 91 {
                    Distance::Incremental
                } else {
                    Distance::Absolute
                };
            }
            (93 | 94, 0) => {
                self.group(5)?;
                self.feed_mode = Some(g == 93);
            }
            // G91.1 (incremental I/J, GRBL's only arc mode) is accepted and does nothing; G90.1 is not.
            (91, 1) => self.group(GROUP_ARC_DISTANCE)?,
            (90, 1) => return Err(20),
            (54..=59, 0) => {
                self.group(12)?;
                self.coord_select = Some((g - 54) as usize);
            }
            // G40 is GRBL's only cutter-compensation mode: accepted (a machinist's safety line carries it)
            (40, 0) => self.group(GROUP_CUTTER_COMP)?,
            (49, 0) | (43, 1) => {
                self.group(GROUP_TOOL_LENGTH)?;
                // GRBL counts G43.1 and G49 as axis commands (AXIS_COMMAND_TOOL_LENGTH_OFFSET)
                if self.axis_command {
                    return Err(24);
                }
                self.axis_command = true;
                self.tool_length = Some(g == 43);
            }
            (43, _) => return Err(20),
            (10, 0) | (28, 0 | 1) | (30, 0 | 1) | (53, 0) | (92, 0 | 1) => {
                self.group(0)?;
                let nm = match (g, mantissa) {
                    (10, _) => NonModal::SetCoord,
                    (28, 0) => NonModal::GoStored(0),
                    (30, 0) => NonModal::GoStored(1),
                    (28, _) => NonModal::SetStored(0),
                    (30, _) => NonModal::SetStored(1),
                    (53, _) => NonModal::Machine,
                    (92, 0) => NonModal::SetOffset,
                    _ => NonModal::ClearOffset,
                };
                // G10, G28/G30 and G92 take the axis words (GRBL's AXIS_COMMAND_NON_MODAL): with G0–G3 in
                // the same block that is an axis command conflict
                if matches!(nm, NonModal::SetCoord | NonModal::GoStored(_) | NonModal::SetOffset) {
                    if self.axis_command {
                        return Err(24);
                    }
                    self.axis_command = true;
                }
                self.non_modal = Some(nm);
            }
            (28 | 30 | 92, _) => return Err(20),
            // G61 (exact path) is GRBL's only path control mode: accepted and does nothing; G61.1 and G64
            // are not supported (error:20)
            (61, 0) => self.group(GROUP_CONTROL_MODE)?,
            (61, _) => return Err(20),
            // G38.2–G38.5 probing: a motion mode (group 1) and an axis command, as G0–G3
            (38, 2..=5) => {
                if self.axis_command {
                    return Err(24);
                }
                self.axis_command = true;
                self.group(1)?;
                self.motion = Some(MotionMode::Probe {
                    away: mantissa >= 4,
                    no_error: mantissa % 2 == 1,
                });
            }
            (38, _) => return Err(20),
            (_, 0) => return Err(20),
            _ => return Err(23),
        }
        Ok(())
    }

    fn m_word(&mut self, code: i32, mantissa: i32, m: &mut Modal) -> Result<(), u16> {
        if mantissa != 0 {
            return Err(23);
        }
        match code {
            0 | 1 | 2 | 30 => {
                self.group(4)?;
                self.program_end = matches!(code, 2 | 30);
                self.program_pause = code == 0;
            }
            3..=5 => {
                self.group(7)?;
                m.spindle = match code {
                    3 => Spindle::Cw,
                    4 => Spindle::Ccw,
                    _ => Spindle::Off,
                };
                self.sync = true;
            }
            7 => {
                self.mist_word = true;
                m.mist = true;
                self.sync = true;
            }
            8 => {
                m.flood = true;
                self.sync = true;
            }
            9 => {
                m.mist = false;
                m.flood = false;
                self.sync = true;
            }
            _ => return Err(20),
        }
        Ok(())
    }

    /// A word with a value (axes, offsets, F, S, P, N, T): each at most once per block.
    fn value_word(&mut self, letter: char, v: f64) -> Result<(), u16> {
        if !self.seen.insert(letter) {
            return Err(25);
        }
        match letter {
            'X' => self.axis[0] = Some(v),
            'Y' => self.axis[1] = Some(v),
            'Z' => self.axis[2] = Some(v),
            'I' => self.ijk[0] = Some(v),
            'J' => self.ijk[1] = Some(v),
            'K' => self.ijk[2] = Some(v),
            'F' => self.f = Some(v),
            'S' => self.s = Some(v),
            'P' => self.p = Some(v),
            'N' => {
                if !(0.0..=MAX_LINE_NUMBER as f64).contains(&v) {
                    return Err(27);
                }
            }
            'T' => {}
            'L' => self.l = Some(v),
            'R' => self.r = Some(v),
            _ => return Err(20),
        }
        if matches!(letter, 'F' | 'S' | 'P' | 'T' | 'N') && v < 0.0 {
            return Err(4);
        }
        Ok(())
    }

    fn has_axis(&self) -> bool {
        self.axis.iter().any(Option::is_some)
    }

    /// The checks across words (GRBL's step 3), once the block's modal state `m` is known.
    fn check(&self, m: &Modal) -> Result<(), u16> {
        let has_axis = self.has_axis();
        if self.dwell && self.p.is_none() {
            return Err(28);
        }
        match self.non_modal {
            Some(NonModal::SetCoord) => {
                // GRBL's order: no axis words 26, P or L missing 28, P beyond G59 29, L not 2 or 20: 20
                if !has_axis {
                    return Err(26);
                }
                let (Some(p), Some(l)) = (self.p, self.l) else {
                    return Err(28);
                };
                if p.trunc() > 6.0 {
                    return Err(29);
                }
                if l != 2.0 && l != 20.0 {
                    return Err(20);
                }
            }
            Some(NonModal::SetOffset) if !has_axis => return Err(26),
            Some(NonModal::Machine) if !matches!(m.motion, MotionMode::Rapid | MotionMode::Linear) => return Err(30),
            _ => {}
        }
        let g10 = self.non_modal == Some(NonModal::SetCoord);
        if self.p.is_some() && !self.dwell && !g10 {
            return Err(36);
        }
        if self.l.is_some() && !g10 {
            return Err(36);
        }
        match self.tool_length {
            // G43.1 takes exactly the Z word (GRBL's TOOL_LENGTH_OFFSET_AXIS)
            Some(true) if self.axis[2].is_none() || self.axis[0].is_some() || self.axis[1].is_some() => return Err(37),
            // G49 is an axis command too: its axis words are used up, and ignored
            _ => {}
        }
        // G10, G92 and G43.1 consume the axis words: no motion check applies to them
        if g10 || self.non_modal == Some(NonModal::SetOffset) || self.tool_length.is_some() {
            return Ok(());
        }
        if has_axis && m.motion == MotionMode::Cancel {
            return Err(31);
        }
        Ok(())
    }

    /// GRBL's last check (step 3, "non-specific"), after the motion's own: offsets or a radius that no arc
    /// used are unused words (an arc in radius form with offsets too fails it in `Controller::arc`).
    fn unused_words(&self, m: &Modal) -> Result<(), u16> {
        let arc = self.has_axis() && matches!(m.motion, MotionMode::ArcCw | MotionMode::ArcCcw);
        if (self.ijk.iter().any(Option::is_some) || self.r.is_some()) && !arc {
            return Err(36);
        }
        Ok(())
    }
}

impl Controller {
    /// Parse and run one G-code block; `Err(code)` is GRBL's error code.
    pub(super) fn gcode(&mut self, text: &str) -> Result<(), u16> {
        let ws = program::words(text).map_err(|e| e.grbl_code())?;
        let mut m = self.modal;
        let parsed = Parsed::new(ws.iter().map(|w| (w.letter, w.value)), &mut m)?;
        if parsed.mist_word && !self.enable_m7 {
            return Err(20); // a default build has no M7
        }
        let k = if m.units == Units::Inch { 25.4 } else { 1.0 };
        let inverse = parsed.feed_mode.unwrap_or(self.inverse_time);
        if inverse {
            // G93: F is this block's 1/minutes, and the feed is undefined after it unless the next block
            // gives one (GRBL zeroes it before and after every inverse-time block)
            m.feed_mm_min = parsed.f;
        } else if self.inverse_time {
            // back to G94: the last feed is not carried over
            m.feed_mm_min = parsed.f.map(|f| f * k);
        } else if let Some(f) = parsed.f {
            m.feed_mm_min = Some(f * k);
        }
        if let Some(s) = parsed.s {
            m.spindle_rpm = s;
        }
        if let Some(mm) = parsed.motion {
            m.motion = mm;
        }
        // GRBL checks G93's F word first, for any motion-mode axis command, G0 included (its condition
        // `motion != NONE || motion != SEEK` is always true)
        let motion_axis_command = parsed.has_axis()
            && parsed.tool_length.is_none()
            && !matches!(
                parsed.non_modal,
                Some(NonModal::SetCoord | NonModal::SetOffset | NonModal::GoStored(_))
            );
        if inverse && motion_axis_command && parsed.f.is_none() {
            return Err(22);
        }
        parsed.check(&m)?;
        let select = parsed.coord_select.unwrap_or(self.coord_select);
        let (coord, g92, stored, tlo) = self.offsets_after(&parsed, select, k);
        // the axis words as a target: machine mm for G53, else work coordinates through the block's system
        // (a G10 that changes `coord` uses up the block's axis words, so the old table serves the target)
        let target = self.axis_target(
            parsed.axis,
            k,
            parsed.non_modal == Some(NonModal::Machine),
            m.distance == Distance::Incremental,
            self.wco_of(select, g92, tlo),
        );
        let consumed =
            matches!(parsed.non_modal, Some(NonModal::SetCoord | NonModal::SetOffset)) || parsed.tool_length.is_some();
        let moves = if consumed {
            None
        } else if let Some(NonModal::GoStored(w)) = parsed.non_modal {
            self.go_stored(&parsed, stored[w], target, leading_line_number(text).unwrap_or(0))
        } else {
            self.motion(&parsed, &m, target, k, text, inverse)?
        };
        parsed.unused_words(&m)?;
        let end = match (&moves, parsed.non_modal) {
            (_, Some(NonModal::GoStored(w))) => Some(self.stored_target(&parsed, stored[w])),
            (Some(blocks), _) => blocks.back().map(|b| b.to),
            (None, _) => None,
        };
        (self.coord, self.g92, self.stored, self.tlo, self.coord_select) = (coord, g92, stored, tlo, select);
        self.inverse_time = inverse;
        if parsed.program_end {
            // M2/M30 select G54 and G94 again
            self.coord_select = 0;
            self.inverse_time = false;
        }
        self.modal = m;
        self.hand_over(&parsed, &m, end.unwrap_or(self.parser_pos), moves);
        Ok(())
    }

    /// The coordinate data after this block's G10, G92/G92.1, G28.1/G30.1 and G43.1/G49, in GRBL's
    /// relations `WPos = MPos − WCS − G92 − TLO` (L20: `WCS = MPos − G92 − TLO − value`; G92:
    /// `G92 = MPos − WCS − TLO − value`); `(G54–G59, G92, G28/G30, TLO)`.
    #[allow(clippy::type_complexity)]
    fn offsets_after(&self, parsed: &Parsed, select: usize, k: f64) -> ([[f64; 3]; 6], [f64; 3], [[f64; 3]; 2], f64) {
        let (mut coord, mut g92, mut stored, mut tlo) = (self.coord, self.g92, self.stored, self.tlo);
        let z_tlo = |i: usize| if i == 2 { self.tlo } else { 0.0 };
        let pos = self.parser_pos;
        match parsed.non_modal {
            Some(NonModal::SetCoord) => {
                let p = parsed.p.unwrap_or(0.0).trunc() as usize;
                let idx = if p > 0 { p - 1 } else { select };
                for i in 0..3 {
                    if let Some(v) = parsed.axis[i] {
                        coord[idx][i] = if parsed.l == Some(20.0) {
                            pos[i] - self.g92[i] - z_tlo(i) - v * k
                        } else {
                            v * k
                        };
                    }
                }
            }
            Some(NonModal::SetOffset) => {
                for i in 0..3 {
                    if let Some(v) = parsed.axis[i] {
                        g92[i] = pos[i] - self.coord[select][i] - z_tlo(i) - v * k;
                    }
                }
            }
            Some(NonModal::ClearOffset) => g92 = [0.0; 3],
            Some(NonModal::SetStored(w)) => stored[w] = pos,
            _ => {}
        }
        match parsed.tool_length {
            Some(true) => tlo = parsed.axis[2].unwrap_or(0.0) * k,
            Some(false) => tlo = 0.0,
            None => {}
        }
        (coord, g92, stored, tlo)
    }

    /// Where G28/G30 ends: the stored position, only on the axes the block names when it names any
    /// (GRBL 1.1: "move only the axes specified in secondary move").
    fn stored_target(&self, parsed: &Parsed, stored: [f64; 3]) -> [f64; 3] {
        let mut home = stored;
        if parsed.has_axis() {
            for (i, h) in home.iter_mut().enumerate() {
                if parsed.axis[i].is_none() {
                    *h = self.parser_pos[i];
                }
            }
        }
        home
    }

    /// G28/G30's rapids: to the intermediate point (the axis words, if any) and on to the stored position
    /// (`None` when neither moves). Each is checked against the soft limits as it is planned.
    fn go_stored(&mut self, parsed: &Parsed, stored: [f64; 3], via: [f64; 3], line: u32) -> Option<Moves> {
        let home = self.stored_target(parsed, stored);
        let first = self.block(BlockKind::Rapid, via, 0.0, line);
        let second = self.block_from(via, BlockKind::Rapid, home, 0.0, line);
        let blocks: Moves = [first, second].into_iter().filter(|b| b.duration_s > 0.0).collect();
        (!blocks.is_empty()).then_some(blocks)
    }

    /// The block's move to `target` (machine mm; `k` converts the block's units to mm), checked, as the
    /// planner blocks it becomes (`None`: it does not move). In inverse time (`inverse`, G93) the feed is
    /// `F` per minute of the block: it takes `1/F` minutes (or longer, when an axis' maximum rate limits
    /// it). An arc becomes GRBL's chords ([`Controller::arc_chords`]).
    #[allow(clippy::too_many_arguments)]
    fn motion(
        &mut self,
        parsed: &Parsed,
        m: &Modal,
        target: [f64; 3],
        k: f64,
        text: &str,
        inverse: bool,
    ) -> Result<Option<Moves>, u16> {
        let probe = matches!(m.motion, MotionMode::Probe { .. });
        let feed = m.feed_mm_min.unwrap_or(0.0);
        if !parsed.has_axis() {
            // GRBL: a G2, G3 or G38.x word without axis words needs a feed (22), then is an error (26); a
            // modal motion without axis words, or G0/G1 alone, just stays
            let needs_axes = probe || matches!(m.motion, MotionMode::ArcCw | MotionMode::ArcCcw);
            return match (needs_axes && parsed.motion.is_some(), feed > 0.0) {
                (false, _) => Ok(None),
                (true, false) => Err(22),
                (true, true) => Err(26),
            };
        }
        if m.motion != MotionMode::Rapid && feed <= 0.0 {
            return Err(22);
        }
        let arc = match m.motion {
            MotionMode::ArcCw | MotionMode::ArcCcw => Some(self.arc(parsed, m, target, k, text)?),
            _ => None,
        };
        if probe && (0..3).all(|i| (target[i] - self.parser_pos[i]).abs() < 1e-9) {
            return Err(33); // a probe to where the tool already is: invalid target
        }
        let line = leading_line_number(text).unwrap_or(0);
        let kind = if m.motion == MotionMode::Rapid {
            BlockKind::Rapid
        } else {
            BlockKind::Linear
        };
        let feed = if inverse && kind != BlockKind::Rapid {
            // F is 1/minutes for the whole move: its feed in mm/min is its length · F
            let length_mm = match &arc {
                Some(a) => a.length_mm(self.parser_pos),
                None => (0..3)
                    .map(|i| (target[i] - self.parser_pos[i]).powi(2))
                    .sum::<f64>()
                    .sqrt(),
            };
            length_mm * feed
        } else {
            feed
        };
        let blocks: Moves = match arc {
            Some(a) => self.arc_chords(&a, feed, line),
            None => [self.block(kind, target, feed, line)].into(),
        };
        let blocks: Moves = blocks.into_iter().filter(|b| b.duration_s > 0.0).collect();
        Ok((!blocks.is_empty()).then_some(blocks))
    }

    /// GRBL's `mc_arc`: the arc from the parser position as its [`Arc::grbl_chords`] chords for `$12`, ends on
    /// the arc, each a linear block at `feed_mm_min` (the last ends exactly at the arc's end). GRBL rotates the
    /// radius vector in single precision with a correction every 12 chords; the ends here are exact, within
    /// 10⁻⁶ mm of it.
    fn arc_chords(&self, arc: &Arc, feed_mm_min: f64, line: u32) -> Moves {
        let from = self.parser_pos;
        let count = arc.grbl_chords(from, self.setting(12));
        let mut blocks = Moves::with_capacity(count.max(1));
        let mut at = from;
        for i in 1..count {
            let pt = arc.point_at(from, i as f64 / count as f64);
            blocks.push_back(self.block_from(at, BlockKind::Linear, pt, feed_mm_min, line));
            at = pt;
        }
        blocks.push_back(self.block_from(at, BlockKind::Linear, arc.to, feed_mm_min, line));
        blocks
    }

    /// An arc in the block's plane from the parser position to `target`, with GRBL 1.1's arc errors
    /// (`gc_execute_line`): 32 without an in-plane axis word. In radius form (`R`, [`Arc::center_from_radius`]):
    /// 33 when the end is the start, 34 when the chord is longer than the diameter, then 36 when offsets
    /// came too (only `R` is used). In offset form (`I J` in G17, `K I` in G18, `J K` in G19): 35 without an
    /// in-plane offset (one normal to the plane is read and ignored, as GRBL clears all three), 33 when the
    /// end radius differs from the start's by more than 0.005 mm and either 0.5 mm or 0.1%.
    fn arc(&mut self, parsed: &Parsed, m: &Modal, target: [f64; 3], k: f64, text: &str) -> Result<Arc, u16> {
        let plane = Plane::from_g(m.plane);
        let (a, b, _) = plane.axes();
        let (axis, ijk) = (parsed.axis, parsed.ijk);
        if axis[a].is_none() && axis[b].is_none() {
            return Err(32);
        }
        let cw = m.motion == MotionMode::ArcCw;
        let from = self.parser_pos;
        let center = if let Some(r) = parsed.r {
            if target == from {
                return Err(33);
            }
            let Some(center) = Arc::center_from_radius(from, target, plane, r * k, cw) else {
                if (target[a] - from[a]).hypot(target[b] - from[b]) == 0.0 {
                    // a helix along the normal alone: GRBL divides by the zero chord and plans a NaN centre
                    self.log.events.push(format!(
                        "not modelled: an `R` arc with no travel in its plane in `{text}`"
                    ));
                    return Err(33);
                }
                return Err(34);
            };
            if ijk.iter().any(Option::is_some) {
                return Err(36);
            }
            center
        } else {
            if ijk[a].is_none() && ijk[b].is_none() {
                return Err(35);
            }
            let c = [from[a] + ijk[a].unwrap_or(0.0) * k, from[b] + ijk[b].unwrap_or(0.0) * k];
            let r0 = (from[a] - c[0]).hypot(from[b] - c[1]);
            let r1 = (target[a] - c[0]).hypot(target[b] - c[1]);
            let dr = (r1 - r0).abs();
            if dr > 0.005 && (dr > 0.5 || dr > 0.001 * r0) {
                return Err(33);
            }
            let mut center = [0.0; 3];
            (center[a], center[b]) = (c[0], c[1]);
            center
        };
        Ok(Arc {
            to: target,
            center,
            plane,
            cw,
            feed_mm_min: m.feed_mm_min.unwrap_or(0.0),
        })
    }

    /// What happens to a valid block: in check mode only its `ok`; spindle, coolant, dwell and program
    /// end wait for the planner to empty, then their motion is planned; plain motion waits for planner
    /// space. The parser moves on to `target` at once.
    fn hand_over(&mut self, parsed: &Parsed, m: &Modal, target: [f64; 3], blocks: Option<Moves>) {
        self.parser_pos = target;
        if self.state == State::Check {
            // no motion is planned in check mode, but soft limits still alarm (GRBL's `mc_line`)
            if blocks.iter().flatten().any(|b| self.beyond_soft_limits(b.to)) {
                self.alarm(2);
            } else {
                self.say("ok");
            }
            return;
        }
        if parsed.program_end {
            self.modal = Modal {
                units: m.units,
                feed_mm_min: m.feed_mm_min,
                spindle_rpm: m.spindle_rpm,
                motion: MotionMode::Linear,
                ..Modal::default()
            };
        }
        // GRBL's order within a block: spindle, coolant and dwell first (each waits for the planner to
        // empty), then the motion (a probe runs alone), then the program flow — an end or a pause — which
        // waits for the motion to finish
        let end = if parsed.program_end {
            Some(Box::new(Waiting::End))
        } else if parsed.program_pause {
            Some(Box::new(Waiting::Pause { held: false }))
        } else {
            None
        };
        let motion = match (blocks, m.motion) {
            (Some(mut blocks), MotionMode::Probe { away, no_error }) => {
                blocks.pop_front().map(|block| Waiting::Probe {
                    block,
                    away,
                    no_error,
                    started: false,
                    then: end.clone(),
                })
            }
            (Some(blocks), _) => Some(Waiting::Plan {
                blocks,
                then: end.clone(),
            }),
            (None, _) => end.clone().map(|e| *e),
        };
        self.waiting = if parsed.sync || parsed.dwell {
            Some(Waiting::Sync {
                dwell_s: if parsed.dwell { parsed.p.unwrap_or(0.0) } else { 0.0 },
                then: motion.map(Box::new),
            })
        } else {
            motion
        };
        if self.waiting.is_none() {
            self.say("ok");
        }
    }
}
