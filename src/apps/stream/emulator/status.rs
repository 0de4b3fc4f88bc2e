//! The `?` status report (GRBL's `report_realtime_status`): state, `MPos` or `WPos` (`$10`), `Bf` (planner
//! blocks and receive-buffer bytes free), `Ln` (the executing block's line number), `FS` (feed and spindle
//! speed), and `WCO` / `Ov` on GRBL's refresh schedule (every 10 reports when idle, 30 when running).

use super::controller::{Controller, State};
use super::planner::BlockKind;
use crate::apps::stream::program::Spindle;
use crate::apps::stream::protocol::{PLANNER_BLOCKS, RX_BUFFER_BYTES};

impl Controller {
    fn state_word(&self) -> String {
        if self.hold {
            return if self.decel_left_s > 0.0 { "Hold:1" } else { "Hold:0" }.into();
        }
        match self.state {
            State::Idle => "Idle",
            State::Run if self.jogging => "Jog",
            State::Run => "Run",
            State::Alarm => "Alarm",
            State::Check => "Check",
        }
        .into()
    }

    pub(super) fn status_report(&mut self) {
        if let Some((_, reports_left)) = self.stall.as_mut() {
            *reports_left = reports_left.saturating_sub(1);
        }
        let mask = self.setting(10) as u32;
        let wco = self.wco();
        let p = if mask & 1 == 1 {
            self.pos
        } else {
            [self.pos[0] - wco[0], self.pos[1] - wco[1], self.pos[2] - wco[2]]
        };
        let mut s = format!("<{}|", self.state_word());
        s += &format!(
            "{}:{:.3},{:.3},{:.3}",
            if mask & 1 == 1 { "MPos" } else { "WPos" },
            p[0],
            p[1],
            p[2]
        );
        if mask & 2 == 2 {
            s += &format!(
                "|Bf:{},{}",
                PLANNER_BLOCKS as usize - self.planner.len().min(PLANNER_BLOCKS as usize),
                RX_BUFFER_BYTES - self.rx.len()
            );
        }
        if self.line_numbers {
            if let Some(b) = self.planner.front() {
                if b.line > 0 {
                    s += &format!("|Ln:{}", b.line);
                }
            }
        }
        let feed = match self.planner.front() {
            Some(b) if self.state == State::Run && !self.hold => {
                if b.kind == BlockKind::Rapid {
                    self.setting(110)
                } else {
                    b.feed_mm_min * f64::from(self.feed_override) / 100.0
                }
            }
            _ => 0.0,
        };
        let rpm = if self.interp.modal.spindle == Spindle::Off {
            0.0
        } else {
            self.interp.modal.spindle_rpm
        };
        s += &format!("|FS:{feed:.0},{rpm:.0}");
        if self.wco_counter == 0 {
            self.wco_counter = if self.state == State::Run { 29 } else { 9 };
            self.ovr_pending = true;
            s += &format!("|WCO:{:.3},{:.3},{:.3}", wco[0], wco[1], wco[2]);
        } else {
            self.wco_counter -= 1;
            if std::mem::take(&mut self.ovr_pending) {
                s += &format!("|Ov:{},100,100", self.feed_override);
            }
        }
        s.push('>');
        self.say(&s);
    }
}
