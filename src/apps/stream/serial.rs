//! The serial adapter: the only place that touches a port. [`Link`] is what the streamer needs —
//! write bytes, read bytes with a timeout — and [`SerialLink`] implements it on `serialport`
//! (default 115200 8N1, no flow control, as GRBL expects).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// GRBL 1.1's serial speed, bits/s.
pub const DEFAULT_BAUD: u32 = 115_200;

/// A byte link to a controller.
pub trait Link {
    /// Write all bytes (an error means the link is gone).
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()>;
    /// Read what is available, waiting at most `timeout`; `Ok(0)` when nothing came.
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize>;
    /// The port name, for messages.
    fn name(&self) -> &str;
}

/// The serial port could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("cannot open serial port {path} at {baud} baud")]
pub struct OpenError {
    /// The port.
    pub path: PathBuf,
    /// The requested speed.
    pub baud: u32,
    /// Why.
    #[source]
    pub source: serialport::Error,
}

/// A serial port opened 8N1 without flow control.
pub struct SerialLink {
    port: serialport::TTYPort,
    name: String,
    timeout: Duration,
}

impl std::fmt::Debug for SerialLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialLink").field("name", &self.name).finish()
    }
}

impl SerialLink {
    /// Open `path` at `baud` bits/s, 8 data bits, no parity, 1 stop bit, no flow control.
    pub fn open(path: &Path, baud: u32) -> Result<SerialLink, OpenError> {
        let err = |source| OpenError {
            path: path.to_path_buf(),
            baud,
            source,
        };
        if !path.exists() {
            return Err(err(serialport::Error::new(
                serialport::ErrorKind::NoDevice,
                "no such device (is the controller plugged in? `ls /dev/tty*`)",
            )));
        }
        let timeout = Duration::from_millis(10);
        let port = serialport::new(path.to_string_lossy(), baud)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(timeout)
            .open_native()
            .map_err(err)?;
        Ok(SerialLink {
            port,
            name: path.display().to_string(),
            timeout,
        })
    }
}

impl Link for SerialLink {
    /// Write everything into the port's output queue; an interrupted system call (EINTR, e.g. Ctrl-C) is
    /// retried, never reported as a failure. It does not wait for the queue to drain (`tcdrain`): the
    /// kernel sends the bytes in order, so character counting and the order of realtime bytes hold without
    /// it, and waiting for every line to reach the wire stalled the stream between lines (measured against
    /// the real firmware: the receive buffer ran dry 5–17 times a run, `$C` at 87–98% of a streamer that
    /// does not wait).
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        Write::write_all(&mut self.port, bytes) // retries EINTR itself
    }

    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        use serialport::SerialPort;
        let timeout = timeout.max(Duration::from_millis(1));
        if timeout != self.timeout {
            self.port.set_timeout(timeout).map_err(std::io::Error::from)?;
            self.timeout = timeout;
        }
        match Read::read(&mut self.port, buf) {
            Ok(0) => Err(std::io::Error::new(std::io::ErrorKind::BrokenPipe, "port closed")),
            Ok(n) => Ok(n),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(0),
            // A signal (Ctrl-C) interrupted the wait: nothing was read, the link is fine.
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(0),
            Err(e) => Err(e),
        }
    }

    fn name(&self) -> &str {
        &self.name
    }
}
