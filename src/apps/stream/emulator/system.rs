//! GRBL's `$` system commands (`system.c`) and its settings (`settings.c`): help, `$$` and `$x=` (with
//! GRBL's checks: unknown setting, negative value, machine busy, soft limits without homing), `$#`, `$G`,
//! `$I`, `$N`, `$X` unlock, `$H` homing (instant: the machine is at its origin), `$C` check mode and
//! `$RST`. Jogging (`$J=`) and sleep (`$SLP`) are not modelled: they answer `error:3` and are logged.

use std::collections::BTreeMap;

use super::controller::{Controller, State};
use super::{BUILD_DATE, VERSION};
use crate::apps::stream::program::{Distance, Modal, MotionMode, Spindle, Units};
use crate::apps::stream::protocol::{PLANNER_BLOCKS, RX_BUFFER_BYTES};

/// GRBL 1.1's default settings (`defaults.h`, generic profile).
pub(super) fn default_settings() -> BTreeMap<u16, f64> {
    [
        (0, 10.0),
        (1, 25.0),
        (2, 0.0),
        (3, 0.0),
        (4, 0.0),
        (5, 0.0),
        (6, 0.0),
        (10, 1.0),
        (11, 0.010),
        (12, 0.002),
        (13, 0.0),
        (20, 0.0),
        (21, 0.0),
        (22, 0.0),
        (23, 0.0),
        (24, 25.0),
        (25, 500.0),
        (26, 250.0),
        (27, 1.0),
        (30, 1000.0),
        (31, 0.0),
        (32, 0.0),
        (100, 250.0),
        (101, 250.0),
        (102, 250.0),
        (110, 500.0),
        (111, 500.0),
        (112, 500.0),
        (120, 10.0),
        (121, 10.0),
        (122, 10.0),
        (130, 200.0),
        (131, 200.0),
        (132, 200.0),
    ]
    .into_iter()
    .collect()
}

pub(super) const INTEGER_SETTINGS: [u16; 17] = [0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32];

/// GRBL's `read_float` for a setting value.
fn parse_grbl_float(v: &str) -> Option<f64> {
    let ok = !v.is_empty()
        && v.chars()
            .all(|c| c.is_ascii_digit() || c == '.' || c == '-' || c == '+')
        && v.chars().any(|c| c.is_ascii_digit());
    if ok {
        v.parse().ok()
    } else {
        None
    }
}

/// How a `$` command is answered once its own output is out.
enum Reply {
    Ok,
    Error(u16),
    /// It answered itself.
    Answered,
}

/// The `$G` number of a motion mode.
fn motion_number(m: MotionMode) -> &'static str {
    // the G code without its letter: `0` … `80`, `38.2` … `38.5`
    &m.name()[1..]
}

/// The `$G` number of a spindle state (`M3`, `M4`, `M5`).
fn spindle_number(s: Spindle) -> u8 {
    match s {
        Spindle::Cw => 3,
        Spindle::Ccw => 4,
        Spindle::Off => 5,
    }
}

impl Controller {
    /// Run a `$` line and answer it.
    pub(super) fn system_command(&mut self, text: &str) {
        match self.system_reply(text) {
            Reply::Ok => self.say("ok"),
            Reply::Error(code) => self.say(&format!("error:{code}")),
            Reply::Answered => {}
        }
    }

    fn system_reply(&mut self, text: &str) -> Reply {
        let idle_or_alarm = matches!(self.state, State::Idle | State::Alarm) && !self.hold;
        match text {
            "$" => self.say("[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"),
            "$$" => self.report_settings(),
            "$#" => {
                let rows: Vec<(String, [f64; 3])> = (0..6)
                    .map(|k| (format!("G{}", 54 + k), self.interp.offsets.coord[k]))
                    .chain([
                        ("G28".to_string(), self.interp.offsets.stored[0]),
                        ("G30".to_string(), self.interp.offsets.stored[1]),
                        ("G92".to_string(), self.interp.offsets.g92),
                    ])
                    .collect();
                for (g, v) in rows {
                    self.say(&format!("[{g}:{:.3},{:.3},{:.3}]", v[0], v[1], v[2]));
                }
                self.say(&format!("[TLO:{:.3}]", self.interp.offsets.tlo));
                self.report_probe();
            }
            "$G" => self.report_modes(),
            "$I" => {
                self.say(&format!("[VER:{VERSION}.{BUILD_DATE}:]"));
                // `V` variable spindle; `N` line numbers and `M` M7 only on builds that enable them.
                let opts = format!(
                    "V{}{}",
                    if self.line_numbers { "N" } else { "" },
                    if self.interp.m7 { "M" } else { "" }
                );
                self.say(&format!("[OPT:{opts},{PLANNER_BLOCKS},{RX_BUFFER_BYTES}]"));
            }
            "$N" => {
                self.say("$N0=");
                self.say("$N1=");
            }
            "$X" => {
                if self.state == State::Alarm {
                    self.state = State::Idle;
                    self.say("[MSG:Caution: Unlocked]");
                }
            }
            "$H" => return self.home(idle_or_alarm),
            "$C" => return self.toggle_check_mode(),
            t if t.starts_with("$RST=") => return self.restore_defaults(&t[5..], idle_or_alarm),
            t if t.starts_with("$N") && t.contains('=') => {
                if !idle_or_alarm {
                    return Reply::Error(8);
                }
            }
            t if t.contains('=') && t[1..].starts_with(|c: char| c.is_ascii_digit()) => {
                return self.write_setting(&t[1..], idle_or_alarm)
            }
            t if t.starts_with("$J=") => return self.jog(&t[3..]),
            other => {
                if other == "$SLP" {
                    self.log.events.push(format!("not modelled: `{other}`"));
                    return Reply::Error(3);
                }
                // GRBL reads anything else as `$<number>=<value>`: no number is a bad number format.
                let numeric = other[1..].starts_with(|c: char| c.is_ascii_digit() || c == '.' || c == '-');
                return Reply::Error(if numeric { 3 } else { 2 });
            }
        }
        Reply::Ok
    }

    /// `$$`: every setting, integers without decimals.
    fn report_settings(&mut self) {
        let lines: Vec<String> = self
            .settings
            .iter()
            .map(|(k, v)| {
                if INTEGER_SETTINGS.contains(k) {
                    format!("${k}={}", *v as i64)
                } else {
                    format!("${k}={v:.3}")
                }
            })
            .collect();
        for l in lines {
            self.say(&l);
        }
    }

    /// `$J=`: a jog (GRBL 1.1 `jog_execute`), only when Idle or already jogging (`error:8`). Its words: G20/G21,
    /// G90/G91 and G53 for this jog only (the parser's modes are kept), X Y Z, a required F (`error:22`), N;
    /// anything else is `error:16`. A target beyond the soft limits is refused with `error:15` (no alarm).
    /// The jog starts at once (state `Jog`) and moves the parser to its target.
    fn jog(&mut self, body: &str) -> Reply {
        if !(self.state == State::Idle && !self.hold || self.jogging) {
            return Reply::Error(8);
        }
        let words = match crate::apps::stream::program::words(body) {
            Ok(w) => w,
            Err(e) => return Reply::Error(e.grbl_code()),
        };
        let mut inch = self.interp.modal.units == Units::Inch;
        let mut incremental = self.interp.modal.distance == Distance::Incremental;
        let (mut machine, mut axis, mut feed) = (false, [None; 3], None);
        for w in &words {
            match (w.letter, (w.value * 10.0).round() as i32) {
                ('G', 200) => inch = true,
                ('G', 210) => inch = false,
                ('G', 900) => incremental = false,
                ('G', 910) => incremental = true,
                ('G', 530) => machine = true,
                ('X', _) => axis[0] = Some(w.value),
                ('Y', _) => axis[1] = Some(w.value),
                ('Z', _) => axis[2] = Some(w.value),
                ('F', _) => feed = Some(w.value),
                ('N', _) => {}
                _ => return Reply::Error(16),
            }
        }
        let Some(f) = feed else {
            return Reply::Error(22);
        };
        let k = if inch { 25.4 } else { 1.0 };
        let target = self.axis_target(axis, k, machine, incremental, self.wco());
        if self.beyond_soft_limits(target) {
            return Reply::Error(15);
        }
        let b = self.block(super::planner::BlockKind::Linear, target, f * k, 0);
        self.interp.pos = target;
        if b.duration_s <= 0.0 {
            return Reply::Ok;
        }
        self.jogging = true;
        self.state = State::Run;
        if self.planner_full() {
            self.waiting = Some(super::planner::Waiting::Plan {
                blocks: [b].into(),
                then: None,
            });
            return Reply::Answered; // `ok` once the planner has room
        }
        self.planner.push_back(b);
        Reply::Ok
    }

    /// `$G`: the parser's modal state.
    fn report_modes(&mut self) {
        let m: Modal = self.interp.modal;
        self.say(&format!(
            "[GC:G{} G{} G{} G{} G{} G{} M{} M9 T0 F{} S{}]",
            motion_number(m.motion),
            54 + self.interp.offsets.select,
            m.plane,
            if m.units == Units::Inch { 20 } else { 21 },
            if m.distance == Distance::Incremental { 91 } else { 90 },
            if self.interp.inverse_time { 93 } else { 94 },
            spindle_number(m.spindle),
            m.feed_mm_min.unwrap_or(0.0),
            m.spindle_rpm
        ));
    }

    /// `$H`: homing needs `$22=1` and a machine at rest; it is instant and leaves the machine at 0.
    fn home(&mut self, idle_or_alarm: bool) -> Reply {
        if self.setting(22) != 1.0 {
            return Reply::Error(5);
        }
        if !idle_or_alarm {
            return Reply::Error(8);
        }
        self.pos = [0.0; 3];
        self.interp.pos = self.pos;
        self.state = State::Idle;
        Reply::Ok
    }

    /// `$C`: enter check mode (idle only), or leave it with a soft reset.
    fn toggle_check_mode(&mut self) -> Reply {
        if self.state == State::Check {
            self.say("[MSG:Disabled]");
            self.say("ok");
            self.soft_reset();
            return Reply::Answered;
        }
        if self.state != State::Idle || self.hold || !self.planner.is_empty() {
            return Reply::Error(8);
        }
        self.state = State::Check;
        self.say("[MSG:Enabled]");
        Reply::Ok
    }

    /// `$RST=$`, `$RST=#`, `$RST=*`: restore the defaults (`#`, the offsets, is a no-op here).
    fn restore_defaults(&mut self, what: &str, idle_or_alarm: bool) -> Reply {
        if !idle_or_alarm {
            return Reply::Error(8);
        }
        if !matches!(what, "$" | "#" | "*") {
            return Reply::Error(3);
        }
        if what.ends_with('$') || what.ends_with('*') {
            self.settings = default_settings();
        }
        Reply::Ok
    }

    /// `$x=value` (`assignment` without the `$`), with GRBL's checks in GRBL's order.
    fn write_setting(&mut self, assignment: &str, idle_or_alarm: bool) -> Reply {
        let (k, v) = assignment.split_once('=').expect("contains =");
        let Ok(k) = k.parse::<u16>() else {
            return Reply::Error(3);
        };
        let Some(v) = parse_grbl_float(v) else {
            return Reply::Error(2);
        };
        if !self.settings.contains_key(&k) {
            return Reply::Error(3);
        }
        if v < 0.0 {
            return Reply::Error(4);
        }
        if !idle_or_alarm {
            return Reply::Error(8);
        }
        if k == 20 && v != 0.0 && self.setting(22) != 1.0 {
            return Reply::Error(10);
        }
        self.settings
            .insert(k, if INTEGER_SETTINGS.contains(&k) { v.trunc() } else { v });
        Reply::Ok
    }
}
