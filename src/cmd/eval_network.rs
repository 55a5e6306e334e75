//! `nelf eval network CAPTURE…`: the network against the ground truth on held-out
//! captures (`nelf_eval::network`); every line it reports is printed as it comes.

pub use nelf_eval::NetworkEvalConfig as NetworkEvalArgs;

pub fn run(args: &NetworkEvalArgs) -> anyhow::Result<()> {
    nelf_eval::run_network(args, &mut |line| println!("{line}"))?;
    Ok(())
}
