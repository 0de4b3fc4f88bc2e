//! One block's words sorted by what they do, each checked on its own: the first half of the crate's one
//! G-code interpreter ([`super::interp`]), GRBL's steps 1–2 of `gc_execute_line` (`gcode.c`).
//!
//! The two dialects read most words alike; where they differ, [`Dialect`] says how ([`Parsed::new`]):
//!
//! | | GRBL 1.1h | LinuxCNC (the subset modelled) |
//! | --- | --- | --- |
//! | `G61.1 G64`, `G90.1`, `G43 H`, `M6`, `Q`, `H` | error 20 | path blending, absolute arc centres, the tool table's length offset, tool change |
//! | `G43.1`, `L`, `M7` | dynamic tool length, `G10`'s `L`, mist (build option `ENABLE_M7`) | — |
//! | `N` | anywhere | first on the line |
//! | a word twice, two codes of one group | error 25, error 21 (24 for two axis commands) | refused |
//! | `T` | at most 255 (error 38) | any whole number |
//!
//! Every refusal is a [`BlockError`]: the 0-based column of the word at fault, GRBL's error code for it (what
//! a GRBL controller answers; the nearest code for a LinuxCNC-only fault) and a message naming the word.

use super::lex::{g_name, tenths, Word};
use super::modal::{Distance, Modal, MotionMode, Spindle, Units};
use super::Dialect;

/// The largest line number GRBL accepts in an `N` word (`MAX_LINE_NUMBER`).
pub const MAX_LINE_NUMBER: usize = 10_000_000;

/// The largest tool number GRBL 1.1h accepts (`MAX_TOOL_NUMBER`, error 38 beyond).
pub const MAX_TOOL_NUMBER: f64 = 255.0;

/// A block the controller refuses: where, GRBL's code, and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct BlockError {
    /// 0-based column (in characters) of the word at fault, or of the word that names the block's command.
    pub column: usize,
    /// GRBL 1.1's error code for the fault (`error:N`).
    pub code: u16,
    /// What is wrong, naming the word.
    pub message: String,
}

/// A [`BlockError`].
pub(crate) fn fail<T>(column: usize, code: u16, message: impl Into<String>) -> Result<T, BlockError> {
    Err(BlockError {
        column,
        code,
        message: message.into(),
    })
}

/// The non-modal commands of group 0 that use or change coordinates (G4 is [`Parsed::dwell`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NonModal {
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

/// A tool length offset command (modal group 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ToolLength {
    /// G43.1 Z: the offset given in the block (GRBL).
    Dynamic,
    /// G43 H: the tool table's entry H (LinuxCNC).
    Table,
    /// G49: no offset.
    Cancel,
}

/// A block's words sorted by what they do, with the modal changes they make already applied to a copy of the
/// interpreter's modal state. Each command keeps the 0-based column of its word, for messages.
#[derive(Debug, Default, Clone)]
pub struct Parsed {
    /// Group 1 motion word in this block, and its column.
    pub motion: Option<(MotionMode, usize)>,
    /// G4, and its column.
    pub dwell: Option<usize>,
    /// A spindle or coolant word (GRBL runs them synchronised with the planner).
    pub sync: bool,
    /// M3, M4 or M5.
    pub spindle_word: Option<Spindle>,
    /// M2 / M30.
    pub program_end: bool,
    /// M0: a program pause (M1, the optional stop, GRBL ignores).
    pub program_pause: bool,
    /// M6, a tool change (LinuxCNC), and its column.
    pub tool_change: Option<usize>,
    /// A command that takes the axis words (GRBL's `axis_command`: G0–G3, G38.x, G10, G28, G30, G92, G43.1,
    /// G49).
    pub axis_command: bool,
    /// M7, which only a GRBL build with `ENABLE_M7` accepts, and its column.
    pub mist_word: Option<usize>,
    /// A group-0 command that uses or changes coordinates, and its column.
    pub non_modal: Option<(NonModal, usize)>,
    /// G54–G59 (0–5), and its column.
    pub coord_select: Option<(usize, usize)>,
    /// G43.1, G43 or G49, and its column.
    pub tool_length: Option<(ToolLength, usize)>,
    /// G64, LinuxCNC's path blending (its `P` and `Q` are the tolerances).
    pub blend: bool,
    /// G93 (`true`, inverse time) or G94 (`false`), and its column.
    pub feed_mode: Option<(bool, usize)>,
    /// Value words by letter (`A` = 0): value and column.
    values: [Option<(f64, usize)>; 26],
    /// Modal groups seen (GRBL's numbering; the G groups that share a number with an M group offset by 100).
    groups: Vec<u16>,
}

/// What a G code is, once a dialect has read it.
enum GCode {
    Motion(MotionMode),
    Dwell,
    Plane(u8),
    Units(Units),
    Distance(Distance),
    ArcDistance(Distance),
    FeedMode(bool),
    CoordSelect(usize),
    CutterCompOff,
    Length(ToolLength),
    NonModal(NonModal),
    PathControl,
    Blend,
}

impl GCode {
    /// Its modal group (GRBL's numbers; G groups 4, 7, 8, 13 offset by 100 so as not to meet the M groups).
    fn group(&self) -> u16 {
        match self {
            GCode::Motion(_) => 1,
            GCode::Dwell | GCode::NonModal(_) => 0,
            GCode::Plane(_) => 2,
            GCode::Distance(_) => 3,
            GCode::ArcDistance(_) => 104,
            GCode::FeedMode(_) => 5,
            GCode::Units(_) => 6,
            GCode::CutterCompOff => 107,
            GCode::Length(_) => 108,
            GCode::CoordSelect(_) => 12,
            GCode::PathControl | GCode::Blend => 113,
        }
    }

    /// It takes the block's axis words (GRBL's `AXIS_COMMAND_*`).
    fn takes_axes(&self) -> bool {
        match self {
            GCode::Motion(m) => *m != MotionMode::Cancel,
            GCode::Length(l) => *l != ToolLength::Table,
            GCode::NonModal(n) => matches!(n, NonModal::SetCoord | NonModal::GoStored(_) | NonModal::SetOffset),
            _ => false,
        }
    }
}

/// GRBL 1.1h's reading of `G<int>.<mantissa>` (`gcode.c`): 20 for a code it lacks, 23 for a fraction on a
/// code that has none.
fn g_grbl(g: i64, mantissa: i64) -> Result<GCode, (u16, String)> {
    let unsupported = |code| {
        Err((
            code,
            format!("{} is not supported by GRBL 1.1", g_name(g * 10 + mantissa)),
        ))
    };
    Ok(match (g, mantissa) {
        (0..=3, 0) | (80, 0) => GCode::Motion(MotionMode::from_tenths(g * 10).expect("a motion code")),
        (4, 0) => GCode::Dwell,
        (17..=19, 0) => GCode::Plane(g as u8),
        (20, 0) => GCode::Units(Units::Inch),
        (21, 0) => GCode::Units(Units::Mm),
        (90, 0) => GCode::Distance(Distance::Absolute),
        (91, 0) => GCode::Distance(Distance::Incremental),
        (93 | 94, 0) => GCode::FeedMode(g == 93),
        // G91.1 (incremental I/J, GRBL's only arc mode) is accepted and does nothing; G90.1 is not
        (91, 1) => GCode::ArcDistance(Distance::Incremental),
        (54..=59, 0) => GCode::CoordSelect((g - 54) as usize),
        // G40 is GRBL's only cutter-compensation mode: accepted (a machinist's safety line carries it)
        (40, 0) => GCode::CutterCompOff,
        (49, 0) => GCode::Length(ToolLength::Cancel),
        (43, 1) => GCode::Length(ToolLength::Dynamic),
        (10, 0) => GCode::NonModal(NonModal::SetCoord),
        (28, 0) => GCode::NonModal(NonModal::GoStored(0)),
        (30, 0) => GCode::NonModal(NonModal::GoStored(1)),
        (28, 1) => GCode::NonModal(NonModal::SetStored(0)),
        (30, 1) => GCode::NonModal(NonModal::SetStored(1)),
        (53, 0) => GCode::NonModal(NonModal::Machine),
        (92, 0) => GCode::NonModal(NonModal::SetOffset),
        (92, 1) => GCode::NonModal(NonModal::ClearOffset),
        // G61 (exact path) is GRBL's only path control mode
        (61, 0) => GCode::PathControl,
        (38, 2..=5) => GCode::Motion(MotionMode::from_tenths(380 + mantissa).expect("a probe code")),
        (43 | 28 | 30 | 92 | 61 | 38, _) | (90, 1) | (_, 0) => return unsupported(20),
        _ => return unsupported(23),
    })
}

/// The modelled LinuxCNC subset's reading of a G code in tenths (the codes a LinuxCNC program for a 3-axis
/// mill commonly carries, and those that take part in coordinates).
fn g_linuxcnc(t: i64) -> Result<GCode, (u16, String)> {
    let no = |s: &str| Err((20, s.to_string()));
    Ok(match t {
        0 | 10 | 20 | 30 | 800 | 382..=385 => GCode::Motion(MotionMode::from_tenths(t).expect("a motion code")),
        40 => GCode::Dwell,
        170 | 180 | 190 => GCode::Plane((t / 10) as u8),
        200 => GCode::Units(Units::Inch),
        210 => GCode::Units(Units::Mm),
        900 => GCode::Distance(Distance::Absolute),
        910 => GCode::Distance(Distance::Incremental),
        901 => GCode::ArcDistance(Distance::Absolute),
        911 => GCode::ArcDistance(Distance::Incremental),
        930 | 940 => GCode::FeedMode(t == 930),
        540..=590 if t % 10 == 0 => GCode::CoordSelect(((t - 540) / 10) as usize),
        400 => GCode::CutterCompOff,
        490 => GCode::Length(ToolLength::Cancel),
        430 => GCode::Length(ToolLength::Table),
        431 => GCode::Length(ToolLength::Dynamic),
        100 => GCode::NonModal(NonModal::SetCoord),
        280 => GCode::NonModal(NonModal::GoStored(0)),
        300 => GCode::NonModal(NonModal::GoStored(1)),
        281 => GCode::NonModal(NonModal::SetStored(0)),
        301 => GCode::NonModal(NonModal::SetStored(1)),
        530 => GCode::NonModal(NonModal::Machine),
        920 => GCode::NonModal(NonModal::SetOffset),
        921 => GCode::NonModal(NonModal::ClearOffset),
        610 | 611 => GCode::PathControl,
        640 => GCode::Blend,
        410 | 411 | 420 | 421 => return no("cutter radius compensation is not supported"),
        432 => return no("only the tool table's length offset (G43 H) is supported"),
        730 | 760 | 810..=890 => return no("canned cycles are not supported"),
        950 => return no("only units-per-minute feed (G94) is supported"),
        _ => {
            return no(&format!(
                "{} is not supported (understood: G0 G1 G2 G3 G4 G17 G18 G19 G20 G21 G40 G43 G49 G54 G61 G61.1 G64 G80 G90 \
                 G90.1 G91 G91.1 G94)",
                g_name(t)
            ))
        }
    })
}

impl Parsed {
    /// Sort a block's words as `dialect` reads them, applying its modal words to `m` (GRBL's steps 1–2: each
    /// word checked on its own, in the order written). `m7`: a GRBL build with `ENABLE_M7`.
    pub fn new(words: &[Word], dialect: Dialect, m7: bool, m: &mut Modal) -> Result<Parsed, BlockError> {
        let mut p = Parsed::default();
        for (k, w) in words.iter().enumerate() {
            match w.letter {
                'G' => p.g_word(w, dialect, m)?,
                'M' => p.m_word(w, dialect, m7, m)?,
                _ => p.value_word(w, k, dialect)?,
            }
        }
        Ok(p)
    }

    /// The value and column of a value word (`X`, `F`, `P`…).
    #[must_use]
    pub fn get(&self, letter: char) -> Option<(f64, usize)> {
        self.values[(letter as u8 - b'A') as usize]
    }

    /// The value of a value word.
    #[must_use]
    pub fn value(&self, letter: char) -> Option<f64> {
        self.get(letter).map(|v| v.0)
    }

    /// The axis words X, Y, Z.
    #[must_use]
    pub fn axes(&self) -> [Option<f64>; 3] {
        [self.value('X'), self.value('Y'), self.value('Z')]
    }

    /// The arc offsets I, J, K.
    #[must_use]
    pub fn offsets(&self) -> [Option<f64>; 3] {
        [self.value('I'), self.value('J'), self.value('K')]
    }

    /// The block has an axis word.
    #[must_use]
    pub fn has_axis(&self) -> bool {
        self.axes().iter().any(Option::is_some)
    }

    /// The column of the first of `letters` in the block.
    #[must_use]
    pub fn first_column(&self, letters: &[char]) -> Option<usize> {
        letters.iter().filter_map(|l| self.get(*l).map(|v| v.1)).min()
    }

    /// Two words of one modal group in a block: `error:21`.
    fn group(&mut self, g: u16, col: usize, name: &str) -> Result<(), BlockError> {
        if self.groups.contains(&g) {
            return fail(
                col,
                21,
                format!("{name} conflicts with another code of its group on this line"),
            );
        }
        self.groups.push(g);
        Ok(())
    }

    fn g_word(&mut self, w: &Word, dialect: Dialect, m: &mut Modal) -> Result<(), BlockError> {
        let col = w.column;
        let code = match dialect {
            Dialect::Grbl => {
                let int = w.value.trunc();
                g_grbl(int as i64, ((w.value - int) * 10.0).round() as i64)
            }
            Dialect::Linuxcnc => match tenths(w.value) {
                Some(t) => g_linuxcnc(t),
                None => Err((20, format!("G{} is not supported", w.value))),
            },
        };
        let code = code.or_else(|(c, msg)| fail(col, c, msg))?;
        let name = match tenths(w.value) {
            Some(t) => g_name(t),
            None => format!("G{}", w.value),
        };
        // Two commands that take the axis words: GRBL checks that conflict before the group for a motion
        // code, after it for the others. LinuxCNC's non-modal group may hold several codes (G4 twice is one
        // dwell); GRBL's may not.
        let motion = matches!(code, GCode::Motion(_));
        let check_group = code.group() != 0 || dialect == Dialect::Grbl;
        if check_group && !motion {
            self.group(code.group(), col, &name)?;
        }
        if code.takes_axes() {
            if self.axis_command {
                return fail(
                    col,
                    24,
                    format!("{name} conflicts with another code on this line that takes the axis words"),
                );
            }
            self.axis_command = true;
        }
        if check_group && motion {
            self.group(code.group(), col, &name)?;
        }
        match code {
            GCode::Motion(mm) => self.motion = Some((mm, col)),
            GCode::Dwell => self.dwell = Some(col),
            GCode::Plane(p) => m.plane = p,
            GCode::Units(u) => m.units = u,
            GCode::Distance(d) => m.distance = d,
            GCode::ArcDistance(d) => m.arc_distance = d,
            GCode::FeedMode(inverse) => self.feed_mode = Some((inverse, col)),
            GCode::CoordSelect(k) => self.coord_select = Some((k, col)),
            GCode::Length(l) => self.tool_length = Some((l, col)),
            GCode::NonModal(n) => self.non_modal = Some((n, col)),
            GCode::Blend => self.blend = true,
            GCode::CutterCompOff | GCode::PathControl => {}
        }
        Ok(())
    }

    fn m_word(&mut self, w: &Word, dialect: Dialect, m7: bool, m: &mut Modal) -> Result<(), BlockError> {
        let col = w.column;
        let code = match tenths(w.value) {
            Some(t) if t % 10 == 0 => t / 10,
            _ if dialect == Dialect::Grbl && w.value >= 0.0 && w.value.fract() != 0.0 => {
                return fail(col, 23, format!("M{} is not a whole number", w.value))
            }
            _ => return fail(col, 20, format!("M{} is not supported", w.value)),
        };
        let understood = match dialect {
            Dialect::Grbl => "M0 M1 M2 M3 M4 M5 M8 M9 M30",
            Dialect::Linuxcnc => "M0 M1 M2 M3 M4 M5 M6 M7 M8 M9 M30",
        };
        let name = format!("M{code}");
        match code {
            0 | 1 | 2 | 30 => {
                self.group(4, col, &name)?;
                self.program_end = matches!(code, 2 | 30);
                self.program_pause = code == 0;
            }
            3..=5 => {
                self.group(7, col, &name)?;
                m.spindle = match code {
                    3 => Spindle::Cw,
                    4 => Spindle::Ccw,
                    _ => Spindle::Off,
                };
                self.spindle_word = Some(m.spindle);
                self.sync = true;
            }
            6 if dialect == Dialect::Linuxcnc => {
                self.group(6, col, &name)?;
                self.tool_change = Some(col);
            }
            7 => {
                if dialect == Dialect::Grbl && !m7 {
                    return fail(col, 20, "M7 (mist) is not in this GRBL build (ENABLE_M7)");
                }
                self.mist_word = Some(col);
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
            _ => return fail(col, 20, format!("M{code} is not supported (understood: {understood})")),
        }
        Ok(())
    }

    /// A word with a value (axes, offsets, F, S, P, N, T…): each at most once per block.
    fn value_word(&mut self, w: &Word, index: usize, dialect: Dialect) -> Result<(), BlockError> {
        let (l, v, col) = (w.letter, w.value, w.column);
        let grbl = dialect == Dialect::Grbl;
        let known = match l {
            'X' | 'Y' | 'Z' | 'I' | 'J' | 'K' | 'R' | 'F' | 'S' | 'P' | 'T' | 'N' => true,
            'L' => grbl,
            'Q' | 'H' => !grbl,
            _ => false,
        };
        if !known {
            if matches!(l, 'A' | 'B' | 'C' | 'U' | 'V' | 'W') {
                return fail(col, 20, format!("axis `{l}`: only X, Y and Z are modelled (3-axis)"));
            }
            return fail(col, 20, format!("word `{l}` is not supported"));
        }
        if l == 'N' && !grbl && index != 0 {
            return fail(col, 20, "a line number `N` must come first on the line");
        }
        let slot = &mut self.values[(l as u8 - b'A') as usize];
        if slot.is_some() {
            return fail(col, 25, format!("`{l}` appears twice on this line"));
        }
        *slot = Some((v, col));
        if l == 'N' && !(0.0..=MAX_LINE_NUMBER as f64).contains(&v) {
            return fail(col, 27, format!("line number N{v} is beyond {MAX_LINE_NUMBER}"));
        }
        if v < 0.0 {
            match l {
                'F' => return fail(col, 4, format!("negative feed F{v}")),
                'S' => return fail(col, 4, format!("negative spindle speed S{v}")),
                'P' => return fail(col, 4, format!("negative `P{v}`")),
                'T' | 'N' => return fail(col, 4, format!("negative `{l}{v}`")),
                _ => {}
            }
        }
        if l == 'T' {
            if grbl && v > MAX_TOOL_NUMBER {
                return fail(
                    col,
                    38,
                    format!("tool number T{v} is above GRBL's largest, {MAX_TOOL_NUMBER}"),
                );
            }
            if !(grbl || v.fract() == 0.0 && v < 1e6) {
                return fail(col, 20, format!("tool number T{v} must be a whole number ≥ 0"));
            }
        }
        Ok(())
    }
}
