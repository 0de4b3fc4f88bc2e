//! File input and output shared by every reader and writer: one error type for a file that cannot be read
//! ([`ReadError`]) and one for a file that cannot be written ([`WriteError`]), and atomic output — every
//! artifact is written to a temporary file beside its destination and renamed into place, so a failure never
//! leaves a half-written file under the final name. Artifacts get the user's usual permissions (`0666` less
//! the umask), not the temporary file's private `0600`.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// An input file could not be opened or read.
#[derive(Debug, thiserror::Error)]
#[error("cannot read {path}")]
pub struct ReadError {
    /// The file.
    pub path: PathBuf,
    /// The underlying I/O error.
    #[source]
    pub source: std::io::Error,
}

/// Read a whole file.
pub fn read(path: &Path) -> Result<Vec<u8>, ReadError> {
    fs::read(path).map_err(|source| ReadError {
        path: path.to_path_buf(),
        source,
    })
}

/// Read a whole text file (UTF-8).
pub fn read_to_string(path: &Path) -> Result<String, ReadError> {
    fs::read_to_string(path).map_err(|source| ReadError {
        path: path.to_path_buf(),
        source,
    })
}

/// An output file could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {path}")]
pub struct WriteError {
    /// The destination that was not written.
    pub path: PathBuf,
    /// The underlying I/O error.
    #[source]
    pub source: std::io::Error,
}

/// Write `bytes` to `path` atomically (temporary file in the same folder, then rename).
///
/// The parent folder is created when missing. On error nothing is left at `path` that was not there before.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Like [`write_atomic`], but the content is produced by `fill` writing into a buffered writer.
pub fn write_atomic_with<F>(path: &Path, fill: F) -> Result<(), WriteError>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    let err = |source| WriteError {
        path: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&dir).map_err(err)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".brdfmill-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // the mode asked for at creation; the kernel applies the umask, as for any file the user creates
        builder.permissions(fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(&dir).map_err(err)?;
    {
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        fill(&mut w).map_err(err)?;
        w.flush().map_err(err)?;
    }
    tmp.as_file().sync_all().map_err(err)?;
    tmp.persist(path).map_err(|e| err(e.error))?;
    Ok(())
}

/// A path as people read it: `a/./b` → `a/b`, `examples/../machines/x.toml` → `machines/x.toml` (lexical
/// only — a `..` after a symbolic link is not resolved; leading `..` are kept).
pub fn tidy(path: &Path) -> std::path::PathBuf {
    use std::path::Component;
    let mut out: Vec<Component> = vec![];
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            c => out.push(c),
        }
    }
    if out.is_empty() {
        ".".into()
    } else {
        out.iter().collect()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn tidy_paths_read_as_people_write_them() {
        use super::tidy;
        use std::path::Path;
        assert_eq!(
            tidy(Path::new("examples/../machines/grbl-3018.toml")),
            Path::new("machines/grbl-3018.toml")
        );
        assert_eq!(tidy(Path::new("./a/./b")), Path::new("a/b"));
        assert_eq!(tidy(Path::new("../x/../y")), Path::new("../y"));
        assert_eq!(tidy(Path::new("/a/b/../../..")), Path::new("/.."));
        assert_eq!(tidy(Path::new("a/..")), Path::new("."));
    }

    use super::*;

    #[cfg(unix)]
    #[test]
    fn artifacts_are_not_private_to_the_owner() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write_atomic(&p, b"x").unwrap();
        let mode = fs::metadata(&p).unwrap().permissions().mode() & 0o777;
        // whatever the umask, the owner can read and write, and a umask that allows it lets others read:
        // the test runner's umask is 022 or 002 here, so group and others can read
        assert_eq!(mode & 0o600, 0o600);
        assert_ne!(mode & 0o044, 0, "mode {mode:o}");
    }

    #[test]
    fn failed_fill_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.json");
        let r = write_atomic_with(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("boom"))
        });
        assert!(r.is_err());
        assert!(!path.exists());
        assert_eq!(
            fs::read_dir(dir.path()).unwrap().count(),
            0,
            "temporary file left behind"
        );
    }

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/out.txt");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
    }
}
