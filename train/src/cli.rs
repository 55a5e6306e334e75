//! The `nelf train` subcommands, shared by the `nelf` binary and the small
//! `nelf_train` example binary (no viewer, no wgpu: what a GPU machine runs, built
//! with `--features cuda`). `data` renders (or resumes) a dataset of training
//! triplets; `run` trains (or resumes training) on one.

use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressStyle};

use crate::TrainConfig;
use crate::data::{DataConfig, generate};
use crate::error::TrainError;

/// Options of `nelf train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    #[command(subcommand)]
    pub command: TrainCommand,
}

/// Train subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum TrainCommand {
    /// Render a dataset of training triplets (source views, a self-rotation and a
    /// novel-light target with depth and alpha, distillation points) with the path
    /// tracer; rerunning with the same settings resumes.
    Data(DataArgs),
    /// Train the network on a dataset (resumes from the run folder's checkpoint;
    /// checkpoints every few minutes; validation on held-out heads in
    /// validation.csv; the network alone in weights.safetensors).
    Run(TrainConfig),
}

/// Options of `nelf train data`.
#[derive(Debug, clap::Args)]
pub struct DataArgs {
    /// Dataset folder (created; a rerun with the same settings resumes it).
    #[arg(short, long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub config: DataConfig,
}

/// Runs a `nelf train` subcommand, printing a summary.
pub fn run(args: &TrainArgs) -> Result<(), TrainError> {
    match &args.command {
        TrainCommand::Data(data) => run_data(data),
        TrainCommand::Run(config) => run_training(config),
    }
}

fn run_data(args: &DataArgs) -> Result<(), TrainError> {
    let progress = ProgressBar::new(0);
    let report = generate(&args.out, &args.config, &progress)?;
    println!(
        "{} heads written, {} skipped (already finished) in {}: {:.1} s per written head, {:.1} s in all",
        report.written.len(),
        report.skipped.len(),
        report.dir.display(),
        report.secs_per_head,
        report.total_secs
    );
    Ok(())
}

fn run_training(config: &TrainConfig) -> Result<(), TrainError> {
    let device = nelf_field::default_device();
    let progress = ProgressBar::new(config.steps).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps, {per_sec}, ETA {eta} · {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    eprintln!("training on {}", nelf_field::device_name(&device));
    let report = crate::run::run(config, &device, &progress)?;
    progress.finish_and_clear();
    println!(
        "step {} ({} now, {:.0} s; {:.0} s in all, {:.3} s/step now): loss {:.4}{}; checkpoint and weights in {}",
        report.step,
        report.steps_now,
        report.secs_now,
        report.train_secs,
        report.secs_now / report.steps_now.max(1) as f64,
        report.last_loss.total,
        report
            .validation
            .map(|v| format!(
                ", validation PSNR {:.2} dB (foreground {:.2} dB; flat colour {:.2}, {:.2} dB)",
                v.psnr, v.foreground_psnr, v.flat_psnr, v.flat_foreground_psnr
            ))
            .unwrap_or_default(),
        config.out.display()
    );
    Ok(())
}
