//! The G-code interpreter (GRBL's `gc_execute_line`, `gcode.c`) for the modelled subset: words from
//! [`program::words`](crate::stream::program::words), modal groups and GRBL's error codes, the modal state
//! as a [`program::Modal`](crate::stream::program::Modal), targets in absolute or incremental mm or inches,
//! arcs in G17, G18 and G19 (I J K offsets) checked for radius, soft limits, and the hand-over of the resulting motion to the
//! planner. Words outside the subset answer `error:20` and are logged as not modelled.

use std::collections::HashSet;

use super::controller::{Controller, State};
use super::line_reader::leading_line_number;
use super::planner::{Block, BlockKind, Waiting};
use crate::stream::program::{self, Distance, Modal, MotionMode, Spindle, Units, MAX_LINE_NUMBER};

/// The modal group of G90.1/G91.1 (GRBL's `MODAL_GROUP_G4`; the other ids here are GRBL's group numbers).
const GROUP_ARC_DISTANCE: u8 = 104;
/// G modal group 7 (cutter radius compensation), numbered apart from the M groups.
const GROUP_CUTTER_COMP: u8 = 107;
/// G modal group 8 (tool length offset), numbered apart from the M groups.
const GROUP_TOOL_LENGTH: u8 = 108;

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
    /// One of G0–G3 (GRBL's `AXIS_COMMAND_MOTION_MODE`).
    axis_command: bool,
    /// M7, which only a build with `ENABLE_M7` accepts.
    mist_word: bool,
    axis: [Option<f64>; 3],
    ijk: [Option<f64>; 3],
    f: Option<f64>,
    s: Option<f64>,
    p: Option<f64>,
    /// A word the emulator does not model.
    unmodelled: Option<String>,
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
                'G' => p.g_word(v, int as i32, mantissa, m)?,
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

    fn g_word(&mut self, v: f64, g: i32, mantissa: i32, m: &mut Modal) -> Result<(), u16> {
        match (g, mantissa) {
            (0..=3, 0) | (80, 0) => {
                // Two of G0–G3 both want the axis words: GRBL's axis command conflict comes first.
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
            (94, 0) => self.group(5)?,
            // G91.1 (incremental I/J, GRBL's only arc mode) is accepted and does nothing; G90.1 is not.
            (91, 1) => self.group(GROUP_ARC_DISTANCE)?,
            (90, 1) => return Err(20),
            (54, 0) => self.group(12)?,
            // G40 is GRBL's only cutter-compensation mode and G49 cancels a tool-length offset the emulator
            // never applies: accepted, as GRBL 1.1 accepts them (a machinist's safety line carries both)
            (40, 0) => self.group(GROUP_CUTTER_COMP)?,
            (49, 0) => self.group(GROUP_TOOL_LENGTH)?,
            (10 | 28 | 30 | 53 | 92 | 38 | 43 | 61 | 93 | 55..=59, _) => {
                self.unmodelled = Some(format!("G{v}"));
            }
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
            'R' | 'L' => self.unmodelled = Some(format!("{letter} word")),
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
        if self.p.is_some() && !self.dwell {
            return Err(36);
        }
        let arc = has_axis && matches!(m.motion, MotionMode::ArcCw | MotionMode::ArcCcw);
        if self.ijk.iter().any(Option::is_some) && !arc {
            return Err(36);
        }
        if has_axis && m.motion == MotionMode::Cancel {
            return Err(31);
        }
        Ok(())
    }
}

/// The motion a block makes, if any.
enum Motion {
    /// No move (no axis word, or a zero-length one).
    None,
    /// A block for the planner.
    Block(Block),
    /// The target is outside the soft limits: `ALARM:2`.
    SoftLimit,
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
        if let Some(what) = &parsed.unmodelled {
            self.log.events.push(format!("not modelled: {what} in `{text}`"));
            return Err(20);
        }
        let k = if m.units == Units::Inch { 25.4 } else { 1.0 };
        if let Some(f) = parsed.f {
            m.feed_mm_min = Some(f * k);
        }
        if let Some(s) = parsed.s {
            m.spindle_rpm = s;
        }
        if let Some(mm) = parsed.motion {
            m.motion = mm;
        }
        parsed.check(&m)?;
        let mut target = self.parser_pos;
        for (i, t) in target.iter_mut().enumerate() {
            if let Some(v) = parsed.axis[i] {
                *t = if m.distance == Distance::Incremental {
                    *t + v * k
                } else {
                    v * k
                };
            }
        }
        let block = match self.motion(&parsed, &m, target, k, text)? {
            Motion::None => None,
            Motion::Block(b) => Some(b),
            Motion::SoftLimit => {
                self.modal = m;
                self.alarm(2);
                return Ok(());
            }
        };
        self.modal = m;
        self.hand_over(&parsed, &m, target, block);
        Ok(())
    }

    /// The block's move to `target` (machine mm; `k` converts the block's units to mm), checked.
    fn motion(&mut self, parsed: &Parsed, m: &Modal, target: [f64; 3], k: f64, text: &str) -> Result<Motion, u16> {
        if !parsed.has_axis() {
            return Ok(Motion::None);
        }
        let feed = m.feed_mm_min.unwrap_or(0.0);
        if m.motion != MotionMode::Rapid && feed <= 0.0 {
            return Err(22);
        }
        let kind = match m.motion {
            MotionMode::Rapid => BlockKind::Rapid,
            MotionMode::Linear => BlockKind::Linear,
            _ => self.arc(parsed, m, target, k, text)?,
        };
        if self.setting(20) == 1.0 {
            for (i, t) in target.iter().enumerate() {
                if *t > 0.0 || *t < -self.setting(130 + i as u16) {
                    return Ok(Motion::SoftLimit);
                }
            }
        }
        let b = self.block(kind, target, feed, leading_line_number(text).unwrap_or(0));
        Ok(if b.duration_s > 0.0 {
            Motion::Block(b)
        } else {
            Motion::None
        })
    }

    /// An arc in the block's plane (offsets `I J` in G17, `K I` in G18, `J K` in G19) from the parser
    /// position to `target`, with GRBL's arc errors: 32 without an in-plane axis word, 35 without an in-plane
    /// offset (one normal to the plane is read and ignored, as GRBL clears all three), 33 when the end radius
    /// differs from the start's by more than 0.005 mm and either 0.5 mm or 0.1% (GRBL 1.1 `gc_execute_line`).
    fn arc(&mut self, parsed: &Parsed, m: &Modal, target: [f64; 3], k: f64, _text: &str) -> Result<BlockKind, u16> {
        let (a, b, n) = crate::gcode::moves::Plane::from_g(m.plane).axes();
        let axes = [a, b, n];
        let (axis, ijk) = (parsed.axis, parsed.ijk);
        if axis[a].is_none() && axis[b].is_none() {
            return Err(32);
        }
        if ijk[a].is_none() && ijk[b].is_none() {
            return Err(35);
        }
        let c = [
            self.parser_pos[a] + ijk[a].unwrap_or(0.0) * k,
            self.parser_pos[b] + ijk[b].unwrap_or(0.0) * k,
        ];
        let r0 = (self.parser_pos[a] - c[0]).hypot(self.parser_pos[b] - c[1]);
        let r1 = (target[a] - c[0]).hypot(target[b] - c[1]);
        let dr = (r1 - r0).abs();
        if dr > 0.005 && (dr > 0.5 || dr > 0.001 * r0) {
            return Err(33);
        }
        Ok(BlockKind::Arc {
            center: c,
            cw: m.motion == MotionMode::ArcCw,
            axes,
        })
    }

    /// What happens to a valid block: in check mode only its `ok`; spindle, coolant, dwell and program
    /// end wait for the planner to empty, then their motion is planned; plain motion waits for planner
    /// space. The parser moves on to `target` at once.
    fn hand_over(&mut self, parsed: &Parsed, m: &Modal, target: [f64; 3], block: Option<Block>) {
        self.parser_pos = target;
        if self.state == State::Check {
            self.say("ok");
            return;
        }
        if parsed.sync || parsed.dwell || parsed.program_end {
            // Spindle, coolant and dwell wait for the planner to empty first (GRBL synchronises them).
            // Motion in the same block is planned after the synchronised commands.
            self.waiting = Some(Waiting::Sync {
                dwell_s: if parsed.dwell { parsed.p.unwrap_or(0.0) } else { 0.0 },
                then: block,
            });
            if parsed.program_end {
                self.modal = Modal {
                    units: m.units,
                    feed_mm_min: m.feed_mm_min,
                    spindle_rpm: m.spindle_rpm,
                    motion: MotionMode::Linear,
                    ..Modal::default()
                };
            }
            return;
        }
        match block {
            Some(b) => self.waiting = Some(Waiting::Plan(b)),
            None => self.say("ok"),
        }
    }
}
