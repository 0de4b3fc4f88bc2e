//! Motion: the blocks the interpreter makes (lines and arcs in G17, G18 or G19, timed at their feed — cruising at it, no
//! acceleration between blocks — and limited by each axis' maximum rate), a feed hold that decelerates
//! along the planned path, GRBL's 15-block planner, the commands that wait for it to empty (spindle,
//! coolant, dwell, program end), and simulated execution — the machine position moving along
//! the head block as simulated time advances, each finished or cut piece logged.

use super::controller::{Controller, State};
use super::Piece;
use crate::stream::protocol::PLANNER_BLOCKS;

/// How a block moves: straight at the rapid rate, straight at its feed, or along an arc in the plane whose
/// (first, second, normal) axes are `axes` (G17 X Y Z, G18 Z X Y, G19 Y Z X), `center` in the first two,
/// clockwise seen from the normal's positive end when `cw`, linear along the normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum BlockKind {
    Rapid,
    Linear,
    Arc {
        center: [f64; 2],
        cw: bool,
        axes: [usize; 3],
    },
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
    fn at(&self, t: f64) -> [f64; 3] {
        let t = t.clamp(0.0, 1.0);
        match self.kind {
            BlockKind::Arc {
                center,
                cw,
                axes: [a, b, n],
            } => {
                if t >= 1.0 {
                    return self.to;
                }
                let (a0, sweep) = arc_sweep(self.from, self.to, center, cw, [a, b]);
                let r = (self.from[a] - center[0]).hypot(self.from[b] - center[1]);
                let ang = a0 + sweep * t;
                let mut p = [0.0; 3];
                p[a] = center[0] + r * ang.cos();
                p[b] = center[1] + r * ang.sin();
                p[n] = self.from[n] + (self.to[n] - self.from[n]) * t;
                p
            }
            _ => std::array::from_fn(|i| self.from[i] + (self.to[i] - self.from[i]) * t),
        }
    }
}

/// Start angle and signed sweep of an arc in the plane axes `[a, b]` (full circle when start = end).
fn arc_sweep(from: [f64; 3], to: [f64; 3], c: [f64; 2], cw: bool, [a, b]: [usize; 2]) -> (f64, f64) {
    let a0 = (from[b] - c[1]).atan2(from[a] - c[0]);
    let a1 = (to[b] - c[1]).atan2(to[a] - c[0]);
    let mut sweep = a1 - a0;
    if cw {
        if sweep >= -1e-9 {
            sweep -= std::f64::consts::TAU;
        }
    } else if sweep <= 1e-9 {
        sweep += std::f64::consts::TAU;
    }
    (a0, sweep)
}

/// What a parsed line waits for before its `ok`.
#[derive(Debug, Clone)]
pub(super) enum Waiting {
    /// A line's motion waiting for planner space.
    Plan(Moves),
    /// A spindle/coolant change or dwell waiting for the planner to empty (GRBL synchronises them), then
    /// the block's own motion, if any.
    Sync { dwell_s: f64, then: Option<Moves> },
    /// Dwelling until this simulated time, then the block's motion.
    Dwell { until_s: f64, then: Option<Moves> },
    /// A G38.x probing move: it waits for the planner to empty, runs alone until the probe's contact
    /// changes (or the move ends), and is answered once the machine has stopped (GRBL's `mc_probe_cycle`).
    Probe {
        block: Block,
        away: bool,
        no_error: bool,
        started: bool,
    },
}

/// A line's motion: one planner block, or two (G28/G30 through an intermediate point: the move home
/// follows the first).
pub(super) type Moves = (Block, Option<Box<Block>>);

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
    /// A motion block from the parser position to `to`, timed at its feed (no acceleration) and limited
    /// by each axis' maximum rate (`$110`–`$112`, mm/min).
    pub(super) fn block(&self, kind: BlockKind, to: [f64; 3], feed_mm_min: f64, line: u32) -> Block {
        let from = self.parser_pos;
        let d: Vec<f64> = (0..3).map(|i| to[i] - from[i]).collect();
        let axis_limited = (0..3)
            .map(|i| d[i].abs() / (self.setting(110 + i as u16).max(1e-9) / 60.0))
            .fold(0.0, f64::max);
        let length = match kind {
            BlockKind::Arc {
                center,
                cw,
                axes: [a, b, n],
            } => {
                let (_, sweep) = arc_sweep(from, to, center, cw, [a, b]);
                let r = (from[a] - center[0]).hypot(from[b] - center[1]);
                ((r * sweep).powi(2) + d[n].powi(2)).sqrt()
            }
            _ => (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
        };
        let duration_s = match kind {
            BlockKind::Rapid => axis_limited,
            _ => (length / (feed_mm_min / 60.0)).max(axis_limited),
        };
        Block {
            line,
            from,
            to,
            kind,
            duration_s: if length < 1e-9 { 0.0 } else { duration_s },
            elapsed_s: 0.0,
            feed_mm_min,
        }
    }

    /// Advance simulated time by `dt_s` seconds: execute motion (decelerating through a feed hold),
    /// finish dwells, run the main loop.
    pub fn advance(&mut self, dt_s: f64) {
        self.sim_time_s += dt_s;
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
        }
        self.run_motion(dt_s);
        if self.jog_cancel && self.decel_left_s <= 0.0 {
            // the jog decelerated to a stop: flush what is left of it, Idle where it stopped
            self.flush_motion();
            self.state = State::Idle;
            self.jog_cancel = false;
        }
        if self.state == State::Run && self.planner.is_empty() {
            self.state = State::Idle;
        }
        if self.state != State::Run {
            self.jogging = false;
        }
        self.main_loop();
    }

    /// Execute `dt` simulated seconds of the planner's blocks (unless holding or locked).
    fn run_motion(&mut self, dt: f64) {
        if !self.hold {
            self.execute_for(dt);
        }
    }

    /// The speed (mm/s) of block `b` at the current feed override.
    pub(super) fn block_speed_mm_s(&self, b: &Block) -> f64 {
        if b.duration_s <= 0.0 {
            return 0.0;
        }
        let len: f64 = (0..3).map(|i| (b.to[i] - b.from[i]).powi(2)).sum::<f64>().sqrt();
        let f = if b.kind == BlockKind::Rapid {
            1.0
        } else {
            f64::from(self.feed_override) / 100.0
        };
        len / b.duration_s * f
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
            Waiting::Plan((b, next)) => {
                if self.planner_full() {
                    self.start_cycle();
                    self.waiting = Some(Waiting::Plan((b, next)));
                    return Served::Blocked;
                }
                self.planner.push_back(b);
                if let Some(n) = next {
                    self.waiting = Some(Waiting::Plan((*n, None)));
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
            } => return self.serve_probe(block, away, no_error, started),
            Waiting::Dwell { until_s, then } => {
                if self.sim_time_s < until_s {
                    self.waiting = Some(Waiting::Dwell { until_s, then });
                    return Served::Blocked;
                }
                match then {
                    Some(b) => {
                        self.waiting = Some(Waiting::Plan(b));
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
    fn serve_probe(&mut self, block: Block, away: bool, no_error: bool, started: bool) -> Served {
        let wait = |c: &mut Controller, block: Block, started: bool| {
            c.waiting = Some(Waiting::Probe {
                block,
                away,
                no_error,
                started,
            });
            Served::Blocked
        };
        if !started {
            if !self.planner.is_empty() {
                self.start_cycle();
                return wait(self, block, false);
            }
            if self.probe_contact(self.pos) != away {
                self.alarm_unlockable(4);
                self.parser_pos = self.pos;
                self.say("ok");
                return Served::Done;
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
            return wait(self, block, true);
        }
        if !self.planner.is_empty() {
            return wait(self, block, true);
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
        self.parser_pos = self.pos;
        self.report_probe();
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
        let len: f64 = (0..3).map(|i| (b.to[i] - b.from[i]).powi(2)).sum::<f64>().sqrt();
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

    /// Throw away all planned and waiting motion (a reset): the parser continues from where the tool is.
    pub(super) fn flush_motion(&mut self) {
        self.log_partial_head();
        self.planner.clear();
        self.waiting = None;
        self.hold = false;
        self.decel_left_s = 0.0;
        self.parser_pos = self.pos;
    }
}
