//! `nelf inspect FILE [--json]`: verifies a `.nelf` file (every checksum and value)
//! and prints its header, sections with stored and decoded sizes, counts, bounding
//! box and metadata. The work is `nelf_format::inspect`.

use std::path::PathBuf;

use anyhow::Context;

/// Options of `nelf inspect`.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The .nelf file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `nelf inspect`.
pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    let report = nelf_format::inspect::inspect(&args.file)
        .with_context(|| format!("cannot inspect {}", args.file.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    Ok(())
}
