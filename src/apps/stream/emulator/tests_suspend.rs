//! The controller as GRBL 1.1h's suspend and `mc_line`/`mc_arc` make it behave, byte for byte as a host
//! sees it: nothing parsed during a feed hold, a soft limit's controlled stop before `ALARM:2`, arcs planned
//! chord by chord with the `ok` after the last, a program end answered once its motion has run, and a probe
//! in a block with spindle and coolant words.

use super::tests::{ctl, send, with_plate};
use super::*;

/// Run `seconds` of simulated time in 10 ms steps; everything the controller said meanwhile.
fn run(c: &mut Controller, seconds: f64) -> String {
    let mut out = String::new();
    for _ in 0..(seconds / 0.01).round() as usize {
        c.advance(0.01);
        out += &String::from_utf8(c.take_output()).unwrap();
    }
    out
}

/// The X of a status report's `MPos`.
fn mpos_x(status: &str) -> f64 {
    status
        .split("MPos:")
        .nth(1)
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// GRBL's `protocol_exec_rt_suspend` keeps the main program waiting while a hold is in force: a line sent
/// during a hold is neither parsed nor answered until the resume, and a reset flushes it unparsed.
#[test]
fn nothing_is_parsed_during_a_feed_hold() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "N1G1X10F600\n"), "ok\r\n");
    run(&mut c, 0.5);
    send(&mut c, "!");
    run(&mut c, 1.0);
    assert!(send(&mut c, "?").starts_with("<Hold:0|"));
    assert_eq!(send(&mut c, "N2G1X20\n"), "", "no answer during the hold");
    assert_eq!(send(&mut c, "$G\n"), "", "not even to a `$` command");
    assert_eq!(run(&mut c, 1.0), "");
    let out = send(&mut c, "~");
    assert!(
        out.starts_with("ok\r\n[GC:G1 "),
        "both answered on the resume, in order: {out}"
    );
    // a hold from Idle blocks too; the reset then flushes the waiting line: it is never parsed
    run(&mut c, 10.0);
    send(&mut c, "!");
    assert_eq!(send(&mut c, "N3G1X0\n"), "");
    let out = send(&mut c, "\x18");
    assert!(out.starts_with("\r\nGrbl 1.1h"), "{out}");
    assert!(
        !c.log.received.iter().any(|l| l.starts_with("N3")),
        "{:?}",
        c.log.received
    );
    assert!(send(&mut c, "?").starts_with("<Idle|MPos:20.000,0.000,0.000"));
}

/// A jog sent while a jog cancel decelerates waits in the receive buffer and runs once the cancel has
/// flushed the planner: GRBL flushes the jog motion it planned, not the lines it has not read.
#[test]
fn a_jog_sent_during_a_jog_cancel_runs_after_it() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "$J=G91X10F300\n"), "ok\r\n");
    assert_eq!(send(&mut c, "$J=G91X10F300\n"), "ok\r\n", "planned behind the first");
    run(&mut c, 0.5);
    c.receive(0x85);
    assert_eq!(send(&mut c, "$J=G91Y1F300\n"), "", "waits for the cancel");
    let out = run(&mut c, 0.6);
    assert_eq!(out, "ok\r\n", "answered once the cancel is done");
    // the cancel stopped at X 3.75 (5 mm/s, 10 mm/s²) and flushed the second X jog; the Y jog ran from there
    run(&mut c, 2.0);
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Idle|MPos:3.750,1.000,0.000"), "{s}");
}

/// A jog waiting for planner space when a jog cancel completes is not flushed with the planned jogs: GRBL's
/// `mc_line` was looping for room with its target already fixed (from the parser position at the end of
/// the jogs planned before it), and once `plan_reset` makes room it plans it from where the machine stopped,
/// `jog_execute` starts it and the line is answered.
#[test]
fn a_jog_waiting_for_the_planner_runs_to_its_target_after_a_jog_cancel() {
    let mut c = ctl();
    // 2 mm jogs at 300 mm/min (0.4 s each): the planner takes 15, the 16th (target X32) waits for room
    for k in 1..=15 {
        assert_eq!(send(&mut c, "$J=G91X2F300\n"), "ok\r\n", "jog {k}");
    }
    assert_eq!(
        send(&mut c, "$J=G91X2F300\n"),
        "",
        "the planner is full: the 16th waits"
    );
    assert_eq!(run(&mut c, 0.3), "", "still waiting while the first jog runs");
    c.receive(0x85);
    // 5 mm/s at $120 = 10 mm/s²: 0.5 s and 1.25 mm to stop, at X 2.75; then the 16th is planned and answered
    let out = run(&mut c, 0.6);
    assert_eq!(out, "ok\r\n", "the waiting jog is answered once the cancel is done");
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Jog|"), "and runs: {s}");
    // 29.25 mm at 5 mm/s
    run(&mut c, 6.0);
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Idle|MPos:32.000,0.000,0.000"), "{s}");
    let last = c.log.executed.last().unwrap();
    assert!(last.complete && (last.from_mm[0] - 2.75).abs() < 1e-9, "{last:?}");
    assert!(send(&mut c, "$G\n").contains(" G90 "), "the jogs' G91 was their own");
}

/// Issue 14, row 3, as GRBL 1.1h's `limits_soft_check` runs it: a target beyond the travel during a cycle
/// first brings the machine to a controlled stop along its path (`Hold:1` meanwhile, the line unanswered,
/// the blocks behind it still executing as they decelerate), then `ALARM:2` and `[MSG:Reset to continue]`.
/// After that no `?` is answered until a reset, after which the line returns from the abort with an `ok`;
/// the position is kept.
#[test]
fn a_soft_limit_in_a_cycle_stops_under_control_then_alarms() {
    let mut c = ctl();
    for s in ["$22=1\n", "$X\n", "$20=1\n"] {
        assert!(send(&mut c, s).ends_with("ok\r\n"), "{s}");
    }
    // 300 mm/min = 5 mm/s along −X; $120 = 10 mm/s²: 0.5 s and 1.25 mm to stop
    assert_eq!(send(&mut c, "N1G1X-100F300\n"), "ok\r\n");
    run(&mut c, 1.0);
    assert_eq!(
        send(&mut c, "N2G1X5\n"),
        "",
        "the line beyond the travel is never answered"
    );
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Hold:1|"), "a controlled stop first: {s}");
    // a quarter second in: 5·0.25 − 10·0.25²/2 = 0.9375 mm further, still decelerating, no alarm yet
    assert_eq!(run(&mut c, 0.25), "");
    assert!((c.position()[0] + 5.9375).abs() < 1e-9, "{:?}", c.position());
    let out = run(&mut c, 1.0);
    assert_eq!(out, "ALARM:2\r\n[MSG:Reset to continue]\r\n");
    assert!((c.position()[0] + 6.25).abs() < 1e-9, "{:?}", c.position());
    assert_eq!(send(&mut c, "?"), "", "locked: no report");
    let out = send(&mut c, "\x18");
    assert!(out.starts_with("ok\r\n\r\nGrbl 1.1h"), "{out}");
    let s = send(&mut c, "?");
    assert!(
        s.starts_with("<Alarm|") && (mpos_x(&s) + 6.25).abs() < 1e-9,
        "kept: {s}"
    );
    let pieces = &c.log.executed;
    assert_eq!(pieces.len(), 1, "{pieces:?}");
    assert!(pieces[0].line == 1 && !pieces[0].complete && (pieces[0].to_mm[0] + 6.25).abs() < 1e-9);
}

/// An arc beyond the travel part of the way: GRBL checks each chord as it plans it, so the chords before
/// the first one outside are planned (and run while the machine stops), the rest never are.
#[test]
fn an_arc_leaving_the_travel_alarms_at_its_first_chord_outside() {
    let mut c = ctl();
    for s in ["$22=1\n", "$X\n", "$20=1\n"] {
        send(&mut c, s);
    }
    // a half circle of radius 5 about (−10, −4.5) from X−15 to X−5, clockwise: it rises to Y+0.5, past
    // machine Y 0 after ⌊55 · 1.12/π⌋ = 19 of its 55 chords — more than the planner holds, so it is already
    // running when the first chord outside is checked
    assert_eq!(send(&mut c, "G0X-15Y-4.5\n"), "ok\r\n");
    run(&mut c, 10.0);
    assert_eq!(send(&mut c, "N3G2X-5I5F300\n"), "");
    assert_eq!(run(&mut c, 5.0), "ALARM:2\r\n[MSG:Reset to continue]\r\n");
    let ran: Vec<&Piece> = c.log.executed.iter().filter(|p| p.line == 3).collect();
    // the 20th chord is checked once the 19th is planned, 15 behind the one executing (the 5th); the stop
    // then takes 1.25 mm, about 4 more chords of 0.29 mm: it ran into none of the 15 that were planned
    assert!((5..19).contains(&ran.len()), "the chords inside ran: {ran:?}");
    assert!(ran.iter().all(|p| p.to_mm[1] <= 1e-9), "none outside: {ran:?}");
    send(&mut c, "\x18");
    let cut = c.log.executed.iter().filter(|p| p.line == 3 && !p.complete).count();
    assert!(cut <= 1, "at most the chord it stopped in is cut");
    // the other way round the arc dips to Y−9.5, inside: it runs, chord by chord
    send(&mut c, "$X\n");
    assert_eq!(send(&mut c, "G0X-15Y-4.5\n"), "ok\r\n");
    run(&mut c, 10.0);
    assert_eq!(send(&mut c, "N4G3X-5I5F300\n"), "");
    let out = run(&mut c, 10.0);
    assert_eq!(out, "ok\r\n");
    let chords = c.log.executed.iter().filter(|p| p.line == 4).count();
    // ⌊|π·5/2| / √(0.002·(10 − 0.002))⌋ = 55
    let expected = ((std::f64::consts::PI * 5.0 / 2.0) / (0.002f64 * (10.0 - 0.002)).sqrt()).floor() as usize;
    assert_eq!(chords, expected);
}

/// An arc longer than the planner is executing before it is answered: `Ln` names it, `Bf` shows the
/// planner full, and the `ok` comes once its last chord is planned — the streamer may not read "not
/// answered" as "not started".
#[test]
fn an_arc_runs_before_its_ok() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "N1G1X10F6000\n"), "ok\r\n");
    run(&mut c, 1.0);
    // a full circle of radius 10: ⌊(2π·10/2) / √(0.002·19.998)⌋ = 157 chords, 2π·10 mm at 600 mm/min ≈ 6.3 s
    assert_eq!(send(&mut c, "N2G2X10I-10F600\n"), "");
    run(&mut c, 1.0);
    let s = send(&mut c, "?");
    assert!(s.contains("|Bf:0,") && s.contains("|Ln:2|"), "{s}");
    assert!(c.log.executed.iter().any(|p| p.line == 2), "chords of line 2 ran");
    let out = run(&mut c, 10.0);
    assert_eq!(out, "ok\r\n");
    let n = c.log.executed.iter().filter(|p| p.line == 2).count();
    assert_eq!(n, 157);
}

/// M2/M30 run after the block's motion and wait for it (GRBL: program flow last, after a buffer
/// synchronise): `[MSG:Pgm End]` and the `ok` come once the machine has stopped at the target.
#[test]
fn a_program_end_is_answered_after_its_motion() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X10F300M2\n"), "", "waits for the motion");
    let out = run(&mut c, 1.9);
    assert_eq!(out, "", "2 s of motion");
    let out = run(&mut c, 0.2);
    assert_eq!(out, "[MSG:Pgm End]\r\nok\r\n");
    assert!((c.position()[0] - 10.0).abs() < 1e-9);
}

/// M0 (GRBL's program pause, as at a tool change): after the block's motion a feed hold that only a cycle
/// start ends — `Hold:0`, nothing answered or parsed meanwhile — and the `ok` after `~`. M1 is ignored.
#[test]
fn a_program_pause_holds_until_a_cycle_start() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X10F300M0\n"), "");
    assert_eq!(send(&mut c, "G1X0\n"), "");
    assert_eq!(run(&mut c, 5.0), "", "held, the next line unparsed");
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Hold:0|MPos:10.000"), "{s}");
    assert_eq!(
        send(&mut c, "~"),
        "ok\r\nok\r\n",
        "the pause's ok, then the next line's"
    );
    run(&mut c, 5.0);
    assert!(c.position()[0].abs() < 1e-9);
    assert_eq!(send(&mut c, "M1\n"), "ok\r\n", "M1 does not stop");
}

/// A G38.2 in a block with M3 and M8 probes: the spindle and coolant wait for the planner, then the probe
/// runs alone and stops at the plate (it used to run as plain motion, through the plate).
#[test]
fn a_probe_with_spindle_and_coolant_words_still_probes() {
    let mut c = with_plate(Some(-5.0));
    assert_eq!(send(&mut c, "G0X5\n"), "ok\r\n");
    assert_eq!(send(&mut c, "M3S1000M8G38.2Z-10F120\n"), "");
    let out = run(&mut c, 10.0);
    assert_eq!(out, "[PRB:5.000,0.000,-5.000:1]\r\nok\r\n");
    assert!(c.position()[2] > -5.3, "stopped at the plate: {:?}", c.position());
}
