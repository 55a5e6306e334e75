//! `nelf demo`: capture → bake → relit turntable → comparison with ground truth,
//! on a built-in procedural head (no files needed).

use std::path::PathBuf;

use anyhow::Context;
use nelf_bake::demo::{DemoConfig, run_demo};
use nelf_bake::progress::Progress;

/// Options of `nelf demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(short, long, default_value = "out/demo")]
    pub out: PathBuf,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub config: DemoConfig,
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let progress = if args.quiet {
        Progress::hidden()
    } else {
        Progress::stderr()
    };
    let report = run_demo(&args.config, &args.out, progress)
        .with_context(|| format!("running the demo into {}", args.out.display()))?;
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
    println!("report     {}", report.out_dir.join("demo_report.json").display());
    Ok(())
}
