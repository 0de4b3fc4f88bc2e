//! The program files a job writes: one program for LinuxCNC (its tool changes are `M6`, each after a retract
//! in machine coordinates), and for GRBL one program per tool, in order.
//!
//! **Why one file per tool on GRBL.** GRBL 1.1 has no `M6`. A pause (`M0`) inside one program would leave the
//! operator in a feed hold, where GRBL parses nothing and accepts no jog, so the new tool's Z zero could not
//! be set; and the work zero the first tool cut from is gone under the cut. So each tool gets its own
//! program, each starting from the unknown position with a Z-only move to the clearance height, and the
//! operator zeroes each new tool's Z on the touch-off pad the setup sheet reserves: uncut stock at the
//! stock's top beside the work (X and Y zero stay as they are).

use super::Summary;
use crate::cut::estimate;
use crate::cut::machine::Machine;
use crate::gcode::emit;
use crate::gcode::moves::{Move, P3};
use crate::gcode::Dialect;
use serde::{Deserialize, Serialize};

/// One program file in numbers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileSummary {
    /// File name in the job's output folder.
    pub file: String,
    /// The profile ids of the tools it uses, in order.
    pub tools: Vec<String>,
    /// Lines of G-code.
    pub lines: usize,
    /// Estimated run time at the planner's block rate, s.
    pub estimated_s: f64,
}

/// One program file: its numbers and its text.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramFile {
    /// Its numbers.
    pub summary: FileSummary,
    /// The G-code.
    pub gcode: String,
}

/// The name of the only program of a job, or of the GRBL program of tool `k` of `n` (from 1).
pub fn file_name(k: usize, n: usize) -> String {
    if n <= 1 {
        "program.nc".into()
    } else {
        format!("program-{k}.nc")
    }
}

/// The moves split where GRBL needs a program of its own: at every tool change after the first (each part
/// then starts with its tool's change). One part for LinuxCNC, or with one tool.
fn parts(moves: &[Move], dialect: Dialect) -> Vec<&[Move]> {
    if dialect != Dialect::Grbl {
        return vec![moves];
    }
    let starts: Vec<usize> = moves
        .iter()
        .enumerate()
        .filter(|(_, m)| matches!(m, Move::ToolChange { .. }))
        .map(|(k, _)| k)
        .skip(1)
        .collect();
    let mut out = vec![];
    let mut from = 0;
    for s in starts {
        out.push(&moves[from..s]);
        from = s;
    }
    out.push(&moves[from..]);
    out
}

/// The program files of `moves` (see the module documentation): each with the job's `header`, its own
/// estimate from `start` (`whole`, the job's, when it is the only file), and a line that says which of the
/// programs it is and how its tool is zeroed.
pub fn program_files(
    setup: &emit::Setup,
    header: &[String],
    moves: &[Move],
    start: P3,
    machine: &Machine,
    whole: &estimate::Estimate,
) -> Vec<ProgramFile> {
    let parts = parts(moves, setup.dialect);
    let n = parts.len();
    parts
        .iter()
        .enumerate()
        .map(|(k, part)| {
            let tools: Vec<String> = part
                .iter()
                .filter_map(|m| match m {
                    Move::ToolChange { number, .. } => Some(
                        machine
                            .tools
                            .iter()
                            .find(|t| t.number == *number)
                            .map_or_else(|| format!("T{number}"), |t| t.id.clone()),
                    ),
                    _ => None,
                })
                .collect();
            let est = if n == 1 {
                *whole
            } else {
                estimate::estimate(part, start, machine, machine.block_rate_limit())
            };
            let mut h = header.to_vec();
            h.push(super::estimate_line(&est));
            if n > 1 {
                h.push(format!(
                    "program {} of {n}, run them in order: tool {} only. Mount it, keep X0 Y0, set Z0 on the \
                     touch-off pad (uncut stock top, see the setup sheet), then start",
                    k + 1,
                    tools.join(", ")
                ));
            }
            let gcode = emit::emit(&emit::Setup { header: &h, ..*setup }, part);
            ProgramFile {
                summary: FileSummary {
                    file: file_name(k + 1, n),
                    tools,
                    lines: gcode.lines().count(),
                    estimated_s: est.block_limited_s,
                },
                gcode,
            }
        })
        .collect()
}

impl Summary {
    /// The files to check and stream, in order.
    pub fn file_names(&self) -> Vec<&str> {
        self.files.iter().map(|f| f.file.as_str()).collect()
    }
}
