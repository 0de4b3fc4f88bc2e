//! [`StreamError`]: the ways a run fails before or outside a job (refusals, an unanswering port, a locked
//! controller, a journal that cannot be resumed). A fault *during* a job is not an error: it ends in a safe
//! stop and an [`Outcome::Stopped`](super::Outcome::Stopped).

use std::path::PathBuf;
use std::time::Duration;

use crate::apps::stream::journal::JournalError;

/// Streaming failed before or outside a job (nothing was moved by this run when these are returned
/// before streaming starts).
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// The port answered, but not like GRBL 1.1.
    #[error("{port} does not answer like a GRBL 1.1 controller (no `[VER:1.1…]` or status report within {timeout:?}); received: {saw:?}")]
    NotGrbl {
        /// The port.
        port: String,
        /// The handshake timeout.
        timeout: Duration,
        /// What came back (first bytes).
        saw: String,
    },
    /// The link failed outside streaming.
    #[error("{port}: {what}")]
    Link {
        /// The port.
        port: String,
        /// What was being done.
        what: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The controller is in alarm and may not be unlocked automatically.
    #[error(
        "{port}: controller is in alarm{detail}; check the machine, home it ($H) or unlock it ($X), or pass --unlock"
    )]
    InAlarm {
        /// The port.
        port: String,
        /// What is known about the alarm.
        detail: String,
    },
    /// The controller did not reach an expected state in time.
    #[error("{port}: {what}")]
    Timeout {
        /// The port.
        port: String,
        /// What was awaited.
        what: String,
    },
    /// The check run found errors: nothing was run.
    #[error("{path}: check mode ($C) found {} problem(s), nothing was run:{}", problems.len(), list(problems))]
    CheckFailed {
        /// The program.
        path: PathBuf,
        /// `(line, message)`.
        problems: Vec<(usize, String)>,
    },
    /// The journal cannot be resumed.
    #[error("cannot resume from {journal}: {what}")]
    Resume {
        /// The journal.
        journal: PathBuf,
        /// Why.
        what: String,
    },
    /// Journal I/O or consistency.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// A controller setting does not match what the program was made and simulated for.
    #[error("{port}: {what}; nothing was sent")]
    Setting {
        /// The port.
        port: String,
        /// Which setting, its value, what the program asks and how to set it.
        what: String,
    },
    /// Interrupted by the user before streaming.
    #[error("interrupted before streaming started; nothing was run")]
    Interrupted,
}

fn list(p: &[(usize, String)]) -> String {
    let mut s: String = p.iter().take(10).map(|(l, m)| format!("\n  line {l}: {m}")).collect();
    if p.len() > 10 {
        s += &format!("\n  … and {} more", p.len() - 10);
    }
    s
}
