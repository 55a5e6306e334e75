//! Synthetic captures: a head mesh lit by a distant environment map and
//! photographed from a few viewpoints, written as a capture folder
//! (`format/CAPTURE.md`) with its exact answers beside it.
//!
//! Every image is `radiance_c = Σ_k T[c][k] · L_k[c]` with `T` from the
//! light-transport path tracer ([`crate::tracer`]) and `L` the map projected into
//! the 8 × 16 basis (world frame = light frame). Source views surround a frontal
//! view (view 0, on +z looking at the head) within `±max_angle_deg` of azimuth and
//! elevation, at `min_distance_m..max_distance_m`; the focal length makes the head's
//! bounding sphere fill `fill` of the frame height. Held-aside target views sit
//! between the source views (novel view) under a different map (novel light), each
//! optionally turned about +y (`target_env_rotate_deg`).
//!
//! Layout written (all paths relative to the output folder):
//! `cameras.json`, `synth_config.json` (the [`SynthConfig`] used),
//! `images/<view>.exr` (linear RGB composited over black, i.e. already multiplied by
//! the mask), `previews/<view>.png` (sRGB), `masks/<view>.png` (coverage),
//! `lighting/source.exr` (+ `.png`) and `lighting/<target>.exr` (8 × 16 maps),
//! `targets/<target>.exr|.png` and `targets/<target>_mask.png`, and a COLMAP text
//! model of the source cameras in `colmap/` (image names as in `images/`).

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use nelf_format::capture::{Capture, CaptureView, TargetView};
use nelf_format::colmap::write_colmap_text;
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::io_error::FileIoError;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};

use crate::envgen::{EnvGenParams, procedural_envmap};
use crate::envmap::{envmap_to_basis, load_envmap, luminance, save_envmap_preview};
use crate::error::SceneError;
use crate::head::{HeadParams, head_traits, procedural_head};
use crate::image_io::{write_exr_rgb, write_png_gray, write_png_srgb};
use crate::mesh::Mesh;
use crate::mesh_io::{LoadOptions, load_mesh};
use crate::render::{RenderError, RenderedImage, render_lt_image};
use crate::tracer::{LtTracer, Specular, TraceError, TraceSettings};

/// Errors writing a synthetic capture.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A mesh, map or image file could not be read or written.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The tracer rejected the mesh or settings.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The capture description could not be written.
    #[error(transparent)]
    Capture(#[from] nelf_format::capture::CaptureError),
    /// The COLMAP export failed.
    #[error(transparent)]
    Colmap(#[from] nelf_format::colmap::ColmapError),
    /// A setting is out of range.
    #[error("invalid synthetic capture settings: {0}")]
    Settings(String),
    /// Writing the configuration failed.
    #[error("{path}: {message}")]
    Config {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Settings of `nelf capture synth`; saved beside its outputs as `synth_config.json`.
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct SynthConfig {
    /// Mesh to photograph (.obj or .off); default: a procedural head from `--head-seed`.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Height a loaded mesh is scaled to, metres (head and neck).
    #[arg(long, default_value_t = 0.23)]
    pub mesh_height_m: f32,
    /// Turn a loaded mesh about +y by this many degrees so that it faces +z
    /// (90 for `data/meshes/head.off`).
    #[arg(long, default_value_t = 0.0)]
    pub mesh_rotate_y_deg: f32,
    /// Seed of the procedural head (shape, skin tone, hair).
    #[arg(long, default_value_t = 0)]
    pub head_seed: u64,
    /// Grid cells along the procedural head's height (triangle count ≈ 4·n²).
    #[arg(long, default_value_t = 96)]
    pub head_cells: u32,
    /// Lighting of the source views: a lat-long .exr or .hdr; default: a procedural
    /// map from `--env-seed`.
    #[arg(long)]
    pub envmap: Option<PathBuf>,
    /// Seed of the procedural source lighting.
    #[arg(long, default_value_t = 1)]
    pub env_seed: u64,
    /// Turn the source lighting about +y by this many degrees.
    #[arg(long, default_value_t = 0.0)]
    pub env_rotate_deg: f32,
    /// Number of source views (view 0 is frontal).
    #[arg(long, default_value_t = 5)]
    pub views: usize,
    /// Largest azimuth and elevation of a view from the frontal one, degrees.
    #[arg(long, default_value_t = 30.0)]
    pub max_angle_deg: f64,
    /// Nearest camera distance from the head centre, metres.
    #[arg(long, default_value_t = 1.0)]
    pub min_distance_m: f64,
    /// Farthest camera distance from the head centre, metres.
    #[arg(long, default_value_t = 2.0)]
    pub max_distance_m: f64,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Share of the frame height the head's bounding sphere fills.
    #[arg(long, default_value_t = 0.9)]
    pub fill: f64,
    /// Seed of the camera placement.
    #[arg(long, default_value_t = 2)]
    pub camera_seed: u64,
    /// Number of held-aside target views (novel view under novel light).
    #[arg(long, default_value_t = 2)]
    pub targets: usize,
    /// Lighting of the target views, one file per target (repeat the option);
    /// default: procedural maps from `--target-env-seed`.
    #[arg(long)]
    pub target_envmap: Vec<PathBuf>,
    /// First seed of the procedural target lighting (target i uses seed + i).
    #[arg(long, default_value_t = 100)]
    pub target_env_seed: u64,
    /// Turn each target's lighting about +y by this many degrees, one value per
    /// target (repeat the option); default: none is turned.
    #[arg(long, allow_negative_numbers = true)]
    #[serde(default)]
    pub target_env_rotate_deg: Vec<f32>,
    /// Interreflection bounces of the path tracer.
    #[arg(long, default_value_t = 2)]
    pub bounces: u32,
    /// Stratified samples per light texel for direct lighting.
    #[arg(long, default_value_t = 16)]
    pub texel_samples: u32,
    /// Indirect directions at the first surface point.
    #[arg(long, default_value_t = 128)]
    pub indirect_samples: u32,
    /// Share of reflected energy in a broad glossy lobe (0 = Lambertian).
    #[arg(long, default_value_t = 0.04)]
    pub specular_weight: f32,
    /// Seed of the path tracer.
    #[arg(long, default_value_t = 0)]
    pub trace_seed: u64,
    /// Colour rays per pixel along each axis (1: the pixel centre, which aliases
    /// texture finer than a pixel; a camera integrates over the pixel, as 4 does).
    #[arg(long, default_value_t = 1)]
    #[serde(default = "one")]
    pub pixel_grid: u32,
}

fn one() -> u32 {
    1
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            mesh: None,
            mesh_height_m: 0.23,
            mesh_rotate_y_deg: 0.0,
            head_seed: 0,
            head_cells: 96,
            envmap: None,
            env_seed: 1,
            env_rotate_deg: 0.0,
            views: 5,
            max_angle_deg: 30.0,
            min_distance_m: 1.0,
            max_distance_m: 2.0,
            width: 512,
            height: 512,
            fill: 0.9,
            camera_seed: 2,
            targets: 2,
            target_envmap: Vec::new(),
            target_env_seed: 100,
            target_env_rotate_deg: Vec::new(),
            bounces: 2,
            texel_samples: 16,
            indirect_samples: 128,
            specular_weight: Specular::MILD_SHEEN.weight,
            trace_seed: 0,
            pixel_grid: 1,
        }
    }
}

impl SynthConfig {
    /// Checks ranges before any work is done.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |m: String| Err(SynthError::Settings(m));
        if self.views < 2 {
            return bad(format!("--views {} (a capture needs at least 2)", self.views));
        }
        if !(self.max_angle_deg.is_finite() && (0.0..=80.0).contains(&self.max_angle_deg)) {
            return bad(format!(
                "--max-angle-deg {} must be in [0, 80]",
                self.max_angle_deg
            ));
        }
        if !(self.min_distance_m > 0.0 && self.max_distance_m >= self.min_distance_m) {
            return bad(format!(
                "distances {}..{} m must be positive and ordered",
                self.min_distance_m, self.max_distance_m
            ));
        }
        if self.width < 16 || self.height < 16 || self.width > 8192 || self.height > 8192 {
            return bad(format!(
                "image size {}×{} must be within 16..8192",
                self.width, self.height
            ));
        }
        if !(self.fill > 0.05 && self.fill <= 1.0) {
            return bad(format!("--fill {} must be in (0.05, 1]", self.fill));
        }
        if !(self.mesh_height_m.is_finite() && self.mesh_height_m > 0.0) {
            return bad(format!("--mesh-height-m {} must be positive", self.mesh_height_m));
        }
        if !self.target_envmap.is_empty() && self.target_envmap.len() != self.targets {
            return bad(format!(
                "{} --target-envmap files for {} targets",
                self.target_envmap.len(),
                self.targets
            ));
        }
        if !self.target_env_rotate_deg.is_empty() && self.target_env_rotate_deg.len() != self.targets {
            return bad(format!(
                "{} --target-env-rotate-deg values for {} targets",
                self.target_env_rotate_deg.len(),
                self.targets
            ));
        }
        if !(0.0..=1.0).contains(&self.specular_weight) {
            return bad(format!(
                "--specular-weight {} must be in [0, 1]",
                self.specular_weight
            ));
        }
        if !(1..=16).contains(&self.pixel_grid) {
            return bad(format!("--pixel-grid {} must be in 1..=16", self.pixel_grid));
        }
        Ok(())
    }

    /// The path tracer settings these options describe.
    pub fn trace_settings(&self) -> TraceSettings {
        TraceSettings {
            bounces: self.bounces,
            texel_samples: self.texel_samples,
            indirect_samples: self.indirect_samples,
            specular: (self.specular_weight > 0.0).then_some(Specular {
                weight: self.specular_weight,
                ..Specular::MILD_SHEEN
            }),
            seed: self.trace_seed,
            pixel_grid: self.pixel_grid,
            ..TraceSettings::default()
        }
    }
}

/// What a synthetic capture run produced, with timings.
#[derive(Debug, Clone, Serialize)]
pub struct SynthReport {
    /// The capture folder.
    pub out_dir: PathBuf,
    /// Source views written.
    pub views: usize,
    /// Target views written.
    pub targets: usize,
    /// Triangles in the mesh.
    pub triangles: usize,
    /// Seconds to build the mesh and the tracer.
    pub setup_secs: f64,
    /// Seconds rendering each source view.
    pub view_secs: Vec<f64>,
    /// Seconds rendering each target view.
    pub target_secs: Vec<f64>,
    /// Seconds for the whole run.
    pub total_secs: f64,
}

/// Azimuth/elevation/distance of a viewpoint around the head centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Viewpoint {
    /// Azimuth from the frontal direction (+z) toward +x, radians.
    pub azimuth_rad: f64,
    /// Elevation above the horizontal, radians.
    pub elevation_rad: f64,
    /// Distance from the head centre, metres.
    pub distance_m: f64,
}

impl Viewpoint {
    /// Unit direction from the head centre to the camera.
    pub fn direction(&self) -> DVec3 {
        let (sa, ca) = self.azimuth_rad.sin_cos();
        let (se, ce) = self.elevation_rad.sin_cos();
        DVec3::new(sa * ce, se, ca * ce)
    }
}

/// Source viewpoints: view 0 frontal at the middle distance; the others on a ring
/// around it at 60–100 % of the largest angle, evenly spread in angle with seeded
/// jitter, at seeded distances.
pub fn source_viewpoints(config: &SynthConfig) -> Vec<Viewpoint> {
    ring_viewpoints(config, config.views, 0.6, 1.0, 0.0, config.camera_seed)
}

/// Target viewpoints: between the source ring's views (half a step around) at
/// 30–60 % of the largest angle — novel, but inside the captured cone.
pub fn target_viewpoints(config: &SynthConfig) -> Vec<Viewpoint> {
    let ring = config.views.saturating_sub(1).max(1) as f64;
    let mut points = ring_viewpoints(
        config,
        config.targets + 1,
        0.3,
        0.6,
        PI / ring,
        config.camera_seed ^ 0x7A,
    );
    points.remove(0);
    points
}

fn ring_viewpoints(
    config: &SynthConfig,
    count: usize,
    radius_lo: f64,
    radius_hi: f64,
    phase: f64,
    seed: u64,
) -> Vec<Viewpoint> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let max = config.max_angle_deg.to_radians();
    let mid = 0.5 * (config.min_distance_m + config.max_distance_m);
    let mut out = vec![Viewpoint {
        azimuth_rad: 0.0,
        elevation_rad: 0.0,
        distance_m: mid,
    }];
    let ring = count.saturating_sub(1).max(1) as f64;
    for i in 1..count {
        let step = 2.0 * PI / ring;
        let angle = phase + (i - 1) as f64 * step + rng.random_range(-0.2..0.2) * step;
        let radius = max * rng.random_range(radius_lo..=radius_hi);
        let distance = rng.random_range(config.min_distance_m..=config.max_distance_m);
        out.push(Viewpoint {
            azimuth_rad: (radius * angle.cos()).clamp(-max, max),
            elevation_rad: (radius * angle.sin()).clamp(-max, max),
            distance_m: distance,
        });
    }
    out
}

/// A camera at `view` around `centre`, looking at it with +y up, whose vertical
/// field of view makes a sphere of `radius_m` fill `fill` of the frame height.
pub fn camera_for(view: &Viewpoint, centre: DVec3, radius_m: f64, config: &SynthConfig) -> PinholeCamera {
    let eye = centre + view.direction() * view.distance_m;
    let half_angle = (radius_m / view.distance_m).clamp(1e-6, 0.999).asin();
    let half_fov_y = (half_angle.tan() / config.fill).atan();
    let fy = 0.5 * f64::from(config.height) / half_fov_y.tan();
    let fov_x = 2.0 * (0.5 * f64::from(config.width) / fy).atan();
    PinholeCamera::look_at(eye, centre, DVec3::Y, config.width, config.height, fov_x)
}

/// The mesh the configuration names: a loaded file or a procedural head.
pub fn synth_mesh(config: &SynthConfig) -> Result<Mesh, SynthError> {
    match &config.mesh {
        Some(path) => Ok(load_mesh(
            path,
            &LoadOptions {
                fit_height_m: Some(config.mesh_height_m),
                rotate_y_deg: config.mesh_rotate_y_deg,
                ..LoadOptions::default()
            },
        )?),
        None => Ok(procedural_head(
            config.head_seed,
            &HeadParams {
                cells_per_height: config.head_cells,
                ..HeadParams::default()
            },
        )),
    }
}

/// Lighting in the 8 × 16 basis from a file or a procedural seed, turned by `rotate_deg`.
fn lighting(file: Option<&Path>, seed: u64, rotate_deg: f32) -> Result<LatLong, SynthError> {
    let full = match file {
        Some(path) => load_envmap(path)?,
        None => procedural_envmap(seed, &EnvGenParams::default()),
    };
    Ok(envmap_to_basis(&full, rotate_deg))
}

/// Exposure (stops) that puts the mean luminance of the covered pixels at 0.36.
fn preview_exposure(image: &RenderedImage) -> f32 {
    let (sum, weight) = image
        .rgb
        .iter()
        .zip(&image.alpha)
        .fold((0.0f64, 0.0f64), |(s, w), (c, &a)| {
            (s + f64::from(luminance(*c) * a), w + f64::from(a))
        });
    let mean = if weight > 0.0 { sum / weight } else { 0.0 };
    if mean > 0.0 && mean.is_finite() {
        (0.36 / mean).log2() as f32
    } else {
        0.0
    }
}

/// Writes one rendered view: linear EXR (over black), sRGB preview and mask.
fn write_view(
    image: &RenderedImage,
    exr: &Path,
    preview: &Path,
    mask: &Path,
    exposure_stops: f32,
) -> Result<(), SynthError> {
    let premultiplied = image.over([0.0; 3]);
    write_exr_rgb(exr, image.width, image.height, &premultiplied)?;
    write_png_srgb(preview, image.width, image.height, &premultiplied, exposure_stops)?;
    write_png_gray(mask, image.width, image.height, &image.alpha)?;
    Ok(())
}

fn create_dir(path: &Path) -> Result<(), SynthError> {
    std::fs::create_dir_all(path)
        .map_err(|source| SynthError::Scene(SceneError::Io(FileIoError::new(path.to_path_buf(), source))))
}

/// Renders and writes a synthetic capture into `out_dir` (created if needed).
/// `progress` shows rendered rows over all views; pass a hidden bar for silence.
pub fn write_synthetic_capture(
    config: &SynthConfig,
    out_dir: &Path,
    progress: &ProgressBar,
) -> Result<SynthReport, SynthError> {
    config.validate()?;
    let start = Instant::now();
    for sub in ["images", "previews", "masks", "lighting", "targets", "colmap"] {
        create_dir(&out_dir.join(sub))?;
    }
    let config_path = out_dir.join("synth_config.json");
    let config_json = serde_json::to_string_pretty(config).map_err(|e| SynthError::Config {
        path: config_path.clone(),
        message: e.to_string(),
    })?;
    nelf_format::atomic::write_bytes_atomically(&config_path, (config_json + "\n").as_bytes()).map_err(
        |e| SynthError::Config {
            path: config_path.clone(),
            message: e.to_string(),
        },
    )?;

    let mesh = synth_mesh(config)?;
    let tracer = LtTracer::new(&mesh, config.trace_settings())?;
    let (centre, radius) = mesh.bounding_sphere();
    let source_light = lighting(config.envmap.as_deref(), config.env_seed, config.env_rotate_deg)?;
    write_exr_rgb(out_dir.join("lighting/source.exr"), 16, 8, source_light.texels())?;
    let setup_secs = start.elapsed().as_secs_f64();

    let sources = source_viewpoints(config);
    let target_views = target_viewpoints(config);
    progress.set_length(u64::from(config.height) * (sources.len() + target_views.len()) as u64);
    progress.set_style(
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} rows, {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );

    let mut views = Vec::with_capacity(sources.len());
    let mut view_secs = Vec::with_capacity(sources.len());
    let mut exposure = None;
    for (i, view) in sources.iter().enumerate() {
        let t0 = Instant::now();
        let name = format!("view_{i:03}");
        progress.set_message(name.clone());
        let camera = camera_for(view, centre, radius, config);
        let image = render_lt_image(&tracer, &camera, &source_light, Some(progress))?;
        let stops = *exposure.get_or_insert_with(|| preview_exposure(&image));
        write_view(
            &image,
            &out_dir.join(format!("images/{name}.exr")),
            &out_dir.join(format!("previews/{name}.png")),
            &out_dir.join(format!("masks/{name}.png")),
            stops,
        )?;
        views.push(CaptureView {
            name: name.clone(),
            image: format!("images/{name}.exr"),
            mask: Some(format!("masks/{name}.png")),
            camera,
        });
        view_secs.push(t0.elapsed().as_secs_f64());
    }
    let exposure = exposure.unwrap_or(0.0);
    save_envmap_preview(out_dir.join("lighting/source.png"), &source_light, exposure)?;

    let mut targets = Vec::with_capacity(target_views.len());
    let mut target_secs = Vec::with_capacity(target_views.len());
    for (i, view) in target_views.iter().enumerate() {
        let t0 = Instant::now();
        let name = format!("target_{i:03}");
        progress.set_message(name.clone());
        let light = lighting(
            config.target_envmap.get(i).map(PathBuf::as_path),
            config.target_env_seed + i as u64,
            config.target_env_rotate_deg.get(i).copied().unwrap_or(0.0),
        )?;
        let env_rel = format!("lighting/{name}.exr");
        write_exr_rgb(out_dir.join(&env_rel), 16, 8, light.texels())?;
        save_envmap_preview(out_dir.join(format!("lighting/{name}.png")), &light, exposure)?;
        let camera = camera_for(view, centre, radius, config);
        let image = render_lt_image(&tracer, &camera, &light, Some(progress))?;
        write_view(
            &image,
            &out_dir.join(format!("targets/{name}.exr")),
            &out_dir.join(format!("targets/{name}.png")),
            &out_dir.join(format!("targets/{name}_mask.png")),
            exposure,
        )?;
        targets.push(TargetView {
            image: format!("targets/{name}.exr"),
            mask: Some(format!("targets/{name}_mask.png")),
            name,
            envmap: env_rel,
            camera,
        });
        target_secs.push(t0.elapsed().as_secs_f64());
    }
    progress.finish_and_clear();

    let colmap: Vec<(String, PinholeCamera)> = views
        .iter()
        .map(|v| (format!("{}.exr", v.name), v.camera))
        .collect();
    write_colmap_text(out_dir.join("colmap"), &colmap)?;

    let mut capture = Capture::new(views);
    capture.envmap = Some("lighting/source.exr".into());
    capture.targets = targets;
    capture.metadata = serde_json::json!({
        "generator": "nelf capture synth",
        "mesh": match &config.mesh {
            Some(path) => serde_json::json!({ "file": path.display().to_string() }),
            None => serde_json::json!({
                "procedural_head_seed": config.head_seed,
                "traits": format!("{:?}", head_traits(config.head_seed, &HeadParams::default())),
            }),
        },
        "triangles": mesh.triangles.len(),
        "head_centre_m": [centre.x, centre.y, centre.z],
        "bounding_radius_m": radius,
        "preview_exposure_stops": exposure,
        "images": "linear RGB radiance composited over black (multiplied by the mask)",
        "world_from_light": "identity",
    });
    capture.save(out_dir)?;

    let triangles = mesh.triangles.len();
    Ok(SynthReport {
        out_dir: out_dir.to_path_buf(),
        views: sources.len(),
        targets: target_views.len(),
        triangles,
        setup_secs,
        view_secs,
        target_secs,
        total_secs: start.elapsed().as_secs_f64(),
    })
}
