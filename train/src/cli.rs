//! The `nelf train` subcommands, shared by the `nelf` binary and the small
//! `nelf_train` example binary (no viewer, no wgpu: what a GPU machine runs, built
//! with `--features cuda`). `data` renders (or resumes) a dataset of training
//! triplets; `run` trains (or resumes training) on one; `eval` scores a network on
//! a dataset's held-out heads with 2–5 source views; `reset-density` repairs a run
//! whose density saturated.

use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressStyle};

use crate::TrainConfig;
use crate::data::{DataConfig, generate_heads};
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
    /// Score a network (default: the shipped one) on a dataset's held-out heads at
    /// their novel-light views, with 2, 3, 4 and 5 source views (the paper's Table 3),
    /// beside the flat-colour baseline.
    Eval(EvalArgs),
    /// Re-initialise the density heads' output layers of a run's checkpoint (weights
    /// scaled down, bias at a small σ, their Adam moments zeroed; the step and every
    /// other tensor kept): for a run whose density saturated inside the visual hull,
    /// where no loss has a gradient left to carve it.
    ResetDensity(ResetDensityArgs),
}

/// Options of `nelf train reset-density`.
#[derive(Debug, clap::Args)]
pub struct ResetDensityArgs {
    /// Run folder (`nelf train run -o`) whose checkpoint is rewritten in place.
    #[arg(long)]
    pub run: PathBuf,
    /// Density the reset heads give everywhere at first, 1/mm (0.05/mm: a 12.5 mm
    /// coarse step lets ~46 % through).
    #[arg(long, default_value_t = 0.05)]
    pub sigma_per_mm: f64,
    /// Factor on the output layers' weights (keeps what the features say, scaled
    /// down so that σ stays near `--sigma-per-mm` at first).
    #[arg(long, default_value_t = 0.05)]
    pub weight_scale: f64,
}

/// Options of `nelf train eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Dataset folder (`nelf train data`); its held-out heads are scored.
    #[arg(long, default_value = "out/train-data")]
    pub data: PathBuf,
    /// Weights to score (default: the shipped network, models/nelf-small.safetensors).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Source-view counts, one table row each.
    #[arg(long, value_delimiter = ',', default_values_t = [2usize, 3, 4, 5])]
    pub views: Vec<usize>,
    /// Held-out heads to score (the first ones).
    #[arg(long, default_value_t = 8)]
    pub heads: usize,
    /// Image side the heads are scored at (default: the weights' working size).
    #[arg(long)]
    pub image_size: Option<usize>,
    /// Evenly spaced samples per ray (coarse pass).
    #[arg(long, default_value_t = 32)]
    pub coarse_samples: usize,
    /// Importance samples per ray (fine pass).
    #[arg(long, default_value_t = 32)]
    pub fine_samples: usize,
    /// Print the table as JSON.
    #[arg(long)]
    pub json: bool,
    /// Which heads to score: the held-out ones (the honest figure) or training heads
    /// (the gap between the two says how much is generalisation, not fitting).
    #[arg(long, value_enum, default_value_t = EvalSplit::HeldOut)]
    pub split: EvalSplit,
    /// Write the last view count's sheet here (PNG; per head: truth | network | flat colour).
    #[arg(long)]
    pub sheet: Option<PathBuf>,
    /// Fine-tune the network on each head's own source views for this many steps
    /// before scoring it (0: score the network as it is).
    #[arg(long, default_value_t = 0)]
    pub fine_tune_steps: u64,
    /// Rays per fine-tuning step.
    #[arg(long, default_value_t = 256)]
    pub fine_tune_rays: usize,
    /// Adam step size of the fine-tuning (MLPs and encoder).
    #[arg(long, default_value_t = 1e-4)]
    pub fine_tune_lr: f64,
    /// Fine-tune by rendering each step's view from the other source views only
    /// (default: from all of them; measured worse, train/README.md).
    #[arg(long)]
    pub fine_tune_leave_one_out: bool,
    /// The Lambertian shading prior (`nelf_field::prior`, as `nelf bake` mixes it in)
    /// of the source-normalised column: its density-gradient step, mm (0: the network's
    /// own normalised transport, no prior).
    #[arg(long, default_value_t = nelf_field::prior::DEFAULT_STEP_MM)]
    pub shading_prior_mm: f32,
    /// The prior's weight against the network's own transport (1: the prior alone).
    #[arg(long, default_value_t = nelf_field::prior::DEFAULT_WEIGHT)]
    pub shading_prior_weight: f32,
}

/// The heads `nelf train eval` scores.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EvalSplit {
    /// Held-out identities under held-out lightings, never trained on.
    HeldOut,
    /// Training heads (a diagnosis, never a figure of merit).
    Train,
}

/// Options of `nelf train data`.
#[derive(Debug, clap::Args)]
pub struct DataArgs {
    /// Dataset folder (created; a rerun with the same settings resumes it).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Write only the heads with these ids (`8-15`, or one id): a shard of a batch
    /// (`nelf batch plan train-data`); the dataset's settings are the same for every
    /// shard, and together the shards write what one whole run writes.
    #[arg(long, value_parser = parse_head_range)]
    pub only_heads: Option<std::ops::RangeInclusive<u32>>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub config: DataConfig,
}

/// `A-B` or `A` as an inclusive range of head ids.
fn parse_head_range(text: &str) -> Result<std::ops::RangeInclusive<u32>, String> {
    let number = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|_| format!("{text:?} is not a head id range like 8-15"))
    };
    let (first, last) = match text.split_once('-') {
        Some((a, b)) => (number(a)?, number(b)?),
        None => (number(text)?, number(text)?),
    };
    if last < first {
        return Err(format!("{text:?}: the range ends before it starts"));
    }
    Ok(first..=last)
}

/// Runs a `nelf train` subcommand, printing a summary.
pub fn run(args: &TrainArgs) -> Result<(), TrainError> {
    match &args.command {
        TrainCommand::Data(data) => run_data(data),
        TrainCommand::Run(config) => run_training(config),
        TrainCommand::Eval(eval) => run_eval(eval),
        TrainCommand::ResetDensity(reset) => {
            let done =
                crate::trainer::reset_density_heads(&reset.run, reset.sigma_per_mm, reset.weight_scale)?;
            println!(
                "{}: step {}; reset {} (σ {} /mm, weights × {})",
                reset.run.display(),
                done.step,
                done.layers.join(", "),
                reset.sigma_per_mm,
                reset.weight_scale
            );
            Ok(())
        }
    }
}

fn run_eval(args: &EvalArgs) -> Result<(), TrainError> {
    let device = nelf_field::default_device();
    let nelf_config = nelf_field::NelfConfig {
        coarse_samples: args.coarse_samples,
        fine_samples: args.fine_samples,
        ..nelf_field::NelfConfig::for_device(&device)
    };
    let (model, name) = nelf_field::shipped::load_or_shipped(args.weights.as_deref(), nelf_config, &device)?;
    let image_size = args.image_size.or(model.working_image_size()).ok_or_else(|| {
        TrainError::Settings(format!(
            "{name} does not say what image size it was trained at: give --image-size"
        ))
    })?;
    let config = TrainConfig {
        image_size,
        coarse_samples: args.coarse_samples,
        fine_samples: args.fine_samples,
        ..TrainConfig::default()
    };
    let dataset = crate::data::Dataset::open(&args.data)?;
    let (ids, split_name) = match args.split {
        EvalSplit::HeldOut => (dataset.val_ids(), "held-out"),
        EvalSplit::Train => (dataset.train_ids(), "training"),
    };
    let ids: Vec<u32> = ids.into_iter().take(args.heads).collect();
    let heads = crate::trainer::prepare_heads(&dataset, &ids, image_size, model.source_relative_light())?;
    let bytes = match &args.weights {
        Some(path) => std::borrow::Cow::Owned(nelf_field::model::read_safetensors_bytes(path)?),
        None => std::borrow::Cow::Borrowed(nelf_field::shipped::SHIPPED_WEIGHTS),
    };
    let origin = PathBuf::from(&name);
    let fine_tune_from = (args.fine_tune_steps > 0).then(|| crate::eval::FineTuneFrom {
        bytes: &bytes,
        origin: &origin,
        tune: crate::finetune::FineTuneConfig {
            steps: args.fine_tune_steps,
            rays: args.fine_tune_rays,
            lr_mlp: args.fine_tune_lr,
            lr_encoder: args.fine_tune_lr,
            leave_one_out: args.fine_tune_leave_one_out,
            ..crate::finetune::FineTuneConfig::default()
        },
    });
    let rows = crate::eval::view_count_table(
        &model,
        &heads,
        &config,
        &args.views,
        args.sheet.as_deref(),
        fine_tune_from.as_ref(),
        nelf_field::prior::ShadingPrior::from_step_mm(args.shading_prior_mm, args.shading_prior_weight),
    )?;
    if args.json {
        let text = serde_json::to_string_pretty(&serde_json::json!({
            "weights": name,
            "data": args.data,
            "image_size": image_size,
            "rows": rows,
        }))
        .map_err(|e| TrainError::Settings(e.to_string()))?;
        println!("{text}");
        return Ok(());
    }
    println!(
        "{name} on {} {split_name} heads of {} at {image_size}², novel-light views, 8-bit sRGB:",
        heads.len(),
        args.data.display()
    );
    println!(
        "  views   PSNR dB   fg PSNR dB   SSIM     | flat colour: PSNR dB   fg PSNR dB   SSIM     \
         | source-view calibrated: PSNR dB   fg PSNR dB   SSIM     median gain \
         | source-normalised + prior: PSNR dB   fg PSNR dB   SSIM"
    );
    for r in &rows {
        println!(
            "  {:>5}   {:>7.2}   {:>10.2}   {:.4}   |              {:>7.2}   {:>10.2}   {:.4}   \
             |                         {:>7.2}   {:>10.2}   {:.4}   {:.3}       \
             |                            {:>7.2}   {:>10.2}   {:.4}",
            r.views,
            r.psnr,
            r.foreground_psnr,
            r.ssim,
            r.flat_psnr,
            r.flat_foreground_psnr,
            r.flat_ssim,
            r.calibrated_psnr,
            r.calibrated_foreground_psnr,
            r.calibrated_ssim,
            r.median_gain,
            r.normalised_psnr,
            r.normalised_foreground_psnr,
            r.normalised_ssim
        );
    }
    Ok(())
}

fn run_data(args: &DataArgs) -> Result<(), TrainError> {
    let progress = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    let report = generate_heads(&args.out, &args.config, args.only_heads.as_ref(), &progress)?;
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
