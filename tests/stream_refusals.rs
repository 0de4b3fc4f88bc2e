//! Bad ports and bad programs are refused with a clear message before anything moves.

use std::process::Command;
use std::time::Duration;

use brdfmill::apps::stream::session::Config;

fn brdfmill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
}

#[test]
fn missing_port_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("p.nc");
    std::fs::write(&p, "G0X1\n").unwrap();
    let out = brdfmill()
        .args(["stream", p.to_str().unwrap(), "--port", "/dev/does-not-exist"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("cannot open serial port /dev/does-not-exist"), "{err}");
    assert!(
        !dir.path().join("p.nc.journal.jsonl").exists(),
        "no journal for a job that never started"
    );
}

#[test]
fn overlong_line_is_refused_before_the_port_is_opened() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("p.nc");
    std::fs::write(&p, format!("G21\nG1 X1 F100 (fine)\nG1 X{}\n", "1".repeat(80))).unwrap();
    // The port does not exist: the program error must come first.
    let out = brdfmill()
        .args(["stream", p.to_str().unwrap(), "--port", "/dev/does-not-exist"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("p.nc:3") && err.contains("at most 79"), "{err}");
}

#[test]
fn a_port_that_is_not_grbl_is_refused() {
    use nix::sys::termios;
    use std::os::fd::AsFd;
    let pty = nix::pty::openpty(None, None).unwrap();
    let mut t = termios::tcgetattr(pty.slave.as_fd()).unwrap();
    termios::cfmakeraw(&mut t);
    termios::tcsetattr(pty.slave.as_fd(), termios::SetArg::TCSANOW, &t).unwrap();
    let path = nix::unistd::ttyname(pty.slave.as_fd()).unwrap();
    drop(pty.slave);
    // Something that chatters but is not GRBL: a modem-like echo of "OK".
    let master = pty.master;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let st = std::sync::Arc::clone(&stop);
    let chatter = std::thread::spawn(move || {
        while !st.load(std::sync::atomic::Ordering::SeqCst) {
            let _ = nix::unistd::write(master.as_fd(), b"OK\r\nhello\r\n");
            std::thread::sleep(Duration::from_millis(100));
        }
    });
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("p.nc");
    std::fs::write(&p, "G0X1\n").unwrap();
    let out = brdfmill()
        .args(["stream", p.to_str().unwrap(), "--port", path.to_str().unwrap()])
        .output()
        .unwrap();
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    chatter.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("does not answer like a GRBL 1.1 controller") && err.contains("hello"),
        "{err}"
    );
    // It gave up when its handshake bound ran out (a GRBL answers `$I` at once), and says so; the chatter
    // goes on until the process has exited, so nothing else could have ended the wait.
    let bound = format!("within {:?}", Config::default().handshake_timeout);
    assert!(
        err.contains(&bound),
        "the refusal should name the handshake bound ({bound}): {err}"
    );
    assert!(!dir.path().join("p.nc.journal.jsonl").exists());
}
