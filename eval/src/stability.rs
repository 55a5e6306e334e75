//! `nelf eval stability INPUT`: where the method breaks. One chart per axis of
//! PSNR (whole image, foreground, and the flat-colour baseline) against:
//!
//! * `views`: number of source views (2–8, the first frontal);
//! * `spread_deg`: the largest angle of a source view from the frontal one;
//! * `target_angle_deg`: the held-aside view's azimuth away from the frontal
//!   source (0–180°, 180 the back of the head; one bake);
//! * `sun_radius_deg`: a sun of shrinking size and constant power over a dim sky
//!   (`perturb::sun_envmap`; one bake). The truth is the path tracer's light
//!   transport shaded by the same map projected onto NeLF's 8 × 16 light texels,
//!   so this axis measures the bake under ever harsher contrast, not the light
//!   basis itself: below a texel (≈ 11°) the projected sun stops shrinking;
//! * `hdri`: the real HDRIs in `data/envmaps` (when the folder exists);
//! * `rank`: the PCA rank (one bake);
//! * `pose_noise_deg`, `pose_noise_mm`: every source camera turned / moved by that
//!   much (`perturb::perturb_poses`); with the ground-truth field only the visual
//!   hull and the PCA weights see the wrong poses;
//! * `mask_px`: masks eroded (< 0) or dilated (> 0) by n pixels; `mask_soft_px`:
//!   masks blurred (`perturb::edit_masks`);
//! * `mesh_defect`: the defect meshes of `nelf_scene::defects` (open sheets, holes,
//!   flipped triangles, fins, loose parts), each photographed and baked.
//!
//! Every point is scored at the same held-aside views (two views between the
//! sources, each under its own procedural lighting), except the target-angle and
//! lighting axes, which vary exactly those. Each chart names where the PSNR first
//! falls below `--threshold-db`; a gallery shows the worst view of the worst point
//! of each axis (truth | ours | ꟻLIP map). Outputs: `stability.json`,
//! `stability.csv`, `report.html`; a stopped run resumes from `stability.json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DMat3, DVec3};
use indicatif::ProgressBar;
use nelf_bake::eval::HeldAside;
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, GroundTruth, Progress, bake_capture, load_capture, sample_field,
    with_capture_job,
};
use nelf_format::Asset;
use nelf_format::conventions::{LatLong, project_envmap};
use nelf_scene::envgen::{EnvGenParams, procedural_envmap};
use nelf_scene::render::render_lt_image;
use nelf_scene::synth::SynthConfig;
use nelf_scene::tracer::LtTracer;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::input::{CaptureSetup, EvalInput, copy_tree, synth_config, synthesize};
use crate::measure::{score_held_aside, write_gallery_png};
use crate::perturb::{MaskEdit, edit_masks, perturb_poses, sun_envmap, target_cameras_at_angles};
use crate::rows::StabilityPoint;

/// Options of `nelf eval stability` (saved in `stability.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct StabilityConfig {
    /// What to evaluate: a mesh file or `head:SEED` (default `head:0`). Captures
    /// are synthesized from it for every point.
    pub input: Option<String>,
    /// Output folder.
    #[arg(short, long, default_value = "out/eval/stability")]
    pub out: PathBuf,
    /// A minute or two: 64² images, grid 32, two or three points per axis.
    #[arg(long)]
    pub quick: bool,
    /// Only these axes (default: all).
    #[arg(long, value_delimiter = ',')]
    pub axes: Vec<String>,
    /// Image side of the synthesized captures and held-aside views, pixels
    /// (default 128; quick 64).
    #[arg(long)]
    pub image_size: Option<u32>,
    /// Grid resolution of every bake (default 96; quick 32).
    #[arg(long)]
    pub resolution: Option<u32>,
    /// PSNR under which a point counts as broken, dB.
    #[arg(long, default_value_t = 28.0)]
    pub threshold_db: f64,
    /// Height a mesh input is scaled to, metres.
    #[arg(long, default_value_t = 0.23)]
    pub mesh_height_m: f32,
    /// Turn a mesh input about +y by this many degrees so that it faces +z (90 for
    /// the shared data/meshes/head.off).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub mesh_rotate_y_deg: f32,
    /// Folder of real HDRIs for the `hdri` axis.
    #[arg(long, default_value = "data/envmaps")]
    pub hdri_dir: PathBuf,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// What every point bakes: the ground truth of its synthesized capture, or a
    /// surface reconstructed from its photographs (`nelf bake --source photos`; the
    /// `rank` axis, which resamples the ground truth, is left out).
    #[arg(long, value_enum, default_value_t)]
    #[serde(default)]
    pub source: StabilitySource,
}

/// What the points of `nelf eval stability` bake.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum StabilitySource {
    /// The capture's ground-truth field.
    #[default]
    Truth,
    /// The photographs' reconstruction (under the lighting the capture names).
    Photos,
}

/// Every axis, in report order.
pub const AXES: [&str; 11] = [
    "views",
    "spread_deg",
    "target_angle_deg",
    "sun_radius_deg",
    "hdri",
    "rank",
    "pose_noise_deg",
    "pose_noise_mm",
    "mask_px",
    "mask_soft_px",
    "mesh_defect",
];

/// What `stability.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StabilityResults {
    /// The options.
    pub config: StabilityConfig,
    /// What was evaluated.
    pub input: String,
    /// Every point measured.
    pub points: Vec<StabilityPoint>,
    /// Per axis, the first value whose PSNR falls below the threshold (`None`: never).
    pub breaks: Vec<(String, Option<String>)>,
    /// Seconds spent on this run, summed over every invocation that resumed it.
    pub run_secs: f64,
}

struct Context<'a> {
    config: &'a StabilityConfig,
    input: EvalInput,
    setup: CaptureSetup,
    bake: BakeConfig,
    held: HeldAside,
    out: &'a Path,
    quiet: bool,
}

impl StabilityConfig {
    fn axes(&self) -> Result<Vec<&'static str>> {
        let photos = self.source == StabilitySource::Photos;
        if self.axes.is_empty() {
            return Ok(AXES
                .iter()
                .copied()
                .filter(|a| !(photos && *a == "rank"))
                .collect());
        }
        self.axes
            .iter()
            .map(|a| {
                if photos && a == "rank" {
                    return Err(EvalError::Input(
                        "--axes rank resamples the ground truth's field: not with --source photos".into(),
                    ));
                }
                AXES.iter().copied().find(|x| x == a).ok_or_else(|| {
                    EvalError::Input(format!("--axes: unknown axis {a:?} (known: {})", AXES.join(", ")))
                })
            })
            .collect()
    }

    fn pick<T: Copy>(&self, full: &[T], quick: &[T]) -> Vec<T> {
        if self.quick { quick.to_vec() } else { full.to_vec() }
    }
}

fn create_dir(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path).map_err(|e| EvalError::Io {
        path: path.to_path_buf(),
        message: format!("cannot create the folder: {e}"),
    })
}

/// `to` made a fresh copy of `from`.
fn copy_dir(from: &Path, to: &Path) -> Result<()> {
    if to.exists() {
        std::fs::remove_dir_all(to).map_err(|e| EvalError::Io {
            path: to.to_path_buf(),
            message: e.to_string(),
        })?;
    }
    copy_tree(from, to)
}

/// The held-aside views every capture-varying point is scored at: two views between
/// the sources (azimuth −20° and +15°) under two procedural lightings, truth from
/// the path tracer's light transport.
fn fixed_held_aside(truth: &GroundTruth, setup: &CaptureSetup) -> Result<HeldAside> {
    let envs = [101u64, 102].map(|seed| procedural_envmap(seed, &EnvGenParams::default()));
    held_aside_at(truth, setup, &[-20.0, 15.0], &envs)
}

/// Held-aside views at azimuths `angles_deg`, view `i` under `envs[i % len]`.
fn held_aside_at(
    truth: &GroundTruth,
    setup: &CaptureSetup,
    angles_deg: &[f64],
    envs: &[LatLong],
) -> Result<HeldAside> {
    let mesh = truth.mesh()?;
    let tracer = LtTracer::new(&mesh, truth.trace_settings()).map_err(|e| EvalError::Input(e.to_string()))?;
    let (centre, radius) = mesh.bounding_sphere();
    let cameras = target_cameras_at_angles(
        centre,
        radius,
        1.5,
        setup.image_size,
        setup.image_size,
        0.9,
        angles_deg,
    );
    let mut held = HeldAside::default();
    for (i, (camera, angle)) in cameras.iter().zip(angles_deg).enumerate() {
        let env = envs[i % envs.len()].clone();
        let light = project_envmap(&env, DMat3::IDENTITY).map_err(|e| EvalError::Input(e.to_string()))?;
        let image =
            render_lt_image(&tracer, camera, &light, None).map_err(|e| EvalError::Input(e.to_string()))?;
        held.names.push(format!("azimuth {angle}°"));
        held.cameras.push(*camera);
        held.images.push(image.over([0.0; 3]));
        held.masks.push(image.alpha.clone());
        held.envs.push(env);
    }
    Ok(held)
}

impl Context<'_> {
    fn progress(&self) -> Progress {
        if self.quiet {
            Progress::hidden()
        } else {
            Progress::stderr()
        }
    }

    fn synth(&self, config: &SynthConfig, name: &str) -> Result<PathBuf> {
        let dir = self.out.join("captures").join(name);
        synthesize(config, &dir, &ProgressBar::hidden())?;
        Ok(dir)
    }

    fn base_synth(&self) -> Result<SynthConfig> {
        synth_config(&self.input, &self.setup).ok_or_else(|| {
            EvalError::Input(
                "nelf eval stability needs a mesh or head:SEED (it photographs it many times)".into(),
            )
        })
    }

    fn bake(&self, capture_dir: &Path) -> Result<Asset> {
        let capture = load_capture(capture_dir, &CaptureLoadOptions::default())?;
        match self.config.source {
            StabilitySource::Truth => {
                let truth = GroundTruth::from_synth_capture(capture_dir)?;
                Ok(bake_capture(&capture, &truth, &self.bake, &Progress::hidden())?.asset)
            }
            StabilitySource::Photos => Ok(nelf_pipeline::photo::bake_photographs(
                &capture,
                None,
                &nelf_pipeline::config::PhotoSettings::default(),
                &nelf_pipeline::PipelineConfig::from(self.bake.clone()),
                Progress::hidden(),
            )?
            .output
            .asset),
        }
    }

    fn point(
        &self,
        axis: &str,
        value: f64,
        label: String,
        asset: &Asset,
        held: &HeldAside,
    ) -> Result<StabilityPoint> {
        let step = self.bake.step_voxels;
        let (scores, views) = score_held_aside(asset, held, step)?;
        let (worst, view) = views
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.scores.psnr_db.total_cmp(&b.1.scores.psnr_db))
            .ok_or_else(|| EvalError::Input("no held-aside views".into()))?;
        let file = format!("gallery/{axis}_{}.png", sanitize(&label));
        write_gallery_png(&self.out.join(&file), &held.images[worst], view)?;
        Ok(StabilityPoint {
            axis: axis.to_string(),
            value,
            label,
            scores,
            worst_psnr_db: view.scores.psnr_db,
            gallery: Some(file),
            failure: None,
        })
    }

    /// Bakes a capture `config` names and scores it at the fixed views.
    fn capture_point(
        &self,
        axis: &str,
        value: f64,
        label: String,
        config: &SynthConfig,
    ) -> Result<StabilityPoint> {
        let dir = self.synth(config, &format!("{axis}_{}", sanitize(&label)))?;
        match self.bake(&dir) {
            Ok(asset) => self.point(axis, value, label, &asset, &self.held),
            Err(e) => Ok(failed_point(axis, value, label, &e)),
        }
    }

    /// The base capture copied to a scratch folder and edited by `edit`, baked and scored.
    fn edited_point(
        &self,
        axis: &str,
        value: f64,
        label: String,
        edit: impl FnOnce(&Path) -> Result<()>,
    ) -> Result<StabilityPoint> {
        let base = self.synth(&self.base_synth()?, "base")?;
        let dir = self
            .out
            .join("captures")
            .join(format!("{axis}_{}", sanitize(&label)));
        copy_dir(&base, &dir)?;
        edit(&dir)?;
        match self.bake(&dir) {
            Ok(asset) => self.point(axis, value, label, &asset, &self.held),
            Err(e) => Ok(failed_point(axis, value, label, &e)),
        }
    }

    fn axis_points(
        &self,
        axis: &str,
        done: &[StabilityPoint],
        mut emit: impl FnMut(StabilityPoint) -> Result<()>,
    ) -> Result<()> {
        let have = |label: &str| done.iter().any(|p| p.axis == axis && p.label == label);
        let base = self.base_synth()?;
        let quick = self.config.quick;
        match axis {
            "views" => {
                for n in self.config.pick(&[2usize, 3, 4, 5, 6, 8], &[2, 5]) {
                    let label = format!("{n} views");
                    if !have(&label) {
                        let config = SynthConfig {
                            views: n,
                            ..base.clone()
                        };
                        emit(self.capture_point(axis, n as f64, label, &config)?)?;
                    }
                }
            }
            "spread_deg" => {
                for deg in self.config.pick(&[5.0, 15.0, 30.0, 45.0, 60.0], &[10.0, 45.0]) {
                    let label = format!("{deg}°");
                    if !have(&label) {
                        let config = SynthConfig {
                            max_angle_deg: deg,
                            ..base.clone()
                        };
                        emit(self.capture_point(axis, deg, label, &config)?)?;
                    }
                }
            }
            "target_angle_deg" | "sun_radius_deg" | "hdri" | "rank" => {
                let dir = self.synth(&base, "base")?;
                let capture = load_capture(&dir, &CaptureLoadOptions::default())?;
                let truth = GroundTruth::from_synth_capture(&dir)?;
                // Baked on first use: a resumed axis with every point measured bakes nothing.
                let mut baked: Option<Asset> = None;
                let mut asset = || -> Result<Asset> {
                    if let Some(a) = &baked {
                        return Ok(a.clone());
                    }
                    let a = self.bake(&dir)?;
                    baked = Some(a.clone());
                    Ok(a)
                };
                match axis {
                    "target_angle_deg" => {
                        for deg in self
                            .config
                            .pick(&[0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0], &[0.0, 90.0, 180.0])
                        {
                            let label = format!("{deg}°");
                            if !have(&label) {
                                let held = held_aside_at(&truth, &self.setup, &[deg], &self.held.envs)?;
                                emit(self.point(axis, deg, label, &asset()?, &held)?)?;
                            }
                        }
                    }
                    "sun_radius_deg" => {
                        for deg in self.config.pick(&[32.0, 16.0, 8.0, 4.0, 2.0, 1.0], &[16.0, 2.0]) {
                            let label = format!("{deg}°");
                            if !have(&label) {
                                let sun =
                                    sun_envmap(deg, DVec3::new(0.6, 0.5, 0.62), 10.0, [0.05; 3], 256, 128);
                                let held = held_aside_at(&truth, &self.setup, &[-20.0, 15.0], &[sun])?;
                                emit(self.point(axis, deg, label, &asset()?, &held)?)?;
                            }
                        }
                    }
                    "hdri" => {
                        let hdri_dir = &self.config.hdri_dir;
                        let mut files: Vec<PathBuf> = std::fs::read_dir(hdri_dir)
                            .map_err(|e| EvalError::Io {
                                path: hdri_dir.clone(),
                                message: format!(
                                    "cannot read the HDRI folder of the hdri axis ({e}); give --hdri-dir or leave the axis out with --axes"
                                ),
                            })?
                            .filter_map(|e| e.ok().map(|e| e.path()))
                            .collect();
                        files.retain(|p| p.extension().is_some_and(|e| e == "exr" || e == "hdr"));
                        if files.is_empty() {
                            return Err(EvalError::Input(format!(
                                "{}: no .exr or .hdr environment maps for the hdri axis",
                                hdri_dir.display()
                            )));
                        }
                        files.sort();
                        if quick {
                            files.truncate(2);
                        }
                        for (i, file) in files.iter().enumerate() {
                            let label = file
                                .file_name()
                                .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                            if !have(&label) {
                                let env =
                                    nelf_scene::envmap::load_envmap(file).map_err(|e| EvalError::Io {
                                        path: file.clone(),
                                        message: e.to_string(),
                                    })?;
                                let held = held_aside_at(&truth, &self.setup, &[-20.0, 15.0], &[env])?;
                                emit(self.point(axis, i as f64, label, &asset()?, &held)?)?;
                            }
                        }
                    }
                    _ => {
                        let top = 64usize;
                        let config = BakeConfig {
                            rank: Some(top),
                            ..self.bake.clone()
                        };
                        let sampled = with_capture_job(
                            &capture,
                            &truth,
                            &config,
                            &Progress::hidden(),
                            |job, prior| sample_field(job, &config, &Progress::hidden(), prior),
                        )?;
                        for k in self.config.pick(&[1usize, 2, 4, 8, 16, 32, 64], &[1, 4, 16]) {
                            let label = format!("rank {k}");
                            if !have(&label) {
                                let asset =
                                    sampled.asset(k.min(sampled.top_rank), self.bake.encoding.encoding())?;
                                emit(self.point(axis, k as f64, label, &asset, &self.held)?)?;
                            }
                        }
                    }
                }
            }
            "pose_noise_deg" => {
                for deg in self.config.pick(&[0.0, 0.5, 1.0, 2.0, 4.0], &[0.0, 2.0]) {
                    let label = format!("{deg}°");
                    if !have(&label) {
                        emit(
                            self.edited_point(axis, deg, label, |dir| Ok(perturb_poses(dir, deg, 0.0, 7)?))?,
                        )?;
                    }
                }
            }
            "pose_noise_mm" => {
                for mm in self.config.pick(&[0.0, 2.0, 5.0, 10.0, 20.0], &[0.0, 10.0]) {
                    let label = format!("{mm} mm");
                    if !have(&label) {
                        emit(self.edited_point(axis, mm, label, |dir| Ok(perturb_poses(dir, 0.0, mm, 7)?))?)?;
                    }
                }
            }
            "mask_px" => {
                for px in self.config.pick(&[-4i32, -2, -1, 0, 1, 2, 4], &[-2, 2]) {
                    let label = format!("{px:+} px");
                    if !have(&label) {
                        emit(self.edited_point(axis, f64::from(px), label, |dir| {
                            let edit = match px {
                                p if p < 0 => Some(MaskEdit::Erode(p.unsigned_abs())),
                                p if p > 0 => Some(MaskEdit::Dilate(p.unsigned_abs())),
                                _ => None,
                            };
                            if let Some(edit) = edit {
                                edit_masks(dir, edit)?;
                            }
                            Ok(())
                        })?)?;
                    }
                }
            }
            "mask_soft_px" => {
                for px in self.config.pick(&[0.0f32, 1.0, 2.0, 4.0], &[2.0]) {
                    let label = format!("{px} px");
                    if !have(&label) {
                        emit(self.edited_point(axis, f64::from(px), label, |dir| {
                            if px > 0.0 {
                                edit_masks(dir, MaskEdit::Soften(px))?;
                            }
                            Ok(())
                        })?)?;
                    }
                }
            }
            _ => {
                let mut cases = nelf_scene::defects::test_cases();
                if quick {
                    cases.truncate(2);
                }
                let mesh_dir = self.out.join("meshes");
                create_dir(&mesh_dir)?;
                for (i, (name, mesh)) in cases.iter().enumerate() {
                    let label = (*name).to_string();
                    if have(&label) {
                        continue;
                    }
                    let path = mesh_dir.join(format!("{}.obj", sanitize(name)));
                    nelf_scene::mesh_io::write_obj(mesh, &path).map_err(|e| EvalError::Io {
                        path: path.clone(),
                        message: e.to_string(),
                    })?;
                    let config = SynthConfig {
                        mesh: Some(path),
                        mesh_height_m: 0.23,
                        ..base.clone()
                    };
                    let dir = self.synth(&config, &format!("defect_{}", sanitize(name)))?;
                    let truth = GroundTruth::from_synth_capture(&dir)?;
                    let held = fixed_held_aside(&truth, &self.setup)?;
                    match self.bake(&dir) {
                        Ok(asset) => emit(self.point(axis, i as f64, label, &asset, &held)?)?,
                        Err(e) => emit(failed_point(axis, i as f64, label, &e))?,
                    }
                }
            }
        }
        Ok(())
    }
}

/// A point where no asset could be made: zero scores and the reason (a bake that
/// refuses its input is where the method breaks, and is charted as such).
fn failed_point(axis: &str, value: f64, label: String, error: &EvalError) -> StabilityPoint {
    StabilityPoint {
        axis: axis.to_string(),
        value,
        label,
        scores: crate::rows::Scores::default(),
        worst_psnr_db: 0.0,
        gallery: None,
        // The whole chain: a context alone ("reconstructing … from its photographs")
        // does not say what broke.
        failure: Some(nelf_scene::error::error_chain(error)),
    }
}

fn sanitize(label: &str) -> String {
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The first point of each axis (in axis order) whose PSNR is below `threshold`.
pub fn breaks(points: &[StabilityPoint], threshold_db: f64) -> Vec<(String, Option<String>)> {
    let mut axes: Vec<String> = Vec::new();
    for p in points {
        if !axes.contains(&p.axis) {
            axes.push(p.axis.clone());
        }
    }
    axes.into_iter()
        .map(|axis| {
            let first = points
                .iter()
                .filter(|p| p.axis == axis)
                .find(|p| p.scores.psnr_db < threshold_db)
                .map(|p| p.label.clone());
            (axis, first)
        })
        .collect()
}

/// Runs the stability sweep (module docs) and writes its outputs.
pub fn run_stability(config: &StabilityConfig) -> Result<StabilityResults> {
    let start = Instant::now();
    let input = EvalInput::parse(config.input.as_deref())?;
    if matches!(input, EvalInput::Capture(_)) {
        return Err(EvalError::Input(
            "nelf eval stability photographs its input many times: give a mesh file or head:SEED, not a capture folder".into(),
        ));
    }
    let axes = config.axes()?;
    let out = &config.out;
    for dir in [out.clone(), out.join("captures"), out.join("gallery")] {
        create_dir(&dir)?;
    }
    // Every point is scored at views rendered here, so the captures need no targets.
    let setup = CaptureSetup {
        mesh_height_m: config.mesh_height_m,
        mesh_rotate_y_deg: config.mesh_rotate_y_deg,
        image_size: config.image_size.unwrap_or(if config.quick { 64 } else { 128 }),
        targets: 0,
        ..if config.quick {
            CaptureSetup::quick()
        } else {
            CaptureSetup::full()
        }
    };
    let bake = BakeConfig {
        resolution: config.resolution.unwrap_or(if config.quick { 32 } else { 96 }),
        render_size: setup.image_size.clamp(8, 128),
        ..BakeConfig::default()
    };
    let base_config = synth_config(&input, &setup)
        .ok_or_else(|| EvalError::Input("no synthetic capture for this input".into()))?;
    let base_dir = out.join("captures").join("base");
    synthesize(&base_config, &base_dir, &ProgressBar::hidden())?;
    let truth = GroundTruth::from_synth_capture(&base_dir)?;
    let held = fixed_held_aside(&truth, &setup)?;
    let ctx = Context {
        config,
        input: input.clone(),
        setup,
        bake,
        held,
        out,
        quiet: config.quiet,
    };
    let results_path = out.join("stability.json");
    let earlier: (Vec<StabilityPoint>, f64) = std::fs::read_to_string(&results_path)
        .ok()
        .and_then(|t| serde_json::from_str::<StabilityResults>(&t).ok())
        .filter(|r| {
            r.config.input == config.input
                && r.config.quick == config.quick
                && r.config.resolution == config.resolution
                && r.config.image_size == config.image_size
                && r.config.mesh_height_m == config.mesh_height_m
                && r.config.mesh_rotate_y_deg == config.mesh_rotate_y_deg
        })
        .map(|r| (r.points, r.run_secs))
        .unwrap_or_default();
    let (earlier, earlier_secs) = earlier;
    let mut results = StabilityResults {
        config: config.clone(),
        input: input.name(),
        points: earlier.clone(),
        breaks: Vec::new(),
        run_secs: 0.0,
    };
    let bar = ctx.progress().bar("axes", axes.len() as u64, "axes");
    for axis in &axes {
        bar.set_message((*axis).to_string());
        let done = results.points.clone();
        let mut fresh = Vec::new();
        ctx.axis_points(axis, &done, |p| {
            fresh.push(p.clone());
            results.points.push(p);
            results.run_secs = earlier_secs + start.elapsed().as_secs_f64();
            crate::report::write_json(&results_path, &results)?;
            Ok(())
        })?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    // Axis order, then the order points were measured in.
    let mut ordered = Vec::new();
    for axis in &axes {
        let mut on_axis: Vec<StabilityPoint> = results
            .points
            .iter()
            .filter(|p| p.axis == *axis)
            .cloned()
            .collect();
        if *axis != "hdri" && *axis != "mesh_defect" {
            on_axis.sort_by(|a, b| a.value.total_cmp(&b.value));
        }
        ordered.extend(on_axis);
    }
    results.points = ordered;
    results.breaks = breaks(&results.points, config.threshold_db);
    results.run_secs = earlier_secs + start.elapsed().as_secs_f64();
    crate::report::write_json(&results_path, &results)?;
    crate::report::write_stability_csv(&out.join("stability.csv"), &results.points)?;
    let sections = crate::report::stability_sections(&results.points, config.threshold_db, out);
    crate::report::write_chart_files(&out.join("charts"), &sections)?;
    crate::report::write_html_report(
        &out.join("report.html"),
        &format!("nelf eval stability: {}", results.input),
        &sections,
    )?;
    Ok(results)
}
