//! The controller's behaviour, byte for byte as a host sees it: answers and error codes, status reports,
//! the planner, resets, overflow accounting, check mode, soft limits and injected faults.

use super::*;

fn ctl() -> Controller {
    let mut c = Controller::new(&EmulatorConfig {
        settings: vec![(10, 3.0)],
        line_numbers: true,
        ..EmulatorConfig::default()
    });
    c.take_output();
    c
}

fn send(c: &mut Controller, s: &str) -> String {
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

#[test]
fn a_critical_alarm_answers_nothing_until_reset_then_a_stray_ok() {
    let mut c = ctl();
    send(&mut c, "$22=1\n");
    send(&mut c, "$X\n");
    send(&mut c, "$20=1\n");
    assert!(send(&mut c, "G0X5\n").starts_with("ALARM:2\r\n[MSG:Reset to continue]"));
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
    let a = send(&mut c, "G0X5\n");
    assert_eq!(a, "ALARM:2\r\n[MSG:Reset to continue]\r\n");
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
    assert!(send(&mut c, "N4G0X2\n").starts_with("ALARM:2"));
    assert!("x:error".parse::<Fault>().is_err());
}

#[test]
fn arcs_in_every_plane_follow_grbl() {
    let mut c = ctl();
    assert_eq!(send(&mut c, "G1X0Y0Z0F600\n"), "ok\r\n");
    // G18: Z→X plane, offsets K I; clockwise seen from +Y, so from (0,0,0) to (2,0,0) about (1,0,0) the
    // tool dips to z = -1 (counter-clockwise with X drawn right, Z up)
    assert_eq!(send(&mut c, "G18G2X2Z0I1K0\n"), "ok\r\n");
    let mut lowest = f64::INFINITY;
    for _ in 0..400 {
        c.advance(0.005);
        lowest = lowest.min(c.position()[2]);
    }
    let end = c.position();
    assert!((end[0] - 2.0).abs() < 1e-9 && end[2].abs() < 1e-9, "{end:?}");
    assert!((lowest + 1.0).abs() < 0.01, "dips to z = -1: {lowest}");
    // in-plane words are required; a J in G18 is read and ignored as GRBL clears I, J and K together
    assert_eq!(send(&mut c, "G18G2Y1J1\n"), "error:32\r\n", "no in-plane axis word");
    assert_eq!(send(&mut c, "G18G2X4J1\n"), "error:35\r\n", "no in-plane offset");
    assert_eq!(send(&mut c, "G18G2X4I1J7\n"), "ok\r\n");
    // G19: Y→Z, offsets J K; radius mismatch beyond 0.005 mm and 0.1%: error:33
    assert_eq!(send(&mut c, "G19G3Y2.01Z0J1K0\n"), "error:33\r\n");
    assert_eq!(send(&mut c, "G19G3Y2.004Z0J1K0\n"), "ok\r\n", "within 0.005 mm");
}
