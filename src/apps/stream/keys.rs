//! Hold and resume from the keyboard while streaming: the keys GRBL's own realtime commands use.
//!
//! When the streamer's standard input is a terminal, [`Keys::listen`] turns off its line buffering and
//! echo (not its signals: Ctrl-C still stops the job) and reads keys in a thread of its own:
//!
//! - `!` or space: feed hold (the same flag `SIGUSR1` raises; the machine decelerates and waits at
//!   `Hold:0`, and streaming goes on into the controller's buffer);
//! - `~` or Enter: cycle start after the hold (the flag of `SIGUSR2`).
//!
//! Every byte read is also passed on ([`Keys::take_input`]), so the streamer can ask the user a question
//! (whether to reset after an alarm) without a second reader on the terminal. Other keys raise nothing.
//! The keys only raise the session's flags ([`super::session::Controls`]): the
//! session sends the realtime bytes and decides what executed, so a key can never put a byte on the wire
//! that the session did not choose. Dropping the [`Keys`] stops the thread and restores the terminal as it
//! was, on every way out of the job (completion, an error, Ctrl-C).

use nix::sys::termios::{self, LocalFlags, SetArg, SpecialCharacterIndices, Termios};
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;

/// What a key asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    /// Feed hold.
    Hold,
    /// Cycle start.
    Resume,
}

/// The meaning of a byte read from the keyboard, if any.
pub fn key_of(b: u8) -> Option<Key> {
    match b {
        b'!' | b' ' => Some(Key::Hold),
        b'~' | b'\r' | b'\n' => Some(Key::Resume),
        _ => None,
    }
}

/// A keyboard listener; dropping it restores the terminal.
pub struct Keys {
    fd: OwnedFd,
    saved: Termios,
    quit: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    input: Option<Receiver<u8>>,
}

impl Keys {
    /// Listen on `fd` (a duplicate is kept) when it is a terminal, raising `hold` and `resume`; `None` when
    /// it is not a terminal (input from a pipe or a file is left alone).
    pub fn listen(fd: BorrowedFd, hold: Arc<AtomicBool>, resume: Arc<AtomicBool>) -> std::io::Result<Option<Self>> {
        if !nix::unistd::isatty(std::os::fd::AsRawFd::as_raw_fd(&fd)).unwrap_or(false) {
            return Ok(None);
        }
        let fd = fd.try_clone_to_owned()?;
        let saved = termios::tcgetattr(fd.as_fd()).map_err(std::io::Error::from)?;
        let mut t = saved.clone();
        // byte at a time, no echo; ISIG stays, so Ctrl-C is still SIGINT
        t.local_flags.remove(LocalFlags::ICANON | LocalFlags::ECHO);
        t.control_chars[SpecialCharacterIndices::VMIN as usize] = 1;
        t.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
        termios::tcsetattr(fd.as_fd(), SetArg::TCSANOW, &t).map_err(std::io::Error::from)?;
        let quit = Arc::new(AtomicBool::new(false));
        let reader = fd.try_clone()?;
        let q = Arc::clone(&quit);
        let (tx, rx) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("keys".into())
            .spawn(move || read_keys(reader, &q, &hold, &resume, &tx))?;
        Ok(Some(Self {
            fd,
            saved,
            quit,
            thread: Some(thread),
            input: Some(rx),
        }))
    }

    /// Every byte typed from now on (once: the first call takes them).
    pub fn take_input(&mut self) -> Option<Receiver<u8>> {
        self.input.take()
    }
}

/// Poll `fd` every 100 ms until `quit`, raising the flags for the keys read.
fn read_keys(fd: OwnedFd, quit: &AtomicBool, hold: &AtomicBool, resume: &AtomicBool, input: &Sender<u8>) {
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    let mut buf = [0u8; 64];
    while !quit.load(Ordering::SeqCst) {
        let mut fds = [PollFd::new(fd.as_fd(), PollFlags::POLLIN)];
        match poll(&mut fds, PollTimeout::from(100u8)) {
            Ok(0) | Err(nix::errno::Errno::EINTR) => continue,
            Ok(_) => {}
            Err(_) => return,
        }
        let rev = fds[0].revents().unwrap_or(PollFlags::empty());
        if !rev.contains(PollFlags::POLLIN) {
            // the terminal hung up: no more keys
            return;
        }
        match nix::unistd::read(std::os::fd::AsRawFd::as_raw_fd(&fd), &mut buf) {
            Ok(0) => return,
            Ok(n) => {
                // each key's flag is raised before the key is passed on, so whoever reads the byte also
                // sees its effect
                for b in &buf[..n] {
                    match key_of(*b) {
                        Some(Key::Hold) => hold.store(true, Ordering::SeqCst),
                        Some(Key::Resume) => resume.store(true, Ordering::SeqCst),
                        None => {}
                    }
                    let _ = input.send(*b);
                }
            }
            Err(nix::errno::Errno::EINTR | nix::errno::Errno::EAGAIN) => {}
            Err(_) => return,
        }
    }
}

impl Drop for Keys {
    fn drop(&mut self) {
        self.quit.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = termios::tcsetattr(self.fd.as_fd(), SetArg::TCSANOW, &self.saved);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::fd::AsRawFd;

    /// Keys typed on a terminal raise the flags, other keys do not, every byte is passed on in order, and
    /// dropping the listener leaves the terminal's modes as they were. The test waits for each key by
    /// receiving it (its flag is raised before it is passed on), not by a clock.
    #[test]
    fn keys_on_a_terminal_raise_hold_and_resume_and_the_terminal_is_restored() {
        let pty = nix::pty::openpty(None, None).unwrap();
        let before = termios::tcgetattr(pty.slave.as_fd()).unwrap();
        assert!(
            before.local_flags.contains(LocalFlags::ICANON),
            "a fresh pty is line-buffered"
        );
        let (hold, resume) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let mut keys = Keys::listen(pty.slave.as_fd(), Arc::clone(&hold), Arc::clone(&resume))
            .unwrap()
            .expect("a pty is a terminal");
        let input = keys.take_input().expect("the typed bytes");
        assert!(keys.take_input().is_none(), "taken once");
        let during = termios::tcgetattr(pty.slave.as_fd()).unwrap();
        assert!(!during.local_flags.contains(LocalFlags::ICANON) && !during.local_flags.contains(LocalFlags::ECHO));
        assert!(
            during.local_flags.contains(LocalFlags::ISIG),
            "Ctrl-C must stay a signal"
        );
        // type one key, take it from the listener, and say which flags it raised
        let press = |k: &[u8]| -> (u8, bool, bool) {
            nix::unistd::write(&pty.master, k).unwrap();
            let b = input.recv().expect("the listener passes every key on");
            (
                b,
                hold.swap(false, Ordering::SeqCst),
                resume.swap(false, Ordering::SeqCst),
            )
        };
        assert_eq!(press(b"x"), (b'x', false, false), "other keys raise nothing");
        assert_eq!(press(b"!"), (b'!', true, false), "`!` holds");
        assert_eq!(press(b"~"), (b'~', false, true), "`~` resumes");
        assert_eq!(press(b" "), (b' ', true, false), "space holds");
        // Enter arrives as a newline where the terminal maps CR to NL
        let (b, h, r) = press(b"\r");
        assert!(matches!(b, b'\r' | b'\n') && !h && r, "Enter resumes: {b} {h} {r}");
        assert!(input.try_recv().is_err(), "one byte per key");
        drop(keys);
        let after = termios::tcgetattr(pty.slave.as_fd()).unwrap();
        assert_eq!(after.local_flags, before.local_flags);
        assert_eq!(
            after.control_chars[SpecialCharacterIndices::VMIN as usize],
            before.control_chars[SpecialCharacterIndices::VMIN as usize]
        );
        let _ = pty.master.as_raw_fd();
    }

    /// Input that is not a terminal is left alone.
    #[test]
    fn a_pipe_is_not_listened_to() {
        let (r, _w) = nix::unistd::pipe().unwrap();
        let f = Arc::new(AtomicBool::new(false));
        assert!(Keys::listen(r.as_fd(), Arc::clone(&f), f).unwrap().is_none());
    }
}
