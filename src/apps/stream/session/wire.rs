//! The wire as the streamer sees it: bytes out, complete lines in (with a timeout), and the periodic
//! status poll. Every other step talks to the controller through these, so a link failure always becomes
//! the same `Fault::Disconnect`.

use std::time::{Duration, Instant};

use super::{Fault, Session, StreamError};
use crate::apps::stream::protocol::Realtime;

impl Session<'_> {
    /// The port name, for messages.
    pub(super) fn port(&self) -> String {
        self.link.name().to_string()
    }

    /// Write bytes; a failure means the link is gone. An interrupted system call (a signal such as Ctrl-C
    /// arriving during the write) is no failure: it is retried.
    pub(super) fn write(&mut self, bytes: &[u8]) -> Result<(), Fault> {
        loop {
            match self.link.write_all(bytes) {
                Ok(()) => return Ok(()),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Fault::Disconnect(format!("write failed: {e}"))),
            }
        }
    }

    /// Next complete line from the controller, waiting at most `timeout`.
    pub(super) fn read_line(&mut self, timeout: Duration) -> Result<Option<String>, Fault> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(i) = self.rbuf.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = self.rbuf.drain(..=i).collect();
                let text = String::from_utf8_lossy(&raw).trim().to_string();
                if text.is_empty() {
                    continue;
                }
                self.last_rx = Instant::now();
                return Ok(Some(text));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let mut buf = [0u8; 512];
            let n = match self.link.read(&mut buf, deadline - now) {
                Ok(n) => n,
                // A signal interrupted the wait (Ctrl-C): not a lost link; read again.
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => 0,
                Err(e) => return Err(Fault::Disconnect(format!("read failed: {e}"))),
            };
            if self.saw.len() < 120 {
                self.saw.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
            self.rbuf.extend_from_slice(&buf[..n]);
        }
    }

    /// A fault outside streaming (handshake, check run, resume) as an error naming the port.
    pub(super) fn link_err(&self, what: &str, f: Fault) -> StreamError {
        let msg = match f {
            Fault::Disconnect(m) | Fault::Protocol(m) => m,
            other => format!("{other:?}"),
        };
        StreamError::Link {
            port: self.port(),
            what: what.into(),
            source: std::io::Error::new(std::io::ErrorKind::BrokenPipe, msg),
        }
    }

    /// Ask for a status report (`?`) when the poll period is up.
    pub(super) fn maybe_poll(&mut self) -> Result<(), Fault> {
        let now = Instant::now();
        if now >= self.next_poll {
            self.write(&[Realtime::Status.byte()])?;
            self.next_poll = now + self.cfg.status_interval.max(Duration::from_millis(200));
        }
        Ok(())
    }
}
