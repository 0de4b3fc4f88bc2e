//! The controller's behaviour, byte for byte as a host sees it: answers and error codes, status reports,
//! the planner, resets, overflow accounting, check mode, soft limits and injected faults.

use super::*;

/// A controller reporting `Bf` and `Ln`, its banner taken.
pub(super) fn ctl() -> Controller {
    let mut c = Controller::new(&EmulatorConfig {
        settings: vec![(10, 3.0)],
        line_numbers: true,
        ..EmulatorConfig::default()
    });
    c.take_output();
    c
}

/// Send `s`, run the main loop, and return what the controller answered.
pub(super) fn send(c: &mut Controller, s: &str) -> String {
    for b in s.bytes() {
        c.receive(b);
    }
    c.advance(0.0);
    String::from_utf8(c.take_output()).unwrap()
}

#[test]
fn answers_like_grbl() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X10\n"), "error:22\r\n");
    assert_eq!(send(&mut c, "X\n"), "error:2\r\n");
    assert_eq!(send(&mut c, "1X\n"), "error:1\r\n");
    assert_eq!(send(&mut c, "G5X1\n"), "error:20\r\n");
    assert_eq!(send(&mut c, "G1G0X1\n"), "error:24\r\n", "two axis commands");
    assert_eq!(send(&mut c, "G0G80X1\n"), "error:21\r\n");
    assert_eq!(
        send(&mut c, "G91.1G1X1\n"),
        "error:22\r\n",
        "G91.1 accepted, then no feed"
    );
    assert_eq!(send(&mut c, "G90.1\n"), "error:20\r\n");
    // G61 is 1.1h's only path control mode: accepted (group 13); G61.1 and G64 are not
    assert_eq!(send(&mut c, "G61\n"), "ok\r\n");
    assert_eq!(send(&mut c, "G61G90G21\n"), "ok\r\n");
    assert_eq!(
        send(&mut c, "G61G61\n"),
        "error:21\r\n",
        "one path control word per block"
    );
    assert_eq!(send(&mut c, "G61.1\n"), "error:20\r\n");
    assert_eq!(send(&mut c, "G64\n"), "error:20\r\n");
    assert_eq!(send(&mut c, "M7\n"), "error:20\r\n", "no ENABLE_M7 on a default build");
    // the machinist's safety line, and its cutter-compensation word beside a spindle word (G and M groups
    // are numbered apart)
    assert_eq!(send(&mut c, "G17G21G40G49G54G80G90G94\n"), "ok\r\n");
    assert_eq!(send(&mut c, "G40M5\n"), "ok\r\n");
    assert_eq!(send(&mut c, "$Z\n"), "error:2\r\n");
    assert_eq!(send(&mut c, "G0X1X2\n"), "error:25\r\n");
    assert_eq!(send(&mut c, "G1X1F100 (comment) ; tail\n"), "ok\r\n");
    assert_eq!(send(&mut c, "\n"), "ok\r\n");
    assert_eq!(send(&mut c, &format!("G1X{}\n", "1".repeat(90))), "error:11\r\n");
    assert_eq!(send(&mut c, "$99=1\n"), "error:3\r\n");
    assert!(send(&mut c, "$I\n").contains("[OPT:VN,15,128]"));
}

#[test]
fn a_default_controller_is_a_stock_build() {
    let mut c = Controller::new(&EmulatorConfig::default());
    c.take_output();
    let i = send(&mut c, "$I\n");
    assert!(
        i.contains("[VER:1.1h.20190830:]") && i.contains("[OPT:V,15,128]"),
        "{i}"
    );
    assert!(send(&mut c, "$$\n").contains("$10=1\r\n"));
    assert_eq!(send(&mut c, "N5G1X10F300\n"), "ok\r\n");
    c.advance(0.5);
    let s = send(&mut c, "?");
    assert!(
        s.starts_with("<Run|MPos:2.500,0.000,0.000|FS:300,0"),
        "no Bf, no Ln: {s}"
    );
}

#[test]
fn a_feed_hold_decelerates_and_a_completed_hold_resets_without_alarm() {
    let mut c = ctl();
    // 300 mm/min = 5 mm/s, $120 = 10 mm/s²: 0.5 s and 1.25 mm to stop.
    send(&mut c, "N1G1X100F300\n");
    c.advance(1.0);
    send(&mut c, "!");
    c.advance(0.2);
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Hold:1|MPos:5.800"), "still decelerating: {s}");
    c.advance(1.0);
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Hold:0|MPos:6.250"), "stopped after v²/2a: {s}");
    let out = send(&mut c, "\x18");
    assert!(out.starts_with("\r\nGrbl 1.1h"), "no ALARM:3 after Hold:0: {out}");
    assert!(send(&mut c, "?").starts_with("<Idle|MPos:6.250,0.000,0.000|Bf:15,128"));
    assert_eq!(send(&mut c, "G0X1\n"), "ok\r\n", "not locked");
}

/// GRBL 1.1h after a critical alarm: `ALARM:2`, then half a second in `report_alarm_message`'s
/// `delay_ms(500)` during which a reset is cleared unheard (seen on the real firmware: a reset 0.2 ms after
/// the alarm is lost), then `[MSG:Reset to continue]`, then nothing answered until a reset.
#[test]
fn a_critical_alarm_answers_nothing_until_reset_then_a_stray_ok() {
    let mut c = ctl();
    send(&mut c, "$22=1\n");
    send(&mut c, "$X\n");
    send(&mut c, "$20=1\n");
    assert_eq!(send(&mut c, "G0X5\n"), "ALARM:2\r\n");
    assert_eq!(send(&mut c, "\x18"), "", "a reset inside the half second is lost");
    c.advance(0.49);
    assert_eq!(String::from_utf8(c.take_output()).unwrap(), "");
    c.advance(0.02);
    assert_eq!(
        String::from_utf8(c.take_output()).unwrap(),
        "[MSG:Reset to continue]\r\n"
    );
    assert_eq!(send(&mut c, "?"), "", "no status report while locked");
    let out = send(&mut c, "\x18");
    assert!(out.starts_with("ok\r\n\r\nGrbl 1.1h"), "{out}");
    assert!(send(&mut c, "?").starts_with("<Alarm|"));
}

#[test]
fn status_reports_planner_and_line() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "N7G1X60F60\n"), "ok\r\n"); // 60 mm at 60 mm/min: 60 s
    c.advance(30.0);
    let s = send(&mut c, "?");
    assert!(
        s.starts_with("<Run|MPos:30.000,0.000,0.000|Bf:14,128|Ln:7|FS:60,0"),
        "{s}"
    );
    send(&mut c, "!");
    c.advance(10.0);
    assert!(
        send(&mut c, "?").starts_with("<Hold:0|MPos:30.050"),
        "0.05 mm to stop from 1 mm/s"
    );
    send(&mut c, "~");
    c.advance(31.0);
    assert!(send(&mut c, "?").starts_with("<Idle|MPos:60.000,0.000,0.000|Bf:15,128|FS:0,0"));
    assert_eq!(c.log.executed.len(), 1);
}

#[test]
fn reset_while_a_hold_decelerates_raises_alarm_3_and_logs_the_partial_block() {
    let mut c = ctl();
    send(&mut c, "N1G1X10F60\n");
    c.advance(5.0);
    send(&mut c, "!");
    let out = send(&mut c, "\x18");
    assert!(out.starts_with("ALARM:3\r\n\r\nGrbl 1.1h"), "{out}");
    assert!(out.contains("'$X' to unlock"));
    let p = c.log.executed[0];
    assert!(!p.complete && (p.to_mm[0] - 5.0).abs() < 1e-9);
    assert_eq!(send(&mut c, "G0X1\n"), "error:9\r\n");
    assert_eq!(send(&mut c, "$X\n"), "[MSG:Caution: Unlocked]\r\nok\r\n");
}

#[test]
fn planner_holds_fifteen_blocks() {
    let mut c = ctl();
    let mut oks = 0;
    for i in 1..=17 {
        oks += send(&mut c, &format!("G1X{i}F60\n")).matches("ok").count();
    }
    assert_eq!(oks, 15, "the 16th waits for a free block");
    c.advance(1.0);
    assert_eq!(String::from_utf8(c.take_output()).unwrap(), "ok\r\n");
}

#[test]
fn overflow_is_counted_not_hidden() {
    let mut c = ctl();
    send(&mut c, "N1G1X100F1\n"); // a long block keeps the planner busy
    for _ in 0..15 {
        send(&mut c, "G1X1F1\n");
    }
    // The parser now waits for a free planner block; the receive buffer fills up.
    for b in std::iter::repeat_n(b'G', 130) {
        c.receive(b);
    }
    assert_eq!(c.log.rx_overflows, 3);
    assert!(c.log.events.iter().any(|e| e.contains("overflow")));
}

#[test]
fn check_mode_and_soft_limits() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "$C\n"), "[MSG:Enabled]\r\nok\r\n");
    assert_eq!(send(&mut c, "G1X10F100\n"), "ok\r\n");
    assert!(send(&mut c, "?").starts_with("<Check|MPos:0.000"));
    let off = send(&mut c, "$C\n");
    assert!(off.starts_with("[MSG:Disabled]\r\nok\r\n\r\nGrbl"), "{off}");
    assert_eq!(send(&mut c, "$20=1\n"), "error:10\r\n");
    assert_eq!(send(&mut c, "$22=1\n"), "ok\r\n");
    assert_eq!(send(&mut c, "$20=1\n"), "ok\r\n");
    assert_eq!(send(&mut c, "G0X-10\n"), "ok\r\n");
    c.advance(10.0);
    let a = send(&mut c, "G0X5\n");
    assert_eq!(a, "ALARM:2\r\n", "at rest: at once");
    c.advance(0.5);
    assert_eq!(
        String::from_utf8(c.take_output()).unwrap(),
        "[MSG:Reset to continue]\r\n"
    );
    assert_eq!(send(&mut c, "G0X-1\n"), "", "locked until reset");
    assert!(send(&mut c, "\x18").contains("'$X' to unlock"));
}

#[test]
fn faults_fire_once() {
    let mut c = Controller::new(&EmulatorConfig {
        faults: vec!["3:error:20".parse().unwrap(), "4:alarm".parse().unwrap()],
        ..EmulatorConfig::default()
    });
    c.take_output();
    assert_eq!(send(&mut c, "N3G0X1\n"), "error:20\r\n");
    assert_eq!(send(&mut c, "N3G0X1\n"), "ok\r\n");
    c.advance(1.0);
    assert!(send(&mut c, "N4G0X2\n").starts_with("ALARM:2"));
    assert!("x:error".parse::<Fault>().is_err());
}

/// A stall holds motion (the planner full, lines backing up) until the receive buffer holds its bytes, or
/// for at most its time limit; a reset ends it.
#[test]
fn a_stall_holds_motion_until_the_receive_buffer_fills() {
    let stalled = || {
        let mut c = Controller::new(&EmulatorConfig {
            faults: vec!["1:stall:40".parse().unwrap()],
            ..EmulatorConfig::default()
        });
        c.take_output();
        assert_eq!(
            send(
                &mut c,
                "N1G1X1F600
"
            ),
            "ok\r\n"
        );
        c
    };
    let mut c = stalled();
    c.advance(5.0);
    assert!(send(&mut c, "?").contains("MPos:0.000,0.000,0.000"), "nothing moved");
    for i in 2..16 {
        send(&mut c, &format!("G1X{i}F600\n"));
    }
    assert_eq!(send(&mut c, "G1X16F600\n"), "", "the planner is full");
    send(&mut c, "G1X17F600\nG1X18F600\nG1X19F600\n");
    assert!(c.rx.len() < 40);
    c.advance(1.0);
    assert!(
        send(&mut c, "?").contains("MPos:0.000,0.000,0.000"),
        "still stalled below 40 bytes"
    );
    send(&mut c, "G1X20F600\nG1X21F600\nG1X22F600\n");
    assert!(c.rx.len() >= 40);
    c.advance(0.05);
    assert!(!send(&mut c, "?").contains("MPos:0.000,0.000,0.000"), "released");
    assert!(c.log.events.iter().any(|e| e.starts_with("stall released")));
    // without the bytes, time alone does not end it; the host's status polls do, after the limit
    let mut c = stalled();
    c.advance(600.0);
    assert!(
        !c.log.events.iter().any(|e| e.starts_with("stall")),
        "{:?}",
        c.log.events
    );
    for _ in 0..fault::STALL_LIMIT_REPORTS {
        send(&mut c, "?");
    }
    c.advance(0.05);
    assert!(c.log.events.iter().any(|e| e.starts_with("stall gave up")));
    // a reset ends it too
    let mut c = stalled();
    send(&mut c, "\x18");
    assert!(c.stall.is_none());
    assert!("2:stall:x".parse::<Fault>().is_err());
}

#[test]
fn arcs_in_every_plane_follow_grbl() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X0Y0Z0F600\n"), "ok\r\n");
    // G18: Z→X plane, offsets K I; clockwise seen from +Y, so from (0,0,0) to (2,0,0) about (1,0,0) the
    // tool dips to z = -1 (counter-clockwise with X drawn right, Z up)
    // π·1 mm in GRBL's chords for $12 = 0.002 mm: ⌊(π/2) / √(0.002·1.998)⌋ = 24 of them (each passing a little
    // more than $12 inside the arc),
    // more than the planner holds, so the `ok` waits until the last is planned
    assert_eq!(send(&mut c, "G18G2X2Z0I1K0\n"), "");
    let mut lowest = f64::INFINITY;
    let mut out = String::new();
    for _ in 0..400 {
        c.advance(0.005);
        lowest = lowest.min(c.position()[2]);
        out += &String::from_utf8(c.take_output()).unwrap();
    }
    assert_eq!(out, "ok\r\n");
    let end = c.position();
    assert!((end[0] - 2.0).abs() < 1e-9 && end[2].abs() < 1e-9, "{end:?}");
    assert!((lowest + 1.0).abs() < 0.002, "dips to z = -1: {lowest}");
    // in-plane words are required; a J in G18 is read and ignored as GRBL clears I, J and K together
    assert_eq!(send(&mut c, "G18G2Y1J1\n"), "error:32\r\n", "no in-plane axis word");
    assert_eq!(send(&mut c, "G18G2X4J1\n"), "error:35\r\n", "no in-plane offset");
    assert_eq!(send_and_run(&mut c, "G18G2X4I1J7\n"), "ok\r\n");
    // G19: Y→Z, offsets J K; radius mismatch beyond 0.005 mm and 0.1%: error:33
    assert_eq!(send(&mut c, "G19G3Y2.01Z0J1K0\n"), "error:33\r\n");
    assert_eq!(send_and_run(&mut c, "G19G3Y2.004Z0J1K0\n"), "ok\r\n", "within 0.005 mm");
}

/// The positions a controller passes through running `block` from rest at (0, 0, 0), sampled every 5 ms,
/// and its answers.
fn trace(block: &str) -> (Vec<[f64; 3]>, String) {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X0Y0Z0F600\n"), "ok\r\n");
    let mut out = send(&mut c, block);
    let mut path = vec![];
    for _ in 0..4000 {
        c.advance(0.005);
        path.push(c.position());
        out += &String::from_utf8(c.take_output()).unwrap();
    }
    (path, out)
}

/// The largest distance between two traces' positions at the same time, mm.
fn gap(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| crate::gcode::moves::dist(*p, *q))
        .fold(0.0, f64::max)
}

/// Arcs in radius form as GRBL 1.1h's `gc_execute_line` reads them: the same chords, at the same times, as
/// the offset form with the centre worked out by hand (which [`arcs_in_every_plane_follow_grbl`] checks), a
/// negative radius the long way round, inch radii converted, and the errors 33, 34, 36, 26 and 32 in
/// GRBL's order.
#[test]
fn arcs_in_radius_form_follow_grbl() {
    // a half turn clockwise from (0,0) to (2,0) over the top: the centre is (1,0) for either sign of R
    let (by_r, out) = trace("G2X2Y0R1\n");
    assert_eq!(out, "ok\r\n");
    let (by_ij, _) = trace("G2X2Y0I1J0\n");
    assert!(
        gap(&by_r, &by_ij) == 0.0,
        "the same chords at the same times: {}",
        gap(&by_r, &by_ij)
    );
    let top = by_r.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    assert!(
        (top - 1.0).abs() < 0.002 && by_r.last() == Some(&[2.0, 0.0, 0.0]),
        "{top}"
    );
    // G3 to (2,0) with: the centre below the chord at (1, −√1.25), 276° the long way round, down to
    // y = −√1.25 − 1.5; in G18 the same arc runs in Z and X (offsets K I)
    let below = -(1.25f64.sqrt());
    let (long, _) = trace("G3X2Y0R-1.5\n");
    let (long_ij, _) = trace(&format!("G3X2Y0I1J{below}\n"));
    assert!(gap(&long, &long_ij) < 1e-9, "{}", gap(&long, &long_ij));
    let low = long.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    assert!((low - (below - 1.5)).abs() < 0.002, "{low}");
    // G18 turns in (Z, X): the chord runs along its second axis, so the long way's centre is at z = +√1.25
    let (zx, _) = trace("G18G3X2Z0R-1.5\n");
    let (zx_ik, _) = trace(&format!("G18G3X2Z0I1K{}\n", -below));
    assert!(gap(&zx, &zx_ik) < 1e-9, "{}", gap(&zx, &zx_ik));
    // inches: 2 mm is 0.0787402 in, the radius of 1 mm 0.0393701 in
    let (inch, out) = trace("G20G2X0.0787402Y0R0.0393701\n");
    assert_eq!(out, "ok\r\n");
    let top = inch.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    assert!((top - 1.0).abs() < 0.002, "{top}");

    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X0Y0Z0F600\n"), "ok\r\n");
    assert_eq!(
        send(&mut c, "G2X2Y0R0.9\n"),
        "error:34\r\n",
        "the chord is longer than the diameter"
    );
    assert_eq!(send(&mut c, "G2X0Y0R1\n"), "error:33\r\n", "the end is the start");
    assert_eq!(
        send(&mut c, "G2X2Y0R1I1\n"),
        "error:36\r\n",
        "R and an offset: the offset is unused"
    );
    assert_eq!(
        send(&mut c, "G2X2Y0R0.9I1\n"),
        "error:34\r\n",
        "the arc's own error comes first"
    );
    assert_eq!(send(&mut c, "G1X1R1\n"), "error:36\r\n", "R without an arc");
    assert_eq!(
        send(&mut c, "G2R1\n"),
        "error:26\r\n",
        "an explicit G2 needs axis words"
    );
    assert_eq!(send(&mut c, "G2Z1R1\n"), "error:32\r\n", "no in-plane axis word");
    // only Z moves: GRBL would divide by the zero chord; the emulator refuses and logs it
    assert_eq!(send(&mut c, "G2X0Z1R1\n"), "error:33\r\n");
    assert!(
        c.log.events.iter().any(|e| e.contains("not modelled")),
        "{:?}",
        c.log.events
    );
    assert_eq!(send_and_run(&mut c, "G2X2R1\n"), "ok\r\n");
    let mut fresh = ctl();
    assert_eq!(send(&mut fresh, "G2X2Y0R1\n"), "error:22\r\n", "no feed yet");
    assert_eq!(
        send(&mut fresh, "G2R1\n"),
        "error:22\r\n",
        "the feed is checked before the axis words"
    );
}

/// [`send`], then run the motion for up to 100 simulated seconds: all the answers.
fn send_and_run(c: &mut Controller, s: &str) -> String {
    let mut out = send(c, s);
    for _ in 0..1000 {
        c.advance(0.1);
        out += &String::from_utf8(c.take_output()).unwrap();
    }
    out
}

/// Run whatever was planned to its end, then the machine position from a status report.
fn settle_mpos(c: &mut Controller) -> [f64; 3] {
    c.advance(1000.0);
    let s = send(c, "?");
    let m = s.split("MPos:").nth(1).expect("MPos").split('|').next().unwrap();
    let v: Vec<f64> = m.split(',').map(|t| t.parse().unwrap()).collect();
    [v[0], v[1], v[2]]
}

fn table(c: &mut Controller, name: &str) -> String {
    let s = send(c, "$#\n");
    let row = s
        .lines()
        .find(|l| l.starts_with(&format!("[{name}:")))
        .unwrap_or_else(|| panic!("{s}"));
    row.trim_start_matches(&format!("[{name}:"))
        .trim_end_matches(']')
        .to_string()
}

/// Work coordinates as GRBL 1.1h keeps them, against its relation `WPos = MPos − WCS − G92 − TLO` worked by
/// hand: G10 L2/L20, G54–G59, G92/G92.1, G43.1/G49, G53, G28/G28.1 (all axes, and only the named ones), the
/// error codes of each, and what a reset keeps (G54–G59, G28) and clears (selection, G92, TLO).
#[test]
fn work_coordinates_follow_grbl() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G10L2P2X10Y20Z-5\n"), "ok\r\n");
    assert_eq!(table(&mut c, "G55"), "10.000,20.000,-5.000");
    assert_eq!(send(&mut c, "G55G0X1Y2Z3\n"), "ok\r\n");
    assert_eq!(settle_mpos(&mut c), [11.0, 22.0, -2.0]);
    // G92 so that here reads X0 Y0: G92 = MPos − WCS − value
    assert_eq!(send(&mut c, "G92X0Y0\n"), "ok\r\n");
    assert_eq!(table(&mut c, "G92"), "1.000,2.000,0.000");
    // L20 on P1 (G54) so that here reads X5 in it: WCS = MPos − G92 − TLO − value = 11 − 1 − 5
    assert_eq!(send(&mut c, "G10L20P1X5\n"), "ok\r\n");
    assert_eq!(table(&mut c, "G54"), "5.000,0.000,0.000");
    assert_eq!(send(&mut c, "G43.1Z2\n"), "ok\r\n");
    assert_eq!(table(&mut c, "TLO"), "2.000");
    // in G55 with G92 (1, 2, 0) and TLO 2: X0 Y0 Z0 is machine (11, 22, −3)
    assert_eq!(send(&mut c, "G1X0Y0Z0F600\n"), "ok\r\n");
    assert_eq!(settle_mpos(&mut c), [11.0, 22.0, -3.0]);
    // G53 moves in machine coordinates whatever the offsets; G91 does not apply to it
    assert_eq!(send(&mut c, "G91G53G0X3Y4Z0\n"), "ok\r\n");
    assert_eq!(settle_mpos(&mut c), [3.0, 4.0, 0.0]);
    assert_eq!(send(&mut c, "G90G28.1\n"), "ok\r\n");
    assert_eq!(table(&mut c, "G28"), "3.000,4.000,0.000");
    assert_eq!(send(&mut c, "G53G0X0Y0Z-1\n"), "ok\r\n");
    assert_eq!(send(&mut c, "G28\n"), "ok\r\n");
    assert_eq!(settle_mpos(&mut c), [3.0, 4.0, 0.0], "G28 alone: every axis home");
    assert_eq!(send(&mut c, "G53G0X0Y0Z-1\n"), "ok\r\n");
    // through work X = 1 (machine 1 + 10 + 1 = 12), then home on X only
    assert_eq!(send(&mut c, "G28X1\n"), "ok\r\n");
    assert_eq!(settle_mpos(&mut c), [3.0, 0.0, -1.0], "G28 X: only X goes home");
    assert_eq!(send(&mut c, "G92.1\n"), "ok\r\n");
    assert_eq!(table(&mut c, "G92"), "0.000,0.000,0.000");
    assert_eq!(send(&mut c, "G49X1\n"), "ok\r\n", "G49 uses up its axis words");
    assert_eq!(table(&mut c, "TLO"), "0.000");
    // GRBL's error codes
    for (line, code) in [
        ("G10L2P1\n", 26),     // no axis words
        ("G10L2X1\n", 28),     // P missing
        ("G10P1X1\n", 28),     // L missing
        ("G10L2P7X1\n", 29),   // beyond G59
        ("G10L3P1X1\n", 20),   // L neither 2 nor 20
        ("G92\n", 26),         // no axis words
        ("G92G1X1F100\n", 24), // two commands want the axis words
        ("G1G92X1F100\n", 24),
        ("G53G2X1I1F100\n", 30), // G53 needs G0 or G1
        ("G43.1X1\n", 37),       // G43.1 takes exactly Z
        ("G43.1\n", 37),
        ("G43Z1\n", 20),
        ("G1X1L2F100\n", 36), // L without G10
        ("G92.2X1\n", 20),
        ("G4G10L2P1X1\n", 21), // two group-0 commands
    ] {
        assert_eq!(send(&mut c, line), format!("error:{code}\r\n"), "{}", line.trim());
    }
    // a reset keeps G54–G59 and G28, selects G54 and clears G92 and TLO
    assert_eq!(
        send(&mut c, "G55G92X0G43.1Z1\n"),
        "error:24\r\n",
        "G92 and G43.1 both want the axis words"
    );
    assert_eq!(send(&mut c, "G55\n"), "ok\r\n");
    assert_eq!(send(&mut c, "G92X0\n"), "ok\r\n");
    send(&mut c, "\x18");
    assert_eq!(table(&mut c, "G55"), "10.000,20.000,-5.000");
    assert_eq!(table(&mut c, "G28"), "3.000,4.000,0.000");
    assert_eq!(table(&mut c, "G92"), "0.000,0.000,0.000");
    assert!(send(&mut c, "$G\n").contains(" G54 "), "a reset selects G54");
}

/// G93 inverse time as GRBL 1.1h runs it: F on every motion block (G0 included, GRBL's condition being always
/// true), a block taking 1/F minutes, and no feed carried over into the next block or back into G94.
#[test]
fn inverse_time_follows_grbl() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G93\n"), "ok\r\n");
    assert!(send(&mut c, "$G\n").contains(" G93 "));
    assert_eq!(send(&mut c, "G1X10\n"), "error:22\r\n", "F on every block");
    assert_eq!(send(&mut c, "G0X1\n"), "error:22\r\n", "even G0");
    // 10 mm in 1/2 minute: at 15 s it is halfway, whatever the distance
    assert_eq!(send(&mut c, "G1X10F2\n"), "ok\r\n");
    c.advance(15.0);
    assert!(send(&mut c, "?").contains("MPos:5.000,0.000,0.000"));
    c.advance(20.0);
    assert_eq!(send(&mut c, "G1X20\n"), "error:22\r\n", "the F was this block's only");
    assert_eq!(send(&mut c, "G94\n"), "ok\r\n");
    assert_eq!(send(&mut c, "G1X20\n"), "error:22\r\n", "nor carried back into G94");
    assert_eq!(send(&mut c, "G1X20F300\n"), "ok\r\n");
    // 10 mm at 300 mm/min (under the default $110): 2 s
    c.advance(0.5);
    let s = send(&mut c, "?");
    assert!(s.contains("MPos:12.500,0.000,0.000"), "{s}");
}

/// `$J=` jogging as GRBL 1.1h runs it: state `Jog`, the jog's G91 for itself only, F required, other words
/// refused with `error:16`, G-code locked while jogging (`error:9`), a jog cancel (0x85, or `!`) decelerating
/// to a stop and leaving the machine Idle where it stopped, and a soft limit refusing the jog (`error:15`).
#[test]
fn jogging_follows_grbl() {
    let mut c = ctl();
    // 10 mm at 300 mm/min (5 mm/s, under the default $110)
    assert_eq!(send(&mut c, "$J=G91X10F300\n"), "ok\r\n");
    c.advance(0.5);
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Jog|MPos:2.500,0.000,0.000"), "{s}");
    assert_eq!(
        send(&mut c, "G1X1F100\n"),
        "error:9\r\n",
        "G-code is locked while jogging"
    );
    assert_eq!(send(&mut c, "$J=X1\n"), "error:22\r\n", "F required");
    assert_eq!(send(&mut c, "$J=G1X1F100\n"), "error:16\r\n");
    assert_eq!(send(&mut c, "$J=X1F100M3\n"), "error:16\r\n");
    // cancel: decelerates (0.5 s at $120 = 10 mm/s² from 5 mm/s covers 1.25 mm), then Idle where it stopped
    c.receive(0x85);
    c.advance(1.0);
    let s = send(&mut c, "?");
    assert!(s.starts_with("<Idle|MPos:3.750,0.000,0.000"), "{s}");
    assert!(send(&mut c, "$G\n").contains(" G90 "), "the jog's G91 was its own");
    // absolute jog back, then G-code is accepted again once the jog is done
    assert_eq!(send(&mut c, "$J=X0F300\n"), "ok\r\n");
    c.advance(2.0);
    assert!(send(&mut c, "?").starts_with("<Idle|MPos:0.000,0.000,0.000"));
    assert_eq!(send(&mut c, "G1X1F100\n"), "ok\r\n");
    c.advance(2.0);
    // with soft limits the jog is refused, not alarmed
    assert_eq!(send(&mut c, "$22=1\n"), "ok\r\n");
    assert_eq!(send(&mut c, "$20=1\n"), "ok\r\n");
    assert_eq!(send(&mut c, "$J=G53X5F100\n"), "error:15\r\n");
    assert!(send(&mut c, "?").starts_with("<Idle"));
}

/// A stock controller with a touch plate at machine Z `plate`.
pub(super) fn with_plate(plate: Option<f64>) -> Controller {
    let mut c = Controller::new(&EmulatorConfig {
        probe_plate_z_mm: plate,
        ..EmulatorConfig::default()
    });
    c.take_output();
    c
}

/// Send a line and run simulated time until its answer arrives; everything the controller said.
fn probe(c: &mut Controller, line: &str) -> String {
    let mut out = send(c, line);
    out.push_str(&run_until_ok(c, out.ends_with("ok\r\n")));
    out
}

/// Run simulated time until the answer to the last line arrives (`done`: it already has).
fn run_until_ok(c: &mut Controller, done: bool) -> String {
    let mut out = String::new();
    if done {
        return out;
    }
    for _ in 0..10_000 {
        c.advance(0.01);
        out.push_str(&String::from_utf8(c.take_output()).unwrap());
        if out.ends_with("ok\r\n") {
            break;
        }
    }
    out
}

/// G38.2 as GRBL 1.1h's `mc_probe_cycle`: the move stops where the probe touches, plus the motion
/// cancel's deceleration `v²/2a`; `[PRB:]` gives the touch point in machine coordinates, then `ok`; the
/// parser continues from where the machine stopped.
#[test]
fn a_probe_stops_at_the_plate_and_reports_where() {
    let mut c = with_plate(Some(-5.0));
    assert_eq!(send(&mut c, "G38.2Z-10F120\n"), "", "the answer waits for the cycle");
    let out = run_until_ok(&mut c, false);
    assert_eq!(out, "[PRB:0.000,0.000,-5.000:1]\r\nok\r\n");
    // 120 mm/min = 2 mm/s against $122 = 10 mm/s² (the least of $120–$122): 0.2 mm past the plate
    let a = (120..=122).map(|k| c.setting(k)).fold(f64::INFINITY, f64::min);
    let over = 2.0f64.powi(2) / (2.0 * a);
    assert!(
        (c.position()[2] - (-5.0 - over)).abs() < 1e-9,
        "stopped at {:?}",
        c.position()
    );
    assert!(send(&mut c, "$#\n").contains("[PRB:0.000,0.000,-5.000:1]"));
    assert!(send(&mut c, "$G\n").starts_with("[GC:G38.2 "), "G38.2 is modal");
    // relative to where the machine is, not to the programmed Z-10
    assert_eq!(send(&mut c, "G91G0Z1\n"), "ok\r\n");
    for _ in 0..100 {
        c.advance(0.05);
    }
    assert!((c.position()[2] - (-4.0 - over)).abs() < 1e-9, "{:?}", c.position());
    // a reset clears the probe's record
    send(&mut c, "\x18");
    assert!(send(&mut c, "$#\n").contains("[PRB:0.000,0.000,0.000:0]"));
}

#[test]
fn a_probe_that_never_touches_alarms_unless_told_not_to() {
    // G38.2 through the whole move without contact: ALARM:5, the record unchanged and failed, then ok;
    // the alarm answers `?` and `$X`, and locks G-code until then
    let mut c = with_plate(Some(-5.0));
    assert_eq!(
        probe(&mut c, "G38.2Z-3F300\n"),
        "ALARM:5\r\n[PRB:0.000,0.000,0.000:0]\r\nok\r\n"
    );
    assert!((c.position()[2] + 3.0).abs() < 1e-9);
    assert!(send(&mut c, "?").starts_with("<Alarm|"));
    assert_eq!(send(&mut c, "G0Z0\n"), "error:9\r\n");
    assert!(send(&mut c, "$X\n").ends_with("ok\r\n"));
    // G38.3: no alarm, the record is where the move ended
    assert_eq!(probe(&mut c, "G38.3Z-4F300\n"), "[PRB:0.000,0.000,-4.000:0]\r\nok\r\n");
    // no probe connected: a G38.2 never touches either
    let mut c = with_plate(None);
    assert!(probe(&mut c, "G38.2Z-1F300\n").starts_with("ALARM:5\r\n"));
}

#[test]
fn a_probe_already_in_the_state_it_seeks_is_refused_and_away_probes_lose_contact() {
    // the tip starts on the plate (contact at z ≤ 0): G38.2 raises ALARM:4 before moving, no [PRB:]
    let mut c = with_plate(Some(0.0));
    assert_eq!(probe(&mut c, "G38.2Z-1F100\n"), "ALARM:4\r\nok\r\n");
    assert_eq!(c.position(), [0.0; 3]);
    send(&mut c, "$X\n");
    // G38.4 from contact: the contact is lost as soon as the tip rises above the plate
    assert_eq!(probe(&mut c, "G38.4Z2F100\n"), "[PRB:0.000,0.000,0.000:1]\r\nok\r\n");
    assert!(c.position()[2] > 0.0 && c.position()[2] < 2.0);
    // G38.5 from out of contact: ALARM:4 too (the away probes seek the loss of contact)
    assert_eq!(probe(&mut c, "G38.5Z3F100\n"), "ALARM:4\r\nok\r\n");
}

#[test]
fn probe_blocks_are_checked_as_grbl_checks_them() {
    let mut c = with_plate(Some(-5.0));
    assert_eq!(send(&mut c, "G38.2F100\n"), "error:26\r\n", "no axis words");
    assert_eq!(send(&mut c, "G38.2Z-1\n"), "error:22\r\n", "no feed yet");
    assert_eq!(send(&mut c, "G38.2Z0F100\n"), "error:33\r\n", "target is the position");
    assert_eq!(send(&mut c, "G38.1Z-1F100\n"), "error:20\r\n");
    assert_eq!(send(&mut c, "G38.6Z-1F100\n"), "error:20\r\n");
    assert_eq!(send(&mut c, "G0G38.2Z-1F100\n"), "error:24\r\n", "two axis commands");
    // check mode: the block is answered, nothing moves, nothing is probed
    assert!(send(&mut c, "$C\n").contains("ok"));
    assert_eq!(send(&mut c, "G38.2Z-10F100\n"), "ok\r\n");
    for _ in 0..10 {
        c.advance(0.1);
    }
    assert_eq!(c.position(), [0.0; 3]);
}
