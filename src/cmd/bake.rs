//! `nelf bake …`: turn a capture or a mesh into a `.nelf` asset (`nelf-bake`).
//! `capture DIR` bakes, over the visual hull of the capture's masks, either its
//! ground-truth field (a mesh: `--mesh`, or the `synth_config.json` of a synthetic
//! capture) or the NeLF network's field from the capture's own images (the shipped
//! network, or `--weights`); `--source` chooses, and by default a capture with no
//! ground truth gets the network. `mesh FILE` bakes a mesh directly (its occupancy
//! is the hull).

use std::path::PathBuf;

use anyhow::Context;
use nelf_bake::{
    BakeConfig, BakeOutput, CaptureFormat, CaptureLoadOptions, ChoiceArgs, ChoiceReport, GroundTruth,
    HullCarved, HullDistance, LoadedCapture, Progress, bake_capture, bake_capture_field, bake_mesh,
    load_capture, plan_capture, sidecar_path, truth_field, truth_field_traced, write_bake,
};
use nelf_field::capture::default_net_from_world;
use nelf_field::shipped::load_or_shipped;
use nelf_field::{Model, NelfConfig, NelfField, NetCapture};
use nelf_format::conventions::LatLong;
use nelf_scene::field::{
    DensityAndTransport, DensityProfile, FieldSource as _, MeshField, SignedLogDensity, TransportShapeFrom,
    TrueNormalsLambert, VoxelFiltered,
};
use nelf_scene::mesh_io::{LoadOptions, load_mesh};
use nelf_scene::tracer::TraceSettings;

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
    /// The capture folder.
    pub dir: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Which field to bake: `truth` (the ground-truth mesh), `network` (the NeLF
    /// network evaluated from the capture's own images) or `auto` (the truth when
    /// there is one, else the network).
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
    #[command(flatten)]
    pub config: BakeConfig,
    #[command(flatten)]
    pub choice: ChoiceArgs,
}

/// Which field `nelf bake capture` bakes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum SourceChoice {
    /// The ground truth when the capture has one (`--mesh` or a synthetic capture's
    /// `synth_config.json`), else the network.
    #[default]
    Auto,
    /// The NeLF network from the capture's own images.
    Network,
    /// The ground-truth mesh.
    Truth,
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
    #[command(flatten)]
    pub config: BakeConfig,
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
    let options = CaptureLoadOptions {
        format: args.capture_format,
        metres_per_unit: args.metres_per_unit,
    };
    let capture = load_capture(&args.dir, &options)
        .with_context(|| format!("loading the capture in {}", args.dir.display()))?;
    let synth_truth = || GroundTruth::from_synth_capture(&args.dir);
    let network = match args.source {
        SourceChoice::Network => true,
        SourceChoice::Truth => false,
        SourceChoice::Auto => args.weights.is_some() || (args.mesh.is_none() && synth_truth().is_err()),
    };
    if network && args.mesh.is_some() {
        anyhow::bail!("--source network bakes the network's field; --mesh gives a ground truth");
    }
    if !network && args.weights.is_some() {
        anyhow::bail!("--weights are the network's; --source truth bakes the ground truth");
    }
    if network && args.choice.is_active() {
        anyhow::bail!(
            "--target-psnr/--max-bytes choose among ground-truth bakes; the network bakes at a given --resolution and --rank"
        );
    }
    if network {
        let name = args.weights.as_ref().map_or_else(
            || nelf_field::shipped::SHIPPED_WEIGHTS_NAME.to_string(),
            |w| w.display().to_string(),
        );
        let mut output = bake_network(
            &capture,
            args.weights.as_deref(),
            &args.config,
            progress(&args.output),
        )
        .with_context(|| format!("baking {} with the network {name}", args.dir.display()))?;
        return finish(&mut output, &args.config, &args.output);
    }
    let truth = match &args.mesh {
        Some(path) => GroundTruth::MeshFile {
            path: path.clone(),
            options: LoadOptions {
                fit_height_m: args.mesh_height_m,
                rotate_y_deg: args.mesh_rotate_y_deg,
                ..LoadOptions::default()
            },
        },
        None => synth_truth().with_context(|| {
            format!(
                "--source truth: no --mesh given, and the capture has no usable synth_config.json to rebuild its ground truth from ({})",
                args.dir.display()
            )
        })?,
    };
    if args.choice.is_active() {
        let (mut output, report) = nelf_bake::bake_capture_to_target(
            &capture,
            &truth,
            &args.config,
            &args.choice,
            &progress(&args.output),
        )
        .with_context(|| format!("choosing and baking {}", args.dir.display()))?;
        if !args.output.json {
            print_choice(&report);
        }
        return finish(&mut output, &args.config, &args.output);
    }
    let mut output = bake_capture(&capture, &truth, &args.config, &progress(&args.output))
        .with_context(|| format!("baking {}", args.dir.display()))?;
    finish(&mut output, &args.config, &args.output)
}

/// The candidates a choice tried (those with measured bytes) and what it chose.
fn print_choice(report: &ChoiceReport) {
    println!(
        "choice over {} held-aside views, resolutions sampled {:?}, {:.1} s:",
        report.views.len(),
        report.resolutions_sampled,
        report.secs
    );
    println!("  resolution  rank  encoding  est. PSNR (dB)  bytes");
    for (i, c) in report.candidates.iter().enumerate() {
        if let Some(bytes) = c.bytes {
            println!(
                "  {:>10}  {:>4}  {:>8}  {:>14.2}  {bytes}{}",
                c.resolution,
                c.rank,
                format!("{:?}", c.encoding).to_lowercase(),
                c.psnr_db,
                if i == report.chosen { "  <- chosen" } else { "" }
            );
        }
    }
    println!("  chose {}", report.reason);
}

/// The network's field over the capture's hull: the views are encoded once, then
/// density and light transport are evaluated at the voxels (toward the mean camera,
/// the policy measured best in field/README.md).
pub fn bake_network(
    capture: &LoadedCapture,
    weights: Option<&std::path::Path>,
    config: &BakeConfig,
    progress: Progress,
) -> anyhow::Result<BakeOutput> {
    let device = nelf_field::default_device();
    let (model, weights_name) = load_or_shipped(weights, NelfConfig::for_device(&device), &device)
        .context("loading the network's weights")?;
    let model_size = model.working_image_size();
    let (prepared, field) = network_field(capture, model, SourceFit::of_config(config))?;
    let encoded_size = prepared.cameras.first().map(|c| [c.width, c.height]);
    let mut provenance = network_provenance(&field, &weights_name);
    provenance["working_image_size"] = serde_json::json!(model_size);
    provenance["encoded_image_size"] = serde_json::json!(encoded_size);
    provenance["device"] = serde_json::json!(nelf_field::device_name(&device));
    provenance["view_policy"] = serde_json::json!("toward the mean camera");
    bake_network_field(
        capture,
        &field,
        &provenance,
        config,
        progress,
        &NetworkSampling::default(),
    )
}

/// What a network bake records of its field: the weights it came from and how its
/// light transport was put in the capture's units (gain, normalisation, shading prior).
pub fn network_provenance(field: &NelfField, weights_name: &str) -> serde_json::Value {
    let model = field.model();
    serde_json::json!({
        "kind": "nelf-network",
        "weights": weights_name,
        "light_transport_scale": field.light_transport_scale(),
        "source_gain": field.source_gain(),
        "source_normalised": model.source_normalised(),
        "shading_prior": model.shading_prior().map(prior_json),
        "source_relative_light": model.source_relative_light(),
        "trained_shading_prior": model.trained_shading_prior().map(prior_json),
    })
}

/// A shading prior as the provenance records it.
fn prior_json(prior: nelf_field::prior::ShadingPrior) -> serde_json::Value {
    serde_json::json!({"step_mm": prior.step_mm, "weight": prior.weight})
}

/// How a network field is fitted to the capture's source views when the capture
/// names the lighting they were taken in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SourceFit {
    /// Left as the network gives it (in physical units when its lighting is known).
    None,
    /// Scaled by the one gain that makes it reproduce the views
    /// (`NelfField::calibrated_to_sources`).
    Gain,
    /// Normalised to the lighting point by point, with an optional Lambertian shading
    /// prior (`NelfField::normalised_to_sources`).
    Normalised(Option<nelf_field::prior::ShadingPrior>),
}

impl SourceFit {
    /// The fit a bake configuration asks for: none with `--no-source-calibration`,
    /// normalised with a prior for `--shading-prior-mm` > 0, else the gain.
    pub fn of_config(config: &BakeConfig) -> Self {
        if config.no_source_calibration {
            Self::None
        } else {
            nelf_field::prior::ShadingPrior::from_step_mm(
                config.shading_prior_mm,
                config.shading_prior_weight,
            )
            .map_or(Self::Gain, |prior| Self::Normalised(Some(prior)))
        }
    }
}

/// The network over `capture`'s views, reduced toward its working image size: the
/// prepared views and the field they encode to, in the capture's light units and
/// fitted to its source views by `fit`.
pub fn network_field(
    capture: &LoadedCapture,
    model: Model,
    fit: SourceFit,
) -> anyhow::Result<(NetCapture, NelfField)> {
    let prepared = NetCapture::for_model(
        &model,
        &capture.cameras,
        &capture.images,
        &capture.masks,
        capture.head_centre_m,
        default_net_from_world(),
    )?;
    let field = NelfField::new(model, &prepared).context("encoding the capture's views")?;
    let field = in_capture_light_units(field, capture.description(), &capture.dir, fit)?;
    Ok((prepared, field))
}

/// `field` in physical units when its network takes source-relative lightings and the
/// capture (`description`, in folder `dir`) names its lighting, then fitted to the
/// capture's views under that lighting by `fit`; otherwise as it is, saying so.
pub fn in_capture_light_units(
    field: NelfField,
    description: Option<&nelf_format::capture::Capture>,
    dir: &std::path::Path,
    fit: SourceFit,
) -> anyhow::Result<NelfField> {
    let Some(map) = capture_source_lighting(description, dir)? else {
        if field.model().source_relative_light() {
            eprintln!(
                "note: {} records no lighting of its views, so the network's light transport stays \
                 relative to it (relit under a map of mean radiance 1 it is as bright as the capture) \
                 and is not calibrated to the views",
                dir.display()
            );
        }
        return Ok(field);
    };
    let field = field.with_source_light_power(map.mean_radiance())?;
    let light = nelf_format::conventions::project_envmap(&map, field.world_from_light())?;
    // The prior's step and weight are chosen for bakes on their own
    // (`nelf_field::prior::DEFAULT_STEP_MM`, `DEFAULT_WEIGHT`); no prior at all departs
    // from what the weights were trained with.
    let without_prior = !matches!(fit, SourceFit::Normalised(Some(_)));
    if let Some(trained) = field.model().trained_shading_prior()
        && without_prior
    {
        eprintln!(
            "note: these weights were last trained through a shading prior of weight {} with normals over {} mm; \
             this fit uses none (the weights' accuracy figures hold with the default prior)",
            trained.weight, trained.step_mm,
        );
    }
    match fit {
        SourceFit::None => Ok(field),
        SourceFit::Gain => {
            let (field, fit) = field
                .calibrated_to_sources(&light)
                .with_context(|| format!("calibrating the network to the views of {}", dir.display()))?;
            eprintln!(
                "  calibrated the network to its {} source pixels under their lighting: light transport × {:.3} \
                 (sRGB RMS error {:.4} -> {:.4}; --no-source-calibration leaves it)",
                fit.pixels, fit.gain, fit.rmse_before, fit.rmse_after
            );
            Ok(field)
        }
        SourceFit::Normalised(prior) => {
            let field = field
                .normalised_to_sources(&light, prior)
                .with_context(|| format!("normalising the network to the lighting of {}", dir.display()))?;
            eprintln!(
                "  normalised the network's light transport to the lighting of its source views{}",
                prior.map_or(String::new(), |p| format!(
                    ", with a Lambertian shading prior (weight {}, normals over {} mm)",
                    p.weight, p.step_mm
                ))
            );
            Ok(field)
        }
    }
}

/// The lighting a capture's views were taken under, when its `cameras.json`
/// (`description`, in folder `dir`) names one (synthetic captures do), checked to
/// have a positive finite mean radiance (`Σ Ω L / 4π`).
pub fn capture_source_lighting(
    description: Option<&nelf_format::capture::Capture>,
    dir: &std::path::Path,
) -> anyhow::Result<Option<LatLong>> {
    let Some(path) = description.and_then(|d| d.envmap_path(dir)) else {
        return Ok(None);
    };
    let map = nelf_scene::envmap::load_envmap(&path)
        .with_context(|| format!("reading the capture's lighting {}", path.display()))?;
    let power = map.mean_radiance();
    anyhow::ensure!(
        power.is_finite() && power > 0.0,
        "{}: the capture's lighting has mean radiance {power}",
        path.display()
    );
    Ok(Some(map))
}

/// Sub-points per voxel edge where a network's field is baked
/// ([`VoxelFiltered`]): a trained network's skin is a shell thinner than a voxel,
/// which point samples at voxel centres alias into stripes. Measured with `nelf eval
/// network` on held-out heads (docs/measurements/2026-11-26-network-bake.md).
pub const NETWORK_VOXEL_FILTER: usize = 2;

/// The part of a network bake the ground truth stands in for (`nelf eval network
/// --split`), to tell the network's geometry error from its shading error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FromTruth {
    /// The ground truth's density with the network's light transport.
    Density,
    /// The network's density (signed and carved as in its bake) with the ground
    /// truth's light transport.
    Transport,
    /// The network's density and its colour under the capture's source lighting, with
    /// the ground truth's transport scaled to that colour: how the colour changes
    /// with the lighting is the truth's ([`TransportShapeFrom`]).
    Shading,
    /// The network's density and its transport scaled to the ground truth's colour
    /// under the capture's source lighting: how the colour changes with the lighting
    /// is the network's.
    Colour,
    /// The network's density and colour, relit by the clamped cosine about the
    /// truth's normals (the shading prior with true normals, alone).
    Normals,
    /// The network's density and colour, relit by the truth's direct Lambertian
    /// transport: its normals and shadows, without interreflection or gloss.
    Shadows,
}

impl FromTruth {
    /// Every split, in the order `nelf eval network --split` bakes and reports them.
    pub const ALL: [Self; 6] = [
        Self::Density,
        Self::Transport,
        Self::Shading,
        Self::Colour,
        Self::Normals,
        Self::Shadows,
    ];

    /// The name of its scores (`truth_density_bake`, …) and `what` its bake swaps.
    pub fn describe(self) -> (&'static str, &'static str) {
        match self {
            Self::Density => (
                "truth_density_bake",
                "the ground truth's density, the network's transport",
            ),
            Self::Transport => (
                "truth_transport_bake",
                "the network's density, the ground truth's transport",
            ),
            Self::Shading => (
                "truth_shading_bake",
                "the network's colour under the source lighting, the ground truth's shading",
            ),
            Self::Colour => (
                "truth_colour_bake",
                "the ground truth's colour under the source lighting, the network's shading",
            ),
            Self::Normals => (
                "truth_normals_bake",
                "the network's colour, a Lambertian shading about the ground truth's normals",
            ),
            Self::Shadows => (
                "truth_shadows_bake",
                "the network's colour, the ground truth's direct Lambertian shading with its shadows",
            ),
        }
    }
}

/// How one network bake is sampled, where it departs from `nelf bake capture`'s.
#[derive(Debug, Clone)]
pub struct NetworkSampling<'a> {
    /// Sub-points per voxel edge ([`NETWORK_VOXEL_FILTER`] by default).
    pub voxel_filter: usize,
    /// The outgoing direction of the light transport (`None`: the network's
    /// recommended policy).
    pub view_policy: Option<nelf_scene::field::ViewPolicy>,
    /// A part of the field taken from this ground truth (`nelf eval network --split`).
    pub from_truth: Option<(&'a GroundTruth, FromTruth)>,
}

impl Default for NetworkSampling<'_> {
    fn default() -> Self {
        Self {
            voxel_filter: NETWORK_VOXEL_FILTER,
            view_policy: None,
            from_truth: None,
        }
    }
}

/// Bakes `field` (the network over `capture`'s views) as `sampling` says (by
/// default toward the network's recommended view policy, box-filtered over voxels by
/// [`NETWORK_VOXEL_FILTER`]), its density stored as a signed function of `ln σ`
/// ([`SignedLogDensity`]) unless `config.network_skin_mm` is 0; `provenance` goes
/// into the asset's metadata.
pub fn bake_network_field(
    capture: &LoadedCapture,
    field: &NelfField,
    provenance: &serde_json::Value,
    config: &BakeConfig,
    progress: Progress,
    sampling: &NetworkSampling<'_>,
) -> anyhow::Result<BakeOutput> {
    let NetworkSampling {
        voxel_filter,
        view_policy,
        from_truth,
    } = sampling.clone();
    let planned = plan_capture(capture, config, field, &progress)?;
    let view_policy = view_policy.unwrap_or_else(|| field.recommended_view_policy());
    let voxel_m = planned.voxel_size_m as f32;
    let filtered = VoxelFiltered::new(field, voxel_m, voxel_filter)?;
    let (signed, carved);
    let source: &dyn nelf_scene::field::FieldSource = if config.network_skin_mm > 0.0 {
        signed = SignedLogDensity::with_skin(
            &filtered,
            config.network_skin_mm / 1000.0,
            config.lead_voxels * voxel_m,
            voxel_m,
        )?;
        if config.no_network_hull_carve {
            &signed
        } else {
            let hull = HullDistance::new(
                &capture.cameras,
                &capture.masks,
                f64::from(config.network_hull_margin_px),
            )
            .with_context(|| format!("the visual hull of {}", capture.dir.display()))?;
            carved = HullCarved::new(&signed, hull);
            &carved
        }
    } else {
        &filtered
    };
    let (truth, split, shaped, recoloured, mesh, lambert);
    let source: &dyn nelf_scene::field::FieldSource = match from_truth {
        None => source,
        Some((ground_truth, part)) => {
            let voxel_size_m = planned.voxel_size_m;
            let of_truth = |what: &str| format!("the ground truth's {what} of {}", capture.dir.display());
            let full_truth =
                || truth_field(ground_truth, config, voxel_size_m).with_context(|| of_truth("field"));
            let source_lighting = || -> anyhow::Result<LatLong> {
                capture_source_lighting(capture.description(), &capture.dir)?
                    .with_context(|| format!("{} names no source lighting", capture.dir.display()))
            };
            match part {
                FromTruth::Density => {
                    truth = full_truth()?;
                    split = DensityAndTransport::new(truth.as_ref(), source);
                    &split
                }
                FromTruth::Transport => {
                    truth = full_truth()?;
                    split = DensityAndTransport::new(source, truth.as_ref());
                    &split
                }
                FromTruth::Shading => {
                    truth = full_truth()?;
                    shaped = TransportShapeFrom::new(truth.as_ref(), source, &source_lighting()?)?;
                    &shaped
                }
                FromTruth::Colour => {
                    truth = full_truth()?;
                    // The network's transport at the truth's colour, the network's density kept.
                    recoloured = TransportShapeFrom::new(source, truth.as_ref(), &source_lighting()?)?;
                    split = DensityAndTransport::new(source, &recoloured);
                    &split
                }
                FromTruth::Normals => {
                    let surface = ground_truth.mesh().with_context(|| of_truth("mesh"))?;
                    mesh = MeshField::new(&surface, TraceSettings::default(), DensityProfile::default())
                        .with_context(|| of_truth("mesh"))?;
                    lambert = TrueNormalsLambert::new(&mesh);
                    shaped = TransportShapeFrom::new(&lambert, source, &source_lighting()?)?;
                    &shaped
                }
                FromTruth::Shadows => {
                    truth = truth_field_traced(ground_truth, config, voxel_size_m, |trace| {
                        trace.bounces = 0;
                        trace.specular = None;
                    })
                    .with_context(|| of_truth("direct field"))?;
                    shaped = TransportShapeFrom::new(truth.as_ref(), source, &source_lighting()?)?;
                    &shaped
                }
            }
        }
    };
    Ok(bake_capture_field(
        capture,
        planned,
        source,
        view_policy,
        provenance,
        config,
        &progress,
    )?)
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
    let mut output = bake_mesh(&mesh, &description, &args.config, &progress(&args.output))
        .with_context(|| format!("baking {}", args.mesh.display()))?;
    finish(&mut output, &args.config, &args.output)
}

fn finish(output: &mut BakeOutput, config: &BakeConfig, args: &OutputArgs) -> anyhow::Result<()> {
    write_bake(output, config, &args.out).with_context(|| format!("writing {}", args.out.display()))?;
    let r = &output.report;
    if args.json {
        println!("{}", serde_json::to_string_pretty(r)?);
        return Ok(());
    }
    let t = &r.timings;
    println!(
        "wrote {} ({} bytes): {} bricks, {} voxels ({:.2} mm), light transport at {} voxels",
        args.out.display(),
        r.file_size,
        r.bricks,
        r.voxels,
        r.voxel_size_m * 1e3,
        r.lt_voxels
    );
    println!(
        "  PCA rank K = {} (energy kept {:.5}, rendered loss {:.4} dB{}; unquantized grid SNR {:.2} dB)",
        r.rank,
        r.energy_kept,
        r.loss_db,
        if r.met_target { "" } else { ", target NOT met" },
        -10.0 * r.reference_relative_error.log10()
    );
    if let Some(v) = &r.view {
        let kept = v.chosen_index.map(|i| &v.candidates[i]);
        let gain = |c: &nelf_bake::view::ViewCandidate| {
            c.gain_db
                .map_or_else(|| "not judged".into(), |g| format!("{g:+.2} dB"))
        };
        match kept {
            Some(c) => match c.exponent {
                Some(exponent) => println!(
                    "  view dependence {} ({}): a glossy lobe of exponent {exponent} about each voxel's mirror direction, {} at {}",
                    v.chosen,
                    v.requested,
                    gain(c),
                    v.judged_at
                ),
                None => println!(
                    "  view dependence {} ({}): {} lobes × view rank {}, {} at {}",
                    v.chosen,
                    v.requested,
                    c.lobes,
                    c.rank,
                    gain(c),
                    v.judged_at
                ),
            },
            None => println!(
                "  view dependence off ({}): {}",
                v.requested,
                if let Some(p) = v.probe.as_ref().filter(|p| !p.band_fitted) {
                    format!(
                        "fitted on {} of {} band voxels, the best candidate would gain about {:+.3} dB over the whole band at {}, below a quarter of --view-min-gain-db; the band was not fitted",
                        p.voxels, p.band_voxels, p.best_extrapolated_gain_db, v.judged_at
                    )
                } else if v.candidates.is_empty() {
                    format!(
                        "residual {:.1e} of the transport, nothing to fit or no views to judge at",
                        v.residual_ratio
                    )
                } else {
                    let best = v.best_gain_db();
                    format!(
                        "best candidate {best:+.2} dB at {}, below the threshold",
                        v.judged_at
                    )
                }
            ),
        }
    }
    println!(
        "  seconds: hull {:.2}, reference {:.2}, density {:.2}, weights {:.2}, light {:.2}, pca {:.2}, rank {:.2}, view {:.2}, write {:.2}",
        t.hull_secs,
        t.reference_secs,
        t.density_secs,
        t.weights_secs,
        t.lt_secs,
        t.pca_secs,
        t.rank_secs,
        t.view_secs,
        t.write_secs
    );
    println!("  settings and report: {}", sidecar_path(&args.out).display());
    Ok(())
}
