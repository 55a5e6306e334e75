//! `nelf render ASSET -o out.png|out.exr`: renders a `.nelf` asset under an environment
//! map with the CPU reference renderer (`nelf_render::render_asset`: trilinear samples,
//! front-to-back emission–absorption compositing, lighting projected once onto the PCA
//! basis). `--gpu` renders the same image with the GPU renderer (`nelf_viewer`), read
//! back before tone mapping.
//!
//! The camera and the lighting are `nelf_scene::shot`'s (the orbit formula, camera
//! files, defaults): `--camera CAM.json` (a `cameras.json` view's camera, or a previous
//! render's `.render.json`), `--view-of CAPTURE_DIR:VIEW_NAME` (a view or target of a
//! capture folder) or `--orbit AZ,EL[,DIST]` around the asset's box centre (default
//! `--orbit 0,0`, from +z); `--envmap FILE.exr|hdr` turned by `--rotate-deg` about +y,
//! else the lighting of the `--view-of` target (or capture) when there is one, else a
//! **constant white map of radiance 1** (every direction), under which a voxel shows
//! its albedo-like total transport. `.png` output is sRGB, scaled by `2^exposure`, clamped;
//! `.exr` output is the linear premultiplied radiance as rendered (exposure not applied).
//! The options, the resolved camera and the timings are saved beside the image as
//! `<out>.render.json`.
//!
//! `--field CAPTURE_DIR [--weights W.safetensors]` renders straight from the NeLF
//! network (the shipped one by default) over a capture instead of an asset
//! (`nelf_pipeline::render_field`): slow, and the reference a bake of that capture
//! must match; `--estimated-light` uses the network's own estimate of the capture's
//! lighting; orbits circle the visual hull's box.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use nelf_format::read_asset;
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::image_io::RenderImageKind;
use nelf_scene::shot::{CameraArgs, CameraJson, LightingArgs, asset_shot, camera_to_json};
use serde::{Deserialize, Serialize};

/// Options of `nelf render`.
#[derive(Debug, Clone, clap::Args, Serialize, Deserialize)]
pub struct RenderArgs {
    /// The .nelf asset (not with --field).
    #[arg(required_unless_present = "field")]
    pub asset: Option<PathBuf>,
    /// Render straight from the NeLF network over this capture folder instead of an
    /// asset (slow: the reference a bake must match).
    #[arg(long, value_name = "CAPTURE_DIR", conflicts_with_all = ["asset", "gpu", "rank"])]
    pub field: Option<PathBuf>,
    /// --field: the network's weights (safetensors, official checkpoint key names;
    /// default: the shipped network, models/nelf-small.safetensors, built in).
    #[arg(long, requires = "field")]
    pub weights: Option<PathBuf>,
    /// --field: light with the network's own estimate of the capture's lighting
    /// (`nelf light`) instead of --envmap / the capture's map / constant white.
    #[arg(long, requires = "field", conflicts_with = "envmap")]
    pub estimated_light: bool,
    /// --field: leave the network's light transport uncalibrated (by default, when the
    /// capture names its lighting, it is scaled so that the network reproduces the
    /// capture's views under it; `nelf bake --no-source-calibration`).
    #[arg(long, requires = "field")]
    #[serde(default)]
    pub no_source_calibration: bool,
    /// --field: random ray samples from this seed instead of stratified ones.
    #[arg(long, requires = "field")]
    pub field_seed: Option<u64>,
    /// Where the camera is (`--camera`, `--view-of`, `--orbit`) and the image size.
    #[command(flatten)]
    #[serde(flatten)]
    pub view: CameraArgs,
    /// The environment map and its rotation.
    #[command(flatten)]
    #[serde(flatten)]
    pub lighting: LightingArgs,
    /// Use only the first K PCA components (default: all).
    #[arg(long)]
    pub rank: Option<usize>,
    /// Exposure of the PNG in stops (scale by 2^stops).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f32,
    /// Ray-march step in voxels.
    #[arg(long, default_value_t = 0.5)]
    pub step_voxels: f32,
    /// Stop a ray once its transmittance falls below this.
    #[arg(long, default_value_t = 1e-3)]
    pub min_transmittance: f32,
    /// Supersampling: `n × n` rays per pixel, averaged (CPU only; 4 matches the
    /// antialiasing of synthetic ground-truth images).
    #[arg(long, default_value_t = 1, conflicts_with = "gpu")]
    pub pixel_grid: u32,
    /// Render on the GPU (`nelf_viewer::GpuRenderer`, wgpu; Mesa's lavapipe on machines
    /// without one) instead of the CPU reference; the same image to f16 precision.
    #[arg(long)]
    pub gpu: bool,
    /// Output image: .png (sRGB, 8-bit) or .exr (linear float).
    #[arg(short, long, default_value = "render.png")]
    pub out: PathBuf,
}

/// What `<out>.render.json` holds.
#[derive(Debug, Serialize)]
struct RenderRecord<'a> {
    config: &'a RenderArgs,
    camera: CameraJson,
    envmap: String,
    rank_used: usize,
    voxels: usize,
    device: &'static str,
    load_seconds: f64,
    render_seconds: f64,
}

/// The output's image kind and the march settings, checked before anything is read
/// (`--field` renders check them too).
pub fn checked_output_and_march(args: &RenderArgs) -> anyhow::Result<(RenderImageKind, MarchSettings)> {
    let output = RenderImageKind::of_path(&args.out)?;
    let settings = MarchSettings {
        step_voxels: args.step_voxels,
        min_transmittance: args.min_transmittance,
        pixel_grid: args.pixel_grid,
    };
    settings.validate()?;
    Ok((output, settings))
}

/// Runs `nelf render` of an asset (`--field` is [`super::render_field::run`]).
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let (output, settings) = checked_output_and_march(args)?;
    let start = Instant::now();
    let asset_path = args
        .asset
        .as_ref()
        .context("an asset (or --field CAPTURE) is required")?;
    let asset = read_asset(asset_path).with_context(|| format!("cannot read {}", asset_path.display()))?;
    let shot = asset_shot(&asset, &args.view, &args.lighting, args.rank)?;
    let load_seconds = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let image = if args.gpu {
        nelf_viewer::render_asset_gpu(
            &asset,
            &shot.camera,
            &shot.env,
            shot.world_from_env,
            shot.rank,
            settings,
        )?
    } else {
        render_asset(
            &asset,
            &shot.camera,
            &shot.env,
            shot.world_from_env,
            shot.rank,
            &settings,
        )?
    };
    let render_seconds = start.elapsed().as_secs_f64();

    output
        .write(&args.out, image.width, image.height, &image.rgb, args.exposure)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let record = RenderRecord {
        config: args,
        camera: camera_to_json(&shot.camera),
        envmap: shot.envmap_name.clone(),
        rank_used: shot.rank.unwrap_or(asset.rank()),
        voxels: asset.voxel_count(),
        device: if args.gpu { "gpu" } else { "cpu" },
        load_seconds,
        render_seconds,
    };
    super::save_record(&args.out, "render", &record)?;
    println!(
        "rendered {}×{} (rank {} of {}, {} voxels, lighting: {}) in {render_seconds:.3} s on the {} -> {}",
        image.width,
        image.height,
        record.rank_used,
        asset.rank(),
        asset.voxel_count(),
        shot.envmap_name,
        if args.gpu { "GPU" } else { "CPU" },
        args.out.display()
    );
    Ok(())
}
