//! One module per subcommand: its arguments (with units in the help) and its thin driver.
//!
//! What the subcommands print is progress and summary for a person; the artifacts, `run.json` and the exit
//! code carry the result. So printing never ends a command: `println!`, `print!`, `eprintln!` and
//! `eprint!` are shadowed here by versions that drop a write error (a pipe closed by `| head`, a full disk
//! behind `> file`) instead of panicking as the standard ones do, and the command goes on to finish its
//! work and its files.

/// `println!` that drops a write error (see the module notes).
macro_rules! println {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

/// `print!` that drops a write error (see the module notes; none uses it yet, so that one that does gets it).
#[allow(unused_macros)]
macro_rules! print {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout(), $($t)*);
    }};
}

/// `eprintln!` that drops a write error (see the module notes).
macro_rules! eprintln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

/// `eprint!` that drops a write error (see the module notes; none uses it yet, so that one that does gets it).
#[allow(unused_macros)]
macro_rules! eprint {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stderr(), $($t)*);
    }};
}

pub mod analyze;
pub mod calibrate;
pub mod compare;
pub mod emulate;
pub mod export;
pub mod facets;
pub mod ndf;
pub mod run;
pub mod simulate;
pub mod stream;
pub mod toolpath;

/// Parse `AxB` (either case of x) into two values; the error names the option and the expected form.
pub fn parse_pair<T: std::str::FromStr>(s: &str, option: &str, form: &str) -> anyhow::Result<(T, T)> {
    let (a, b) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| anyhow::anyhow!("{option} `{s}`: expected {form}"))?;
    let parse = |v: &str| {
        v.trim().parse::<T>().map_err(|_| {
            anyhow::anyhow!(
                "{option} `{s}`: `{v}` is not a valid {}",
                if form.contains("mm") { "number" } else { "whole number" }
            )
        })
    };
    Ok((parse(a)?, parse(b)?))
}

/// Refuse, before any work, an output file `path` (given by `option`) that cannot be written: an existing
/// folder, or a path under an existing file.
pub fn check_out_file(option: &str, path: &std::path::Path) -> anyhow::Result<()> {
    if path.is_dir() {
        anyhow::bail!("{option} {}: is a folder; expected the path of a file", path.display());
    }
    under_a_file(option, path)
}

/// Refuse, before any work, an output folder `path` (given by `option`) that cannot be made: an existing
/// file, or a path under one.
pub fn check_out_dir(option: &str, path: &std::path::Path) -> anyhow::Result<()> {
    if path.exists() && !path.is_dir() {
        anyhow::bail!(
            "{option} {}: is a file; expected a folder (made when missing)",
            path.display()
        );
    }
    under_a_file(option, path)
}

/// A path whose existing ancestor is a file cannot be created.
fn under_a_file(option: &str, path: &std::path::Path) -> anyhow::Result<()> {
    if let Some(f) = path.ancestors().skip(1).find(|a| a.is_file()) {
        anyhow::bail!("{option} {}: {} is a file, not a folder", path.display(), f.display());
    }
    Ok(())
}
