//! `nelf demo`: capture → bake → relit turntable → comparison with ground truth,
//! on a built-in procedural head (no files needed); then the same capture baked with
//! the shipped NeLF network, and from its photographs by reconstruction, each scored
//! at the same targets beside the ground-truth bake (`nelf_pipeline::run_demo`).

use std::path::PathBuf;

use anyhow::Context;
use nelf_bake::eval::ViewScore;
use nelf_bake::progress::Progress;
use nelf_pipeline::{DemoConfig, DemoSteps, ImagesBakeDemo, run_demo};

/// Options of `nelf demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(short, long, default_value = "out/demo")]
    pub out: PathBuf,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Skip the step that bakes the capture with the shipped network.
    #[arg(long)]
    pub no_network: bool,
    /// Skip the step that bakes the capture from its photographs by reconstruction.
    #[arg(long)]
    pub no_photos: bool,
    #[command(flatten)]
    pub config: DemoConfig,
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let progress = if args.quiet {
        Progress::hidden()
    } else {
        Progress::stderr()
    };
    let steps = DemoSteps {
        network: !args.no_network,
        photos: !args.no_photos,
    };
    let run = run_demo(&args.config, &args.out, progress, steps)
        .with_context(|| format!("running the demo into {}", args.out.display()))?;
    let report = &run.report;
    let bake = &report.bake;
    println!(
        "capture    {}  ({:.1} s)",
        report.capture_dir.display(),
        report.capture_secs
    );
    println!(
        "asset      {}  ({} bytes, {} voxels in {} bricks, rank {} keeping {:.4} of the energy, bake {:.1} s)",
        report.asset.display(),
        bake.file_size,
        bake.voxels,
        bake.bricks,
        bake.rank,
        bake.energy_kept,
        report.bake_secs
    );
    for dir in &report.turntables {
        println!("turntable  {}", dir.display());
    }
    println!(
        "           ({:.2} s per frame on the CPU reference renderer)",
        report.turntable_frame_secs
    );
    for (path, score) in report.comparisons.iter().zip(&report.scores) {
        println!(
            "compare    {}  (ground truth | baked | |diff|×4; PSNR {:.2} dB, SSIM {:.4})",
            path.display(),
            score.psnr_db,
            score.ssim
        );
    }
    if let Some(network) = &run.network {
        print_images_bake("network", "bake", "network bake", network, &report.scores);
    }
    if let Some(photos) = &run.photos {
        print_images_bake(
            "photos",
            "reconstruction and bake",
            "photographs' bake",
            photos,
            &report.scores,
        );
    }
    println!("report     {}", report.out_dir.join("demo_report.json").display());
    Ok(())
}

/// One of the demo's bakes from the capture's images: the asset, then each target's
/// comparison beside the ground-truth bake's scores (`truth`).
fn print_images_bake(label: &str, timed: &str, what: &str, bake: &ImagesBakeDemo, truth: &[ViewScore]) {
    println!(
        "{label:<10} {}  ({} bytes, rank {}, {timed} {:.1} s; {})",
        bake.asset.display(),
        bake.bake.file_size,
        bake.bake.rank,
        bake.bake_secs,
        bake.made_by
    );
    for ((path, score), truth) in bake.comparisons.iter().zip(&bake.scores).zip(truth) {
        println!(
            "compare    {}  (ground truth | {what} | |diff|×4; PSNR {:.2} dB, SSIM {:.4}; ground-truth bake {:.2} dB, {:.4})",
            path.display(),
            score.psnr_db,
            score.ssim,
            truth.psnr_db,
            truth.ssim
        );
    }
}
