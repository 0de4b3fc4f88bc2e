//! A G-code program annotated line by line, as the streamer sees it: every line cleaned the way GRBL cleans it (comments and
//! whitespace removed, letters upper-cased), classified (G-code, settings write, other `$` command), and
//! annotated with the modal state and the tool position before and after it.
//!
//! The modal model is what makes a resume possible: the preamble re-sent before the resume point is the
//! state *before* that line, and the approach goes to the line's start point. Positions are in **work
//! coordinates, mm** (G20 programs are converted), `None` per axis while the program has not yet set it
//! with an absolute move.

use std::path::{Path, PathBuf};

/// GRBL 1.1's line buffer (`LINE_BUFFER_SIZE`): 80 bytes including the terminating NUL, so a block may
/// hold at most 79 significant characters after whitespace and comments are removed.
pub const LINE_BUFFER_BYTES: usize = 80;

/// The most significant characters one block may have (see [`LINE_BUFFER_BYTES`]).
pub const MAX_BLOCK_CHARS: usize = LINE_BUFFER_BYTES - 1;

/// The largest line number GRBL accepts in an `N` word (`MAX_LINE_NUMBER`).
pub const MAX_LINE_NUMBER: usize = 10_000_000;

/// A program could not be read or is not streamable to GRBL.
#[derive(Debug, thiserror::Error)]
pub enum ProgramError {
    /// The file could not be read.
    #[error("cannot read program {path}")]
    Read {
        /// The program file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A block is longer than GRBL's line buffer: GRBL would answer `error:11` and skip it.
    #[error(
        "{path}:{line}: block has {chars} characters once cleaned (`{block}`); GRBL's line buffer \
         holds at most {max} (LINE_BUFFER_SIZE = 80){hint}"
    )]
    LineTooLong {
        /// The program file.
        path: PathBuf,
        /// 1-based line in the file.
        line: usize,
        /// Characters of the block as it would be sent.
        chars: usize,
        /// The limit, [`MAX_BLOCK_CHARS`].
        max: usize,
        /// The block as it would be sent.
        block: String,
        /// Extra advice (the line-number prefix added by the streamer).
        hint: String,
    },
    /// A G-code word is malformed (a letter without a number, a number without a letter).
    #[error("{path}:{line}: {what} in `{text}`")]
    Syntax {
        /// The program file.
        path: PathBuf,
        /// 1-based line in the file.
        line: usize,
        /// What is wrong.
        what: String,
        /// The source line.
        text: String,
    },
    /// The program has more lines than GRBL's `N` words can number.
    #[error("{path}: {lines} lines is more than GRBL's largest line number {max}; stream without line numbers")]
    TooManyLines {
        /// The program file.
        path: PathBuf,
        /// Lines in the file.
        lines: usize,
        /// [`MAX_LINE_NUMBER`].
        max: usize,
    },
}

use crate::gcode::block::{BlockError, NonModal};
use crate::gcode::interp::{Interpreter, Motion};
use crate::gcode::lex::{self, Block};
pub use crate::gcode::modal::{Distance, Modal, MotionMode, Spindle, Units};
use crate::gcode::Dialect;

/// What kind of line this is, for the streaming protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineKind {
    /// Nothing left after cleaning (blank, comment, `%`): not sent.
    Empty,
    /// A G-code block, streamed with character counting.
    Gcode,
    /// A block that writes EEPROM or settings (`$x=`, `$N`, `$RST`, `G10`, `G28.1`, `G30.1`): GRBL needs
    /// it alone in its buffer and the machine idle, so it is sent alone and waited for.
    Setting,
    /// Another `$` system command (`$H`, `$X`, `$C`, `$$`…), also sent alone.
    System,
}

/// A position per axis in mm, `None` where not yet known.
pub type Position = [Option<f64>; 3];

/// One line of the program.
#[derive(Debug, Clone)]
pub struct Line {
    /// 1-based line in the file (also the `N` number sent, when numbering).
    pub number: usize,
    /// The line as in the file.
    pub source: String,
    /// The cleaned block without any `N` word: what GRBL would see.
    pub block: String,
    /// How it is streamed.
    pub kind: LineKind,
    /// Modal state before the line.
    pub before: Modal,
    /// Modal state after the line.
    pub after: Modal,
    /// Tool position before the line (work coordinates, mm).
    pub start_mm: Position,
    /// Tool position after the line (work coordinates, mm).
    pub end_mm: Position,
    /// The line moves the tool (a G0–G3 with a non-zero displacement, or one whose target is unknown).
    pub moves: bool,
    /// The motion mode of the move, when it moves.
    pub motion: Option<MotionMode>,
    /// The line makes later positions unknowable to this model (G28, G30, G53, G38.x, an absolute change of
    /// the work offsets, homing, a jog…) until an absolute move sets them again.
    pub breaks_position: bool,
    /// GRBL 1.1h would refuse this block: its `error:N` code and why (the model leaves its state as it was,
    /// as the controller does).
    pub refusal: Option<BlockError>,
}

impl Line {
    /// The program-flow word GRBL acts on in this block: `M0` (a pause) or `M2`/`M30` (the end), as 0, 2 or
    /// 30. `M1`, the optional stop, GRBL 1.1 parses and ignores (`case 1: break;` in `gcode.c`): no wait, no
    /// pause.
    fn program_flow(&self) -> Option<i64> {
        let ws = words(&self.block).ok()?;
        ws.iter()
            .filter(|w| w.letter == 'M' && w.value.fract() == 0.0)
            .map(|w| w.value as i64)
            .find(|m| matches!(m, 0 | 2 | 30))
    }

    /// GRBL may run this line's motion, in part or whole, before it answers it: an arc (`mc_arc` plans it
    /// chord by chord and the `ok` comes after the last) or a move in a block with `M0`, `M2` or `M30` (the
    /// program flow waits for the motion to finish before the `ok`). So at a stop the oldest unanswered line
    /// may have run when it is one of these.
    #[must_use]
    pub fn answered_after_its_motion(&self) -> bool {
        let arc = matches!(self.motion, Some(MotionMode::ArcCw | MotionMode::ArcCcw));
        self.kind == LineKind::Gcode && self.moves && (arc || self.program_flow().is_some())
    }

    /// The line holds `M0`, GRBL's program pause: once its motion has run the controller holds (`Hold:0`)
    /// until a cycle start, and answers it after that.
    #[must_use]
    pub fn pauses(&self) -> bool {
        self.kind == LineKind::Gcode && self.program_flow() == Some(0)
    }

    /// GRBL answers this line only once the planner has emptied (`protocol_buffer_synchronize`): a dwell,
    /// a program pause or end (not `M1`, which GRBL ignores), a spindle state change or a speed change
    /// while it runs, a coolant change. Its `ok`, received before any reset, therefore proves that every
    /// line planned before it executed.
    #[must_use]
    pub fn synchronises(&self) -> bool {
        let (b, a) = (&self.before, &self.after);
        let spindle = b.spindle != a.spindle || (a.spindle != Spindle::Off && b.spindle_rpm != a.spindle_rpm);
        let coolant = b.mist != a.mist || b.flood != a.flood;
        let dwell = words(&self.block).is_ok_and(|ws| ws.iter().any(|w| w.letter == 'G' && w.value == 4.0));
        self.kind == LineKind::Gcode && (spindle || coolant || dwell || self.program_flow().is_some())
    }

    /// The text sent for this line: the cleaned block, prefixed with `N<number>` when `numbered`.
    #[must_use]
    pub fn wire_text(&self, numbered: bool) -> String {
        if numbered && self.kind == LineKind::Gcode {
            format!("N{}{}", self.number, self.block)
        } else {
            self.block.clone()
        }
    }
}

/// A whole program, ready to stream.
#[derive(Debug, Clone)]
pub struct Program {
    /// Where it was read from (for messages).
    pub path: PathBuf,
    /// Every line of the file, in order, including empty ones (index = number − 1).
    pub lines: Vec<Line>,
    /// FNV-1a 64-bit hash of the file bytes, to check on resume that the program is the same one.
    pub fingerprint: u64,
}

/// A word of a block (the crate's one tokenizer, `crate::gcode::lex`).
pub use crate::gcode::lex::Word;

/// Why a cleaned block could not be split into words; [`WordError::grbl_code`] gives GRBL's error code.
pub use crate::gcode::lex::LexErrorKind as WordError;

/// Clean a line as GRBL's serial reader does: drop `(…)` and `;…` comments, whitespace and control
/// characters and `/`, upper-case letters; a `%` line (a program's start or end mark) is nothing to send.
#[must_use]
pub fn clean(line: &str) -> String {
    let out = clean_keeping_percent(line);
    if out == "%" {
        String::new()
    } else {
        out
    }
}

/// [`clean`], keeping a `%` line as `%`.
fn clean_keeping_percent(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut in_paren = false;
    for c in line.chars() {
        if in_paren {
            if c == ')' {
                in_paren = false;
            }
            continue;
        }
        match c {
            '(' => in_paren = true,
            ';' => break,
            '/' => {}
            c if c <= ' ' => {}
            c => out.push(c.to_ascii_uppercase()),
        }
    }
    out
}

/// Split a cleaned G-code block into words, as GRBL's parser does (`read_float`: optional sign, digits,
/// one decimal point, no exponent).
pub fn words(block: &str) -> Result<Vec<Word>, WordError> {
    match lex::lex(block) {
        Ok(Block::Words(w)) => Ok(w),
        Ok(Block::Percent) => Ok(Vec::new()),
        Err(e) => Err(e.kind),
    }
}

/// FNV-1a, 64 bit: a cheap fingerprint of the program bytes (not cryptographic; it only guards against
/// resuming a different or edited file).
#[must_use]
pub fn fingerprint(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// How a program's header asks for GRBL's arc tolerance: the comment `(controller: $12=T mm …)` among the
/// comment lines before its first block. The toolpath stage writes it for a GRBL profile (the `$12` its
/// verdict's simulation cut the arcs with), and `stream` reads it to refuse a controller set coarser.
pub const ARC_TOLERANCE_MARK: &str = "controller: $12=";

impl Program {
    /// The arc tolerance `$12` the program's header asks for, mm ([`ARC_TOLERANCE_MARK`]), if it asks.
    pub fn arc_tolerance_asked_mm(&self) -> Option<f64> {
        self.lines
            .iter()
            .take_while(|l| l.kind == LineKind::Empty)
            .find_map(|l| {
                let t = l.source.trim();
                let rest = t.strip_prefix('(')?.strip_prefix(ARC_TOLERANCE_MARK)?;
                let num: String = rest.chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
                num.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0)
            })
    }

    /// Read and annotate a program file. `numbered`: the streamer will prefix each block with
    /// `N<line>`, which counts against GRBL's line length.
    pub fn read(path: &Path, numbered: bool) -> Result<Program, ProgramError> {
        let bytes = std::fs::read(path).map_err(|source| ProgramError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let text = String::from_utf8_lossy(&bytes);
        Program::parse(path, &text, fingerprint(&bytes), numbered)
    }

    /// Annotate program text (see [`Program::read`]); `path` is only used in messages.
    pub fn parse(path: &Path, text: &str, fingerprint: u64, numbered: bool) -> Result<Program, ProgramError> {
        let src: Vec<&str> = text.lines().collect();
        if numbered && src.len() >= MAX_LINE_NUMBER {
            return Err(ProgramError::TooManyLines {
                path: path.to_path_buf(),
                lines: src.len(),
                max: MAX_LINE_NUMBER,
            });
        }
        let mut interp = Interpreter::unknown_frame(Dialect::Grbl, [None; 3]);
        let mut lines: Vec<Line> = Vec::with_capacity(src.len());
        // where the program ended, as the simulator reads it: `M2`/`M30`, or a `%` after content (a first
        // `%` before any is the start mark)
        let mut end: Option<(usize, &str)> = None;
        let (mut percents, mut content) = (0, false);
        for (i, s) in src.iter().enumerate() {
            let number = i + 1;
            let syntax = |what: String| ProgramError::Syntax {
                path: path.to_path_buf(),
                line: number,
                what,
                text: (*s).to_string(),
            };
            // A control character in a line is never G-code: it is a corrupted file or text injected into it
            // (GRBL would drop it silently and run the rest of the line).
            if let Some(c) = s.chars().find(|c| c.is_control() && *c != '\t' && *c != '\r') {
                return Err(syntax(format!(
                    "control character U+{:04X}: a program line holds printable text only",
                    u32::from(c)
                )));
            }
            let raw = clean_keeping_percent(s);
            if let Some((at, what)) = end.filter(|_| !raw.is_empty() && raw != "%") {
                // GRBL would run it; the simulation, and so the verification, never read it
                return Err(syntax(format!(
                    "a block after the program's end ({what} at line {at}), which the simulation does not read: \
                     remove it or the end"
                )));
            }
            if raw == "%" {
                percents += 1;
                if percents == 2 || content {
                    end = Some((number, "`%`"));
                }
            } else if !raw.is_empty() {
                content = true;
            }
            // `clean`, from the text already cleaned above
            let cleaned = if raw == "%" { String::new() } else { raw };
            let (kind, block) = if cleaned.is_empty() {
                (LineKind::Empty, cleaned)
            } else if cleaned.starts_with('$') {
                let setting = cleaned.contains('=') || cleaned.starts_with("$N") || cleaned.starts_with("$RST");
                let jog = cleaned.starts_with("$J=");
                let kind = if jog {
                    LineKind::Gcode
                } else if setting {
                    LineKind::Setting
                } else {
                    LineKind::System
                };
                (kind, cleaned)
            } else {
                let ws = words(&cleaned).map_err(|e| syntax(e.to_string()))?;
                let block: String = strip_n(&cleaned, &ws);
                let setting = ws
                    .iter()
                    .any(|w| w.letter == 'G' && (same(w.value, 10.0) || same(w.value, 28.1) || same(w.value, 30.1)));
                (if setting { LineKind::Setting } else { LineKind::Gcode }, block)
            };
            let mut line = Line {
                number,
                source: (*s).to_string(),
                block,
                kind,
                before: interp.modal,
                after: interp.modal,
                start_mm: [None; 3],
                end_mm: [None; 3],
                moves: false,
                motion: None,
                breaks_position: false,
                refusal: None,
            };
            annotate(&mut interp, &mut line).map_err(|e| syntax(e.to_string()))?;
            match line.program_flow() {
                Some(2) => end = Some((number, "`M2`")),
                Some(30) => end = Some((number, "`M30`")),
                _ => {}
            }
            if kind != LineKind::Empty {
                let chars = line.wire_text(numbered).len();
                if chars > MAX_BLOCK_CHARS {
                    let hint = if line.block.len() <= MAX_BLOCK_CHARS {
                        format!("; without the `N{number}` prefix it would fit: stream with line numbers off")
                    } else {
                        String::new()
                    };
                    return Err(ProgramError::LineTooLong {
                        path: path.to_path_buf(),
                        line: number,
                        chars,
                        max: MAX_BLOCK_CHARS,
                        block: line.wire_text(numbered),
                        hint,
                    });
                }
            }
            lines.push(line);
        }
        Ok(Program {
            path: path.to_path_buf(),
            lines,
            fingerprint,
        })
    }

    /// The same program modelled from a known start: the work position before its first line (as a
    /// controller reported it), so that the axes a program has not yet set by an absolute move — a first
    /// move along Z only, incremental moves — are known too.
    #[must_use]
    pub fn anchored(&self, start_mm: [f64; 3]) -> Program {
        let mut p = self.clone();
        let mut interp = Interpreter::unknown_frame(Dialect::Grbl, start_mm.map(Some));
        for line in &mut p.lines {
            // the words were read once already, so they read again
            let _ = annotate(&mut interp, line);
        }
        p
    }

    /// Lines that will be sent (non-empty).
    pub fn sendable(&self) -> impl Iterator<Item = &Line> {
        self.lines.iter().filter(|l| l.kind != LineKind::Empty)
    }

    /// The line with 1-based number `n`.
    #[must_use]
    pub fn line(&self, n: usize) -> Option<&Line> {
        n.checked_sub(1).and_then(|i| self.lines.get(i))
    }
}

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6
}

/// Remove an `N` word from a cleaned block (the streamer numbers lines itself).
fn strip_n(cleaned: &str, ws: &[Word]) -> String {
    if !ws.iter().any(|w| w.letter == 'N') {
        return cleaned.to_string();
    }
    let b = cleaned.as_bytes();
    let mut out = String::new();
    let mut i = 0;
    while i < b.len() {
        let start = i;
        i += 1;
        while i < b.len() && !b[i].is_ascii_uppercase() {
            i += 1;
        }
        if b[start] != b'N' {
            out.push_str(&cleaned[start..i]);
        }
    }
    out
}

/// Note on `line` the modal state and work position before it, and what it does: a G-code block through the
/// interpreter ([`model`]), homing and jogs as leaving the position unknown.
fn annotate(interp: &mut Interpreter, line: &mut Line) -> Result<(), WordError> {
    let pos = interp.work_position();
    (line.before, line.after, line.start_mm, line.end_mm) = (interp.modal, interp.modal, pos, pos);
    (line.moves, line.motion, line.breaks_position, line.refusal) = (false, None, false, None);
    if line.kind != LineKind::Empty && !line.block.starts_with('$') {
        let ws = words(&line.block)?;
        model(interp, &ws, line);
    } else if line.kind == LineKind::System && (line.block == "$H" || line.block.starts_with("$J")) {
        line.breaks_position = true;
        interp.known = [false; 3];
        line.end_mm = interp.work_position();
    }
    Ok(())
}

/// Run a block through the interpreter as GRBL 1.1h reads it, and note on `line` what it does: the modal
/// state and work position after it, whether and how it moves, whether it leaves the position unknown. A
/// block GRBL would refuse is noted ([`Line::refusal`]) and changes nothing.
fn model(interp: &mut Interpreter, ws: &[Word], line: &mut Line) {
    let known_before = interp.known;
    let step = match interp.block(ws) {
        Ok(step) => step,
        Err(e) => {
            line.refusal = Some(e);
            return;
        }
    };
    if let Some(motion) = step.motion {
        let probe = matches!(step.modal.motion, MotionMode::Probe { .. });
        if probe {
            // a probing move stops wherever the probe touches: where it ends is unknowable here
            interp.known = [false; 3];
        }
        line.motion = match motion {
            Motion::Stored { .. } => None,
            _ => Some(step.modal.motion),
        };
        let end = interp.work_position();
        let displaced = (0..3).any(|i| match (line.start_mm[i], end[i]) {
            (Some(a), Some(b)) => (a - b).abs() > 1e-9,
            (None, None) => step.parsed.axes()[i].is_some(),
            _ => true,
        });
        // an arc always moves (one whose end is its start is a full circle)
        line.moves = displaced || matches!(motion, Motion::Arc { .. }) || !step.geometry_known;
    }
    line.after = interp.modal;
    line.end_mm = interp.work_position();
    line.breaks_position = (0..3).any(|i| known_before[i] && !interp.known[i])
        || step
            .parsed
            .non_modal
            .is_some_and(|n| !matches!(n.0, NonModal::SetStored(_)))
        || step.parsed.tool_length.is_some()
        || matches!(step.modal.motion, MotionMode::Probe { .. }) && step.motion.is_some();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prog(text: &str) -> Program {
        Program::parse(Path::new("t.nc"), text, 0, true).unwrap()
    }

    /// GRBL 1.1 waits for the planner at `M0`, `M2`, `M30` and `G4`, and ignores `M1` (`case 1: break;`):
    /// an `M1`'s `ok` proves nothing about the lines before it. `M0` pauses; a move with `M2` or an arc is
    /// answered after its motion.
    #[test]
    fn program_flow_as_grbl_reads_it() {
        let p = prog("G21G90\nM0\nM1\nG4P1\nG1X2F100\nG2X4I1J0\nG1X1M30\n");
        let sync: Vec<bool> = [2, 3, 4, 5, 7].map(|n| p.line(n).unwrap().synchronises()).to_vec();
        assert_eq!(sync, [true, false, true, false, true]);
        assert!(p.line(2).unwrap().pauses() && !p.line(3).unwrap().pauses() && !p.line(7).unwrap().pauses());
        let after: Vec<bool> = (4..=7)
            .map(|n| p.line(n).unwrap().answered_after_its_motion())
            .collect();
        assert_eq!(after, [false, false, true, true]);
        let end = prog("G21G90\nG1X1F100M2\n");
        assert!(end.line(2).unwrap().synchronises() && end.line(2).unwrap().answered_after_its_motion());
    }

    /// A block after `M2`/`M30` or a closing `%` would run on GRBL, which reads on, but the simulation stops
    /// at the end (as LinuxCNC does): such a program is refused, naming the line and the end. `%` marks, a
    /// start before any block and an end after `M30`, and comments after the end are fine.
    #[test]
    fn a_block_after_the_programs_end_is_refused() {
        for (text, line, end) in [
            ("G21\nM30\nG1X5F100\n", 3, "`M30` at line 2"),
            ("%\nG21\nM2\n\nG0X1\n", 5, "`M2` at line 3"),
            ("%\nG21\n%\nG1X5F100\n", 4, "`%` at line 3"),
            ("G21\n%\nG1X5F100\n", 3, "`%` at line 2"),
        ] {
            let e = Program::parse(Path::new("p.nc"), text, 0, false)
                .unwrap_err()
                .to_string();
            assert!(e.contains(&format!("p.nc:{line}:")) && e.contains(end), "{text:?}: {e}");
        }
        let ok = prog("%\n(start)\nG21G90\nG1X1F100\nM30\n%\n(after the end)\n; and this\n");
        assert_eq!(ok.sendable().count(), 3);
    }

    #[test]
    fn cleans_like_grbl() {
        assert_eq!(clean("g1 x1.5 (move) y2 ; tail"), "G1X1.5Y2");
        assert_eq!(clean("%"), "");
        assert_eq!(clean("  (only a comment)"), "");
    }

    #[test]
    fn words_report_grbl_codes() {
        assert_eq!(words("G1X-1.5").unwrap().len(), 2);
        assert_eq!(words("1X").unwrap_err().grbl_code(), 1);
        assert_eq!(words("GX1").unwrap_err().grbl_code(), 2);
        // GRBL's read_float stops at the second point, which is then not a command letter.
        assert_eq!(words("X1.2.3").unwrap_err().grbl_code(), 1);
        assert_eq!(words("O100").unwrap_err().grbl_code(), 20);
    }

    #[test]
    fn tracks_modal_state_and_position() {
        let p = prog("G21 G90\nG0 X1 Y2 Z3\nM3 S1000\nG1 Z-1 F200\nG91 X1\nG20 G1 X1 F10\n");
        let l = &p.lines;
        assert_eq!(l[1].end_mm, [Some(1.0), Some(2.0), Some(3.0)]);
        assert!(l[1].moves && !l[2].moves);
        assert_eq!(l[3].before.spindle, Spindle::Cw);
        assert_eq!(l[3].end_mm[2], Some(-1.0));
        assert_eq!(l[4].end_mm[0], Some(2.0));
        assert!((l[5].end_mm[0].unwrap() - 27.4).abs() < 1e-9);
        assert_eq!(l[5].before.feed_mm_min, Some(200.0));
        assert!((p.lines[5].end_mm[0].unwrap() - (2.0 + 25.4)).abs() < 1e-9);
    }

    #[test]
    fn probing_is_modal_and_ends_where_it_touches() {
        let p = prog("G0 X1 Y1\nG38.2 Z-5 F50\nZ-6\nG0 Z2\nX3\n");
        let l = &p.lines;
        for k in [1, 2] {
            assert!(l[k].moves && l[k].breaks_position, "line {k} probes");
            assert_eq!(l[k].end_mm, [None; 3]);
            assert!(matches!(
                l[k].motion,
                Some(MotionMode::Probe {
                    away: false,
                    no_error: false
                })
            ));
        }
        // G0 ends the probing mode; Z is known again, X and Y only once given
        assert_eq!(l[3].end_mm, [None, None, Some(2.0)]);
        assert_eq!(l[4].end_mm, [Some(3.0), None, Some(2.0)]);
    }

    #[test]
    fn settings_and_line_numbers() {
        let p = prog("N10 G1 X1 F100\n$110=500\nG10 L2 P1 X0\n$H\n");
        assert_eq!(p.lines[0].block, "G1X1F100");
        assert_eq!(p.lines[0].wire_text(true), "N1G1X1F100");
        assert_eq!(p.lines[1].kind, LineKind::Setting);
        assert_eq!(p.lines[2].kind, LineKind::Setting);
        assert_eq!(p.lines[3].kind, LineKind::System);
        assert!(p.lines[3].breaks_position);
    }

    #[test]
    fn control_characters_are_refused_with_the_line() {
        for bad in ["G0 X1\u{7}\n", "G0 X1\n(evil\u{8}G0 Z-40)\n", "G1 X1\u{1b}[2J F100\n"] {
            let e = Program::parse(Path::new("p.nc"), bad, 0, true).unwrap_err();
            assert!(e.to_string().contains("control character"), "{bad:?}: {e}");
        }
        assert!(Program::parse(Path::new("p.nc"), "G0 X1\t(tab)\r\n", 0, true).is_ok());
    }

    #[test]
    fn long_line_is_refused_with_its_number() {
        let long = format!("G1X1F100\nG1 X{}\n", "1".repeat(80));
        let e = Program::parse(Path::new("p.nc"), &long, 0, true).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("p.nc:2") && msg.contains("79"), "{msg}");
        // 79 significant characters fit alone but not with the N1 prefix.
        let edge = format!("G1X{}\n", "1".repeat(76));
        let e = Program::parse(Path::new("p.nc"), &edge, 0, true).unwrap_err();
        assert!(e.to_string().contains("line numbers off"), "{e}");
        assert!(Program::parse(Path::new("p.nc"), &edge, 0, false).is_ok());
    }
}
