//! `nelf capture …`: make capture folders. `synth` renders a synthetic capture of a
//! mesh (default: a procedural head) with the ground-truth path tracer.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::ProgressBar;
use nelf_scene::synth::{SynthConfig, write_synthetic_capture};

/// Options of `nelf capture`.
#[derive(Debug, clap::Args)]
pub struct CaptureArgs {
    #[command(subcommand)]
    pub command: CaptureCommand,
}

/// Capture subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum CaptureCommand {
    /// Render a synthetic capture (source views, masks, cameras, COLMAP model,
    /// ground-truth lighting, held-aside target views) with the path tracer.
    Synth(SynthArgs),
}

/// Options of `nelf capture synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(short, long, default_value = "out/capture")]
    pub out: PathBuf,
    /// Print the run report as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub config: SynthConfig,
}

pub fn run(args: &CaptureArgs) -> anyhow::Result<()> {
    match &args.command {
        CaptureCommand::Synth(synth) => run_synth(synth),
    }
}

fn run_synth(args: &SynthArgs) -> anyhow::Result<()> {
    let progress = ProgressBar::new(0);
    // synth_config.json names its input files; absolute paths keep it usable from
    // any working directory (a bake of the capture rebuilds the mesh from it).
    let absolute = |p: &std::path::Path| {
        std::path::absolute(p).with_context(|| format!("resolving the path {}", p.display()))
    };
    let mut config = args.config.clone();
    config.mesh = config.mesh.as_deref().map(absolute).transpose()?;
    config.envmap = config.envmap.as_deref().map(absolute).transpose()?;
    config.target_envmap = config
        .target_envmap
        .iter()
        .map(|p| absolute(p))
        .collect::<anyhow::Result<_>>()?;
    let report = write_synthetic_capture(&config, &args.out, &progress)
        .with_context(|| format!("writing a synthetic capture to {}", args.out.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let per_view = report.view_secs.iter().sum::<f64>() / report.view_secs.len().max(1) as f64;
        println!(
            "wrote {} source views and {} target views ({} triangles) to {} in {:.1} s ({:.1} s per view)",
            report.views,
            report.targets,
            report.triangles,
            report.out_dir.display(),
            report.total_secs,
            per_view
        );
        println!("  cameras: {}", report.out_dir.join("cameras.json").display());
        println!("  previews: {}", report.out_dir.join("previews").display());
    }
    Ok(())
}
