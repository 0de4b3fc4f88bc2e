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
pub mod emulate;
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
