//! Writing a dataset: every head rendered into a temporary folder, completed with
//! depth maps and distillation points, then renamed into place.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec2, Vec3};
use indicatif::{ProgressBar, ProgressStyle};
use nelf_format::capture::Capture;
use nelf_format::conventions::PinholeCamera;
use nelf_scene::envgen::{EnvGenParams, procedural_envmap};
use nelf_scene::image_io::write_exr_rgb;
use nelf_scene::synth::{SynthConfig, synth_mesh, write_synthetic_capture};
use nelf_scene::tracer::LtTracer;
use rayon::prelude::*;
use serde::Serialize;

use super::config::DataConfig;
use super::distill::{DistillSettings, distill_field, distill_points};
use super::plan::{
    EnvCatalogue, HeadSpec, Identity, LightSource, LightSpec, SplitRecord, procedural_env_file,
};
use super::{
    CONFIG_FILE, DEPTH_SUFFIX, DISTILL_FILE, HEAD_FILE, HEADS_DIR, SPLIT_FILE, TARGET_MODES, TargetMode,
    head_dir,
};
use crate::error::TrainError;
use crate::files::write_bytes;

/// What a [`generate`] run did.
#[derive(Debug, Clone, Serialize)]
pub struct GenerateReport {
    /// The dataset folder (absolute).
    pub dir: PathBuf,
    /// Heads rendered by this run.
    pub written: Vec<u32>,
    /// Heads found finished and left alone.
    pub skipped: Vec<u32>,
    /// Seconds for the whole run.
    pub total_secs: f64,
    /// Mean seconds per written head (0 when none was written).
    pub secs_per_head: f64,
}

/// Seconds spent on one head, saved in its `head.json`.
#[derive(Debug, Clone, Copy, Default, Serialize, serde::Deserialize)]
pub struct HeadTimings {
    /// Rendering the synthetic capture (source and target views).
    pub render_secs: f64,
    /// Building the ground-truth field and the target depth maps.
    pub depth_secs: f64,
    /// Evaluating the distillation points.
    pub distill_secs: f64,
    /// Everything.
    pub total_secs: f64,
}

/// `head.json`: a head's draw, its targets' modes and its timings.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct HeadRecord {
    /// The draw.
    pub spec: HeadSpec,
    /// Mode of each target, in target order.
    pub target_modes: Vec<TargetMode>,
    /// Seconds spent.
    pub timings: HeadTimings,
}

/// Renders every head of `config` that `dir` does not hold yet (creating `dir`),
/// ticking `progress` once per head (its length is set to the number of heads).
///
/// The first run writes `data_config.json` and `split.json`; a later run must be
/// given the same settings (and find the same HDRIs) or it stops with
/// [`TrainError::ConfigMismatch`] before rendering anything. Heads are written to
/// `heads/.tmp-hNNNNN` and renamed to `heads/hNNNNN` when complete, so a killed run
/// leaves no folder that looks finished; leftovers are removed by the next run.
pub fn generate(
    dir: &Path,
    config: &DataConfig,
    progress: &ProgressBar,
) -> Result<GenerateReport, TrainError> {
    generate_heads(dir, config, None, progress)
}

/// [`generate`] of only the heads with ids in `only` (a shard of a batch: several
/// processes, on several machines, fill one dataset folder). Each head is written
/// whole under a name of its own process and renamed into place, so shards and
/// duplicate runs of one shard never see each other's parts; a shard leaves the
/// folders of killed runs (`heads/.tmp-…`) for a whole run to remove.
pub fn generate_heads(
    dir: &Path,
    config: &DataConfig,
    only: Option<&std::ops::RangeInclusive<u32>>,
    progress: &ProgressBar,
) -> Result<GenerateReport, TrainError> {
    let start = Instant::now();
    config.validate()?;
    let dir = std::path::absolute(dir).map_err(|e| TrainError::io(dir, e))?;
    let envs = EnvCatalogue::scan(config)?;
    let split = SplitRecord::new(config, &envs);
    let scan_mesh = if split.heads.iter().any(|h| h.identity == Identity::Scan) {
        let path =
            std::path::absolute(&config.scan_mesh).map_err(|e| TrainError::io(&config.scan_mesh, e))?;
        if !path.is_file() {
            return Err(TrainError::file(
                &path,
                "the scanned head (--scan-mesh) is missing",
            ));
        }
        Some(path)
    } else {
        None
    };
    let heads = dir.join(HEADS_DIR);
    std::fs::create_dir_all(&heads).map_err(|e| TrainError::io(&heads, e))?;
    check_or_write_json(&dir.join(CONFIG_FILE), config)?;
    check_or_write_json(&dir.join(SPLIT_FILE), &split)?;
    if only.is_none() {
        remove_leftovers(&heads)?;
    }
    let wanted = |id: u32| only.as_ref().is_none_or(|r| r.contains(&id));
    let total = split.heads.iter().filter(|s| wanted(s.id)).count();
    if total == 0 {
        return Err(TrainError::Settings(format!(
            "no head ids in {only:?}: the dataset has ids 0–{}",
            split.heads.len().saturating_sub(1)
        )));
    }

    progress.set_length(total as u64);
    progress.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} heads, {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut written = Vec::new();
    let mut skipped = Vec::new();
    let mut render_total = 0.0;
    // Validation heads first: a run stopped early can still be validated.
    let order = split
        .heads
        .iter()
        .filter(|s| config.is_val(s.id))
        .chain(split.heads.iter().filter(|s| !config.is_val(s.id)))
        .filter(|s| wanted(s.id));
    for spec in order {
        if head_dir(&dir, spec.id).is_dir() {
            skipped.push(spec.id);
            progress.inc(1);
            continue;
        }
        progress.set_message(format!("h{:05}", spec.id));
        match write_head(&dir, spec, config, &envs, scan_mesh.as_deref())? {
            Some(timings) => {
                render_total += timings.total_secs;
                written.push(spec.id);
            }
            // Another process wrote the same head meanwhile.
            None => skipped.push(spec.id),
        }
        progress.inc(1);
    }
    progress.finish_and_clear();
    let secs_per_head = if written.is_empty() {
        0.0
    } else {
        render_total / written.len() as f64
    };
    Ok(GenerateReport {
        dir,
        written,
        skipped,
        total_secs: start.elapsed().as_secs_f64(),
        secs_per_head,
    })
}

/// Writes `value` as pretty JSON to `path`, or, when the file exists, checks that it
/// holds the same JSON.
fn check_or_write_json(path: &Path, value: &impl Serialize) -> Result<(), TrainError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| TrainError::file(path, e.to_string()))? + "\n";
    match std::fs::read_to_string(path) {
        Ok(existing) => {
            let old: serde_json::Value = serde_json::from_str(&existing).map_err(|e| {
                TrainError::file(path, format!("damaged (not the JSON this tool writes): {e}"))
            })?;
            let new: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| TrainError::file(path, e.to_string()))?;
            if old == new {
                Ok(())
            } else {
                Err(TrainError::ConfigMismatch {
                    path: path.to_path_buf(),
                    differences: json_differences(&old, &new),
                })
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => write_bytes(path, text.as_bytes()),
        Err(e) => Err(TrainError::io(path, e)),
    }
}

/// `key: old → new` for every top-level key that differs (values shortened).
fn json_differences(old: &serde_json::Value, new: &serde_json::Value) -> String {
    let short = |v: Option<&serde_json::Value>| {
        let s = v.map_or_else(|| "(none)".to_owned(), ToString::to_string);
        if s.chars().count() > 60 {
            format!("{}…", s.chars().take(60).collect::<String>())
        } else {
            s
        }
    };
    match (old.as_object(), new.as_object()) {
        (Some(a), Some(b)) => {
            let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
            keys.sort();
            keys.dedup();
            keys.into_iter()
                .filter(|k| a.get(*k) != b.get(*k))
                .map(|k| format!("{k}: {} → {}", short(a.get(k)), short(b.get(k))))
                .collect::<Vec<_>>()
                .join("; ")
        }
        _ => "the file is not a JSON object".into(),
    }
}

/// Removes temporary head folders a killed run left behind.
fn remove_leftovers(heads: &Path) -> Result<(), TrainError> {
    let entries = std::fs::read_dir(heads).map_err(|e| TrainError::io(heads, e))?;
    for entry in entries {
        let path = entry.map_err(|e| TrainError::io(heads, e))?.path();
        let leftover = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with(".tmp-"));
        if leftover && path.is_dir() {
            std::fs::remove_dir_all(&path).map_err(|e| TrainError::io(&path, e))?;
        }
    }
    Ok(())
}

/// The file of a lighting, writing a procedural map into `dir/envs/` when needed.
fn light_file(dir: &Path, envs: &EnvCatalogue, light: &LightSpec) -> Result<PathBuf, TrainError> {
    match &light.source {
        LightSource::Hdri { name } => envs
            .files
            .get(name)
            .cloned()
            .ok_or_else(|| TrainError::Settings(format!("no HDRI named {name:?}"))),
        LightSource::Procedural { seed } => {
            let path = procedural_env_file(dir, *seed);
            if !path.is_file() {
                if let Some(parent) = path.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| TrainError::io(parent, e))?;
                }
                let params = EnvGenParams::default();
                let map = procedural_envmap(*seed, &params);
                write_exr_rgb(&path, map.width() as u32, map.height() as u32, map.texels())
                    .map_err(|e| TrainError::file(&path, e.to_string()))?;
            }
            Ok(path)
        }
    }
}

/// The synthetic capture settings of a head: target 0 under lighting A turned by
/// the self-rotation, target 1 under lighting B.
pub fn head_synth_config(
    dir: &Path,
    spec: &HeadSpec,
    config: &DataConfig,
    envs: &EnvCatalogue,
    scan_mesh: Option<&Path>,
) -> Result<SynthConfig, TrainError> {
    let file_a = light_file(dir, envs, &spec.light_a)?;
    let file_b = light_file(dir, envs, &spec.light_b)?;
    let (mesh, head_seed) = match spec.identity {
        Identity::Procedural { seed } => (None, seed),
        Identity::Scan => (
            Some(
                scan_mesh
                    .map(Path::to_path_buf)
                    .ok_or_else(|| TrainError::Settings("a scanned head without --scan-mesh".into()))?,
            ),
            0,
        ),
    };
    debug_assert_eq!(TARGET_MODES, [TargetMode::SelfRotation, TargetMode::NovelLight]);
    Ok(SynthConfig {
        mesh,
        mesh_height_m: config.scan_height_m,
        mesh_rotate_y_deg: config.scan_rotate_y_deg,
        head_seed,
        head_cells: config.head_cells,
        envmap: Some(file_a.clone()),
        env_seed: 0,
        env_rotate_deg: spec.light_a.rotate_deg,
        views: config.views,
        max_angle_deg: config.max_angle_deg,
        min_distance_m: spec.min_distance_m,
        max_distance_m: spec.max_distance_m,
        width: config.size,
        height: config.size,
        fill: spec.fill,
        camera_seed: spec.camera_seed,
        targets: TARGET_MODES.len(),
        target_envmap: vec![file_a, file_b],
        target_env_seed: 0,
        target_env_rotate_deg: vec![spec.rotated_light_a().rotate_deg, spec.light_b.rotate_deg],
        bounces: config.bounces,
        texel_samples: config.texel_samples,
        indirect_samples: config.indirect_samples,
        specular_weight: spec.specular_weight,
        trace_seed: spec.trace_seed,
        pixel_grid: 1,
    })
}

/// Depth along the optical axis (metres) of each pixel: the mean over the sub-pixel
/// rays of the tracer's coverage grid that hit the mesh (the rays whose hit
/// fraction is the pixel's alpha), 0 where none does.
pub fn depth_map(tracer: &LtTracer, camera: &PinholeCamera) -> Vec<f32> {
    let grid = tracer.settings().coverage_grid.max(1);
    let eye = camera.centre();
    let forward = camera.forward();
    (0..camera.height)
        .into_par_iter()
        .flat_map_iter(|v| {
            (0..camera.width).map(move |u| {
                let (mut sum, mut hits) = (0.0f64, 0u32);
                for j in 0..grid {
                    for i in 0..grid {
                        let pixel = DVec2::new(
                            f64::from(u) + (f64::from(i) + 0.5) / f64::from(grid),
                            f64::from(v) + (f64::from(j) + 0.5) / f64::from(grid),
                        );
                        let dir = camera.ray_direction(pixel);
                        if let Some(hit) = tracer.intersect(eye.as_vec3(), dir.as_vec3()) {
                            sum += f64::from(hit.t) * dir.dot(forward);
                            hits += 1;
                        }
                    }
                }
                if hits == 0 {
                    0.0
                } else {
                    (sum / f64::from(hits)) as f32
                }
            })
        })
        .collect()
}

/// Renders head `spec` into a temporary folder and renames it into place; `None`
/// when another process put the same head there first.
fn write_head(
    dir: &Path,
    spec: &HeadSpec,
    config: &DataConfig,
    envs: &EnvCatalogue,
    scan_mesh: Option<&Path>,
) -> Result<Option<HeadTimings>, TrainError> {
    let start = Instant::now();
    let id = spec.id;
    let tmp = dir
        .join(HEADS_DIR)
        .join(format!(".tmp-h{id:05}-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    let synth = head_synth_config(dir, spec, config, envs, scan_mesh)?;
    write_synthetic_capture(&synth, &tmp, &ProgressBar::hidden()).map_err(|source| TrainError::Synth {
        id,
        path: tmp.clone(),
        source: Box::new(source),
    })?;
    let render_secs = start.elapsed().as_secs_f64();

    let t0 = Instant::now();
    let ground_truth = |message: String| TrainError::GroundTruth { id, message };
    let mesh = synth_mesh(&synth).map_err(|e| ground_truth(e.to_string()))?;
    let tracer = LtTracer::new(&mesh, synth.trace_settings()).map_err(|e| ground_truth(e.to_string()))?;
    let field = distill_field(tracer, config.distill_shell_mm * 1e-3).map_err(ground_truth)?;
    let capture = Capture::load(&tmp)?;
    for target in &capture.targets {
        let depth = depth_map(field.tracer(), &target.camera);
        let bytes: Vec<u8> = depth.iter().flat_map(|d| d.to_le_bytes()).collect();
        write_bytes(
            &tmp.join(format!("targets/{}{DEPTH_SUFFIX}", target.name)),
            &bytes,
        )?;
    }
    let depth_secs = t0.elapsed().as_secs_f64();

    let t0 = Instant::now();
    let eyes: Vec<Vec3> = capture
        .views
        .iter()
        .map(|v| v.camera)
        .chain(capture.targets.iter().map(|t| t.camera))
        .map(|c| c.centre().as_vec3())
        .collect();
    let settings = DistillSettings {
        points: config.distill_points,
        uniform_share: config.distill_uniform_share,
        offset_m: config.distill_offset_mm * 1e-3,
        shell_m: config.distill_shell_mm * 1e-3,
        seed: spec.distill_seed,
    };
    let distill = distill_points(&field, &eyes, &settings).map_err(ground_truth)?;
    write_bytes(&tmp.join(DISTILL_FILE), &distill.to_bytes())?;
    let distill_secs = t0.elapsed().as_secs_f64();

    let timings = HeadTimings {
        render_secs,
        depth_secs,
        distill_secs,
        total_secs: start.elapsed().as_secs_f64(),
    };
    let record = HeadRecord {
        spec: spec.clone(),
        target_modes: TARGET_MODES.to_vec(),
        timings,
    };
    let head_json = tmp.join(HEAD_FILE);
    let text =
        serde_json::to_string_pretty(&record).map_err(|e| TrainError::file(&head_json, e.to_string()))?;
    write_bytes(&head_json, (text + "\n").as_bytes())?;
    let target = head_dir(dir, id);
    match std::fs::rename(&tmp, &target) {
        Ok(()) => Ok(Some(timings)),
        // Another process (a duplicate run of the same shard) finished this head
        // first: its folder is whole and, the draws being seeded, the same.
        Err(_) if target.is_dir() => {
            std::fs::remove_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
            Ok(None)
        }
        Err(e) => Err(TrainError::io(&target, e)),
    }
}
