//! `nelf bake capture`: which field a capture is baked from ([`SourceChoice`]: its
//! ground truth, a mesh given for it, or the NeLF network from its own images) and
//! the bake itself ([`bake_capture_dir`]), with a choice among ground-truth bakes
//! when `--target-psnr`/`--max-bytes` ask for one.

use std::path::PathBuf;

use nelf_bake::{
    BakeOutput, CaptureFormat, CaptureLoadOptions, ChoiceArgs, ChoiceReport, GroundTruth, LoadedCapture,
    Progress, bake_capture, bake_capture_to_target, load_capture,
};
use nelf_scene::mesh_io::LoadOptions;

use crate::config::{PhotoSettings, PipelineConfig};
use crate::error::{Context as _, Result, invalid};
use crate::network_bake::bake_network;
use crate::photo::{Reconstruction, bake_photographs};

/// Which field `nelf bake capture` bakes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum SourceChoice {
    /// The ground truth when the capture has one (`--mesh` or a synthetic capture's
    /// `synth_config.json`), else the photographs' reconstruction (the network when
    /// `--weights` are given).
    #[default]
    Auto,
    /// The NeLF network from the capture's own images.
    Network,
    /// A surface and its reflectance reconstructed from the capture's photographs
    /// (`nelf_pipeline::photo`: the masks' visual hull refined by the network's
    /// density or by stereo, the lighting, the albedo from the views), baked as a
    /// mesh; measured in `docs/measurements/2026-12-06-photographs.md`.
    Photos,
    /// The ground-truth mesh.
    Truth,
}

/// What `nelf bake capture` bakes and how (every option but where the asset goes).
#[derive(Debug, Clone, clap::Args)]
pub struct CaptureBakeOptions {
    /// The capture folder.
    pub dir: PathBuf,
    /// Which field to bake: `truth` (the ground-truth mesh), `network` (the NeLF
    /// network evaluated from the capture's own images), `photos` (a surface and its
    /// reflectance reconstructed from the photographs, baked as a mesh) or `auto` (the truth when there is one, else the photographs).
    #[arg(long, value_enum, default_value_t)]
    pub source: SourceChoice,
    /// The network's weights (safetensors with the official checkpoint's key names,
    /// field/CHECKPOINT.md; default: the shipped network, models/nelf-small.safetensors,
    /// built in). Implies `--source network`.
    #[arg(long, conflicts_with = "mesh")]
    pub weights: Option<PathBuf>,
    /// Ground-truth mesh in the capture's world frame (default: rebuilt from
    /// the `synth_config.json` every synthetic capture has).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Scale --mesh to this height (metres) and centre it at the origin (default: as stored).
    #[arg(long)]
    pub mesh_height_m: Option<f32>,
    /// Turn --mesh about +y by this many degrees.
    #[arg(long, default_value_t = 0.0)]
    pub mesh_rotate_y_deg: f32,
    /// Which capture description to read.
    #[arg(long, value_enum, default_value_t)]
    pub capture_format: CaptureFormat,
    /// Metres per COLMAP model unit.
    #[arg(long, default_value_t = 1.0)]
    pub metres_per_unit: f64,
    /// Every setting of the bake.
    #[command(flatten)]
    pub config: PipelineConfig,
    /// A choice among ground-truth bakes (`--target-psnr`, `--max-bytes`).
    #[command(flatten)]
    pub choice: ChoiceArgs,
    /// How `--source photos` reconstructs the capture.
    #[command(flatten)]
    pub photo: PhotoSettings,
}

/// A baked capture, not yet written: the bake and, when one was asked for, the
/// choice that picked its settings.
#[derive(Debug)]
pub struct CaptureBake {
    /// The asset and its report.
    pub output: BakeOutput,
    /// The candidates tried and the one chosen (`--target-psnr`, `--max-bytes`).
    pub choice: Option<ChoiceReport>,
    /// The surface reconstructed from the photographs (`--source photos`).
    pub reconstruction: Option<Reconstruction>,
}

/// The field a bake reads, once `auto` is resolved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    Truth,
    Network,
    Photos,
}

/// Which field `options` bake, checked against the options that only one of them
/// reads. `auto`: the ground truth when there is one and no `--weights` are given;
/// else the network when `--weights` are given; else the photographs'
/// reconstruction, which beats the network's bake on every capture measured
/// (`docs/measurements/2026-12-06-photographs.md`).
fn chosen_source(options: &CaptureBakeOptions, synth_truth: impl Fn() -> bool) -> Result<Source> {
    let source = match options.source {
        SourceChoice::Truth => Source::Truth,
        SourceChoice::Photos => Source::Photos,
        SourceChoice::Auto if options.weights.is_none() && (options.mesh.is_some() || synth_truth()) => {
            Source::Truth
        }
        SourceChoice::Auto if options.weights.is_none() => Source::Photos,
        SourceChoice::Network | SourceChoice::Auto => Source::Network,
    };
    if source != Source::Truth && options.mesh.is_some() {
        return Err(invalid(
            "--mesh gives a ground truth; --source network and --source photos bake without one",
        ));
    }
    if source == Source::Truth && options.weights.is_some() {
        return Err(invalid(
            "--weights are the network's; --source truth bakes the ground truth",
        ));
    }
    if source != Source::Truth && options.choice.is_active() {
        return Err(invalid(
            "--target-psnr/--max-bytes choose among ground-truth bakes; the network and the photographs' reconstruction bake at a given --resolution and --rank",
        ));
    }
    Ok(source)
}

/// Bakes the capture in `options.dir` from the field [`SourceChoice`] picks.
pub fn bake_capture_dir(options: &CaptureBakeOptions, progress: Progress) -> Result<CaptureBake> {
    let dir = &options.dir;
    let load = CaptureLoadOptions {
        format: options.capture_format,
        metres_per_unit: options.metres_per_unit,
    };
    let capture =
        load_capture(dir, &load).with_context(|| format!("loading the capture in {}", dir.display()))?;
    let mut baked = bake_loaded_capture(&capture, options, progress)?;
    baked.output.report.notes.extend(capture.notes);
    Ok(baked)
}

/// [`bake_capture_dir`] once the capture is loaded.
fn bake_loaded_capture(
    capture: &LoadedCapture,
    options: &CaptureBakeOptions,
    progress: Progress,
) -> Result<CaptureBake> {
    let dir = &options.dir;
    let synth_truth = || GroundTruth::from_synth_capture(dir);
    match chosen_source(options, || synth_truth().is_ok())? {
        Source::Network => {
            let name = options.weights.as_ref().map_or_else(
                || nelf_field::shipped::SHIPPED_WEIGHTS_NAME.to_string(),
                |w| w.display().to_string(),
            );
            let output = bake_network(capture, options.weights.as_deref(), &options.config, progress)
                .with_context(|| format!("baking {} with the network {name}", dir.display()))?;
            return Ok(CaptureBake {
                output,
                choice: None,
                reconstruction: None,
            });
        }
        Source::Photos => {
            let baked = bake_photographs(
                capture,
                options.weights.as_deref(),
                &options.photo,
                &options.config,
                progress,
            )?;
            return Ok(CaptureBake {
                output: baked.output,
                choice: None,
                reconstruction: Some(baked.reconstruction),
            });
        }
        Source::Truth => {}
    }
    let truth = match &options.mesh {
        Some(path) => GroundTruth::MeshFile {
            path: path.clone(),
            options: LoadOptions {
                fit_height_m: options.mesh_height_m,
                rotate_y_deg: options.mesh_rotate_y_deg,
                ..LoadOptions::default()
            },
        },
        None => synth_truth().with_context(|| {
            format!(
                "--source truth: no --mesh given, and the capture has no usable synth_config.json to rebuild its ground truth from ({})",
                dir.display()
            )
        })?,
    };
    bake_truth(capture, &truth, options, progress)
}

/// The ground truth's bake, or the choice among its bakes when one is asked for.
fn bake_truth(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    options: &CaptureBakeOptions,
    progress: Progress,
) -> Result<CaptureBake> {
    let dir = &options.dir;
    let config = &options.config.bake;
    if options.choice.is_active() {
        let (output, report) = bake_capture_to_target(capture, truth, config, &options.choice, &progress)
            .with_context(|| format!("choosing and baking {}", dir.display()))?;
        return Ok(CaptureBake {
            output,
            choice: Some(report),
            reconstruction: None,
        });
    }
    let output = bake_capture(capture, truth, config, &progress)
        .with_context(|| format!("baking {}", dir.display()))?;
    Ok(CaptureBake {
        output,
        choice: None,
        reconstruction: None,
    })
}
