//! One module per subcommand: its arguments (with units in the help) and its thin driver.

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
