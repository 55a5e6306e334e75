//! `nelf demo`: capture → bake → relit turntable → comparison with ground truth,
//! on a built-in procedural head (no files needed); then the same capture baked with
//! the shipped NeLF network, and from its photographs by reconstruction, each scored
//! at the same targets beside the ground-truth bake (`nelf_pipeline::run_demo`).

use std::path::PathBuf;

use anyhow::Context;
use nelf_bake::progress::Progress;
use nelf_pipeline::{DemoConfig, DemoSteps, run_demo};

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
        println!(
            "network    {}  ({} bytes, rank {}, bake {:.1} s; {})",
            network.asset.display(),
            network.bake.file_size,
            network.bake.rank,
            network.bake_secs,
            network.weights
        );
        for ((path, score), truth) in network
            .comparisons
            .iter()
            .zip(&network.scores)
            .zip(&report.scores)
        {
            println!(
                "compare    {}  (ground truth | network bake | |diff|×4; PSNR {:.2} dB, SSIM {:.4}; ground-truth bake {:.2} dB, {:.4})",
                path.display(),
                score.psnr_db,
                score.ssim,
                truth.psnr_db,
                truth.ssim
            );
        }
    }
    if let Some(photos) = &run.photos {
        println!(
            "photos     {}  ({} bytes, rank {}, reconstruction and bake {:.1} s; surface and albedo in {})",
            photos.asset.display(),
            photos.bake.file_size,
            photos.bake.rank,
            photos.bake_secs,
            photos.reconstruction.display()
        );
        for ((path, score), truth) in photos.comparisons.iter().zip(&photos.scores).zip(&report.scores) {
            println!(
                "compare    {}  (ground truth | photographs' bake | |diff|×4; PSNR {:.2} dB, SSIM {:.4}; ground-truth bake {:.2} dB, {:.4})",
                path.display(),
                score.psnr_db,
                score.ssim,
                truth.psnr_db,
                truth.ssim
            );
        }
    }
    println!("report     {}", report.out_dir.join("demo_report.json").display());
    Ok(())
}
