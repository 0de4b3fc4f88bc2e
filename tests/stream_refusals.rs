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

/// `--check` off a terminal (stdout a pipe) says how the `$C` check run went in one line on stdout: a program
/// with errors ends the run with the first line GRBL rejected, how many more, and that nothing was run (and the
/// controller's record shows no motion); a clean one says how many lines passed before the job streams.
#[test]
fn a_check_run_ends_with_its_result_line() {
    use brdfmill::apps::stream::emulator::{Emulator, EmulatorConfig};
    let emu = Emulator::start(EmulatorConfig {
        time_scale: 50.0,
        ..EmulatorConfig::default()
    })
    .expect("pseudo-terminal");
    let port = emu.port_path().expect("the emulator's port");
    let dir = tempfile::tempdir().unwrap();
    let stream = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        let o = brdfmill()
            .args([
                "stream",
                p.to_str().unwrap(),
                "--port",
                port.to_str().unwrap(),
                "--check",
            ])
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
        (o, stdout)
    };
    // G5 (cubic spline) and G7 (lathe diameter mode) are not GRBL's: error:20 on lines 3 and 4
    let (o, stdout) = stream("bad.nc", "G21 G90\nG1 X1 Y1 F500\nG5 X0 Y0\nG7 X0\nG1 X0 Y0\nM2\n");
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        stdout.lines().last(),
        Some("check failed at line 3: error:20 (unsupported or invalid G-code command), and 1 more line; nothing was run"),
        "{stdout}"
    );
    assert!(
        emu.log().executed.is_empty(),
        "a failed check moved: {:?}",
        emu.log().executed
    );

    let text = "G21 G90\nG1 X1 Y1 F500\nG1 X0 Y0\nM2\n";
    let (o, stdout) = stream("good.nc", text);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines.first().copied(),
        Some(format!("check passed: {} lines, no error", text.lines().count()).as_str()),
        "{stdout}"
    );
    assert!(
        lines[1].starts_with("done: 4 lines"),
        "the job streamed after the check: {stdout}"
    );
    drop(emu);
}
