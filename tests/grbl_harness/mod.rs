//! The harness for streaming against the **real GRBL 1.1h firmware**: the grbl-sim kit (`shared/grbl-sim`:
//! the firmware compiled for Linux, on a pseudo-terminal, with a step trace and fault injection). Every
//! verdict on which program lines ran comes from the firmware's own step trace (`trace.py --json`), not
//! from the streamer, its journal or the virtual controller. Shared by `tests/grbl_firmware.rs` and the
//! benchmark `examples/bench_grbl_faults.rs`.
//!
//! The kit is found at `$BRDFMILL_GRBL_SIM`, else at `../shared/grbl-sim` beside the repository. It is
//! built once per process into `<target>/grbl-sim` (`build.sh` does nothing when it is up to date). Without
//! the kit (or python3, or a C compiler) a test says it is skipped, except when `BRDFMILL_REQUIRE_GRBL_SIM`
//! is set (`.ci/run` sets it once it has built the kit), where a missing kit or a failed build is a failure. One simulator runs at a time (a static mutex).
#![allow(dead_code)]

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use serde::Deserialize;

/// The flag a user gives `--resume` once they re-established the machine's position after the controller
/// restarted (homed, or set the work coordinates of where the tool stands). Proposed, not yet in the CLI.
pub const REESTABLISHED: &str = "--position-reestablished";

/// Short dwell on resume: the tests are about what ran, not about spindle spin-up.
pub const DWELL: [&str; 2] = ["--spindle-dwell-s", "0.2"];

// ---------------------------------------------------------------------------------------------------------
// The kit: where it is, building it once, one simulator at a time

pub static ONE_SIMULATOR: Mutex<()> = Mutex::new(());
pub static SIM_EXE: OnceLock<Result<PathBuf, String>> = OnceLock::new();

/// Holds the simulator lock for a test (a panicking test poisons it; the next one takes it anyway).
pub fn one_at_a_time() -> MutexGuard<'static, ()> {
    ONE_SIMULATOR.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

pub fn kit_dir() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("BRDFMILL_GRBL_SIM") {
        return Some(PathBuf::from(p));
    }
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/grbl-sim");
    p.join("run.py").exists().then_some(p)
}

/// The cargo target folder: the brdfmill binary is `<target>/<profile>/brdfmill`.
pub fn target_dir() -> PathBuf {
    let bin = brdfmill_exe();
    let bin = bin.as_path();
    bin.parent()
        .and_then(Path::parent)
        .expect("target/<profile>/brdfmill")
        .to_path_buf()
}

/// Build the simulator once (`build.sh DEST`; quick and a no-op when DEST is up to date).
pub fn sim_exe(kit: &Path) -> Result<PathBuf, String> {
    SIM_EXE
        .get_or_init(|| {
            let dest = target_dir().join("grbl-sim");
            let out = Command::new("bash")
                .arg(kit.join("build.sh"))
                .arg(&dest)
                .output()
                .map_err(|e| format!("cannot run build.sh: {e}"))?;
            let exe = dest.join("grbl_sim.exe");
            if out.status.success() && exe.exists() {
                Ok(exe)
            } else {
                Err(format!(
                    "build.sh failed ({}):\n{}{}",
                    out.status,
                    String::from_utf8_lossy(&out.stdout),
                    String::from_utf8_lossy(&out.stderr)
                ))
            }
        })
        .clone()
}

/// The kit and the built simulator, or `None` (skip) when the kit is absent outside CI.
pub fn kit_or_skip(test: &str) -> Option<(PathBuf, PathBuf)> {
    let ci = std::env::var_os("BRDFMILL_REQUIRE_GRBL_SIM").is_some();
    let Some(kit) = kit_dir() else {
        assert!(!ci, "{test}: the grbl-sim kit is missing (set BRDFMILL_GRBL_SIM)");
        eprintln!("{test}: skipped, no grbl-sim kit (../shared/grbl-sim or $BRDFMILL_GRBL_SIM)");
        return None;
    };
    match sim_exe(&kit) {
        Ok(exe) => Some((kit, exe)),
        Err(e) if !ci => {
            eprintln!("{test}: skipped, {e}");
            None
        }
        Err(e) => panic!("{test}: {e}"),
    }
}

// ---------------------------------------------------------------------------------------------------------
// One simulator: run.py --fast in a temporary folder, killed on drop

/// One event of the wire log (`SECONDS TAG b'bytes'`).
#[derive(Debug, Clone)]
pub struct Event {
    pub t: f64,
    pub tag: String,
    pub data: Vec<u8>,
}

impl Event {
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.data).into_owned()
    }
}

pub struct Sim {
    pub kit: PathBuf,
    pub dir: tempfile::TempDir,
    pub child: Child,
    pub port: PathBuf,
    pub sock: PathBuf,
    pub trace: PathBuf,
    pub wire: PathBuf,
}

impl Sim {
    /// Start `run.py --fast` with extra settings (`$N=V`, stored before the port appears); waits for
    /// `ready:`.
    pub fn start(kit: &Path, exe: &Path, settings: &[&str]) -> Sim {
        let dir = tempfile::Builder::new().prefix("grbl-fw-").tempdir().unwrap();
        let p = |n: &str| dir.path().join(n);
        let (port, sock, trace, wire) = (p("port"), p("ctl.sock"), p("trace.txt"), p("wire.log"));
        let mut cmd = Command::new("python3");
        cmd.arg(kit.join("run.py"))
            .arg("--sim")
            .arg(exe)
            .arg("--port")
            .arg(&port)
            .arg("--trace")
            .arg(&trace)
            .arg("--wire")
            .arg(&wire)
            .arg("--control")
            .arg(&sock)
            .arg("--fast");
        for s in settings {
            cmd.arg("--setting").arg(s);
        }
        let err = std::fs::File::create(p("run.stderr")).unwrap();
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(err)
            .spawn()
            .expect("python3 run.py");
        let out = child.stdout.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut r = BufReader::new(out);
            let mut l = String::new();
            let _ = r.read_line(&mut l);
            let _ = tx.send(l);
            // keep reading so that run.py never blocks on its stdout
            let _ = std::io::copy(&mut r, &mut std::io::sink());
        });
        let ready = rx.recv_timeout(Duration::from_secs(30)).unwrap_or_default();
        let sim = Sim {
            kit: kit.to_path_buf(),
            dir,
            child,
            port,
            sock,
            trace,
            wire,
        };
        assert!(
            ready.starts_with("ready:"),
            "run.py did not start: {ready:?}; stderr: {}",
            std::fs::read_to_string(sim.path("run.stderr")).unwrap_or_default()
        );
        sim
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// A control command over the socket (`inject 18`, `disconnect`, `connect`, `restart`, `cmd LINE`…).
    pub fn ctl(&self, command: &str) -> String {
        let mut s = UnixStream::connect(&self.sock).expect("control socket");
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        s.write_all(format!("{command}\n").as_bytes()).unwrap();
        let mut out = String::new();
        let _ = s.read_to_string(&mut out);
        out.trim().to_string()
    }

    /// The wire log so far.
    pub fn wire(&self) -> Vec<Event> {
        let text = std::fs::read_to_string(&self.wire).unwrap_or_default();
        text.lines().filter_map(parse_event).collect()
    }

    /// Wait (bounded) until `pred` holds for the wire log; returns it.
    pub fn wait_wire(&self, what: &str, timeout: Duration, pred: impl Fn(&[Event]) -> bool) -> Vec<Event> {
        let end = Instant::now() + timeout;
        loop {
            let w = self.wire();
            if pred(&w) {
                return w;
            }
            assert!(Instant::now() < end, "waited {timeout:?} for {what}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Wait until program line `n` has been written to the controller (`N<n>` numbering) after wire event
    /// `from`.
    pub fn wait_line_sent(&self, from: usize, n: usize) {
        let needle = format!("N{n}G");
        self.wait_wire(&format!("line {n} on the wire"), Duration::from_secs(60), |w| {
            w.iter()
                .skip(from)
                .any(|e| e.tag == "H>C" && e.text().contains(&needle))
        });
    }

    /// Ask the controller for a status report while no host has the port open (`cmd ?`).
    pub fn status(&self) -> String {
        self.ctl("cmd ?")
    }

    /// Wait until the controller reports `Idle` or `Alarm` (no host may have the port open).
    pub fn wait_at_rest(&self) -> String {
        let end = Instant::now() + Duration::from_secs(60);
        loop {
            let s = self.status();
            if s.starts_with("<Idle") || s.starts_with("<Alarm") {
                return s;
            }
            assert!(Instant::now() < end, "controller not at rest: {s}");
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// The step trace judged against `program` (`trace.py --json`).
    pub fn verdict(&self, program: &Path, wco: [f64; 3], life: Option<u32>, physical: bool) -> Verdict {
        let mut cmd = Command::new("python3");
        cmd.arg(self.kit.join("trace.py"))
            .arg(program)
            .arg(&self.trace)
            .arg("--json")
            .arg("--wco")
            .args(wco.iter().map(|v| format!("{v}")));
        if let Some(l) = life {
            cmd.arg("--life").arg(l.to_string());
        }
        if physical {
            cmd.arg("--physical");
        }
        let out = cmd.output().expect("python3 trace.py");
        assert!(
            out.status.success(),
            "trace.py: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).expect("trace.py --json")
    }

    /// Samples in the step trace file so far (to tell whether anything moved in between).
    pub fn trace_samples(&self) -> usize {
        std::fs::read_to_string(&self.trace)
            .unwrap_or_default()
            .lines()
            .filter(|l| l.starts_with("T ") || l.starts_with("B "))
            .count()
    }

    /// Whether the machine moved during controller life `life` (samples at more than one position).
    pub fn moved_in_life(&self, life: u32) -> bool {
        let mut cur = 1;
        let mut seen: Option<String> = None;
        for l in std::fs::read_to_string(&self.trace).unwrap().lines() {
            let f: Vec<&str> = l.split_whitespace().collect();
            match f.as_slice() {
                ["L", n] => cur = n.parse().unwrap_or(cur + 1),
                [_, _, x, y, z] if cur == life => {
                    let p = format!("{x} {y} {z}");
                    match &seen {
                        None => seen = Some(p),
                        Some(q) if *q != p => return true,
                        Some(_) => {}
                    }
                }
                _ => {}
            }
        }
        false
    }

    /// The last machine position (mm) of controller life `life` in the step trace.
    pub fn last_position(&self, life: u32) -> [f64; 3] {
        let mut cur = 1;
        let mut last = [0.0; 3];
        for l in std::fs::read_to_string(&self.trace).unwrap().lines() {
            let f: Vec<&str> = l.split_whitespace().collect();
            match f.as_slice() {
                ["L", n] => cur = n.parse().unwrap_or(cur + 1),
                [_, _, x, y, z] if cur == life => {
                    for (i, v) in [x, y, z].iter().enumerate() {
                        last[i] = v.parse::<f64>().unwrap() / 250.0;
                    }
                }
                _ => {}
            }
        }
        last
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        // a failing trial's wire log, trace and journal kept for reading when asked
        if std::thread::panicking() && std::env::var_os("BRDFMILL_KEEP_FAILED_SIM").is_some() {
            let kept = self.dir.path().with_extension("kept");
            if copy_dir(self.dir.path(), &kept).is_ok() {
                eprintln!("kept the failing trial's files in {}", kept.display());
            }
        }
        // SIGTERM stops run.py cleanly (simulator killed, port and socket removed)
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
        let end = Instant::now() + Duration::from_secs(10);
        while Instant::now() < end {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `12.3456 C>H(no host) b'ok\r\n'` → an event.
pub fn parse_event(line: &str) -> Option<Event> {
    let (t, rest) = line.split_once(' ')?;
    let at = rest.find(" b'").or_else(|| rest.find(" b\""))?;
    Some(Event {
        t: t.parse().ok()?,
        tag: rest[..at].to_string(),
        data: py_bytes(&rest[at + 1..])?,
    })
}

/// A Python bytes literal (`repr(bytes)`) → the bytes.
pub fn py_bytes(lit: &str) -> Option<Vec<u8>> {
    let b = lit.as_bytes();
    if b.len() < 3 || b[0] != b'b' {
        return None;
    }
    let body = &b[2..b.len() - 1];
    let mut out = Vec::with_capacity(body.len());
    let mut i = 0;
    while i < body.len() {
        if body[i] != b'\\' {
            out.push(body[i]);
            i += 1;
            continue;
        }
        let c = *body.get(i + 1)?;
        i += 2;
        match c {
            b'n' => out.push(b'\n'),
            b'r' => out.push(b'\r'),
            b't' => out.push(b'\t'),
            b'x' => {
                let h = std::str::from_utf8(body.get(i..i + 2)?).ok()?;
                out.push(u8::from_str_radix(h, 16).ok()?);
                i += 2;
            }
            other => out.push(other),
        }
    }
    Some(out)
}

/// `trace.py --json`: which motion lines ran, by the firmware's own step trace.
#[allow(dead_code)] // every field is shown in failure messages (Debug)
#[derive(Debug, Deserialize)]
pub struct Verdict {
    pub motion_lines: Vec<usize>,
    pub ran_once: Vec<usize>,
    pub never: Vec<usize>,
    pub partial: Vec<usize>,
    pub twice: Vec<usize>,
    #[serde(default)]
    pub samples: usize,
    #[serde(default)]
    pub ambiguous: Vec<usize>,
}

impl Verdict {
    /// Every motion line ran exactly once.
    pub fn all_once(&self) -> bool {
        self.ran_once == self.motion_lines && self.twice.is_empty()
    }
}

// ---------------------------------------------------------------------------------------------------------
// brdfmill itself

#[derive(Debug)]
pub struct Run {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

impl Run {
    pub fn ok(&self) -> bool {
        self.code == Some(0)
    }
    pub fn said(&self) -> String {
        format!("{}{}", self.stdout, self.stderr)
    }
}

/// The `brdfmill` binary: cargo's for a test, the one beside the `examples` folder for an example.
pub fn brdfmill_exe() -> PathBuf {
    if let Some(p) = option_env!("CARGO_BIN_EXE_brdfmill") {
        return PathBuf::from(p);
    }
    let me = std::env::current_exe().expect("the running example");
    me.parent()
        .and_then(Path::parent)
        .map(|d| d.join("brdfmill"))
        .expect("target/<profile>/examples/NAME")
}

pub fn brdfmill_bg(args: &[&str]) -> Child {
    Command::new(brdfmill_exe())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("brdfmill")
}

/// Wait (at most `timeout`) for a brdfmill process and collect what it said.
pub fn finish(mut child: Child, timeout: Duration) -> Run {
    let mut so = child.stdout.take().unwrap();
    let mut se = child.stderr.take().unwrap();
    let a = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = so.read_to_string(&mut s);
        s
    });
    let b = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = se.read_to_string(&mut s);
        s
    });
    let end = Instant::now() + timeout;
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if Instant::now() > end {
            let _ = child.kill();
            let _ = child.wait();
            panic!("brdfmill still running after {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Run {
        code: status.code(),
        stdout: a.join().unwrap(),
        stderr: b.join().unwrap(),
    }
}

pub fn brdfmill(args: &[&str]) -> Run {
    finish(brdfmill_bg(args), Duration::from_secs(180))
}

/// `brdfmill stream PROGRAM --port P --journal J [extra…]`.
pub fn stream_args<'a>(sim: &'a Sim, prog: &'a Path, journal: &'a Path, extra: &[&'a str]) -> Vec<String> {
    let mut v: Vec<String> = vec![
        "stream".into(),
        prog.display().to_string(),
        "--port".into(),
        sim.port.display().to_string(),
        "--journal".into(),
        journal.display().to_string(),
    ];
    v.extend(extra.iter().map(|s| (*s).to_string()));
    v
}

pub fn stream(sim: &Sim, prog: &Path, journal: &Path, extra: &[&str]) -> Run {
    let a = stream_args(sim, prog, journal, extra);
    brdfmill(&a.iter().map(String::as_str).collect::<Vec<_>>())
}

pub fn stream_bg(sim: &Sim, prog: &Path, journal: &Path, extra: &[&str]) -> Child {
    let a = stream_args(sim, prog, journal, extra);
    brdfmill_bg(&a.iter().map(String::as_str).collect::<Vec<_>>())
}

/// The journal's records, as JSON values (new record kinds need no change here).
pub fn records(journal: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(journal)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

pub fn event(r: &serde_json::Value) -> &str {
    r["event"].as_str().unwrap_or("")
}

/// The journal's last stop was located: the streamer found where motion stopped.
pub fn assert_stop_located(journal: &Path, what: &str) {
    let st = brdfmill::apps::stream::journal::Journal::load(journal).expect("journal loads");
    assert!(
        matches!(
            st.stop,
            Some(brdfmill::apps::stream::journal::Record::Stop { located: true, .. })
        ),
        "{what}: stop not located: {:?}",
        st.stop
    );
}

/// The journal's claims at its last stop are the trace's truth: every line it calls executed ran
/// completely, and — when the stop was located — every line the trace shows moving is executed or the one
/// it calls cut.
pub fn assert_journal_truthful(journal: &Path, v: &Verdict, what: &str) {
    let st = brdfmill::apps::stream::journal::Journal::load(journal).expect("journal loads");
    let motion: BTreeSet<usize> = v.motion_lines.iter().copied().collect();
    for n in st.executed.iter().filter(|n| motion.contains(n)) {
        assert!(
            v.ran_once.contains(n),
            "{what}: journal says line {n} executed; trace: {v:?}"
        );
    }
    let located = matches!(
        st.stop,
        Some(brdfmill::apps::stream::journal::Record::Stop { located: true, .. })
    );
    if located {
        for n in v.ran_once.iter().chain(&v.partial) {
            let cut = st.partial.is_some_and(|(p, _)| p == *n);
            assert!(
                st.executed.contains(n) || cut,
                "{what}: line {n} moved (trace) but the journal has it neither executed nor cut: {st:?}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// Programs written for the trace: motion on every line, X monotone, no path retraced

#[allow(clippy::too_many_arguments)]
/// `head` lines, then `n` moves `G1 X(x0 + sign·i) Y(dy·(i mod 2)) Z(z)`, the feed on the first.
pub fn zigzag(dir: &Path, name: &str, head: &[&str], n: usize, x0: f64, sign: f64, dy: f64, z: f64) -> PathBuf {
    let mut lines: Vec<String> = head.iter().map(|s| (*s).to_string()).collect();
    for i in 1..=n {
        let f = if i == 1 { "F1500" } else { "" };
        lines.push(format!(
            "G1X{:.3}Y{:.3}Z{:.3}{f}",
            x0 + sign * i as f64,
            dy * (i % 2) as f64,
            z
        ));
    }
    let p = dir.join(name);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    p
}

/// Replace program line `n` (1-based) by `text`.
pub fn set_line(p: &Path, n: usize, text: &str) {
    let mut lines: Vec<String> = std::fs::read_to_string(p).unwrap().lines().map(String::from).collect();
    lines[n - 1] = text.to_string();
    std::fs::write(p, lines.join("\n") + "\n").unwrap();
}

/// Soft limits on an unhomed controller: 1.1h only locks at power-up with `$22=1`, so after `run.py`
/// stores these it is Idle at machine 0,0,0 and its travel is `-$13x…0`.
pub const SOFT_LIMITS: [&str; 5] = ["$22=1", "$20=1", "$130=50", "$131=50", "$132=50"];

/// X from −30 to −70 in work coordinates: with `$130=50` line 24 (X−51) is the first target beyond
/// travel, and GRBL raises `ALARM:2` when it parses it, after a controlled stop of what it had planned.
pub fn beyond_travel(dir: &Path) -> PathBuf {
    zigzag(
        dir,
        "soft.nc",
        &["G21G90G94", "M3S1000", "G0X-30Y0Z-1"],
        40,
        -30.0,
        -1.0,
        -0.5,
        -1.0,
    )
}

/// If the controller answers nothing (locked in a critical alarm), reset it as a user would.
pub fn reset_if_locked(sim: &Sim) {
    if !sim.status().starts_with('<') {
        assert_eq!(sim.ctl("inject 18"), "ok");
        sim.wait_wire("banner after the user's reset", Duration::from_secs(5), |w| {
            w.iter().rev().take(10).any(|e| e.text().contains("Grbl 1.1h"))
        });
    }
}

// ---------------------------------------------------------------------------------------------------------
// Ten seeded random faults

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Reset,
    Alarm,
    Disconnect,
    DisconnectRestart,
    ErrorLine,
}

impl Kind {
    /// Every kind, in the order trials cycle through them.
    pub const ALL: [Kind; 5] = [
        Kind::Reset,
        Kind::Alarm,
        Kind::Disconnect,
        Kind::DisconnectRestart,
        Kind::ErrorLine,
    ];
}

/// A small deterministic generator (SplitMix64).
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next() % (hi - lo + 1) as u64) as usize
    }
}

/// One trial: a 30-move program (X from −2 to −32), one fault, then what a user does (the resume the stop
/// message asks for, and the fix it names), until the job completes; the trace must show every motion line
/// exactly once (across lives, physically, for a restart).
///
/// A disconnect is injected once the harness sees the fault line on the wire; if the harness was so late
/// that the job had already ended (its host closed the port before the disconnect), the fault missed: the
/// completed job is checked like any other and the trial is repeated, at most twice more.
pub fn trial(kit: &Path, exe: &Path, seed: u64, kind: Kind) {
    for _ in 0..3 {
        if attempt(kit, exe, seed, kind) {
            return;
        }
        eprintln!("seed {seed} {kind:?}: the disconnect came after the job had ended; trial repeated");
    }
    panic!("seed {seed} {kind:?}: the disconnect came after the job had ended, three times");
}

/// One try of [`trial`]: `false` when the fault missed the job (see there).
fn attempt(kit: &Path, exe: &Path, seed: u64, kind: Kind) -> bool {
    let mut rng = Rng(seed);
    let fault_line = rng.range(8, 24);
    // soft limit: the first target beyond −$130 is line `fault_line`
    let travel = format!("$130={}.5", fault_line - 4 + 2);
    let settings: Vec<&str> = match kind {
        Kind::Alarm => vec!["$22=1", "$20=1", travel.as_str(), "$131=50", "$132=50"],
        _ => vec![],
    };
    let sim = Sim::start(kit, exe, &settings);
    let head = ["G21G90G94", "M3S1000", "G0X-2Y0Z-1"];
    let prog = zigzag(sim.dir.path(), "p.nc", &head, 30, -2.0, -1.0, -0.5, -1.0);
    if kind == Kind::ErrorLine {
        set_line(&prog, fault_line, "M6");
    }
    let j = sim.path("j.jsonl");
    let ctx = format!("seed {seed} {kind:?} at line {fault_line}");
    let from = sim.wire().len();
    let child = stream_bg(&sim, &prog, &j, &[]);
    match kind {
        Kind::Reset => {
            sim.wait_line_sent(from, fault_line);
            sim.ctl("inject 18");
        }
        Kind::Disconnect | Kind::DisconnectRestart => {
            sim.wait_line_sent(from, fault_line);
            sim.ctl("disconnect");
        }
        Kind::Alarm | Kind::ErrorLine => {}
    }
    let first = finish(child, Duration::from_secs(120));
    if first.ok() && matches!(kind, Kind::Disconnect | Kind::DisconnectRestart) {
        let w = sim.wire();
        let at = |tag: &str, text: &str| (from..w.len()).find(|&k| w[k].tag == tag && w[k].text().contains(text));
        if let (Some(closed), Some(cut)) = (at("HOST-CLOSE", ""), at("CTL", "disconnect")) {
            if closed < cut {
                let v = sim.verdict(&prog, [0.0; 3], None, false);
                assert!(v.all_once(), "{ctx}: the job ended before the fault, yet: {v:?}");
                return false;
            }
        }
    }
    assert!(!first.ok(), "{ctx}: the fault did not stop the job: {first:?}");
    if matches!(kind, Kind::Reset | Kind::Alarm | Kind::ErrorLine) {
        assert!(
            !first.said().contains("no banner"),
            "{ctx}: the reset was lost: {first:?}"
        );
        assert_stop_located(&j, &ctx);
        assert_journal_truthful(&j, &sim.verdict(&prog, [0.0; 3], None, false), &ctx);
    }
    let mut extra: Vec<String> = Vec::new();
    match kind {
        Kind::Reset => extra.push("--unlock".into()),
        Kind::Alarm => {
            reset_if_locked(&sim);
            assert_eq!(sim.ctl("cmd $130=200"), "ok", "{ctx}");
        }
        Kind::ErrorLine => extra.extend(["--skip-line".to_string(), fault_line.to_string()]),
        Kind::Disconnect => {
            sim.wait_at_rest();
            sim.ctl("connect");
        }
        Kind::DisconnectRestart => {
            sim.wait_at_rest();
            sim.ctl("connect");
            let from = sim.wire().len();
            let child = stream_bg(&sim, &prog, &j, &["--resume", DWELL[0], DWELL[1]]);
            sim.wait_wire("HOST-OPEN", Duration::from_secs(10), |w| {
                w.iter().skip(from).any(|e| e.tag == "HOST-OPEN")
            });
            sim.ctl("restart");
            let r = finish(child, Duration::from_secs(120));
            assert!(!r.ok() && r.said().to_lowercase().contains("restart"), "{ctx}: {r:?}");
            let at = sim.last_position(1);
            let g10 = format!("cmd G10L20P1X{:.3}Y{:.3}Z{:.3}", at[0], at[1], at[2]);
            assert_eq!(sim.ctl(&g10), "ok", "{ctx}");
            extra.push(REESTABLISHED.into());
        }
    }
    let mut args: Vec<&str> = vec!["--resume", DWELL[0], DWELL[1]];
    args.extend(extra.iter().map(String::as_str));
    let r = stream(&sim, &prog, &j, &args);
    assert!(r.ok(), "{ctx}: the resume did not complete: {r:?}");
    let v = sim.verdict(&prog, [0.0; 3], None, kind == Kind::DisconnectRestart);
    assert!(v.all_once(), "{ctx}: {v:?}");
    assert!(v.ambiguous.is_empty(), "{ctx}: the test program retraces itself: {v:?}");
    assert_eq!(event(records(&j).last().unwrap()), "complete", "{ctx}");
    true
}

/// Copy the files of a folder (not its subfolders) into a new one.
fn copy_dir(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(to)?;
    for e in std::fs::read_dir(from)?.flatten() {
        if e.file_type()?.is_file() {
            std::fs::copy(e.path(), to.join(e.file_name()))?;
        }
    }
    Ok(())
}
