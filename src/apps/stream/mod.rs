//! `stream`: send a G-code program to a GRBL 1.1 controller over a serial port, safely.
//!
//! - [`protocol`]: the streaming protocol as a pure state machine (character counting, response parsing).
//! - [`program`]: the program as GRBL will see it, with the modal state and position before each line.
//! - [`journal`]: the append-only record of what was sent, answered and executed.
//! - [`session`]: the streamer — handshake, check mode, streaming, safe stop on faults, resume.
//! - [`serial`]: the thin serial-port adapter ([`serial::Link`]).
//! - [`emulator`]: a virtual GRBL 1.1 controller on a pseudo-terminal, for tests and dry runs.
//!
//! See `docs/STREAM.md` for the user-level description and the guarantees.

pub mod emulator;
pub mod journal;
pub mod keys;
/// The program model the streamer reads (the crate's one annotated G-code program, [`crate::gcode::program`]).
pub use crate::gcode::program;
pub mod protocol;
pub mod serial;
pub mod session;
