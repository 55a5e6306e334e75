//! `nelf inspect FILE`: placeholder replaced by the format work.

use std::path::PathBuf;

/// Options of `nelf inspect`.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The .nelf file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    anyhow::bail!("{}: reader not written yet", args.file.display())
}
