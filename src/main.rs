//! `nelf`: bake, view and ship relightable portrait light-transport fields.
//! Thin: every subcommand parses its options and calls a library.

mod cmd;

use clap::{Parser, Subcommand};

/// Relightable portrait assets from neural light-transport fields (NeLF, Sun et al. 2021).
#[derive(Debug, Parser)]
#[command(name = "nelf", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The main job on a built-in default: synthetic head capture → bake → relit turntable → ground-truth comparison.
    Demo(cmd::demo::DemoArgs),
    /// Print a .nelf file's header, sections, sizes and metadata.
    Inspect(cmd::inspect::InspectArgs),
    /// Make capture folders (synthetic captures rendered by the path tracer).
    Capture(cmd::capture::CaptureArgs),
    /// Bake a capture or a mesh into a .nelf asset (visual hull, sparse bricks, PCA).
    Bake(cmd::bake::BakeArgs),
    /// Estimate a capture's lighting with the NeLF network and write it as a lat-long EXR.
    Light(cmd::light::LightArgs),
    /// Render a .nelf asset under an environment map (CPU reference renderer).
    Render(cmd::render::RenderArgs),
    /// Measure: `pareto` (accuracy against bytes and frame time over resolution × rank × encoding) and `stability` (where quality breaks).
    Eval(cmd::eval::EvalArgs),
    /// Export a .nelf asset for other tools: `vdb` (OpenVDB: density, relit colour, PCA grids).
    Export(cmd::export::ExportArgs),
    /// Open the interactive viewer (wgpu + egui): orbit, relight, rank, debug views.
    View(cmd::view::ViewArgs),
    /// Train the NeLF network on path-traced ground truth: `data` renders a dataset of training triplets, `run` trains on it.
    Train(cmd::train::TrainArgs),
    /// Batches beyond one machine: `plan` many bakes, training heads or sweep points, `run` one index (Slurm array, Kubernetes Indexed Job, farm queue), `slurm`, `local`, `status`, `collect`.
    Batch(cmd::batch::BatchArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    // Training and the network's CPU passes allocate hundreds of large tensors per
    // step; off glibc the allocator keeps its defaults, which only costs speed.
    nelf_field::cpu::keep_freed_memory();
    match cli.command {
        Command::Demo(args) => cmd::demo::run(&args),
        Command::Inspect(args) => cmd::inspect::run(&args),
        Command::Capture(args) => cmd::capture::run(&args),
        Command::Bake(args) => cmd::bake::run(&args),
        Command::Light(args) => cmd::light::run(&args),
        Command::Render(args) => match &args.field {
            Some(capture) => cmd::render_field::run(&args, capture),
            None => cmd::render::run(&args),
        },
        Command::Eval(args) => cmd::eval::run(&args),
        Command::Export(args) => cmd::export::run(&args),
        Command::View(args) => cmd::view::run(&args),
        Command::Train(args) => cmd::train::run(&args),
        Command::Batch(args) => cmd::batch::run(&args),
    }
}
