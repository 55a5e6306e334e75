//! `nelf train …`: training the NeLF network on our own path-traced ground truth
//! (the subcommands live in `nelf_train::cli`, shared with its small GPU binary).

use anyhow::Context;
pub use nelf_train::cli::TrainArgs;
use nelf_train::cli::TrainCommand;

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let what = match &args.command {
        TrainCommand::Data(data) => format!("writing the training dataset {}", data.out.display()),
        TrainCommand::Run(config) => format!("training into {}", config.out.display()),
    };
    nelf_train::cli::run(args).context(what)
}
