//! GRBL 1.1's streaming protocol as a pure state machine: no I/O, no clock. It is told what was sent and
//! fed the lines that came back, and it answers what may be sent next and what each answer meant.
//!
//! **Character counting** (GRBL's `doc/markdown/interface.md`, `stream.py`): GRBL's serial receive buffer
//! holds 128 bytes (127 usable, it is a ring). Every line sent and not yet answered occupies its bytes plus
//! its newline; the sum must stay ≤ 127, or bytes are silently dropped. Each `ok` or `error:N` answers the
//! **oldest** unanswered line. Settings writes are sent alone: nothing else in flight before or after.
//! Realtime bytes ([`Realtime`]) are picked off by GRBL's serial interrupt and never enter the buffer, so
//! they are outside the count.
//!
//! # Example
//! ```
//! use brdfmill::apps::stream::protocol::{Counter, Decision, Response, parse_response};
//! let mut c: Counter<usize> = Counter::new(128);
//! assert_eq!(c.decide(100, false), Decision::Send);
//! c.sent(1, 100, false);
//! assert!(matches!(c.decide(30, false), Decision::WaitForBuffer { .. })); // 100 + 30 > 127
//! assert_eq!(parse_response("ok"), Response::Ok);
//! assert_eq!(c.answered(), Some(1));
//! ```

use std::collections::VecDeque;
use std::fmt;

/// GRBL 1.1's default serial receive buffer (`RX_BUFFER_SIZE`), bytes.
pub const RX_BUFFER_BYTES: usize = 128;

/// GRBL 1.1's planner blocks available when empty (`BLOCK_BUFFER_SIZE` − 1).
pub const PLANNER_BLOCKS: u16 = 15;

/// Realtime command bytes: executed on receipt, outside the receive buffer and the character count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Realtime {
    /// `?` status report request.
    Status = b'?',
    /// `!` feed hold: decelerate to a stop and hold.
    FeedHold = b'!',
    /// `~` cycle start / resume.
    CycleStart = b'~',
    /// Ctrl-X (0x18) soft reset: stops everything, flushes the buffers.
    SoftReset = 0x18,
    /// 0x85 jog cancel.
    JogCancel = 0x85,
    /// 0x90 feed override back to 100 %.
    FeedOverrideReset = 0x90,
}

impl Realtime {
    /// The byte on the wire.
    #[must_use]
    pub fn byte(self) -> u8 {
        self as u8
    }

    /// Is `b` a realtime byte GRBL 1.1 picks off (`?`, `!`, `~`, 0x18, 0x84–0x87, 0x90–0x9D, 0x9E, 0xA0, 0xA1)?
    #[must_use]
    pub fn is_realtime(b: u8) -> bool {
        matches!(b, b'?' | b'!' | b'~' | 0x18 | 0x84..=0x87 | 0x90..=0x9E | 0xA0 | 0xA1)
    }
}

/// The machine state word of a status report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum MachineState {
    /// Idle: nothing executing (the planner may still hold blocks before the cycle auto-starts).
    Idle,
    /// Run: executing motion.
    Run,
    /// Hold: feed hold; `sub` 0 = complete (stopped), 1 = decelerating.
    Hold {
        /// 0 hold complete, 1 hold in progress.
        sub: u8,
    },
    /// Jog.
    Jog,
    /// Alarm: locked, needs reset and/or unlock.
    Alarm,
    /// Safety door.
    Door {
        /// Door sub-state.
        sub: u8,
    },
    /// `$C` check mode.
    Check,
    /// Homing cycle.
    Home,
    /// Sleep.
    Sleep,
}

impl fmt::Display for MachineState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MachineState::Hold { sub } => write!(f, "Hold:{sub}"),
            MachineState::Door { sub } => write!(f, "Door:{sub}"),
            other => write!(f, "{other:?}"),
        }
    }
}

/// A parsed `<…>` status report. Positions in mm (GRBL's `$13=0`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Status {
    /// State word (`None` only for a report this parser did not understand).
    pub state: Option<MachineState>,
    /// `MPos`: machine position.
    pub mpos: Option<[f64; 3]>,
    /// `WPos`: work position.
    pub wpos: Option<[f64; 3]>,
    /// `WCO`: work coordinate offset (MPos = WPos + WCO), sent every 10–30 reports.
    pub wco: Option<[f64; 3]>,
    /// `Bf`: planner blocks available.
    pub planner_free: Option<u16>,
    /// `Bf`: receive-buffer bytes available.
    pub rx_free: Option<u16>,
    /// `Ln`: line number of the block executing (only when a block is in the planner and GRBL was built
    /// with `USE_LINE_NUMBERS`).
    pub line: Option<u32>,
    /// `FS`/`F`: current feed (mm/min).
    pub feed: Option<f64>,
    /// `FS`: spindle speed (rpm).
    pub spindle: Option<f64>,
}

/// One line received from GRBL, classified.
#[derive(Debug, Clone, PartialEq)]
pub enum Response {
    /// `ok`: the oldest line was accepted (planned, **not** executed).
    Ok,
    /// `error:N`: the oldest line was rejected.
    Error(u16),
    /// `ALARM:N`: the controller stopped and locked.
    Alarm(u16),
    /// `<…>` status report.
    Status(Status),
    /// `[MSG:…]` feedback message (text inside).
    Message(String),
    /// Another `[…]` push message (`[VER:…]`, `[OPT:…]`, `[GC:…]`, `[HLP:…]`…), brackets removed.
    Feedback(String),
    /// The welcome banner `Grbl 1.1h ['$' for help]` (after a reset or power-up): the version.
    Banner(String),
    /// `$N=value` setting line from `$$`.
    Setting(u16, String),
    /// Anything else (not GRBL, noise, echo).
    Other(String),
}

/// Parse one received line (without its line ending).
#[must_use]
pub fn parse_response(line: &str) -> Response {
    let l = line.trim();
    if l == "ok" {
        return Response::Ok;
    }
    if let Some(n) = l.strip_prefix("error:") {
        if let Ok(n) = n.trim().parse() {
            return Response::Error(n);
        }
    }
    if let Some(n) = l.strip_prefix("ALARM:") {
        if let Ok(n) = n.trim().parse() {
            return Response::Alarm(n);
        }
    }
    if l.starts_with('<') && l.ends_with('>') {
        if let Some(s) = parse_status(&l[1..l.len() - 1]) {
            return Response::Status(s);
        }
    }
    if let Some(m) = l.strip_prefix("[MSG:").and_then(|m| m.strip_suffix(']')) {
        return Response::Message(m.to_string());
    }
    if l.starts_with('[') && l.ends_with(']') {
        return Response::Feedback(l[1..l.len() - 1].to_string());
    }
    if let Some(rest) = l.strip_prefix("Grbl ") {
        let version = rest.split_whitespace().next().unwrap_or("").to_string();
        return Response::Banner(version);
    }
    if let Some(rest) = l.strip_prefix('$') {
        if let Some((n, v)) = rest.split_once('=') {
            if let Ok(n) = n.parse() {
                return Response::Setting(n, v.to_string());
            }
        }
    }
    Response::Other(l.to_string())
}

fn parse_state(s: &str) -> Option<MachineState> {
    let (word, sub) = match s.split_once(':') {
        Some((w, n)) => (w, n.parse::<u8>().ok()),
        None => (s, None),
    };
    Some(match word {
        "Idle" => MachineState::Idle,
        "Run" => MachineState::Run,
        "Hold" => MachineState::Hold { sub: sub.unwrap_or(0) },
        "Jog" => MachineState::Jog,
        "Alarm" => MachineState::Alarm,
        "Door" => MachineState::Door { sub: sub.unwrap_or(0) },
        "Check" => MachineState::Check,
        "Home" => MachineState::Home,
        "Sleep" => MachineState::Sleep,
        _ => return None,
    })
}

fn parse_axes(s: &str) -> Option<[f64; 3]> {
    let v: Vec<f64> = s.split(',').map(|x| x.parse().ok()).collect::<Option<_>>()?;
    (v.len() >= 3).then(|| [v[0], v[1], v[2]])
}

/// Parse the inside of `<…>`.
fn parse_status(inner: &str) -> Option<Status> {
    let mut fields = inner.split('|');
    let mut st = Status {
        state: Some(parse_state(fields.next()?)?),
        ..Status::default()
    };
    for f in fields {
        let (k, v) = f.split_once(':')?;
        match k {
            "MPos" => st.mpos = Some(parse_axes(v)?),
            "WPos" => st.wpos = Some(parse_axes(v)?),
            "WCO" => st.wco = Some(parse_axes(v)?),
            "Bf" => {
                let (b, r) = v.split_once(',')?;
                st.planner_free = Some(b.parse().ok()?);
                st.rx_free = Some(r.parse().ok()?);
            }
            "Ln" => st.line = Some(v.parse().ok()?),
            "FS" => {
                let (fe, sp) = v.split_once(',')?;
                st.feed = Some(fe.parse().ok()?);
                st.spindle = Some(sp.parse().ok()?);
            }
            "F" => st.feed = Some(v.parse().ok()?),
            _ => {} // Pn, Ov, A: not needed here.
        }
    }
    Some(st)
}

/// May the next line be sent now?
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Yes.
    Send,
    /// Not until enough answers free the receive buffer.
    WaitForBuffer {
        /// Bytes in flight now.
        in_flight: usize,
        /// Bytes the line needs (with its newline).
        needed: usize,
    },
    /// Not until every line in flight is answered (a line sent alone, before or after).
    WaitForAlone,
    /// Never: the line cannot fit the receive buffer at all.
    TooLong {
        /// Bytes the line needs (with its newline).
        needed: usize,
    },
}

#[derive(Debug, Clone)]
struct InFlight<T> {
    tag: T,
    bytes: usize,
    alone: bool,
}

/// The character counter: which lines are in GRBL's receive buffer and how many bytes they take.
/// `T` tags each line (the streamer uses its queue index).
#[derive(Debug, Clone)]
pub struct Counter<T> {
    capacity: usize,
    in_flight: VecDeque<InFlight<T>>,
    used: usize,
}

impl<T: Clone> Counter<T> {
    /// A counter for a receive buffer of `rx_buffer_bytes` (GRBL reports it in `[OPT:…,blocks,bytes]`;
    /// 128 by default). One byte of the ring is never usable, so the budget is `rx_buffer_bytes − 1`.
    #[must_use]
    pub fn new(rx_buffer_bytes: usize) -> Self {
        Counter {
            capacity: rx_buffer_bytes.saturating_sub(1).max(1),
            in_flight: VecDeque::new(),
            used: 0,
        }
    }

    /// Bytes usable (127 for GRBL's 128-byte buffer).
    #[must_use]
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes in flight (sent, not yet answered).
    #[must_use]
    pub fn used(&self) -> usize {
        self.used
    }

    /// Lines in flight.
    #[must_use]
    pub fn outstanding(&self) -> usize {
        self.in_flight.len()
    }

    /// May a line of `bytes` (newline included) be sent now? `alone`: a settings write that must be the
    /// only line in GRBL's buffer.
    #[must_use]
    pub fn decide(&self, bytes: usize, alone: bool) -> Decision {
        if bytes > self.capacity {
            return Decision::TooLong { needed: bytes };
        }
        if (alone && !self.in_flight.is_empty()) || self.in_flight.iter().any(|l| l.alone) {
            return Decision::WaitForAlone;
        }
        if self.used + bytes > self.capacity {
            return Decision::WaitForBuffer {
                in_flight: self.used,
                needed: bytes,
            };
        }
        Decision::Send
    }

    /// Record that a line of `bytes` (newline included) was written.
    pub fn sent(&mut self, tag: T, bytes: usize, alone: bool) {
        self.used += bytes;
        self.in_flight.push_back(InFlight { tag, bytes, alone });
    }

    /// An `ok` or `error:N` arrived: it answers the oldest line, returned (None: nothing was in flight —
    /// the controller answered a line that this counter never sent, a protocol fault).
    pub fn answered(&mut self) -> Option<T> {
        let l = self.in_flight.pop_front()?;
        self.used -= l.bytes;
        Some(l.tag)
    }

    /// Tags of the lines in flight, oldest first.
    pub fn pending(&self) -> impl Iterator<Item = &T> {
        self.in_flight.iter().map(|l| &l.tag)
    }

    /// Forget everything in flight (after a soft reset flushed GRBL's buffer); returns the dropped tags.
    pub fn flush(&mut self) -> Vec<T> {
        self.used = 0;
        self.in_flight.drain(..).map(|l| l.tag).collect()
    }
}

/// The text of a GRBL 1.1 error code (`doc/csv/error_codes_en_US.csv`).
#[must_use]
pub fn error_text(code: u16) -> &'static str {
    match code {
        1 => "expected command letter",
        2 => "bad number format",
        3 => "invalid '$' statement",
        4 => "negative value",
        5 => "homing not enabled",
        8 => "'$' command needs Idle",
        9 => "G-code locked out during alarm or jog",
        10 => "soft limits need homing enabled",
        11 => "line overflow (more than 79 characters)",
        15 => "jog travel exceeded",
        16 => "invalid jog command",
        20 => "unsupported or invalid G-code command",
        21 => "modal group violation",
        22 => "feed rate undefined",
        23 => "command requires an integer value",
        24 => "two commands both need the axis words",
        25 => "repeated word",
        26 => "no axis words for a command that needs them",
        27 => "invalid line number",
        28 => "missing required value word",
        31 => "axis words with no command to use them",
        33 => "invalid motion target",
        35 => "arc needs an in-plane offset",
        36 => "unused value words",
        _ => "see GRBL's error code table",
    }
}

/// The text of a GRBL 1.1 alarm code (`doc/csv/alarm_codes_en_US.csv`).
#[must_use]
pub fn alarm_text(code: u16) -> &'static str {
    match code {
        1 => "hard limit triggered; machine position likely lost, re-home",
        2 => "soft limit: motion target exceeds machine travel; position retained",
        3 => "reset while in motion; position may be lost, re-homing recommended",
        4 | 5 => "probe fail",
        6..=9 => "homing fail",
        _ => "see GRBL's alarm code table",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Replay a transcript: `> line` sends (counted), `< text` receives. Returns the tags answered, in order,
    /// with their responses.
    fn replay(transcript: &str) -> (Counter<usize>, Vec<(usize, Response)>) {
        let mut c = Counter::new(RX_BUFFER_BYTES);
        let mut answers = Vec::new();
        let mut tag = 0;
        for l in transcript.lines().map(str::trim).filter(|l| !l.is_empty()) {
            if let Some(sent) = l.strip_prefix("> ") {
                tag += 1;
                let bytes = sent.len() + 1;
                assert_eq!(c.decide(bytes, false), Decision::Send, "{sent} should fit");
                c.sent(tag, bytes, false);
            } else if let Some(got) = l.strip_prefix("< ") {
                let r = parse_response(got);
                if matches!(r, Response::Ok | Response::Error(_)) {
                    answers.push((c.answered().expect("answer with nothing in flight"), r));
                }
            }
        }
        (c, answers)
    }

    #[test]
    fn answers_go_to_the_oldest_line() {
        let (c, a) = replay(
            "> G21G90
             > G0X10
             < ok
             > G1X1F0
             < <Run|MPos:1.000,0.000,0.000|Bf:14,100|Ln:2|FS:0,0>
             < ok
             < error:22",
        );
        assert_eq!(a, vec![(1, Response::Ok), (2, Response::Ok), (3, Response::Error(22))]);
        assert_eq!(c.used(), 0);
    }

    #[test]
    fn never_exceeds_127_bytes() {
        let mut c: Counter<u32> = Counter::new(128);
        let line = 42; // 41 characters and a newline
        for i in 0..3 {
            assert_eq!(c.decide(line, false), Decision::Send);
            c.sent(i, line, false);
        }
        assert_eq!(c.used(), 126);
        assert_eq!(c.decide(1, false), Decision::Send);
        assert_eq!(
            c.decide(2, false),
            Decision::WaitForBuffer {
                in_flight: 126,
                needed: 2
            }
        );
        assert_eq!(c.answered(), Some(0));
        assert_eq!(c.decide(line, false), Decision::Send);
        assert_eq!(c.decide(200, false), Decision::TooLong { needed: 200 });
    }

    #[test]
    fn settings_go_alone() {
        let mut c: Counter<u32> = Counter::new(128);
        c.sent(1, 5, false);
        assert_eq!(c.decide(8, true), Decision::WaitForAlone);
        c.answered();
        assert_eq!(c.decide(8, true), Decision::Send);
        c.sent(2, 8, true);
        assert_eq!(c.decide(3, false), Decision::WaitForAlone);
        c.answered();
        assert_eq!(c.decide(3, false), Decision::Send);
    }

    #[test]
    fn parses_status_reports() {
        let r = parse_response("<Hold:0|MPos:1.500,-2.000,0.250|Bf:12,80|Ln:57|FS:400,1000|WCO:0.000,0.000,0.000>");
        let Response::Status(s) = r else { panic!("{r:?}") };
        assert_eq!(s.state, Some(MachineState::Hold { sub: 0 }));
        assert_eq!(s.mpos, Some([1.5, -2.0, 0.25]));
        assert_eq!((s.planner_free, s.rx_free, s.line), (Some(12), Some(80), Some(57)));
        assert_eq!((s.feed, s.spindle), (Some(400.0), Some(1000.0)));
        assert_eq!(s.wco, Some([0.0; 3]));
        let Response::Status(s) = parse_response("<Idle|WPos:0.000,0.000,0.000|F:0>") else {
            panic!()
        };
        assert_eq!(s.state, Some(MachineState::Idle));
        assert_eq!(s.wpos, Some([0.0; 3]));
    }

    #[test]
    fn parses_push_messages() {
        assert_eq!(parse_response("ALARM:2"), Response::Alarm(2));
        assert_eq!(
            parse_response("[MSG:Reset to continue]"),
            Response::Message("Reset to continue".into())
        );
        assert_eq!(
            parse_response("[VER:1.1h.20190825:]"),
            Response::Feedback("VER:1.1h.20190825:".into())
        );
        assert_eq!(
            parse_response("Grbl 1.1h ['$' for help]"),
            Response::Banner("1.1h".into())
        );
        assert_eq!(parse_response("$110=500.000"), Response::Setting(110, "500.000".into()));
        assert_eq!(parse_response("hello"), Response::Other("hello".into()));
        assert!(matches!(parse_response("<garbage"), Response::Other(_)));
        assert!(matches!(parse_response("<Nope|MPos:1,2,3>"), Response::Other(_)));
    }

    #[test]
    fn realtime_bytes_are_outside_the_count() {
        for b in [b'?', b'!', b'~', 0x18, 0x85, 0x90, 0x9D] {
            assert!(Realtime::is_realtime(b));
        }
        for b in [b'G', b'\n', b'$', b'0'] {
            assert!(!Realtime::is_realtime(b));
        }
    }
}
