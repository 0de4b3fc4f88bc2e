//! The crate's one model of G-code, below every stage that reads or writes it.
//!
//! - `lex`: the tokenizer (words with their columns, comments, `%`);
//! - `modal`: the modal state between blocks (units, distance modes, plane, motion, feed, spindle);
//! - [`block`] and [`interp`]: the one interpreter — a block's words sorted and checked, then executed
//!   against the controller's state into what the block does, with GRBL 1.1h's error codes and a [`Dialect`]
//!   policy where LinuxCNC reads a block differently. The simulator (`stages::simulate::gcode`), the virtual
//!   controller (`apps::stream::emulator`) and the program model ([`program`]) all read programs through it;
//! - [`moves`]: the machine-independent move list that `toolpath` produces, the checker and time estimator
//!   read, the emitter writes and the simulator's reader returns;
//! - `emit`: the modal writer of a move list for a controller [`Dialect`];
//! - [`program`]: a program file annotated line by line (cleaned block, modal state and tool position before
//!   and after each line, GRBL's line limits, GRBL's refusal of a line): what the streamer sends and resumes
//!   from.

pub mod block;
pub(crate) mod emit;
pub mod interp;
pub(crate) mod lex;
pub(crate) mod modal;
pub mod moves;
pub mod program;

pub use emit::{tool_table, TOOL_TABLE_FILE};

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

impl Dialect {
    /// The controller's name for people: "GRBL", "LinuxCNC".
    pub fn name(self) -> &'static str {
        match self {
            Dialect::Grbl => "GRBL",
            Dialect::Linuxcnc => "LinuxCNC",
        }
    }
}
