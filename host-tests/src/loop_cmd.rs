//! `piezo loop`: placeholder being written (issue #2).
use clap::Args;

/// Arguments of `piezo loop`.
#[derive(Args, Debug)]
pub struct LoopArgs {
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Run `piezo loop`.
pub fn run(_a: &LoopArgs) -> anyhow::Result<()> {
    anyhow::bail!("not yet")
}
