//! `nelf demo`: capture → bake → relit turntable → comparison with ground truth,
//! on a built-in procedural head (no files needed); then the same capture baked with
//! the shipped NeLF network (`nelf_field::shipped`), scored at the same targets
//! beside the ground-truth bake.

use std::path::PathBuf;

use std::time::Instant;

use anyhow::Context;
use nelf_bake::demo::{DemoConfig, DemoReport, run_demo, side_by_side};
use nelf_bake::eval::{data_range, read_linear_rgb, score_view};
use nelf_bake::progress::Progress;
use nelf_bake::{BakeConfig, CaptureLoadOptions, ViewChoice, load_capture, write_bake};
use nelf_field::shipped::SHIPPED_WEIGHTS_NAME;
use nelf_format::read_asset;
use nelf_scene::envmap::load_envmap;

/// Options of `nelf demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(short, long, default_value = "out/demo")]
    pub out: PathBuf,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Skip the last step (the capture baked with the shipped network).
    #[arg(long)]
    pub no_network: bool,
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
    if !args.no_network {
        network_step(args, &report, progress)?;
    }
    println!("report     {}", report.out_dir.join("demo_report.json").display());
    Ok(())
}

/// The demo's capture baked with the shipped network (no view-dependent part: the
/// network's transport is evaluated toward the mean camera), scored at the targets
/// beside the ground-truth bake; `demo_network.json` records it.
fn network_step(args: &DemoArgs, report: &DemoReport, progress: Progress) -> anyhow::Result<()> {
    let start = Instant::now();
    let capture = load_capture(&report.capture_dir, &CaptureLoadOptions::default())
        .with_context(|| format!("loading {}", report.capture_dir.display()))?;
    let config = BakeConfig {
        resolution: args.config.resolution,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    };
    let mut output = super::bake::bake_network(&capture, None, &config, progress)
        .context("baking the demo's capture with the shipped network")?;
    let asset_path = report.out_dir.join("head_network.nelf");
    write_bake(&mut output, &config, &asset_path)
        .with_context(|| format!("writing {}", asset_path.display()))?;
    let bake_secs = start.elapsed().as_secs_f64();
    let asset = read_asset(&asset_path).with_context(|| format!("reading {}", asset_path.display()))?;
    println!(
        "network    {}  ({} bytes, rank {}, bake {:.1} s; {})",
        asset_path.display(),
        output.report.file_size,
        output.report.rank,
        bake_secs,
        SHIPPED_WEIGHTS_NAME
    );
    let mut scores = Vec::new();
    if let Some(description) = capture.description() {
        for (target, truth_score) in description.targets.iter().zip(&report.scores) {
            let env = load_envmap(target.envmap_path(&report.capture_dir))?;
            let (_, _, truth) = read_linear_rgb(&target.image_path(&report.capture_dir))?;
            let (score, image) = score_view(&asset, &target.camera, &env, &truth, &target.name)?;
            let path = report
                .out_dir
                .join(format!("compare_network_{}.png", target.name));
            side_by_side(
                &path,
                &target.camera,
                &truth,
                &image.rgb,
                (0.6 / data_range(&truth)).log2(),
            )?;
            println!(
                "compare    {}  (ground truth | network bake | |diff|×4; PSNR {:.2} dB, SSIM {:.4}; ground-truth bake {:.2} dB, {:.4})",
                path.display(),
                score.psnr_db,
                score.ssim,
                truth_score.psnr_db,
                truth_score.ssim
            );
            scores.push(score);
        }
    }
    let summary = serde_json::json!({
        "weights": SHIPPED_WEIGHTS_NAME,
        "asset": asset_path,
        "bake": output.report,
        "bake_secs": bake_secs,
        "scores": scores,
        "ground_truth_bake_scores": report.scores,
    });
    let path = report.out_dir.join("demo_network.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
