//! `brdfmill stream` (being built: see issue "Streaming to a GRBL mill").

/// Arguments of `brdfmill stream`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_a: &Args) -> anyhow::Result<()> {
    anyhow::bail!("`brdfmill stream` is not available in this build yet")
}
