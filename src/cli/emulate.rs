//! `brdfmill emulate` (being built: see issue "Streaming to a GRBL mill").

/// Arguments of `brdfmill emulate`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_a: &Args) -> anyhow::Result<()> {
    anyhow::bail!("`brdfmill emulate` is not available in this build yet")
}
