//! `brdfmill simulate` (being built: see issue "Cut simulation").

/// Arguments of `brdfmill simulate`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_a: &Args) -> anyhow::Result<()> {
    anyhow::bail!("`brdfmill simulate` is not available in this build yet")
}
