//! The [`Emulator`]: a [`Controller`] on a pseudo-terminal, run by its own thread. The thread moves bytes
//! between the pseudo-terminal and the controller at the configured baud (10 bits per byte, 8N1, paced
//! both ways by a [`Pacer`]), advances simulated time `time_scale` times faster than real time, publishes
//! the log, and carries out an injected disconnect: it closes the pseudo-terminal and opens a new one
//! (optionally behind a stable symbolic link) after `reconnect_delay`.

use std::collections::VecDeque;
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::{Controller, EmulatorConfig, EmulatorLog};

/// Paces bytes over a simulated serial line: one byte per `10 / baud` seconds, no banked credit while the
/// line is idle.
#[derive(Debug)]
struct Pacer {
    byte_time: Duration,
    next_free: Instant,
}

impl Pacer {
    fn new(baud: u32) -> Pacer {
        Pacer {
            byte_time: Duration::from_secs_f64(10.0 / f64::from(baud.max(1))),
            next_free: Instant::now(),
        }
    }

    /// Bytes were queued on an idle line at `now`: the first one finishes crossing one byte time later.
    fn arrive(&mut self, now: Instant) {
        self.next_free = self.next_free.max(now);
    }

    /// How many of `waiting` bytes have finished crossing the line by `now`.
    fn take(&mut self, now: Instant, waiting: usize) -> usize {
        if waiting == 0 || now < self.next_free + self.byte_time {
            return 0;
        }
        let n = ((now - self.next_free).as_secs_f64() / self.byte_time.as_secs_f64()) as usize;
        let n = n.min(waiting);
        self.next_free += self.byte_time * n as u32;
        n
    }
}

#[derive(Debug, Default)]
struct Shared {
    port: Option<PathBuf>,
    generation: u64,
    log: EmulatorLog,
    failure: Option<String>,
}

/// A virtual GRBL controller running on a pseudo-terminal in its own thread. Dropping it stops it.
#[derive(Debug)]
pub struct Emulator {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// A pseudo-terminal: the master end the emulator reads and writes, and the slave's path.
struct Pty {
    master: OwnedFd,
    path: PathBuf,
}

fn open_pty(link: Option<&Path>) -> std::io::Result<Pty> {
    use nix::sys::termios;
    let pty = nix::pty::openpty(None, None).map_err(std::io::Error::from)?;
    let mut t = termios::tcgetattr(pty.slave.as_fd()).map_err(std::io::Error::from)?;
    termios::cfmakeraw(&mut t);
    termios::tcsetattr(pty.slave.as_fd(), termios::SetArg::TCSANOW, &t).map_err(std::io::Error::from)?;
    let path = nix::unistd::ttyname(pty.slave.as_fd()).map_err(std::io::Error::from)?;
    let flags =
        nix::fcntl::fcntl(pty.master.as_raw_fd(), nix::fcntl::FcntlArg::F_GETFL).map_err(std::io::Error::from)?;
    let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
    nix::fcntl::fcntl(pty.master.as_raw_fd(), nix::fcntl::FcntlArg::F_SETFL(flags)).map_err(std::io::Error::from)?;
    // The slave end is closed here: a client opening it is the only user (so serialport's exclusive
    // lock is released when the client closes it), and the master sees a hang-up when nobody has it open.
    drop(pty.slave);
    if let Some(link) = link {
        let tmp = link.with_extension("tmp-link");
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(&path, &tmp)?;
        std::fs::rename(&tmp, link)?;
    }
    Ok(Pty {
        master: pty.master,
        path,
    })
}

impl Emulator {
    /// Open a pseudo-terminal and start the controller on it.
    pub fn start(cfg: EmulatorConfig) -> std::io::Result<Emulator> {
        let pty = open_pty(cfg.link_path.as_deref())?;
        let shared = Arc::new((
            Mutex::new(Shared {
                port: Some(pty.path.clone()),
                generation: 1,
                ..Shared::default()
            }),
            Condvar::new(),
        ));
        let stop = Arc::new(AtomicBool::new(false));
        let (sh, st) = (Arc::clone(&shared), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name("grbl-emulator".into())
            .spawn(move || {
                if let Err(e) = run_link(cfg, pty, &sh, &st) {
                    let (m, cv) = &*sh;
                    let mut g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                    g.failure = Some(e.to_string());
                    g.port = None;
                    cv.notify_all();
                }
            })?;
        Ok(Emulator {
            shared,
            stop,
            thread: Some(thread),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Shared> {
        self.shared.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The current port path (changes after an injected disconnect; `None` while reconnecting).
    #[must_use]
    pub fn port_path(&self) -> Option<PathBuf> {
        self.lock().port.clone()
    }

    /// Wait up to `timeout` for a port other than the one of connection `generation` (see
    /// [`Emulator::generation`]); returns the new path and generation.
    #[must_use]
    pub fn wait_new_port(&self, generation: u64, timeout: Duration) -> Option<(PathBuf, u64)> {
        let (m, cv) = &*self.shared;
        let g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let (g, _) = cv
            .wait_timeout_while(g, timeout, |s| {
                s.failure.is_none() && (s.generation == generation || s.port.is_none())
            })
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        g.port
            .clone()
            .filter(|_| g.generation != generation)
            .map(|p| (p, g.generation))
    }

    /// How many pseudo-terminals have been opened (1 at start, +1 per injected disconnect).
    #[must_use]
    pub fn generation(&self) -> u64 {
        self.lock().generation
    }

    /// A copy of the log so far.
    #[must_use]
    pub fn log(&self) -> EmulatorLog {
        self.lock().log.clone()
    }

    /// Why the emulator thread stopped, if it failed.
    #[must_use]
    pub fn failure(&self) -> Option<String> {
        self.lock().failure.clone()
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// What the emulator thread and the [`Emulator`] handle share.
type SharedState = Arc<(Mutex<Shared>, Condvar)>;

fn lock(shared: &SharedState) -> MutexGuard<'_, Shared> {
    shared.0.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The emulator thread's state: the controller, the pseudo-terminal (none while reconnecting) and the
/// bytes on the simulated wire in each direction.
struct LinkThread<'a> {
    cfg: EmulatorConfig,
    ctl: Controller,
    pty: Option<Pty>,
    reconnect_at: Option<Instant>,
    wire_in: VecDeque<u8>,
    wire_out: VecDeque<u8>,
    pace_in: Pacer,
    pace_out: Pacer,
    last: Instant,
    shared: &'a SharedState,
}

/// The emulator thread: move bytes between the pseudo-terminal and the controller at the baud rate,
/// advance simulated time, publish the log.
fn run_link(cfg: EmulatorConfig, first: Pty, shared: &SharedState, stop: &AtomicBool) -> std::io::Result<()> {
    let mut t = LinkThread {
        ctl: Controller::new(&cfg),
        pty: Some(first),
        reconnect_at: None,
        wire_in: VecDeque::new(),
        wire_out: VecDeque::new(),
        pace_in: Pacer::new(cfg.baud),
        pace_out: Pacer::new(cfg.baud),
        last: Instant::now(),
        shared,
        cfg,
    };
    while !stop.load(Ordering::SeqCst) {
        let hung_up = t.read_pty();
        if hung_up || t.pty.is_none() {
            std::thread::sleep(Duration::from_millis(1));
        }
        let now = Instant::now();
        t.run_controller(now);
        if t.ctl.take_disconnect() {
            t.drop_link(now);
        }
        t.write_pty(now);
        if t.reconnect_at.is_some_and(|r| now >= r) {
            t.reconnect()?;
        }
        let mut fresh = t.ctl.take_log();
        lock(t.shared).log.append(&mut fresh);
    }
    Ok(())
}

impl LinkThread<'_> {
    /// Take what the host wrote (waiting up to 1 ms) onto the inbound wire; true when nobody has the port
    /// open.
    fn read_pty(&mut self) -> bool {
        use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
        let Some(p) = &self.pty else { return false };
        let mut buf = [0u8; 4096];
        let mut fds = [PollFd::new(p.master.as_fd(), PollFlags::POLLIN)];
        let n = poll(&mut fds, PollTimeout::from(1u8)).unwrap_or(0);
        let rev = fds[0].revents().unwrap_or(PollFlags::empty());
        if n > 0 && rev.contains(PollFlags::POLLIN) {
            match nix::unistd::read(p.master.as_raw_fd(), &mut buf) {
                Ok(k) => {
                    if self.wire_in.is_empty() {
                        self.pace_in.arrive(Instant::now());
                    }
                    self.wire_in.extend(&buf[..k]);
                    false
                }
                Err(nix::errno::Errno::EAGAIN) => false,
                Err(_) => true,
            }
        } else {
            n > 0 // POLLHUP: no client has the port open
        }
    }

    /// Deliver the bytes that have crossed the wire, advance simulated time, queue the answers.
    fn run_controller(&mut self, now: Instant) {
        let dt = (now - self.last).as_secs_f64();
        self.last = now;
        let k = self.pace_in.take(now, self.wire_in.len());
        for b in self.wire_in.drain(..k) {
            self.ctl.receive(b);
        }
        self.ctl.advance(dt * self.cfg.time_scale);
        let fresh_out = self.ctl.take_output();
        if self.wire_out.is_empty() && !fresh_out.is_empty() {
            self.pace_out.arrive(now);
        }
        self.wire_out.extend(fresh_out);
    }

    /// An injected disconnect: close the pseudo-terminal (the client sees a hang-up), lose what is on the
    /// wire, and reconnect later.
    fn drop_link(&mut self, now: Instant) {
        self.ctl.link_lost();
        self.wire_in.clear();
        self.wire_out.clear();
        self.pty = None; // closes the master: the client sees a hang-up
        self.reconnect_at = Some(now + self.cfg.reconnect_delay);
        let mut g = lock(self.shared);
        g.port = None;
        g.log.events.push("link dropped (injected disconnect)".into());
        self.shared.1.notify_all();
    }

    /// Write the bytes that have crossed the wire to the host.
    fn write_pty(&mut self, now: Instant) {
        let Some(p) = &self.pty else { return };
        let k = self.pace_out.take(now, self.wire_out.len());
        if k > 0 {
            let chunk: Vec<u8> = self.wire_out.iter().take(k).copied().collect();
            match nix::unistd::write(p.master.as_fd(), &chunk) {
                Ok(w) => {
                    self.wire_out.drain(..w);
                    self.ctl.log.bytes_out += w as u64;
                }
                Err(nix::errno::Errno::EAGAIN) => {}
                Err(_) => {} // nobody reading: keep the bytes, a real UART would lose them
            }
        }
    }

    /// Open the new pseudo-terminal after a disconnect and announce it.
    fn reconnect(&mut self) -> std::io::Result<()> {
        self.reconnect_at = None;
        let p = open_pty(self.cfg.link_path.as_deref())?;
        let mut g = lock(self.shared);
        g.port = Some(p.path.clone());
        g.generation += 1;
        g.log.events.push(format!("link up on {}", p.path.display()));
        self.shared.1.notify_all();
        drop(g);
        self.pty = Some(p);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pacer_keeps_the_baud_rate() {
        let mut p = Pacer::new(115_200);
        let t0 = Instant::now() + Duration::from_millis(5);
        p.arrive(t0);
        assert_eq!(p.take(t0, 100), 0);
        assert_eq!(p.take(t0 + Duration::from_millis(1), 100), 11);
        assert_eq!(p.take(t0 + Duration::from_millis(10), 1000), 115 - 11);
    }
}
