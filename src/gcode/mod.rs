//! The crate's one model of G-code, below every stage that reads or writes it.
//!
//! - `lex`: the tokenizer (words with their columns, comments, `%`), shared by the simulator's reader and
//!   the streamer's program model;
//! - `modal`: the modal state between blocks (units, distance modes, plane, motion, feed, spindle);
//! - [`moves`]: the machine-independent move list that `toolpath` produces, the checker and time estimator
//!   read, the emitter writes and the simulator's reader returns;
//! - `emit`: the modal writer of a move list for a controller [`Dialect`];
//! - [`program`]: a program file annotated line by line (cleaned block, modal state and tool position before
//!   and after each line, GRBL's line limits): what the streamer sends and resumes from.
//!
//! The simulator's reader, `simulate::gcode`, builds on `lex` and `modal`: any program → straight
//! segments, refusing what it does not understand with the line and column.

pub(crate) mod emit;
pub(crate) mod lex;
pub(crate) mod modal;
pub mod moves;
pub mod program;

use serde::{Deserialize, Serialize};

/// Controller dialect of a program.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dialect {
    /// GRBL 1.1: no G64 (its junction deviation `$11` plays that role), `M2`, no `%`.
    Grbl,
    /// LinuxCNC: `G64 P<tolerance>` path blending, `M2`.
    Linuxcnc,
}
