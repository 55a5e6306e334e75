//! `nelf bake …`: turn a capture or a mesh into a `.nelf` asset. `capture DIR` bakes,
//! over the visual hull of the capture's masks, either its ground-truth field (a
//! mesh: `--mesh`, or the `synth_config.json` of a synthetic capture) or the NeLF
//! network's field from the capture's own images (the shipped network, or
//! `--weights`); `--source` chooses, and by default a capture with no ground truth
//! gets the network (`nelf_pipeline::bake_capture_dir`). `mesh FILE` bakes a mesh
//! directly (its occupancy is the hull; `nelf_bake::bake_mesh`).

use std::path::PathBuf;

use anyhow::Context;
use nelf_bake::{BakeOutput, Progress, bake_mesh};
use nelf_pipeline::photo::write_reconstruction;
use nelf_pipeline::summary::{describe_bake, describe_choice};
use nelf_pipeline::{CaptureBakeOptions, PipelineConfig, bake_capture_dir, write_bake};
use nelf_scene::mesh_io::{LoadOptions, load_mesh};

/// Options of `nelf bake`.
#[derive(Debug, clap::Args)]
pub struct BakeArgs {
    #[command(subcommand)]
    pub command: BakeCommand,
}

/// Bake subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum BakeCommand {
    /// Bake a capture folder (cameras.json or a COLMAP text model, images, masks):
    /// visual hull, sparse bricks, the ground-truth field, PCA with a per-scene rank.
    Capture(CaptureBakeArgs),
    /// Bake a mesh (.obj or .off) directly into a relightable asset, no network.
    Mesh(MeshBakeArgs),
}

/// Output options shared by both subcommands.
#[derive(Debug, clap::Args)]
pub struct OutputArgs {
    /// The asset to write (its settings and report go beside it, `<asset>.bake.json`).
    #[arg(short, long)]
    pub out: PathBuf,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Options of `nelf bake capture`.
#[derive(Debug, clap::Args)]
pub struct CaptureBakeArgs {
    #[command(flatten)]
    pub capture: CaptureBakeOptions,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// Options of `nelf bake mesh`.
#[derive(Debug, clap::Args)]
pub struct MeshBakeArgs {
    /// The mesh (.obj or .off).
    pub mesh: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Scale the mesh to this height in metres and centre it at the origin (0 = keep the file's units and placement).
    #[arg(long, default_value_t = 0.23)]
    pub height_m: f32,
    /// Turn the mesh about +y by this many degrees so that it faces +z (90 for the shared head.off).
    #[arg(long, default_value_t = 0.0)]
    pub rotate_y_deg: f32,
    /// Every setting of the bake (the network's are accepted and recorded, not read).
    #[command(flatten)]
    pub config: PipelineConfig,
}

pub fn run(args: &BakeArgs) -> anyhow::Result<()> {
    match &args.command {
        BakeCommand::Capture(a) => run_capture(a),
        BakeCommand::Mesh(a) => run_mesh(a),
    }
}

fn progress(output: &OutputArgs) -> Progress {
    if output.quiet {
        Progress::hidden()
    } else {
        Progress::stderr()
    }
}

fn run_capture(args: &CaptureBakeArgs) -> anyhow::Result<()> {
    let mut baked = bake_capture_dir(&args.capture, progress(&args.output))?;
    if let Some(choice) = baked.choice.as_ref().filter(|_| !args.output.json) {
        print!("{}", describe_choice(choice));
    }
    finish(&mut baked.output, &args.capture.config, &args.output)?;
    if let Some(reconstruction) = &baked.reconstruction {
        let dir = args.output.out.with_extension("reconstruction");
        write_reconstruction(reconstruction, &dir)
            .with_context(|| format!("writing the reconstruction to {}", dir.display()))?;
        if !args.output.json {
            println!("reconstruction: {}", dir.display());
        }
    }
    Ok(())
}

fn run_mesh(args: &MeshBakeArgs) -> anyhow::Result<()> {
    let options = LoadOptions {
        fit_height_m: (args.height_m > 0.0).then_some(args.height_m),
        rotate_y_deg: args.rotate_y_deg,
        ..LoadOptions::default()
    };
    let mesh = load_mesh(&args.mesh, &options).with_context(|| format!("loading {}", args.mesh.display()))?;
    let description = serde_json::json!({
        "file": args.mesh.display().to_string(),
        "fit_height_m": options.fit_height_m,
        "rotate_y_deg": options.rotate_y_deg,
    });
    let mut output = bake_mesh(&mesh, &description, &args.config.bake, &progress(&args.output))
        .with_context(|| format!("baking {}", args.mesh.display()))?;
    finish(&mut output, &args.config, &args.output)
}

/// Writes the asset and its sidecar, and prints the report.
fn finish(output: &mut BakeOutput, config: &PipelineConfig, args: &OutputArgs) -> anyhow::Result<()> {
    write_bake(output, config, &args.out).with_context(|| format!("writing {}", args.out.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&output.report)?);
    } else {
        print!("{}", describe_bake(&args.out, &output.report));
    }
    Ok(())
}
