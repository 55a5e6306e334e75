//! `nelf train` alone: the same subcommands as the `nelf` binary's, without the
//! viewer and wgpu, so that a build with `--features cuda` is small enough to carry
//! to a GPU machine.
//!
//! ```text
//! cargo build --release -p nelf-train --features cuda --example nelf_train
//! nelf_train data -o DATA --heads 400 && nelf_train run --data DATA -o RUN
//! ```

use clap::Parser;

/// Train the NeLF network on path-traced ground truth.
#[derive(Debug, Parser)]
#[command(name = "nelf_train", version, about)]
struct Cli {
    #[command(flatten)]
    args: nelf_train::cli::TrainArgs,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cli = Cli::parse();
    if !nelf_field::cpu::keep_freed_memory() {
        eprintln!("note: the allocator kept its defaults (not glibc): CPU training runs slower");
    }
    nelf_train::cli::run(&cli.args)?;
    Ok(())
}
