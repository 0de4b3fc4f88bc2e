//! The job journal: an append-only JSON Lines log of what was sent, what GRBL answered and what is known
//! to have executed, so that a job cut off by a fault resumes at the earliest line that may not have run.
//!
//! **Why append, not atomic rewrite:** the journal grows by one record per event, thousands per minute; a
//! rewrite-and-rename per event would be quadratic. Every record is one `write` of a complete line
//! (`O_APPEND`), so a crash of this process loses nothing already written and can at worst leave a torn
//! last line, which [`Journal::load`] ignores. `fsync` runs at most every [`SYNC_INTERVAL`] and always at a
//! stop, a resume and the end, which bounds what an operating-system crash could lose.
//!
//! A `sent` record is written **before** the line goes out, so "sent" means "may have reached the
//! controller": a line the journal does not list as sent cannot have run.

use std::collections::BTreeSet;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

/// Journal format version.
pub const VERSION: u32 = 1;

/// Longest time between two `fsync`s of the journal while streaming.
pub const SYNC_INTERVAL: Duration = Duration::from_millis(250);

/// One journal record (one JSON object per line, tagged by `event`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Record {
    /// A run started (the first, or a resume).
    Start {
        /// [`VERSION`].
        version: u32,
        /// The program file.
        program: String,
        /// FNV-1a of the program bytes.
        fingerprint: u64,
        /// Lines in the program file.
        lines: usize,
        /// `N` numbers were added to the blocks.
        numbered: bool,
        /// First program line of this run (1 for a fresh run).
        from_line: usize,
        /// Work position (mm) when the run started, as the controller reported it: where the tool is
        /// before the first line of a fresh run, which the program model cannot know.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        position_mm: Option<[f64; 3]>,
        /// The controller's work offset `WCO` (mm) when the run started: a controller that restarted, or
        /// whose offsets were changed, reports another one, and the program's coordinates no longer mean
        /// the same place.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        wco_mm: Option<[f64; 3]>,
    },
    /// The line may have been sent (written before the bytes go out).
    Sent {
        /// Program line.
        line: usize,
    },
    /// GRBL answered `ok`: planned, not yet executed.
    Ok {
        /// Program line.
        line: usize,
    },
    /// GRBL answered `error:N`: the line was rejected and did not run.
    Error {
        /// Program line.
        line: usize,
        /// GRBL error code.
        code: u16,
    },
    /// Lines `from..=to` are known to have executed completely (from `Ln`, an idle controller, or the
    /// position at a stop).
    Executed {
        /// First line.
        from: usize,
        /// Last line.
        to: usize,
    },
    /// The line was executing when motion stopped: it ran from its start up to `at_mm` (work coordinates).
    Partial {
        /// Program line.
        line: usize,
        /// Where the tool stopped on it, mm.
        at_mm: [f64; 3],
    },
    /// The stop position lay on the path more than once: the `executed`/`partial` records that follow are
    /// the earliest consistent explanation, and this says why.
    Ambiguous {
        /// What was ambiguous.
        message: String,
    },
    /// The run stopped before the end.
    Stop {
        /// Why (`error`, `alarm`, `user`, `disconnect`, `protocol`).
        reason: String,
        /// The program line concerned, when there is one.
        line: Option<usize>,
        /// The controller's message or the fault.
        message: String,
        /// What executed is known exactly (the stop was located).
        located: bool,
        /// The machine position is trustworthy (motion had stopped before any reset).
        position_retained: bool,
    },
    /// The user resumed past a line GRBL rejected (`--skip-line`): it will never run, on purpose.
    Skip {
        /// Program line.
        line: usize,
        /// The `error:N` GRBL answered it with.
        code: u16,
    },
    /// Every line executed.
    Complete,
}

/// The journal could not be written or read, or is not consistent.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// I/O on the journal file.
    #[error("journal {path}")]
    Io {
        /// The journal.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A fresh run would overwrite a journal.
    #[error("journal {path} already exists: resume with --resume, or move it away to start over")]
    Exists {
        /// The journal.
        path: PathBuf,
    },
    /// A record contradicts the ones before it.
    #[error("journal {path}:{record}: {what}")]
    Inconsistent {
        /// The journal.
        path: PathBuf,
        /// 1-based record (line) number.
        record: usize,
        /// What is wrong.
        what: String,
    },
}

/// What a journal says, replayed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JournalState {
    /// Fingerprint of the program it was written for.
    pub fingerprint: u64,
    /// Lines of that program.
    pub lines: usize,
    /// Whether blocks were numbered.
    pub numbered: bool,
    /// Lines that may have been sent.
    pub sent: BTreeSet<usize>,
    /// Lines answered `ok`.
    pub ok: BTreeSet<usize>,
    /// Lines answered `error:N`, with the code.
    pub errors: Vec<(usize, u16)>,
    /// Lines known executed.
    pub executed: BTreeSet<usize>,
    /// The line cut mid-way at the last stop, and where.
    pub partial: Option<(usize, [f64; 3])>,
    /// The last stop record, if the last run stopped.
    pub stop: Option<Record>,
    /// The job completed.
    pub complete: bool,
    /// Number of runs (start records).
    pub runs: usize,
    /// Work position before the first run's first line (from its start record), if reported.
    pub origin: Option<[f64; 3]>,
    /// The work offset the controller reported when the job's latest run started, if recorded.
    pub wco: Option<[f64; 3]>,
    /// Rejected lines the user chose to skip, with GRBL's code.
    pub skipped: Vec<(usize, u16)>,
}

/// An open journal, appending.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
    last_sync: Instant,
}

impl JournalState {
    /// Whether the user chose to leave line `n` out (`--skip-line`, a `skip` record).
    pub fn is_skipped(&self, n: usize) -> bool {
        self.skipped.iter().any(|s| s.0 == n)
    }

    /// The code GRBL rejected line `n` with, if it did and never accepted it later.
    pub fn rejection(&self, n: usize) -> Option<u16> {
        if self.ok.contains(&n) {
            return None;
        }
        self.errors.iter().find(|(l, _)| *l == n).map(|e| e.1)
    }
}

impl Journal {
    /// Create a new journal; refuses to replace an existing one.
    pub fn create(path: &Path) -> Result<Journal, JournalError> {
        let file = OpenOptions::new()
            .append(true)
            .create_new(true)
            .open(path)
            .map_err(|source| match source.kind() {
                std::io::ErrorKind::AlreadyExists => JournalError::Exists {
                    path: path.to_path_buf(),
                },
                _ => JournalError::Io {
                    path: path.to_path_buf(),
                    source,
                },
            })?;
        Ok(Journal {
            path: path.to_path_buf(),
            file,
            last_sync: Instant::now(),
        })
    }

    /// Open an existing journal to append to it (a resume).
    pub fn append(path: &Path) -> Result<Journal, JournalError> {
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|source| JournalError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(Journal {
            path: path.to_path_buf(),
            file,
            last_sync: Instant::now(),
        })
    }

    /// The journal file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Append one record as one complete line; `fsync` if the last one is older than [`SYNC_INTERVAL`].
    pub fn record(&mut self, r: &Record) -> Result<(), JournalError> {
        let mut line = serde_json::to_string(r).expect("journal records always serialise");
        line.push('\n');
        self.file.write_all(line.as_bytes()).map_err(|source| self.io(source))?;
        if self.last_sync.elapsed() >= SYNC_INTERVAL {
            self.sync()?;
        }
        Ok(())
    }

    /// Append a record and `fsync` now (stops, resumes, the end).
    pub fn record_synced(&mut self, r: &Record) -> Result<(), JournalError> {
        self.record(r)?;
        self.sync()
    }

    /// `fsync` the journal.
    pub fn sync(&mut self) -> Result<(), JournalError> {
        self.file.sync_data().map_err(|source| self.io(source))?;
        self.last_sync = Instant::now();
        Ok(())
    }

    fn io(&self, source: std::io::Error) -> JournalError {
        JournalError::Io {
            path: self.path.clone(),
            source,
        }
    }

    /// Read and replay a journal, checking that it is consistent: answers only for sent lines and in
    /// sending order, nothing executed that was never sent or was rejected. A torn last line (a crash in
    /// the middle of a write) is ignored.
    pub fn load(path: &Path) -> Result<JournalState, JournalError> {
        let text = std::fs::read_to_string(path).map_err(|source| JournalError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut replay = Replay::default();
        let all: Vec<&str> = text.lines().collect();
        for (i, l) in all.iter().enumerate() {
            let bad = |what: String| JournalError::Inconsistent {
                path: path.to_path_buf(),
                record: i + 1,
                what,
            };
            let r: Record = match serde_json::from_str(l) {
                Ok(r) => r,
                Err(_) if i + 1 == all.len() && !text.ends_with('\n') => break,
                Err(e) => return Err(bad(format!("not a journal record: {e}"))),
            };
            replay.apply(&r).map_err(bad)?;
        }
        Ok(replay.st)
    }
}

/// A journal being replayed: the state so far and the lines sent but not yet answered, oldest first.
#[derive(Debug, Default)]
struct Replay {
    st: JournalState,
    in_flight: std::collections::VecDeque<usize>,
}

impl Replay {
    /// Apply one record; `Err` says how it contradicts the records before it.
    fn apply(&mut self, r: &Record) -> Result<(), String> {
        let st = &mut self.st;
        match r {
            Record::Start {
                version,
                fingerprint,
                lines,
                numbered,
                position_mm,
                wco_mm,
                ..
            } => {
                if *version != VERSION {
                    return Err(format!("version {version}, this build reads {VERSION}"));
                }
                if st.runs > 0 && *fingerprint != st.fingerprint {
                    return Err("a later run is for a different program".into());
                }
                st.fingerprint = *fingerprint;
                st.lines = *lines;
                st.numbered = *numbered;
                if st.runs == 0 {
                    st.origin = *position_mm;
                }
                if wco_mm.is_some() {
                    st.wco = *wco_mm;
                }
                st.runs += 1;
                st.stop = None;
                // A new connection: whatever was in flight before was either flushed or drained.
                self.in_flight.clear();
            }
            Record::Sent { line } => {
                if st.runs == 0 {
                    return Err("record before the start record".into());
                }
                if *line == 0 || *line > st.lines {
                    return Err(format!("line {line} is not in the program"));
                }
                st.sent.insert(*line);
                self.in_flight.push_back(*line);
            }
            Record::Ok { line } | Record::Error { line, .. } => {
                if self.in_flight.pop_front() != Some(*line) {
                    return Err(format!(
                        "answer for line {line}, which is not the oldest line in flight"
                    ));
                }
                if let Record::Error { code, .. } = r {
                    st.errors.push((*line, *code));
                } else {
                    st.ok.insert(*line);
                }
            }
            Record::Executed { from, to } => self.executed(*from, *to)?,
            Record::Partial { line, at_mm } => {
                if !st.sent.contains(line) {
                    return Err(format!("line {line} partly executed but never sent"));
                }
                st.partial = Some((*line, *at_mm));
            }
            Record::Stop { .. } => {
                st.stop = Some(r.clone());
                self.in_flight.clear();
            }
            Record::Complete => st.complete = true,
            Record::Ambiguous { .. } => {}
            Record::Skip { line, code } => {
                if !st.errors.iter().any(|e| e == &(*line, *code)) {
                    return Err(format!(
                        "line {line} skipped, but GRBL never rejected it with error:{code}"
                    ));
                }
                st.skipped.push((*line, *code));
            }
        }
        Ok(())
    }

    /// Lines `from..=to` executed: each must have been sent and not only rejected.
    fn executed(&mut self, from: usize, to: usize) -> Result<(), String> {
        let st = &mut self.st;
        for n in from..=to {
            if !st.sent.contains(&n) {
                return Err(format!("line {n} executed but never sent"));
            }
            if st.errors.iter().any(|&(l, _)| l == n) && !st.ok.contains(&n) {
                return Err(format!("line {n} executed but was rejected"));
            }
            st.executed.insert(n);
        }
        if matches!(st.partial, Some((p, _)) if p >= from && p <= to) {
            st.partial = None;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start(lines: usize) -> Record {
        Record::Start {
            version: VERSION,
            program: "p.nc".into(),
            fingerprint: 7,
            lines,
            numbered: true,
            from_line: 1,
            position_mm: None,
            wco_mm: None,
        }
    }

    #[test]
    fn replays_a_stopped_run() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("j.jsonl");
        let mut j = Journal::create(&p).unwrap();
        for r in [
            start(5),
            Record::Sent { line: 1 },
            Record::Sent { line: 2 },
            Record::Ok { line: 1 },
            Record::Executed { from: 1, to: 1 },
            Record::Sent { line: 3 },
            Record::Ok { line: 2 },
            Record::Partial {
                line: 2,
                at_mm: [1.0, 0.0, 0.0],
            },
            Record::Stop {
                reason: "user".into(),
                line: None,
                message: "Ctrl-C".into(),
                located: true,
                position_retained: true,
            },
        ] {
            j.record(&r).unwrap();
        }
        j.sync().unwrap();
        let st = Journal::load(&p).unwrap();
        assert_eq!(st.executed, BTreeSet::from([1]));
        assert_eq!(st.partial, Some((2, [1.0, 0.0, 0.0])));
        assert!(st.sent.contains(&3) && !st.ok.contains(&3));
        assert!(matches!(Journal::create(&p), Err(JournalError::Exists { .. })));
    }

    #[test]
    fn refuses_answers_out_of_order_and_ignores_a_torn_tail() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("j.jsonl");
        let good = [start(3), Record::Sent { line: 1 }, Record::Sent { line: 2 }];
        let mut text: String = good.iter().map(|r| serde_json::to_string(r).unwrap() + "\n").collect();
        std::fs::write(&p, format!("{text}{{\"event\":\"ok\",\"li")).unwrap();
        assert_eq!(Journal::load(&p).unwrap().sent.len(), 2);
        text.push_str(&(serde_json::to_string(&Record::Ok { line: 2 }).unwrap() + "\n"));
        std::fs::write(&p, &text).unwrap();
        let e = Journal::load(&p).unwrap_err().to_string();
        assert!(e.contains(":4:") && e.contains("oldest"), "{e}");
    }
}
