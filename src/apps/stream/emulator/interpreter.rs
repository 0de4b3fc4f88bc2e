//! The virtual controller's G-code interpreter, GRBL's `gc_execute_line` (`gcode.c`): the crate's one
//! interpreter ([`crate::gcode::interp`], GRBL 1.1h's dialect) checks the block and works out what it does —
//! modal groups and GRBL's error codes, absolute or incremental mm or inches, work coordinates (G54–G59 set by
//! G10 L2/L20, G92 and G92.1, G43.1 and G49, G53, G28/G30 and their G28.1/G30.1), arcs in G17, G18 and G19 in
//! offset and `R` form, G93, G38.x — and this file hands the result to the planner: GRBL's arc chords, soft
//! limits in check mode, and the order in which a block's spindle, dwell, motion and program flow run.

use super::controller::{Controller, State};
use super::line_reader::leading_line_number;
use super::planner::{BlockKind, Moves, Waiting};
use crate::apps::stream::program::{self, MotionMode};
use crate::gcode::interp::{Motion, Step, R_ARC_WITHOUT_TRAVEL};
use crate::gcode::moves::Arc;

impl Controller {
    /// Parse and run one G-code block; `Err(code)` is GRBL's error code.
    pub(super) fn gcode(&mut self, text: &str) -> Result<(), u16> {
        let ws = program::words(text).map_err(|e| e.grbl_code())?;
        let step = self.interp.block(&ws).map_err(|e| {
            if e.message == R_ARC_WITHOUT_TRAVEL {
                // a helix along the normal alone: GRBL divides by the zero chord and plans a NaN centre
                self.log.events.push(format!(
                    "not modelled: an `R` arc with no travel in its plane in `{text}`"
                ));
            }
            e.code
        })?;
        let line = leading_line_number(text).unwrap_or(0);
        let moves = step.motion.and_then(|mo| self.planned(&step, mo, line));
        self.hand_over(&step, moves);
        Ok(())
    }

    /// The planner blocks of a block's motion, from where the block started (`None`: it does not move).
    /// G28/G30 is two rapids, through the intermediate point; an arc is GRBL's chords
    /// ([`Controller::arc_chords`]). Each is checked against the soft limits as it is planned.
    fn planned(&self, step: &Step, motion: Motion, line: u32) -> Option<Moves> {
        let from = step.from;
        let blocks: Moves = match motion {
            Motion::Stored { via, to } => [
                self.block_from(from, BlockKind::Rapid, via, 0.0, line),
                self.block_from(via, BlockKind::Rapid, to, 0.0, line),
            ]
            .into(),
            Motion::Arc { arc, .. } => self.arc_chords(from, &arc, line),
            Motion::Line { mode, to, feed_mm_min } => {
                let kind = if mode == MotionMode::Rapid {
                    BlockKind::Rapid
                } else {
                    BlockKind::Linear
                };
                [self.block_from(from, kind, to, feed_mm_min, line)].into()
            }
        };
        let blocks: Moves = blocks.into_iter().filter(|b| b.duration_s > 0.0).collect();
        (!blocks.is_empty()).then_some(blocks)
    }

    /// GRBL's `mc_arc`: the arc from `from` as its [`Arc::grbl_chords`] chords for `$12`, ends on
    /// the arc, each a linear block at the arc's feed (the last ends exactly at the arc's end). GRBL rotates the
    /// radius vector in single precision with a correction every 12 chords; the ends here are exact, within
    /// 10⁻⁶ mm of it.
    fn arc_chords(&self, from: [f64; 3], arc: &Arc, line: u32) -> Moves {
        let feed_mm_min = arc.feed_mm_min;
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

    /// What happens to a valid block: in check mode only its `ok`; spindle, coolant, dwell and program
    /// end wait for the planner to empty, then their motion is planned; plain motion waits for planner
    /// space. The interpreter has moved the parser on to the block's end already.
    fn hand_over(&mut self, step: &Step, blocks: Option<Moves>) {
        let (parsed, m) = (&step.parsed, &step.modal);
        if self.state == State::Check {
            // no motion is planned in check mode, but soft limits still alarm (GRBL's `mc_line`)
            if blocks.iter().flatten().any(|b| self.beyond_soft_limits(b.to)) {
                self.alarm(2);
            } else {
                self.say("ok");
            }
            return;
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
        self.waiting = if parsed.sync || step.dwell_s.is_some() {
            Some(Waiting::Sync {
                dwell_s: step.dwell_s.unwrap_or(0.0),
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
