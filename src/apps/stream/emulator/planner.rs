//! Motion: the blocks the interpreter makes (straight lines — an arc arrives as GRBL's `mc_arc` chords —
//! timed at their feed, cruising at it, no acceleration between blocks, and limited by each axis' maximum
//! rate), soft limits checked as each block is planned (GRBL's `mc_line`), a feed hold that decelerates
//! along the planned path, GRBL's 15-block planner, the commands that wait for it to empty (spindle,
//! coolant, dwell, program end), and simulated execution — the machine position moving along the head block
//! as simulated time advances, each finished or cut piece logged.

use std::collections::VecDeque;

use super::controller::{Controller, State};
use super::Piece;
use crate::apps::stream::protocol::PLANNER_BLOCKS;

/// How a block moves: straight at the rapid rate, or straight at its feed (every arc chord is one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum BlockKind {
    Rapid,
    Linear,
}

/// A planned motion block, in machine coordinates (mm).
#[derive(Debug, Clone)]
pub(super) struct Block {
    pub(super) line: u32,
    pub(super) from: [f64; 3],
    pub(super) to: [f64; 3],
    pub(super) kind: BlockKind,
    /// Simulated seconds at 100 % override.
    pub(super) duration_s: f64,
    /// Simulated seconds done.
    pub(super) elapsed_s: f64,
    pub(super) feed_mm_min: f64,
}

impl Block {
    /// The point a fraction `t` of the way along the block.
    fn at(&self, t: f64) -> [f64; 3] {
        let t = t.clamp(0.0, 1.0);
        std::array::from_fn(|i| self.from[i] + (self.to[i] - self.from[i]) * t)
    }

    fn length_mm(&self) -> f64 {
        (0..3).map(|i| (self.to[i] - self.from[i]).powi(2)).sum::<f64>().sqrt()
    }
}

/// What a parsed line waits for before its `ok`.
#[derive(Debug, Clone)]
pub(super) enum Waiting {
    /// A line's motion blocks waiting for planner space, one at a time as GRBL's `mc_line` plans them,
    /// each checked against the soft limits first; then what the line does after its motion, if anything
    /// (a program end waits for the planner to empty).
    Plan { blocks: Moves, then: Option<Box<Waiting>> },
    /// A spindle/coolant change or dwell waiting for the planner to empty (GRBL synchronises them), then
    /// the block's own motion, if any.
    Sync { dwell_s: f64, then: Option<Box<Waiting>> },
    /// Dwelling until this simulated time, then the block's motion.
    Dwell { until_s: f64, then: Option<Box<Waiting>> },
    /// A G38.x probing move: it waits for the planner to empty, runs alone until the probe's contact
    /// changes (or the move ends), and is answered once the machine has stopped (GRBL's `mc_probe_cycle`).
    Probe {
        block: Block,
        away: bool,
        no_error: bool,
        started: bool,
        /// What the line does once the probe has stopped (a program end), if anything.
        then: Option<Box<Waiting>>,
    },
    /// M2/M30 after the block's motion: once the planner is empty, `[MSG:Pgm End]` and the `ok`.
    End,
    /// M0 after the block's motion: once the planner is empty a feed hold (`Hold:0`) that only a cycle start
    /// (`~`) ends; the `ok` comes after it (GRBL's `PROGRAM_FLOW_PAUSED`).
    Pause { held: bool },
}

/// A line's motion, in order: one planner block, two (G28/G30 through an intermediate point), or an arc's
/// chords.
pub(super) type Moves = VecDeque<Block>;

/// What serving the waiting line came to.
pub(super) enum Served {
    /// It still waits (planner full, not yet empty, dwelling).
    Blocked,
    /// It moved on to its next stage: serve it again.
    Again,
    /// It was answered `ok` (or nothing was waiting): read the next line.
    Done,
}

impl Controller {
    /// A motion block from the parser position to `to` (see [`Controller::block_from`]).
    pub(super) fn block(&self, kind: BlockKind, to: [f64; 3], feed_mm_min: f64, line: u32) -> Block {
        self.block_from(self.interp.pos, kind, to, feed_mm_min, line)
    }

    /// A straight motion block from `from` to `to`, timed at its feed (no acceleration) and limited by each
    /// axis' maximum rate (`$110`–`$112`, mm/min); a rapid runs at those rates.
    pub(super) fn block_from(
        &self,
        from: [f64; 3],
        kind: BlockKind,
        to: [f64; 3],
        feed_mm_min: f64,
        line: u32,
    ) -> Block {
        let mut b = Block {
            line,
            from,
            to,
            kind,
            duration_s: 0.0,
            elapsed_s: 0.0,
            feed_mm_min,
        };
        let length = b.length_mm();
        if length >= 1e-9 {
            let axis_limited = (0..3)
                .map(|i| (to[i] - from[i]).abs() / (self.setting(110 + i as u16).max(1e-9) / 60.0))
                .fold(0.0, f64::max);
            b.duration_s = match kind {
                BlockKind::Rapid => axis_limited,
                BlockKind::Linear => (length / (feed_mm_min / 60.0)).max(axis_limited),
            };
        }
        b
    }

    /// Advance simulated time by `dt_s` seconds: execute motion (decelerating through a feed hold),
    /// finish dwells, run the main loop.
    pub fn advance(&mut self, dt_s: f64) {
        self.sim_time_s += dt_s;
        self.end_alarm_delay();
        if self.hold && self.decel_left_s > 0.0 {
            // Speed falls linearly to 0 over `decel_total_s`: the path covered in this step is the
            // integral of the speed fraction over it, run as that much time at full speed.
            let t = dt_s.min(self.decel_left_s);
            let (l0, l1) = (self.decel_left_s, self.decel_left_s - t);
            let effective = (l0 * l0 - l1 * l1) / (2.0 * self.decel_total_s.max(1e-12));
            self.decel_left_s = l1;
            self.execute_for(effective);
            if self.planner.is_empty() {
                self.decel_left_s = 0.0;
            }
            if self.soft_limit_pending && self.decel_left_s <= 0.0 {
                // the controlled stop before a soft limit's reset is complete
                self.soft_limit_pending = false;
                self.alarm(2);
            }
        }
        self.run_motion(dt_s);
        if self.jog_cancel && self.decel_left_s <= 0.0 {
            self.end_jog_cancel();
        }
        if self.state == State::Run && self.planner.is_empty() {
            self.state = State::Idle;
        }
        if self.state != State::Run {
            self.jogging = false;
        }
        self.main_loop();
    }

    /// Execute `dt` simulated seconds of the planner's blocks (unless holding, stalled or locked).
    fn run_motion(&mut self, dt: f64) {
        if let Some((bytes, reports_left)) = self.stall {
            if self.rx.len() < bytes && reports_left > 0 {
                return;
            }
            let how = if self.rx.len() >= bytes { "released" } else { "gave up" };
            self.log.events.push(format!(
                "stall {how} with {} bytes in the receive buffer",
                self.rx.len()
            ));
            self.stall = None;
        }
        if !self.hold {
            self.execute_for(dt);
        }
    }

    /// The speed (mm/s) of block `b` at the current feed override.
    pub(super) fn block_speed_mm_s(&self, b: &Block) -> f64 {
        if b.duration_s <= 0.0 {
            return 0.0;
        }
        let f = if b.kind == BlockKind::Rapid {
            1.0
        } else {
            f64::from(self.feed_override) / 100.0
        };
        b.length_mm() / b.duration_s * f
    }

    /// Move along the planner's blocks for `dt` simulated seconds at their programmed speed.
    fn execute_for(&mut self, mut dt: f64) {
        while dt > 0.0 && self.state == State::Run && !self.critical {
            let Some(b) = self.planner.front_mut() else { break };
            let f = if b.kind == BlockKind::Rapid {
                1.0
            } else {
                f64::from(self.feed_override) / 100.0
            };
            if self.probing.is_some() {
                self.probe_trigger(dt, f);
            }
            let Some(b) = self.planner.front_mut() else { break };
            let remaining = (b.duration_s - b.elapsed_s) / f;
            if dt >= remaining {
                dt -= remaining;
                let b = self.planner.pop_front().expect("front exists");
                self.pos = b.to;
                self.log.executed.push(Piece {
                    line: b.line,
                    from_mm: b.from,
                    to_mm: b.to,
                    complete: true,
                });
            } else {
                b.elapsed_s += dt * f;
                self.pos = b.at(b.elapsed_s / b.duration_s);
                dt = 0.0;
            }
        }
    }

    /// Serve the line whose `ok` waits on the planner: plan its block when there is room, start its
    /// synchronised command once the planner has emptied, finish its dwell.
    pub(super) fn serve_waiting(&mut self) -> Served {
        let Some(w) = self.waiting.take() else {
            return Served::Done;
        };
        match w {
            Waiting::Plan { mut blocks, then } => {
                while let Some(b) = blocks.front() {
                    if self.beyond_soft_limits(b.to) {
                        // the stop, ALARM:2 and, after the user's reset, the line's `ok` follow
                        self.soft_limit();
                        return Served::Blocked;
                    }
                    if self.planner_full() {
                        self.start_cycle();
                        self.waiting = Some(Waiting::Plan { blocks, then });
                        return Served::Blocked;
                    }
                    self.planner.extend(blocks.pop_front());
                }
                if let Some(w) = then {
                    self.waiting = Some(*w);
                    return Served::Again;
                }
                self.say("ok");
            }
            Waiting::Sync { dwell_s, then } => {
                if !self.planner.is_empty() {
                    self.start_cycle();
                    self.waiting = Some(Waiting::Sync { dwell_s, then });
                    return Served::Blocked;
                }
                self.waiting = Some(Waiting::Dwell {
                    until_s: self.sim_time_s + dwell_s,
                    then,
                });
                return Served::Again;
            }
            Waiting::Probe {
                block,
                away,
                no_error,
                started,
                then,
            } => return self.serve_probe(block, away, no_error, started, then),
            Waiting::End | Waiting::Pause { held: false } if !self.planner.is_empty() => {
                self.start_cycle();
                self.waiting = Some(w);
                return Served::Blocked;
            }
            Waiting::End => {
                self.say("[MSG:Pgm End]");
                self.say("ok");
            }
            Waiting::Pause { held: false } => {
                // the main loop waits while the hold is in force; it comes back here once `~` ended it
                self.hold = true;
                self.decel_left_s = 0.0;
                self.waiting = Some(Waiting::Pause { held: true });
                return Served::Blocked;
            }
            Waiting::Pause { held: true } => self.say("ok"),
            Waiting::Dwell { until_s, then } => {
                if self.sim_time_s < until_s {
                    self.waiting = Some(Waiting::Dwell { until_s, then });
                    return Served::Blocked;
                }
                match then {
                    Some(w) => {
                        self.waiting = Some(*w);
                        return Served::Again;
                    }
                    None => self.say("ok"),
                }
            }
        }
        if self.planner_full() {
            self.start_cycle();
        }
        Served::Done
    }

    /// A probing cycle: once the planner is empty, refuse a probe already in the state it seeks
    /// (`ALARM:4`), else run the move alone; once stopped, report `[PRB:]` (after `ALARM:5` when a G38.2 or
    /// G38.4 never changed contact) and answer `ok`. The parser then continues from where the machine
    /// stopped (GRBL's `gc_sync_position`), except after `ALARM:4`, when it never moved.
    fn serve_probe(
        &mut self,
        block: Block,
        away: bool,
        no_error: bool,
        started: bool,
        then: Option<Box<Waiting>>,
    ) -> Served {
        let wait = |c: &mut Controller, block: Block, started: bool, then: Option<Box<Waiting>>| {
            c.waiting = Some(Waiting::Probe {
                block,
                away,
                no_error,
                started,
                then,
            });
            Served::Blocked
        };
        if !started {
            if !self.planner.is_empty() {
                self.start_cycle();
                return wait(self, block, false, then);
            }
            // GRBL checks the probe's state before its move's soft limit (`mc_probe_cycle`, then `mc_line`)
            if self.probe_contact(self.pos) != away {
                self.alarm_unlockable(4);
                self.interp.pos = self.pos;
                self.say("ok");
                return Served::Done;
            }
            if self.beyond_soft_limits(block.to) {
                self.soft_limit();
                return Served::Blocked;
            }
            // the fraction of the move where the tip crosses the plate, going down (toward) or up (away)
            let (z0, z1) = (block.from[2], block.to[2]);
            let trigger_at = self.probe_plate_z_mm.and_then(|zp| {
                let crosses = if away { z1 > zp } else { z1 <= zp };
                crosses.then(|| {
                    if (z1 - z0).abs() < 1e-12 {
                        0.0
                    } else {
                        ((zp - z0) / (z1 - z0)).clamp(0.0, 1.0)
                    }
                })
            });
            self.probing = Some(super::controller::Probing { trigger_at, hit: false });
            self.planner.push_back(block.clone());
            self.start_cycle();
            return wait(self, block, true, then);
        }
        if !self.planner.is_empty() {
            return wait(self, block, true, then);
        }
        let hit = self.probing.take().is_some_and(|p| p.hit);
        if hit {
            self.probe_result.1 = true;
        } else if no_error {
            self.probe_result = (self.pos, false);
        } else {
            self.probe_result.1 = false;
            self.alarm_unlockable(5);
        }
        self.interp.pos = self.pos;
        self.report_probe();
        if let Some(w) = then {
            self.waiting = Some(*w);
            return Served::Again;
        }
        self.say("ok");
        Served::Done
    }

    /// `[PRB:x,y,z:s]`: the last probe position (machine mm) and whether it succeeded.
    pub(super) fn report_probe(&mut self) {
        let ([x, y, z], ok) = self.probe_result;
        self.say(&format!("[PRB:{x:.3},{y:.3},{z:.3}:{}]", u8::from(ok)));
    }

    /// The probe's contact changes `dt` simulated seconds into the head block: note where, and shorten
    /// the block to where the motion cancel brings the machine to rest (`v²/2a` further, at `$120`–`$122`'s
    /// least, as a feed hold).
    fn probe_trigger(&mut self, dt: f64, f: f64) {
        let Some(p) = self.probing.filter(|p| !p.hit) else {
            return;
        };
        let Some(t_hit) = p.trigger_at else {
            return;
        };
        let a = (120..=122)
            .map(|k| self.setting(k))
            .fold(f64::INFINITY, f64::min)
            .max(1e-6);
        let Some(b) = self.planner.front() else {
            return;
        };
        if b.duration_s <= 0.0 || (b.elapsed_s + dt * f) / b.duration_s < t_hit {
            return;
        }
        let v = self.block_speed_mm_s(b);
        let len = b.length_mm();
        let t_end = (t_hit + v * v / (2.0 * a) / len.max(1e-12)).min(1.0);
        let at = b.at(t_hit);
        let end = b.at(t_end);
        if let Some(b) = self.planner.front_mut() {
            b.to = end;
            b.duration_s *= t_end;
        }
        self.probe_result.0 = at;
        self.probing = Some(super::controller::Probing { hit: true, ..p });
    }

    pub(super) fn planner_full(&self) -> bool {
        self.planner.len() >= PLANNER_BLOCKS as usize
    }

    /// Start the cycle (GRBL's auto cycle start) when there is motion to run and no feed hold.
    pub(super) fn start_cycle(&mut self) {
        if self.state == State::Idle && !self.planner.is_empty() && !self.hold {
            self.state = State::Run;
        }
    }

    /// Log the head block's executed part when motion is cut short.
    fn log_partial_head(&mut self) {
        if let Some(b) = self.planner.front() {
            if b.elapsed_s > 0.0 {
                self.log.executed.push(Piece {
                    line: b.line,
                    from_mm: b.from,
                    to_mm: self.pos,
                    complete: false,
                });
            }
        }
    }

    /// The jog cancel's stop is complete: the planned jog motion is flushed and the machine is Idle where it
    /// stopped (GRBL's cycle stop with `SUSPEND_JOG_CANCEL`: `plan_reset`, `gc_sync_position`). A jog line
    /// that was waiting for planner space is not flushed: it was parsed, its target fixed from the parser
    /// position of then, and its `mc_line` was looping for room. Now that there is room it is planned from
    /// where the machine stopped to that target, `jog_execute` starts it (state `Jog`) and it is answered.
    fn end_jog_cancel(&mut self) {
        let kept = match self.waiting.take() {
            Some(Waiting::Plan { blocks, then: None }) if blocks.len() == 1 => blocks.into_iter().next(),
            other => {
                self.waiting = other;
                None
            }
        };
        self.flush_motion();
        self.state = State::Idle;
        self.jog_cancel = false;
        if let Some(b) = kept {
            let jog = self.block_from(self.pos, b.kind, b.to, b.feed_mm_min, b.line);
            self.interp.pos = b.to;
            if jog.duration_s > 0.0 {
                self.planner.push_back(jog);
                self.state = State::Run;
                self.jogging = true;
            }
            self.say("ok");
        }
    }

    /// Throw away all planned and waiting motion (a reset): the parser continues from where the tool is.
    pub(super) fn flush_motion(&mut self) {
        self.log_partial_head();
        self.planner.clear();
        self.waiting = None;
        self.hold = false;
        self.decel_left_s = 0.0;
        self.interp.pos = self.pos;
    }
}
