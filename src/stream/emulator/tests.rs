//! The controller's behaviour, byte for byte as a host sees it: answers and error codes, status reports,
//! the planner, resets, overflow accounting, check mode, soft limits and injected faults.

use super::*;

fn ctl() -> Controller {
    let mut c = Controller::new(&EmulatorConfig {
        settings: vec![(10, 3.0)],
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
    assert_eq!(send(&mut c, "G0G1X1\n"), "error:21\r\n");
    assert_eq!(send(&mut c, "G0X1X2\n"), "error:25\r\n");
    assert_eq!(send(&mut c, "G1X1F100 (comment) ; tail\n"), "ok\r\n");
    assert_eq!(send(&mut c, "\n"), "ok\r\n");
    assert_eq!(send(&mut c, &format!("G1X{}\n", "1".repeat(90))), "error:11\r\n");
    assert_eq!(send(&mut c, "$99=1\n"), "error:3\r\n");
    assert!(send(&mut c, "$I\n").contains("[OPT:VNL,15,128]"));
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
    assert!(send(&mut c, "?").starts_with("<Hold:0|MPos:30.000"));
    send(&mut c, "~");
    c.advance(31.0);
    assert!(send(&mut c, "?").starts_with("<Idle|MPos:60.000,0.000,0.000|Bf:15,128|FS:0,0"));
    assert_eq!(c.log.executed.len(), 1);
}

#[test]
fn reset_while_holding_raises_alarm_3_and_logs_the_partial_block() {
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
