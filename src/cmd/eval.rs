//! `nelf eval pareto|stability|network`: speed charted against accuracy, and accuracy
//! where methods fail (`nelf-eval`; both write report.html, a CSV and a JSON beside
//! it); the network against the ground truth on held-out captures.

use anyhow::Context;
use nelf_eval::{ParetoConfig, StabilityConfig, run_pareto, run_stability};

/// Options of `nelf eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    #[command(subcommand)]
    pub command: EvalCommand,
}

/// Evaluation subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum EvalCommand {
    /// Sweep resolution × rank × encoding: PSNR / SSIM / ꟻLIP at held-aside views
    /// against bytes, bake seconds, CPU and GPU frame times; Pareto fronts.
    Pareto(ParetoConfig),
    /// Accuracy along the axes where methods fail: views, spread, target angle,
    /// light sharpness, rank, pose noise, mask errors, mesh defects.
    Stability(StabilityConfig),
    /// The NeLF network (the shipped one, or --weights) on captures with ground
    /// truth: the network itself, its bake and the ground-truth bake at the held-aside
    /// targets, 8-bit sRGB, beside the flat-colour baseline.
    Network(super::eval_network::NetworkEvalArgs),
}

pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    match &args.command {
        EvalCommand::Network(network) => super::eval_network::run(network)?,
        EvalCommand::Pareto(config) => {
            let results = run_pareto(config)
                .with_context(|| format!("nelf eval pareto into {}", config.out.display()))?;
            println!(
                "{} settings of {} in {:.1} s; Pareto front (PSNR vs bytes):",
                results.rows.len(),
                results.input,
                results.run_secs
            );
            for row in results.rows.iter().filter(|r| r.front_bytes) {
                println!(
                    "  {:<16} {:>10} bytes  {:.2} dB (fg {:.2}, baseline {:.2})  ꟻLIP {:.4}",
                    row.id,
                    row.file_bytes,
                    row.scores.psnr_db,
                    row.scores.psnr_fg_db,
                    row.scores.baseline_psnr_db,
                    row.scores.flip
                );
            }
            println!("report     {}", config.out.join("report.html").display());
        }
        EvalCommand::Stability(config) => {
            let results = run_stability(config)
                .with_context(|| format!("nelf eval stability into {}", config.out.display()))?;
            println!(
                "{} points of {} in {:.1} s; below {} dB:",
                results.points.len(),
                results.input,
                results.run_secs,
                config.threshold_db
            );
            for (axis, first) in &results.breaks {
                println!("  {axis:<18} {}", first.as_deref().unwrap_or("never"));
            }
            println!("report     {}", config.out.join("report.html").display());
        }
    }
    Ok(())
}
