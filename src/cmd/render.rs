//! `nelf render ASSET -o out.png|out.exr`: renders a `.nelf` asset under an environment
//! map with the CPU reference renderer (`nelf_render::render_asset`: trilinear samples,
//! front-to-back emission–absorption compositing, lighting projected once onto the PCA
//! basis). `--gpu` renders the same image with the GPU renderer (`nelf_viewer`), read
//! back before tone mapping.
//!
//! The camera is one of `--camera CAM.json` (the fields of a `cameras.json` view, metres:
//! `width`, `height`, `intrinsics {fx, fy, cx, cy}`, `world_to_camera {rotation (row-major),
//! translation}`; or a previous render's `.render.json`, whose `camera` is that object),
//! `--view-of CAPTURE_DIR:VIEW_NAME` (a view or target of a capture folder), or
//! `--orbit AZ,EL[,DIST]` (degrees, degrees, metres: a camera at `centre + DIST · (cos EL
//! sin AZ, sin EL, cos EL cos AZ)` looking at the asset's box centre with +y up; DIST
//! defaults to the distance at which the box's bounding sphere fills the view). The
//! default is `--orbit 0,0`, from +z.
//!
//! Lighting: `--envmap FILE.exr|hdr` turned by `--rotate-deg` about +y; without it, the
//! lighting of the `--view-of` target (or capture) when there is one, else a **constant
//! white map of radiance 1** (every direction), under which a voxel shows its
//! albedo-like total transport. `.png` output is sRGB, scaled by `2^exposure`, clamped;
//! `.exr` output is the linear premultiplied radiance as rendered (exposure not applied).
//! The options, the resolved camera and the timings are saved beside the image as
//! `<out>.render.json`.
//!
//! `--field CAPTURE_DIR --weights W.safetensors` renders straight from the NeLF
//! network over a capture instead of an asset (`nelf_field`: coarse + fine
//! hierarchical sampling inside the head sphere, visual-hull pruning): slow, and the
//! reference a bake of that capture must match. The lighting is projected into the
//! network's light frame; `--estimated-light` uses the network's own estimate of the
//! capture's lighting; orbits circle the visual hull's box.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use glam::{DMat3, DVec3};
use nelf_format::capture::Capture;
use nelf_format::conventions::{ENV_H, ENV_W, LatLong, PinholeCamera, rotation_y};
use nelf_format::{Asset, read_asset};
use nelf_render::{Image, MarchSettings, render_asset};
use serde::{Deserialize, Serialize};

/// Options of `nelf render`.
#[derive(Debug, Clone, clap::Args, Serialize, Deserialize)]
pub struct RenderArgs {
    /// The .nelf asset (not with --field).
    #[arg(required_unless_present = "field")]
    pub asset: Option<PathBuf>,
    /// Render straight from the NeLF network over this capture folder instead of an
    /// asset (slow: the reference a bake must match). Needs --weights.
    #[arg(long, value_name = "CAPTURE_DIR", requires = "weights", conflicts_with_all = ["asset", "gpu", "rank"])]
    pub field: Option<PathBuf>,
    /// --field: the network's weights (safetensors, official checkpoint key names).
    #[arg(long, requires = "field")]
    pub weights: Option<PathBuf>,
    /// --field: light with the network's own estimate of the capture's lighting
    /// (`nelf light`) instead of --envmap / the capture's map / constant white.
    #[arg(long, requires = "field", conflicts_with = "envmap")]
    pub estimated_light: bool,
    /// --field: random ray samples from this seed instead of stratified ones.
    #[arg(long, requires = "field")]
    pub field_seed: Option<u64>,
    /// Camera file: a cameras.json view object (metres) or a previous `.render.json`.
    #[arg(long, group = "view")]
    pub camera: Option<PathBuf>,
    /// A view or target of a capture folder, as `CAPTURE_DIR:VIEW_NAME`.
    #[arg(long, value_name = "CAPTURE_DIR:VIEW_NAME", group = "view")]
    pub view_of: Option<String>,
    /// Orbit camera `AZ,EL[,DIST]` (degrees, degrees, metres) around the box centre.
    #[arg(long, value_name = "AZ,EL[,DIST]", group = "view", allow_hyphen_values = true)]
    pub orbit: Option<String>,
    /// Image width in pixels (orbit default 512; rescales a given camera's intrinsics).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (orbit default 512; rescales a given camera's intrinsics).
    #[arg(long)]
    pub height: Option<u32>,
    /// Horizontal field of view of the orbit camera, degrees.
    #[arg(long, default_value_t = 30.0)]
    pub fov_deg: f64,
    /// Environment map (.exr or .hdr, lat-long, any resolution); default: constant white.
    #[arg(long)]
    pub envmap: Option<PathBuf>,
    /// Turn the lighting about +y by this many degrees.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub rotate_deg: f64,
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

/// A camera in the `cameras.json` view layout, metres.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    name: Option<String>,
    width: u32,
    height: u32,
    intrinsics: IntrinsicsJson,
    world_to_camera: ExtrinsicsJson,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct IntrinsicsJson {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ExtrinsicsJson {
    /// Row-major `R`.
    rotation: [[f64; 3]; 3],
    /// Metres.
    translation: [f64; 3],
}

impl CameraJson {
    fn from_camera(camera: &PinholeCamera) -> Self {
        let r = camera.rotation;
        Self {
            name: None,
            width: camera.width,
            height: camera.height,
            intrinsics: IntrinsicsJson {
                fx: camera.fx,
                fy: camera.fy,
                cx: camera.cx,
                cy: camera.cy,
            },
            world_to_camera: ExtrinsicsJson {
                rotation: [0, 1, 2].map(|i| r.row(i).to_array()),
                translation: camera.translation.to_array(),
            },
        }
    }

    fn to_camera(&self) -> PinholeCamera {
        let rows = self.world_to_camera.rotation.map(DVec3::from_array);
        PinholeCamera {
            width: self.width,
            height: self.height,
            fx: self.intrinsics.fx,
            fy: self.intrinsics.fy,
            cx: self.intrinsics.cx,
            cy: self.intrinsics.cy,
            rotation: DMat3::from_cols(rows[0], rows[1], rows[2]).transpose(),
            translation: DVec3::from_array(self.world_to_camera.translation),
        }
    }
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

/// Runs `nelf render`.
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let output = OutputKind::of(&args.out)?;
    let settings = MarchSettings {
        step_voxels: args.step_voxels,
        min_transmittance: args.min_transmittance,
        pixel_grid: args.pixel_grid,
    };
    settings.validate()?;
    if let Some(capture) = &args.field {
        return run_field(args, capture, output);
    }
    let start = Instant::now();
    let asset_path = args
        .asset
        .as_ref()
        .context("an asset (or --field CAPTURE) is required")?;
    let asset = read_asset(asset_path).with_context(|| format!("cannot read {}", asset_path.display()))?;
    let rank = match args.rank {
        Some(k) if k == 0 || k > asset.rank() => {
            bail!(
                "--rank {k}: the asset has PCA rank {} (use 1..={})",
                asset.rank(),
                asset.rank()
            )
        }
        other => other,
    };
    let asset_box = (
        DVec3::from_array(asset.grid.bbox_min_m),
        DVec3::from_array(asset.grid.bbox_max_m()),
    );
    let (camera, capture_envmap) = resolve_camera(args, asset_box)?;
    let (env, envmap_name) = lighting(args, capture_envmap.as_deref())?;
    let world_from_env = rotation_y(args.rotate_deg.to_radians());
    let load_seconds = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let image = if args.gpu {
        render_gpu(&asset, &camera, &env, world_from_env, rank, settings)?
    } else {
        render_cpu(&asset, &camera, &env, world_from_env, rank, settings)?
    };
    let render_seconds = start.elapsed().as_secs_f64();

    match output {
        OutputKind::Png => nelf_scene::image_io::write_png_srgb(
            &args.out,
            image.width,
            image.height,
            &image.rgb,
            args.exposure,
        ),
        OutputKind::Exr => {
            nelf_scene::image_io::write_exr_rgb(&args.out, image.width, image.height, &image.rgb)
        }
    }
    .with_context(|| format!("cannot write {}", args.out.display()))?;
    let record = RenderRecord {
        config: args,
        camera: CameraJson::from_camera(&camera),
        envmap: envmap_name.clone(),
        rank_used: rank.unwrap_or(asset.rank()),
        voxels: asset.voxel_count(),
        device: if args.gpu { "gpu" } else { "cpu" },
        load_seconds,
        render_seconds,
    };
    super::save_record(&args.out, "render", &record)?;
    println!(
        "rendered {}×{} (rank {} of {}, {} voxels, lighting: {envmap_name}) in {render_seconds:.3} s on the {} -> {}",
        image.width,
        image.height,
        record.rank_used,
        asset.rank(),
        asset.voxel_count(),
        if args.gpu { "GPU" } else { "CPU" },
        args.out.display()
    );
    Ok(())
}

/// The CPU path (the reference renderer); [`render_gpu`] sits beside it.
fn render_cpu(
    asset: &Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    world_from_env: DMat3,
    rank: Option<usize>,
    settings: MarchSettings,
) -> anyhow::Result<Image> {
    Ok(render_asset(asset, camera, env, world_from_env, rank, &settings)?)
}

/// The GPU path (`nelf_viewer`): the same camera, lighting, rank and march settings,
/// no jitter, read back as the same premultiplied linear image. The time includes
/// creating the device and uploading the asset.
fn render_gpu(
    asset: &Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    world_from_env: DMat3,
    rank: Option<usize>,
    settings: MarchSettings,
) -> anyhow::Result<Image> {
    let mut gpu = nelf_viewer::GpuRenderer::new_headless()?;
    gpu.load_asset(asset)?;
    gpu.set_lighting(env, world_from_env)?;
    gpu.set_rank(rank);
    let view = nelf_viewer::ViewSettings {
        march: settings,
        jitter: false,
        frame_index: 0,
        view: nelf_viewer::MarchView::Shaded,
        pass: nelf_viewer::MarchPass::default(),
    };
    Ok(gpu.render(camera, &view)?)
}

/// `--field CAPTURE --weights W`: renders every pixel straight from the NeLF network
/// (`nelf_field::render::render_image`: coarse + fine hierarchical sampling, rays
/// through pixel centres, bounded by the head sphere) under the lighting projected
/// into the network's light frame. Orbits circle the field's hull box.
fn run_field(args: &RenderArgs, capture_dir: &Path, output: OutputKind) -> anyhow::Result<()> {
    use nelf_field::capture::{default_net_from_world, load_capture_dir};
    use nelf_field::render::{ImageSettings, Sampling, render_image};
    use nelf_scene::field::FieldSource;

    let start = Instant::now();
    let weights = args.weights.as_ref().context("--field needs --weights")?;
    let (capture, _) = load_capture_dir(capture_dir, default_net_from_world())
        .with_context(|| format!("loading the capture {}", capture_dir.display()))?;
    let device = nelf_field::default_device();
    let model = nelf_field::Model::load(weights, nelf_field::NelfConfig::for_device(&device), &device)
        .with_context(|| format!("loading the weights {}", weights.display()))?;
    let field = nelf_field::NelfField::new(model, &capture).context("encoding the capture")?;
    let (lo, hi) = field.bounds();
    let (camera, capture_envmap) = resolve_camera(args, (lo.as_dvec3(), hi.as_dvec3()))?;
    let world_from_light = field.world_from_light();
    let (light, light_name) = if args.estimated_light {
        (
            field.source_light()?,
            "the network's estimate of the capture's lighting".to_string(),
        )
    } else {
        let (env, name) = lighting(args, capture_envmap.as_deref())?;
        let world_from_env = rotation_y(args.rotate_deg.to_radians());
        (
            nelf_format::conventions::project_envmap(&env, world_from_env.transpose() * world_from_light)?,
            name,
        )
    };
    let net_light = nelf_field::light::latlong_to_net_light(&light)?;
    let load_seconds = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let settings = ImageSettings {
        head_centre: capture.head_centre_net(),
        sampling: args.field_seed.map_or(Sampling::Stratified, Sampling::Random),
        ..ImageSettings::default()
    };
    let progress = indicatif::ProgressBar::new(0);
    let image = render_image(
        field.model(),
        field.encoded(),
        &capture.net_camera(&camera),
        &net_light,
        &settings,
        Some(&progress),
    )?;
    progress.finish_and_clear();
    let render_seconds = start.elapsed().as_secs_f64();
    let (width, height) = (image.width as u32, image.height as u32);
    match output {
        OutputKind::Png => {
            nelf_scene::image_io::write_png_srgb(&args.out, width, height, &image.rgb, args.exposure)
        }
        OutputKind::Exr => nelf_scene::image_io::write_exr_rgb(&args.out, width, height, &image.rgb),
    }
    .with_context(|| format!("cannot write {}", args.out.display()))?;
    let record = serde_json::json!({
        "config": args,
        "camera": CameraJson::from_camera(&camera),
        "envmap": light_name,
        "device": format!("nelf-network ({})", nelf_field::device_name(&device)),
        "world_from_light": world_from_light.to_cols_array(),
        "load_seconds": load_seconds,
        "render_seconds": render_seconds,
    });
    super::save_record(&args.out, "render", &record)?;
    println!(
        "rendered {width}×{height} from the NeLF network over {} (lighting: {light_name}) in {render_seconds:.1} s -> {}",
        capture_dir.display(),
        args.out.display()
    );
    Ok(())
}

/// Output formats, chosen by extension.
#[derive(Debug, Clone, Copy)]
enum OutputKind {
    Png,
    Exr,
}

impl OutputKind {
    fn of(path: &Path) -> anyhow::Result<Self> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("png") => Ok(Self::Png),
            Some("exr") => Ok(Self::Exr),
            _ => bail!("output {} must end in .png or .exr", path.display()),
        }
    }
}

/// The lighting to render under: `--envmap`, else the capture's env map (when the
/// camera came from a capture), else a constant white map; with its name.
fn lighting(
    args: &RenderArgs,
    capture_envmap: Option<&std::path::Path>,
) -> anyhow::Result<(LatLong, String)> {
    Ok(match args.envmap.as_deref().or(capture_envmap) {
        Some(path) => (
            nelf_scene::envmap::load_envmap(path)
                .with_context(|| format!("cannot load environment map {}", path.display()))?,
            path.display().to_string(),
        ),
        None => (
            LatLong::constant(ENV_W, ENV_H, [1.0; 3]),
            "constant white (radiance 1)".to_string(),
        ),
    })
}

/// The camera from `--camera`, `--view-of` or `--orbit` (default `--orbit 0,0`), and the
/// lighting a capture view comes with, if any.
fn resolve_camera(
    args: &RenderArgs,
    scene_box: (DVec3, DVec3),
) -> anyhow::Result<(PinholeCamera, Option<PathBuf>)> {
    let (camera, envmap) = if let Some(path) = &args.camera {
        (resized(load_camera_file(path)?, args)?, None)
    } else if let Some(spec) = &args.view_of {
        let (dir, name) = spec
            .rsplit_once(':')
            .with_context(|| format!("--view-of {spec:?}: expected CAPTURE_DIR:VIEW_NAME"))?;
        let capture = Capture::load(dir).with_context(|| format!("cannot load the capture folder {dir}"))?;
        let dir = Path::new(dir);
        if let Some(view) = capture.view(name) {
            (resized(view.camera, args)?, capture.envmap_path(dir))
        } else if let Some(target) = capture.target(name) {
            (resized(target.camera, args)?, Some(target.envmap_path(dir)))
        } else {
            bail!("capture {} has no view or target named {name:?}", dir.display());
        }
    } else {
        (
            orbit_camera(args.orbit.as_deref().unwrap_or("0,0"), args, scene_box)?,
            None,
        )
    };
    camera.validate().context("invalid camera")?;
    Ok((camera, envmap))
}

/// Reads a camera object, or the `camera` of a previous `.render.json`.
fn load_camera_file(path: &Path) -> anyhow::Result<PinholeCamera> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))?;
    let object = value.get("camera").cloned().unwrap_or(value);
    let camera: CameraJson = serde_json::from_value(object).with_context(|| {
        format!(
            "{}: expected a camera {{width, height, intrinsics {{fx, fy, cx, cy}}, world_to_camera {{rotation, translation}}}}",
            path.display()
        )
    })?;
    let camera = camera.to_camera();
    camera
        .validate()
        .with_context(|| format!("invalid camera in {}", path.display()))?;
    Ok(camera)
}

/// A given camera at `--width`/`--height` (intrinsics scaled; one given keeps the aspect).
fn resized(camera: PinholeCamera, args: &RenderArgs) -> anyhow::Result<PinholeCamera> {
    let (w0, h0) = (f64::from(camera.width), f64::from(camera.height));
    let (width, height) = match (args.width, args.height) {
        (None, None) => return Ok(camera),
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, (f64::from(w) * h0 / w0).round().max(1.0) as u32),
        (None, Some(h)) => ((f64::from(h) * w0 / h0).round().max(1.0) as u32, h),
    };
    if width == 0 || height == 0 {
        bail!("image size {width}×{height} must be positive");
    }
    let (sx, sy) = (f64::from(width) / w0, f64::from(height) / h0);
    Ok(PinholeCamera {
        width,
        height,
        fx: camera.fx * sx,
        fy: camera.fy * sy,
        cx: camera.cx * sx,
        cy: camera.cy * sy,
        ..camera
    })
}

/// `--orbit AZ,EL[,DIST]` around the centre of `scene_box` (the asset's box, or the
/// field's hull box), +y up.
fn orbit_camera(spec: &str, args: &RenderArgs, scene_box: (DVec3, DVec3)) -> anyhow::Result<PinholeCamera> {
    let numbers = spec
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("--orbit {spec:?}: expected AZ,EL[,DIST] numbers"))?;
    let (azimuth_deg, elevation_deg, distance) = match numbers[..] {
        [a, e] => (a, e, None),
        [a, e, d] => (a, e, Some(d)),
        _ => bail!("--orbit {spec:?}: expected two or three numbers AZ,EL[,DIST]"),
    };
    if !(azimuth_deg.is_finite() && elevation_deg.is_finite() && elevation_deg.abs() < 89.9) {
        bail!("--orbit {spec:?}: azimuth must be finite and elevation within (-89.9, 89.9) degrees");
    }
    let (width, height) = (args.width.unwrap_or(512), args.height.unwrap_or(512));
    if width == 0 || height == 0 {
        bail!("image size {width}×{height} must be positive");
    }
    if !(args.fov_deg.is_finite() && args.fov_deg > 0.0 && args.fov_deg < 179.0) {
        bail!("--fov-deg {} must be in (0, 179)", args.fov_deg);
    }
    let fov_x = args.fov_deg.to_radians();
    let (lo, hi) = scene_box;
    let centre = 0.5 * (lo + hi);
    let distance = match distance {
        Some(d) if d.is_finite() && d > 0.0 => d,
        Some(d) => bail!("--orbit distance {d} must be positive"),
        None => {
            // The narrower of the two fields of view must hold the box's bounding sphere.
            let fov_y = 2.0 * ((0.5 * fov_x).tan() * f64::from(height) / f64::from(width)).atan();
            0.5 * (hi - lo).length() / (0.5 * fov_x.min(fov_y)).sin()
        }
    };
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let eye = centre + distance * DVec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    Ok(PinholeCamera::look_at(
        eye,
        centre,
        DVec3::Y,
        width,
        height,
        fov_x,
    ))
}
