//! `nelf demo`: the whole pipeline on a built-in default, needing no files.
//!
//! 1. A synthetic capture of a procedural head (`nelf_scene::synth`): source views
//!    around a frontal one, masks, cameras, ground-truth lighting, and held-aside
//!    target views under other lighting.
//! 2. A bake of that capture (`nelf_bake::bake_capture`): visual hull, sparse
//!    bricks, the ground-truth field, weighted PCA with the rank chosen per scene,
//!    quantization, one `.nelf` file.
//! 3. A turntable of the asset under several lightings, rendered by the reference
//!    renderer (`nelf-render`): relighting is the env map projected onto the PCA
//!    basis, so each lighting costs K × 3 numbers.
//! 4. Side-by-sides at the target views (novel view, novel light): ground truth |
//!    baked | |difference| × 4, with PSNR and SSIM (`nelf_bake::eval`).
//! 5. Unless left out, the same capture baked with the shipped NeLF network
//!    (`nelf_field::shipped`; no view-dependent part: the network's transport is
//!    evaluated toward the mean camera), scored at the same targets beside the
//!    ground-truth bake ([`ImagesBakeDemo`], `demo_network.json`).
//! 6. Unless left out, the same capture baked from its photographs by reconstruction
//!    (`--source photos`, [`crate::photo`]: a surface carved from the masks' hull by
//!    stereo, its albedo from the views under the capture's lighting, baked as a
//!    mesh), scored the same way (`demo_photos.json`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DMat3, DVec3};
use indicatif::ProgressBar;
use nelf_format::conventions::{LatLong, PinholeCamera, rotation_y};
use nelf_format::io_error::FileIoError;
use nelf_format::read_asset;
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::envgen::{EnvGenParams, procedural_envmap};
use nelf_scene::envmap::load_envmap;
use nelf_scene::image_io::write_png_srgb;
use nelf_scene::synth::{SynthConfig, write_synthetic_capture};
use serde::{Deserialize, Serialize};

use nelf_bake::eval::{ViewScore, data_range, read_linear_rgb, score_view};
use nelf_bake::{
    BakeConfig, BakeOutput, BakeReport, CaptureLoadOptions, GroundTruth, LoadedCapture, Progress, ViewChoice,
    bake_capture, load_capture,
};

use crate::config::PhotoSettings;
use crate::config::{PipelineConfig, write_bake};
use crate::error::{Context as _, PipelineError, Result};
use crate::network_bake::bake_network;
use crate::photo::{bake_photographs, write_reconstruction};

/// Settings of `nelf demo`; saved as `demo_config.json` in the output folder.
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct DemoConfig {
    /// Seed of the procedural head.
    #[arg(long, default_value_t = 0)]
    pub head_seed: u64,
    /// Side of the capture's square images, pixels.
    #[arg(long, default_value_t = 192)]
    pub capture_size: u32,
    /// Source views in the capture.
    #[arg(long, default_value_t = 5)]
    pub views: usize,
    /// Held-aside target views (novel view and light) for the comparison.
    #[arg(long, default_value_t = 2)]
    pub targets: usize,
    /// Stratified samples per light texel in the ground-truth tracer.
    #[arg(long, default_value_t = 4)]
    pub texel_samples: u32,
    /// Indirect directions per surface point in the ground-truth tracer.
    #[arg(long, default_value_t = 32)]
    pub indirect_samples: u32,
    /// Interreflection bounces in the ground-truth tracer.
    #[arg(long, default_value_t = 1)]
    pub bounces: u32,
    /// Bake resolution: voxels along the longest side of the head's occupied box
    /// (64: 3.2 mm voxels on the default head, a quick bake).
    #[arg(long, default_value_t = 64)]
    pub resolution: u32,
    /// Frames in each turntable (evenly spaced over 360°).
    #[arg(long, default_value_t = 8)]
    pub turntable_frames: u32,
    /// Side of the turntable images, pixels.
    #[arg(long, default_value_t = 256)]
    pub turntable_size: u32,
    /// Seeds of the procedural lightings of the turntable (the capture's own
    /// lighting is always the first).
    #[arg(long, value_delimiter = ',', default_values_t = [7u64, 3, 0])]
    pub turntable_env_seeds: Vec<u64>,
}

impl Default for DemoConfig {
    fn default() -> Self {
        Self {
            head_seed: 0,
            capture_size: 192,
            views: 5,
            targets: 2,
            texel_samples: 4,
            indirect_samples: 32,
            bounces: 1,
            resolution: 64,
            turntable_frames: 8,
            turntable_size: 256,
            turntable_env_seeds: vec![7, 3, 0],
        }
    }
}

/// What the demo wrote, with its measurements.
#[derive(Debug, Clone, Serialize)]
pub struct DemoReport {
    /// The output folder.
    pub out_dir: PathBuf,
    /// The synthetic capture folder.
    pub capture_dir: PathBuf,
    /// The baked asset.
    pub asset: PathBuf,
    /// The bake's report (rank, sizes, timings).
    pub bake: BakeReport,
    /// Turntable frames, one folder per lighting.
    pub turntables: Vec<PathBuf>,
    /// Side-by-side images at the target views.
    pub comparisons: Vec<PathBuf>,
    /// Scores at the target views.
    pub scores: Vec<ViewScore>,
    /// Seconds per stage: capture, bake, turntable, compare.
    pub capture_secs: f64,
    /// Seconds baking (all stages).
    pub bake_secs: f64,
    /// Seconds rendering the turntables.
    pub turntable_secs: f64,
    /// Mean seconds per turntable frame.
    pub turntable_frame_secs: f64,
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    nelf_format::atomic::write_bytes_atomically(path, (text + "\n").as_bytes())
        .map_err(|source| PipelineError::Io(FileIoError::new(path.to_path_buf(), source)))
}

fn create_dir(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path)
        .map_err(|source| PipelineError::Io(FileIoError::new(path.to_path_buf(), source)))
}

/// Centre and radius of the sphere around the box of the voxels that are more
/// than 1 % opaque per voxel: what a camera should frame.
fn occupied_sphere(asset: &nelf_format::Asset) -> (DVec3, f64) {
    let threshold = 0.01 / asset.grid.voxel_size_m as f32;
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for v in 0..asset.voxel_count() {
        if asset.density_at(v) > threshold {
            let p = asset.voxel_position_m(v);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if lo.x > hi.x {
        let [a, b] = [asset.grid.bbox_min_m, asset.grid.bbox_max_m()].map(DVec3::from_array);
        (lo, hi) = (a, b);
    }
    (0.5 * (lo + hi), 0.5 * (hi - lo).length())
}

/// Ground truth | baked | |difference| × 4, side by side, sRGB at `stops`.
pub fn side_by_side(
    path: &Path,
    camera: &PinholeCamera,
    truth: &[[f32; 3]],
    baked: &[[f32; 3]],
    stops: f32,
) -> Result<()> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut strip = vec![[0.0f32; 3]; 3 * w * h];
    for y in 0..h {
        for x in 0..w {
            let t = truth[y * w + x];
            let b = baked[y * w + x];
            let row = y * 3 * w;
            strip[row + x] = t;
            strip[row + w + x] = b;
            strip[row + 2 * w + x] = std::array::from_fn(|c| 4.0 * (t[c] - b[c]).abs());
        }
    }
    Ok(write_png_srgb(
        path,
        3 * camera.width,
        camera.height,
        &strip,
        stops,
    )?)
}

/// What the demo wrote and measured: the ground-truth part and, unless left out, the
/// network's.
#[derive(Debug, Clone)]
pub struct DemoRun {
    /// Steps 1-4 (`demo_report.json`).
    pub report: DemoReport,
    /// Step 5 (`demo_network.json`); `None` when left out.
    pub network: Option<ImagesBakeDemo>,
    /// Step 6 (`demo_photos.json`); `None` when left out.
    pub photos: Option<ImagesBakeDemo>,
}

/// The demo's capture baked from its five images alone (steps 5 and 6), scored at
/// the targets.
#[derive(Debug, Clone)]
pub struct ImagesBakeDemo {
    /// The asset.
    pub asset: PathBuf,
    /// Its bake's report.
    pub bake: BakeReport,
    /// Seconds from the loaded capture to the written asset (a reconstruction's too).
    pub bake_secs: f64,
    /// What else made it: the network's weights, or where the reconstruction went.
    pub made_by: String,
    /// Side-by-side images at the target views (ground truth | this bake | |diff|×4).
    pub comparisons: Vec<PathBuf>,
    /// Its scores at the target views (the ground-truth bake's are the report's).
    pub scores: Vec<ViewScore>,
}

/// Which of the demo's last steps run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DemoSteps {
    /// Step 5: the shipped network's bake.
    pub network: bool,
    /// Step 6: the photographs' reconstruction and its bake.
    pub photos: bool,
}

/// Runs the demo into `out_dir`, with the last steps `steps` asks for. Progress bars
/// go to standard error when `progress` is visible.
pub fn run_demo(
    config: &DemoConfig,
    out_dir: &Path,
    progress: Progress,
    steps: DemoSteps,
) -> Result<DemoRun> {
    let report = run_ground_truth(config, out_dir, progress)?;
    let (mut network, mut photos) = (None, None);
    if steps.network || steps.photos {
        let capture = load_capture(&report.capture_dir, &CaptureLoadOptions::default())
            .with_context(|| format!("loading {}", report.capture_dir.display()))?;
        let bake_config = PipelineConfig::from(BakeConfig {
            resolution: config.resolution,
            view_dependence: ViewChoice::Off,
            ..BakeConfig::default()
        });
        if steps.network {
            network = Some(network_step(&capture, &bake_config, &report, progress)?);
        }
        if steps.photos {
            photos = Some(photos_step(&capture, &bake_config, &report, progress)?);
        }
    }
    Ok(DemoRun {
        report,
        network,
        photos,
    })
}

/// Steps 1-4: capture, the ground truth's bake, turntables, comparisons.
fn run_ground_truth(config: &DemoConfig, out_dir: &Path, progress: Progress) -> Result<DemoReport> {
    create_dir(out_dir)?;
    write_json(&out_dir.join("demo_config.json"), config)?;

    // 1. Capture.
    let t = Instant::now();
    let capture_dir = out_dir.join("capture");
    let synth = SynthConfig {
        head_seed: config.head_seed,
        views: config.views,
        targets: config.targets,
        width: config.capture_size,
        height: config.capture_size,
        texel_samples: config.texel_samples,
        indirect_samples: config.indirect_samples,
        bounces: config.bounces,
        ..SynthConfig::default()
    };
    let bar = progress.bar("capture", 0, "rows");
    write_synthetic_capture(&synth, &capture_dir, &bar)?;
    let capture_secs = t.elapsed().as_secs_f64();

    // 2. Bake.
    let t = Instant::now();
    let capture = load_capture(&capture_dir, &CaptureLoadOptions::default())?;
    let truth = GroundTruth::from_synth_capture(&capture_dir)?;
    let bake_config = BakeConfig {
        resolution: config.resolution,
        ..BakeConfig::default()
    };
    let mut output = bake_capture(&capture, &truth, &bake_config, &progress)?;
    let asset_path = out_dir.join("head.nelf");
    write_bake(&mut output, &PipelineConfig::from(bake_config), &asset_path)?;
    let bake_secs = t.elapsed().as_secs_f64();
    // Render what a user of the file gets: the asset as read back.
    let asset = read_asset(&asset_path)?;

    // 3. Turntables.
    let t = Instant::now();
    let source_env = match capture.source_envmap_path() {
        Some(path) => load_envmap(&path)?,
        None => procedural_envmap(1, &EnvGenParams::default()),
    };
    let mut lightings: Vec<(String, LatLong)> = vec![("capture_light".into(), source_env)];
    for &seed in &config.turntable_env_seeds {
        lightings.push((
            format!("env_seed_{seed}"),
            procedural_envmap(seed, &EnvGenParams::default()),
        ));
    }
    let (centre, radius) = occupied_sphere(&asset);
    let distance = 1.5;
    let half_fov = (radius / distance).asin() / 0.9;
    let frames = config.turntable_frames.max(1);
    let bar: ProgressBar = progress.bar("turntable", u64::from(frames) * lightings.len() as u64, "frames");
    let mut turntables = Vec::new();
    let mut stops = None;
    for (name, env) in &lightings {
        let dir = out_dir.join("turntable").join(name);
        create_dir(&dir)?;
        for f in 0..frames {
            let angle = 2.0 * std::f64::consts::PI * f64::from(f) / f64::from(frames);
            let eye = centre + rotation_y(angle) * DVec3::new(0.0, 0.0, distance);
            let camera = PinholeCamera::look_at(
                eye,
                centre,
                DVec3::Y,
                config.turntable_size,
                config.turntable_size,
                2.0 * half_fov,
            );
            let image = render_asset(
                &asset,
                &camera,
                env,
                DMat3::IDENTITY,
                None,
                &MarchSettings::default(),
            )?;
            let exposure = *stops.get_or_insert_with(|| (0.6 / data_range(&image.rgb)).log2());
            write_png_srgb(
                dir.join(format!("frame_{f:03}.png")),
                camera.width,
                camera.height,
                &image.rgb,
                exposure,
            )?;
            bar.inc(1);
        }
        turntables.push(dir);
    }
    bar.finish_and_clear();
    let turntable_secs = t.elapsed().as_secs_f64();

    // 4. Comparisons at the held-aside targets.
    let mut scores = Vec::new();
    let mut comparisons = Vec::new();
    if let Some(description) = capture.description() {
        for target in &description.targets {
            let env = load_envmap(target.envmap_path(&capture_dir))?;
            let (_, _, truth_rgb) = read_linear_rgb(&target.image_path(&capture_dir))?;
            let (score, image) = score_view(&asset, &target.camera, &env, &truth_rgb, &target.name)?;
            let path = out_dir.join(format!("compare_{}.png", target.name));
            let exposure = (0.6 / data_range(&truth_rgb)).log2();
            side_by_side(&path, &target.camera, &truth_rgb, &image.rgb, exposure)?;
            comparisons.push(path);
            scores.push(score);
        }
    }

    let report = DemoReport {
        out_dir: out_dir.to_path_buf(),
        capture_dir,
        asset: asset_path,
        bake: output.report,
        turntables,
        comparisons,
        scores,
        capture_secs,
        bake_secs,
        turntable_secs,
        turntable_frame_secs: turntable_secs / (f64::from(frames) * lightings.len() as f64),
    };
    write_json(&out_dir.join("demo_report.json"), &report)?;
    Ok(report)
}

/// Step 5: the demo's capture baked with the shipped network (no view-dependent part:
/// the network's transport is evaluated toward the mean camera), scored at the
/// targets beside the ground-truth bake; `demo_network.json` records it.
fn network_step(
    capture: &LoadedCapture,
    config: &PipelineConfig,
    report: &DemoReport,
    progress: Progress,
) -> Result<ImagesBakeDemo> {
    let weights = nelf_field::shipped::SHIPPED_WEIGHTS_NAME;
    images_step(capture, config, report, "network", |_| {
        let output = bake_network(capture, None, config, progress)
            .context("baking the demo's capture with the shipped network")?;
        Ok((
            output,
            serde_json::json!({ "weights": weights }),
            weights.to_string(),
        ))
    })
}

/// Step 6: the demo's capture baked from its photographs by reconstruction (under
/// the lighting the capture names), scored at the targets beside the ground-truth
/// bake; `demo_photos.json` records it.
fn photos_step(
    capture: &LoadedCapture,
    config: &PipelineConfig,
    report: &DemoReport,
    progress: Progress,
) -> Result<ImagesBakeDemo> {
    images_step(capture, config, report, "photos", |asset_path| {
        let baked = bake_photographs(capture, None, &PhotoSettings::default(), config, progress)
            .context("baking the demo's capture from its photographs")?;
        let reconstruction = asset_path.with_extension("reconstruction");
        write_reconstruction(&baked.reconstruction, &reconstruction)?;
        let extra = serde_json::json!({
            "reconstruction": reconstruction,
            "reconstruction_report": baked.reconstruction.report,
        });
        let made_by = format!("surface and albedo in {}", reconstruction.display());
        Ok((baked.output, extra, made_by))
    })
}

/// One bake of the demo's capture from its images: `bake` makes it (given where the
/// asset goes; it returns the bake, the fields it adds to the summary and what made
/// it), then the asset is written to `head_<label>.nelf`, read back, scored at the
/// targets (`compare_<label>_<target>.png`) and summed up in `demo_<label>.json`.
fn images_step(
    capture: &LoadedCapture,
    config: &PipelineConfig,
    report: &DemoReport,
    label: &str,
    bake: impl FnOnce(&Path) -> Result<(BakeOutput, serde_json::Value, String)>,
) -> Result<ImagesBakeDemo> {
    let start = Instant::now();
    let asset_path = report.out_dir.join(format!("head_{label}.nelf"));
    let (mut output, extra, made_by) = bake(&asset_path)?;
    write_bake(&mut output, config, &asset_path)
        .with_context(|| format!("writing {}", asset_path.display()))?;
    let bake_secs = start.elapsed().as_secs_f64();
    let asset = read_asset(&asset_path).with_context(|| format!("reading {}", asset_path.display()))?;
    let (comparisons, scores) = target_comparisons(capture, &asset, report, label)?;
    let mut summary = serde_json::json!({
        "asset": asset_path,
        "bake": output.report,
        "bake_secs": bake_secs,
        "scores": scores,
        "ground_truth_bake_scores": report.scores,
    });
    if let (Some(summary), serde_json::Value::Object(extra)) = (summary.as_object_mut(), extra) {
        summary.extend(extra);
    }
    write_json(&report.out_dir.join(format!("demo_{label}.json")), &summary)?;
    Ok(ImagesBakeDemo {
        asset: asset_path,
        bake: output.report,
        bake_secs,
        made_by,
        comparisons,
        scores,
    })
}

/// An asset at the capture's targets: side-by-sides (`compare_<label>_<target>.png`)
/// and scores.
fn target_comparisons(
    capture: &LoadedCapture,
    asset: &nelf_format::Asset,
    report: &DemoReport,
    label: &str,
) -> Result<(Vec<PathBuf>, Vec<ViewScore>)> {
    let (mut comparisons, mut scores) = (Vec::new(), Vec::new());
    if let Some(description) = capture.description() {
        for target in &description.targets {
            let env = load_envmap(target.envmap_path(&report.capture_dir))?;
            let (_, _, truth) = read_linear_rgb(&target.image_path(&report.capture_dir))?;
            let (score, image) = score_view(asset, &target.camera, &env, &truth, &target.name)?;
            let path = report
                .out_dir
                .join(format!("compare_{label}_{}.png", target.name));
            side_by_side(
                &path,
                &target.camera,
                &truth,
                &image.rgb,
                (0.6 / data_range(&truth)).log2(),
            )?;
            comparisons.push(path);
            scores.push(score);
        }
    }
    Ok((comparisons, scores))
}
