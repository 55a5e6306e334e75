//! The bake, stage by stage: region (visual hull or mesh box) → density pass and
//! brick drop → visibility weights → light transport on the band that shows →
//! weighted PCA → rank choice by rendered loss → quantize → write.
//!
//! The asset written depends only on the inputs and the [`BakeConfig`]: every
//! stage is deterministic (fixed chunking, sums in a fixed order), and timings are
//! kept out of the file (they go to the `.bake.json` beside it), so baking twice
//! gives byte-identical files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec3, Vec3};
use nelf_format::conventions::{LT_DIM, LatLong, PinholeCamera};
use nelf_format::{
    Asset, CoefficientEncoding, Coefficients, WriteOptions, WriteReport, encode_density, write_asset,
};
use nelf_render::{MarchSettings, visibility_weights};
use nelf_scene::envmap::load_envmap;
use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::mesh::Mesh;
use nelf_scene::render::render_lt_image;
use nelf_scene::synth::{SynthConfig, camera_for, source_viewpoints};
use nelf_scene::tracer::{LtTracer, MAX_AVERAGED_DIRECTIONS, TraceSettings};
use serde::{Deserialize, Serialize};

use crate::capture_in::LoadedCapture;
use crate::error::{BakeError, Result, io_error};
use crate::grid::{
    GridPlan, evaluate_density, evaluate_light_transport, geometry_for_box, light_transport_band,
    occupied_box, plan_all_bricks, plan_from_hull, voxel_size_for,
};
use crate::hull::{HullCarver, hull_bounds};
use crate::pca::{WeightedPca, fit_weighted_pca, project_coefficients};
use crate::progress::Progress;
use crate::rank::{
    CandidateLoss, RankScene, TestEnv, box_downsample, candidate_loss, candidate_ranks, component_images,
    light_texels, reduced_camera, reference_renders, relative_error_vs_images, test_environments,
    unquantized_radiance,
};
use crate::source::{GroundTruth, ShellPlacement, TraceOverrides, describe_trace, mesh_field};

/// Which outgoing direction the light transport is baked for (a baked vector has
/// one; the viewer cannot change it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ViewPolicyChoice {
    /// The mean of `T` over the directions toward every camera centre.
    #[default]
    AverageCameras,
    /// `T` toward the mean of the camera centres.
    MeanCamera,
}

/// How PCA coefficients are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum EncodingChoice {
    /// One byte per coefficient, affine per component.
    #[default]
    U8,
    /// IEEE binary16 per coefficient.
    F16,
}

impl EncodingChoice {
    /// The file's encoding.
    pub fn encoding(self) -> CoefficientEncoding {
        match self {
            Self::U8 => CoefficientEncoding::U8Affine,
            Self::F16 => CoefficientEncoding::F16,
        }
    }
}

/// Every setting of a bake (the `nelf bake` options); saved beside the asset in
/// `<asset>.bake.json` and recorded in its metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct BakeConfig {
    /// Voxels along the longest side of the region baked (hull or mesh box); ignored
    /// when --voxel-size-m is given.
    #[arg(long, default_value_t = 128)]
    pub resolution: u32,
    /// Voxel edge in metres (overrides --resolution).
    #[arg(long)]
    pub voxel_size_m: Option<f64>,
    /// Visual hull: grow every mask by this many pixels (a (2r+1)² square) before carving.
    #[arg(long, default_value_t = 2)]
    pub dilate_px: u32,
    /// Drop a brick whose densest voxel is less opaque than this across one voxel
    /// (`σ_min = −ln(1 − α)/voxel_size`).
    #[arg(long, default_value_t = 0.01)]
    pub min_brick_opacity: f64,
    /// Evaluate light transport only where the optical depth from outside is below
    /// this (plus one voxel around), elsewhere the PCA mean.
    #[arg(long, default_value_t = 10.0)]
    pub max_optical_depth: f64,
    /// Ground-truth field: how density follows the signed distance to the mesh (a
    /// signed linear ramp through the surface, a ramp inside it, or one centred on it).
    #[arg(long, value_enum, default_value_t)]
    pub shell_placement: ShellPlacement,
    /// Ground-truth field, `inside`/`centred` shells: ramp width, voxels.
    #[arg(long, default_value_t = 2.0)]
    pub shell_voxels: f32,
    /// Ground-truth field, `signed` shell: how far outside the surface the density
    /// crosses zero, voxels (the slope puts transmittance ½ at the surface).
    #[arg(long, default_value_t = 0.25)]
    pub lead_voxels: f32,
    /// Outgoing direction the light transport is baked for.
    #[arg(long, value_enum, default_value_t)]
    pub view_policy: ViewPolicyChoice,
    /// Longest side, pixels, of the renders that weight the PCA and choose the rank.
    #[arg(long, default_value_t = 128)]
    pub render_size: u32,
    /// Ray-march step of those renders, voxels.
    #[arg(long, default_value_t = 0.5)]
    pub step_voxels: f32,
    /// PCA weight floor, relative to the mean visibility weight, so unseen voxels
    /// still count a little.
    #[arg(long, default_value_t = 0.01)]
    pub weight_floor: f64,
    /// Force the PCA rank K (skip the choice; its loss is still measured).
    #[arg(long)]
    pub rank: Option<usize>,
    /// Largest rank the choice may take.
    #[arg(long, default_value_t = 64)]
    pub max_rank: usize,
    /// Rank choice: largest rendered-image loss accepted, dB.
    #[arg(long, default_value_t = 0.1)]
    pub max_loss_db: f64,
    /// Rank choice: the signal-to-noise ratio (dB) assumed for the unquantized grid
    /// against ground truth when the capture's lighting is unknown (no envmap in
    /// cameras.json). The default synthetic capture measures about 13 dB at 128
    /// voxels; 20 dB asks for more accuracy than that.
    #[arg(long, default_value_t = 20.0)]
    pub reference_snr_db: f64,
    /// Coefficient storage.
    #[arg(long, value_enum, default_value_t)]
    pub encoding: EncodingChoice,
    /// 8-bit coefficients: one quantization step for every component, sized so that
    /// rounding adds this share of the PCA truncation error (0: each component's
    /// own range over 254 steps).
    #[arg(long, default_value_t = 0.1)]
    pub quantization_share: f64,
    /// Ground-truth path-tracer overrides.
    #[command(flatten)]
    pub trace: TraceOverrides,
}

impl Default for BakeConfig {
    fn default() -> Self {
        Self {
            resolution: 128,
            voxel_size_m: None,
            dilate_px: 2,
            min_brick_opacity: 0.01,
            max_optical_depth: 10.0,
            shell_placement: ShellPlacement::Signed,
            shell_voxels: 2.0,
            lead_voxels: 0.25,
            view_policy: ViewPolicyChoice::AverageCameras,
            render_size: 128,
            step_voxels: 0.5,
            weight_floor: 0.01,
            rank: None,
            max_rank: 64,
            max_loss_db: 0.1,
            reference_snr_db: 20.0,
            encoding: EncodingChoice::U8,
            quantization_share: 0.1,
            trace: TraceOverrides::default(),
        }
    }
}

impl BakeConfig {
    /// Checks ranges before any work.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(BakeError::Settings(m));
        if let Some(k) = self.rank
            && !(1..=LT_DIM).contains(&k)
        {
            return bad(format!("--rank {k} must be in 1..={LT_DIM}"));
        }
        if !(1..=LT_DIM).contains(&self.max_rank) {
            return bad(format!("--max-rank {} must be in 1..={LT_DIM}", self.max_rank));
        }
        if !(self.max_loss_db.is_finite() && self.max_loss_db >= 0.0) {
            return bad(format!("--max-loss-db {} must be ≥ 0", self.max_loss_db));
        }
        if !self.reference_snr_db.is_finite() {
            return bad(format!(
                "--reference-snr-db {} must be finite",
                self.reference_snr_db
            ));
        }
        if !(self.quantization_share.is_finite() && self.quantization_share >= 0.0) {
            return bad(format!(
                "--quantization-share {} must be ≥ 0",
                self.quantization_share
            ));
        }
        if !(self.weight_floor.is_finite() && self.weight_floor >= 0.0) {
            return bad(format!("--weight-floor {} must be ≥ 0", self.weight_floor));
        }
        if !(self.max_optical_depth.is_finite() && self.max_optical_depth > 0.0) {
            return bad(format!(
                "--max-optical-depth {} must be positive",
                self.max_optical_depth
            ));
        }
        if !(8..=4096).contains(&self.render_size) {
            return bad(format!("--render-size {} must be in 8..=4096", self.render_size));
        }
        if !(self.shell_voxels.is_finite() && self.shell_voxels > 0.0) {
            return bad(format!("--shell-voxels {} must be positive", self.shell_voxels));
        }
        if !(self.lead_voxels.is_finite() && self.lead_voxels > 0.0 && self.lead_voxels <= 2.0) {
            return bad(format!("--lead-voxels {} must be in (0, 2]", self.lead_voxels));
        }
        self.march().validate()?;
        Ok(())
    }

    /// Ray-marching settings of the bake's renders.
    pub fn march(&self) -> MarchSettings {
        MarchSettings {
            step_voxels: self.step_voxels,
            ..MarchSettings::default()
        }
    }
}

/// The one 8-bit step floor for every component
/// (`Coefficients::quantize_with_min_step`): uniform rounding with step `δ` adds
/// `δ²/12` of squared error per component, so `K` components add `K δ²/12`; setting
/// that to `share` (`--quantization-share`) of the weighted PCA's truncation error at
/// rank `K` (the sum of the dropped eigenvalues) gives
/// `δ = √(12 · share · Σ_{k>K} λ_k / K)`. Equal error per component is the
/// reverse water-filling allocation (least squared error for the bits). The rank
/// choice then judges the quantized asset, so the loss it reports includes this.
pub fn quantization_step(pca: &WeightedPca, rank: usize, share: f64) -> f32 {
    let dropped: f64 = pca.eigenvalues.iter().skip(rank).map(|l| l.max(0.0)).sum();
    let step = (12.0 * share * dropped / rank.max(1) as f64).sqrt();
    if step.is_finite() { step as f32 } else { 0.0 }
}

/// How the unquantized grid's own error `m₀` is known (see [`crate::rank`]).
#[derive(Debug, Clone)]
pub enum Reference {
    /// Ground-truth images of the views (full resolution, linear RGB), their masks,
    /// and the lighting they were taken under (lat-long, world frame).
    Images {
        /// One image per view.
        images: Vec<Vec<[f32; 3]>>,
        /// One mask per view.
        masks: Vec<Vec<f32>>,
        /// The lighting.
        lighting: LatLong,
    },
    /// Assumed signal-to-noise ratio of the unquantized grid, dB.
    AssumedSnrDb(f64),
}

/// Seconds spent in each stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimings {
    /// Visual hull (or mesh box) and the candidate bricks.
    pub hull_secs: f64,
    /// Path-tracing the ground-truth reference views (mesh bakes only).
    pub reference_secs: f64,
    /// Density of every candidate voxel, brick drop.
    pub density_secs: f64,
    /// Visibility weights of every view.
    pub weights_secs: f64,
    /// Light-transport band and its evaluation.
    pub lt_secs: f64,
    /// Weighted PCA and coefficients.
    pub pca_secs: f64,
    /// Rank choice (renders).
    pub rank_secs: f64,
    /// Encoding and writing the file.
    pub write_secs: f64,
}

/// What a bake produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BakeReport {
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
    /// Grid extent in bricks.
    pub grid_bricks: [u32; 3],
    /// Voxels inside the visual hull (all candidate voxels for a mesh bake).
    pub hull_voxels: usize,
    /// Bricks evaluated for density.
    pub candidate_bricks: usize,
    /// Bricks kept (apron bricks included).
    pub bricks: usize,
    /// Bricks kept only as an apron around dense ones.
    pub apron_bricks: usize,
    /// Voxels kept (bricks × 512).
    pub voxels: usize,
    /// Voxels whose light transport was evaluated.
    pub lt_voxels: usize,
    /// PCA rank chosen.
    pub rank: usize,
    /// Energy kept at that rank.
    pub energy_kept: f64,
    /// Rendered loss at that rank, dB.
    pub loss_db: f64,
    /// Whether the loss met the target (always true when the rank was forced).
    pub met_target: bool,
    /// `m₀`, the unquantized grid's relative squared error against ground truth.
    pub reference_relative_error: f64,
    /// Every candidate tried.
    pub candidates: Vec<CandidateLoss>,
    /// Seconds per stage.
    pub timings: StageTimings,
    /// File size in bytes (0 until written).
    pub file_size: u64,
}

/// A baked asset and its report.
#[derive(Debug, Clone)]
pub struct BakeOutput {
    /// The asset (exactly what the file will hold).
    pub asset: Asset,
    /// What happened.
    pub report: BakeReport,
}

/// A field to bake over a planned grid.
pub struct FieldBake<'a> {
    /// The source of density and light transport.
    pub field: &'a dyn FieldSource,
    /// Candidate bricks.
    pub plan: GridPlan,
    /// The views the asset is judged by (the capture's own cameras, full resolution).
    pub cameras: Vec<PinholeCamera>,
    /// Outgoing direction of the light transport.
    pub view_policy: ViewPolicy,
    /// How the unquantized grid's own error is known.
    pub reference: Reference,
    /// Provenance for the metadata (source files, field).
    pub provenance: serde_json::Value,
}

impl std::fmt::Debug for FieldBake<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FieldBake")
            .field("plan_bricks", &self.plan.bricks.len())
            .field("cameras", &self.cameras.len())
            .field("view_policy", &self.view_policy)
            .field("provenance", &self.provenance)
            .finish_non_exhaustive()
    }
}

/// The view policy `choice` for cameras centred at `centres` (at most 64 are
/// averaged; more are subsampled evenly).
pub fn view_policy_for(choice: ViewPolicyChoice, centres: &[DVec3]) -> Result<ViewPolicy> {
    if centres.is_empty() {
        return Err(BakeError::Settings(
            "a view policy needs at least one camera".into(),
        ));
    }
    let policy = match choice {
        ViewPolicyChoice::AverageCameras => {
            let n = centres.len();
            let m = n.min(MAX_AVERAGED_DIRECTIONS);
            ViewPolicy::AverageTowardPoints((0..m).map(|i| centres[i * n / m].as_vec3()).collect())
        }
        ViewPolicyChoice::MeanCamera => {
            let mean = centres.iter().copied().sum::<DVec3>() / centres.len() as f64;
            ViewPolicy::TowardPoint(mean.as_vec3())
        }
    };
    policy.validate()?;
    Ok(policy)
}

fn policy_json(policy: &ViewPolicy, choice: ViewPolicyChoice) -> serde_json::Value {
    let points = |list: &[Vec3]| list.iter().map(Vec3::to_array).collect::<Vec<_>>();
    let detail = match policy {
        ViewPolicy::Direction(d) => serde_json::json!({ "direction": d.to_array() }),
        ViewPolicy::TowardPoint(p) => serde_json::json!({ "toward_point_m": p.to_array() }),
        ViewPolicy::AverageDirections(list) => serde_json::json!({ "average_directions": points(list) }),
        ViewPolicy::AverageTowardPoints(list) => {
            serde_json::json!({ "average_toward_points_m": points(list) })
        }
    };
    serde_json::json!({ "choice": choice, "policy": detail })
}

/// Bakes `job` with `config`: density, weights, light transport, PCA, rank, asset.
/// `prior` holds the seconds of the stages the caller ran (planning the grid,
/// rendering references); the others are filled in.
pub fn bake_field(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    prior: StageTimings,
) -> Result<BakeOutput> {
    config.validate()?;
    let mut timings = prior;

    // Density and brick drop.
    let t = Instant::now();
    let dense = evaluate_density(&job.plan, job.field, config.min_brick_opacity, progress)?;
    let grid = &dense.grid;
    let density = &dense.density;
    let voxels = grid.voxel_count();
    timings.density_secs = t.elapsed().as_secs_f64();

    // Visibility weights at reduced resolution.
    let t = Instant::now();
    let march = config.march();
    let reduced: Vec<(PinholeCamera, u32)> = job
        .cameras
        .iter()
        .map(|c| reduced_camera(c, config.render_size))
        .collect();
    let views: Vec<PinholeCamera> = reduced.iter().map(|(c, _)| *c).collect();
    let mut visibility = vec![0.0f32; voxels];
    let bar = progress.bar("weights", views.len() as u64, "views");
    for cam in &views {
        visibility_weights(grid, density, cam, &march, &mut visibility)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    timings.weights_secs = t.elapsed().as_secs_f64();

    // Light transport on the band.
    let t = Instant::now();
    let lt_voxels = light_transport_band(grid, density, config.max_optical_depth);
    if lt_voxels.is_empty() {
        return Err(BakeError::Empty("no voxel has positive density".into()));
    }
    let (lt, _) = evaluate_light_transport(grid, &lt_voxels, job.field, &job.view_policy, progress)?;
    timings.lt_secs = t.elapsed().as_secs_f64();

    // Weighted PCA.
    let t = Instant::now();
    let seen: Vec<f64> = lt_voxels.iter().map(|&v| f64::from(visibility[v])).collect();
    let mean_seen = seen.iter().sum::<f64>() / seen.len() as f64;
    let floor = if mean_seen > 0.0 {
        config.weight_floor * mean_seen
    } else {
        1.0
    };
    let weights: Vec<f64> = seen.iter().map(|w| w + floor).collect();
    let pca = fit_weighted_pca(&lt, &weights)?;
    let data_rank = pca.numerical_rank();
    let top_rank = match config.rank {
        Some(k) => k,
        None => config.max_rank.min(data_rank).max(1),
    };
    let model = pca.model(top_rank);
    let compact = project_coefficients(&model, &lt);
    let mut coefficients = vec![0.0f32; voxels * top_rank];
    for (i, &v) in lt_voxels.iter().enumerate() {
        coefficients[v * top_rank..(v + 1) * top_rank]
            .copy_from_slice(&compact[i * top_rank..(i + 1) * top_rank]);
    }
    let encoding = config.encoding.encoding();
    let min_step = quantization_step(&pca, top_rank, config.quantization_share);
    let world_from_light = job.field.world_from_light();
    let stored_density = encode_density(density)?;
    let full = Asset {
        grid: *grid.geometry(),
        world_from_light,
        bricks: grid.bricks().to_vec(),
        density: stored_density.clone(),
        pca: model.clone(),
        coefficients: Coefficients::quantize_with_min_step(&coefficients, top_rank, encoding, min_step)?,
        metadata: serde_json::json!({}),
    };
    timings.pca_secs = t.elapsed().as_secs_f64();

    // Rank choice.
    let t = Instant::now();
    let scene = RankScene {
        grid,
        density,
        views: &views,
        march,
        world_from_light,
    };
    let (m0, reference_json) = match &job.reference {
        Reference::Images {
            images,
            masks,
            lighting,
        } => {
            let light = light_texels(lighting, world_from_light)?;
            let radiance = unquantized_radiance(voxels, &lt_voxels, &lt, &model.mean, &light);
            let mut small_images = Vec::with_capacity(images.len());
            let mut small_masks = Vec::with_capacity(images.len());
            for ((img, mask), (cam, (_, factor))) in
                images.iter().zip(masks).zip(job.cameras.iter().zip(&reduced))
            {
                small_images.push(box_downsample(img, cam.width, cam.height, *factor));
                let m: Vec<[f32; 1]> = mask.iter().map(|&x| [x]).collect();
                small_masks.push(
                    box_downsample(&m, cam.width, cam.height, *factor)
                        .iter()
                        .map(|x| x[0])
                        .collect(),
                );
            }
            let m0 = relative_error_vs_images(&scene, &radiance, &small_images, &small_masks)?;
            let json = serde_json::json!({
                "kind": "capture-images",
                "relative_error": m0,
                "snr_db": -10.0 * m0.log10(),
            });
            (m0, json)
        }
        Reference::AssumedSnrDb(snr) => {
            let m0 = 10f64.powf(-snr / 10.0);
            let json = serde_json::json!({ "kind": "assumed-snr", "relative_error": m0, "snr_db": snr });
            (m0, json)
        }
    };
    if !(m0.is_finite() && m0 > 0.0) {
        return Err(BakeError::Settings(format!(
            "the unquantized grid's relative error against ground truth is {m0}; the rank cannot be chosen from it (force --rank)"
        )));
    }
    // The fixed test maps, plus the capture's own lighting when known: the views the
    // loss is judged at are the capture's, and that lighting is a real one for them.
    let mut envs = test_environments();
    if let Reference::Images { lighting, .. } = &job.reference
        && !envs.iter().any(|e| e.map == *lighting)
    {
        envs.push(TestEnv {
            name: "capture-lighting".into(),
            map: lighting.clone(),
        });
    }
    let references = reference_renders(&scene, &envs, &lt_voxels, &lt, &model.mean)?;
    let components = component_images(&scene, &full)?;
    let ranks = match config.rank {
        Some(k) => vec![k],
        None => candidate_ranks(config.max_rank, data_rank),
    };
    let bar = progress.bar("rank", ranks.len() as u64, "candidates");
    let mut candidates = Vec::new();
    let mut chosen = None;
    for &k in &ranks {
        let per_env_db = candidate_loss(&references, &components, &full, k, m0)?;
        let loss = per_env_db.iter().copied().fold(0.0f64, f64::max);
        candidates.push(CandidateLoss {
            rank: k,
            loss_db: loss,
            per_env_db,
            energy_kept: pca.energy_kept(k),
        });
        bar.inc(1);
        if loss <= config.max_loss_db {
            chosen = Some(candidates.len() - 1);
            break;
        }
    }
    bar.finish_and_clear();
    let met_target = chosen.is_some() || config.rank.is_some();
    let pick = chosen.unwrap_or(candidates.len() - 1);
    let rank = candidates[pick].rank;
    timings.rank_secs = t.elapsed().as_secs_f64();

    // The asset at the chosen rank.
    let truncated: Vec<f32> = coefficients
        .chunks_exact(top_rank)
        .flat_map(|c| c[..rank].iter().copied())
        .collect();
    let report = BakeReport {
        voxel_size_m: grid.geometry().voxel_size_m,
        grid_bricks: grid.geometry().grid_bricks,
        hull_voxels: job.plan.hull_voxels,
        candidate_bricks: dense.candidate_bricks,
        bricks: grid.bricks().len(),
        apron_bricks: dense.apron_bricks,
        voxels,
        lt_voxels: lt_voxels.len(),
        rank,
        energy_kept: pca.energy_kept(rank),
        loss_db: candidates[pick].loss_db,
        met_target,
        reference_relative_error: m0,
        candidates: candidates.clone(),
        timings,
        file_size: 0,
    };
    let metadata = serde_json::json!({
        "generator": "nelf bake",
        "generator_version": env!("CARGO_PKG_VERSION"),
        "source": job.provenance,
        "view_policy": policy_json(&job.view_policy, config.view_policy),
        "settings": config,
        "grid": {
            "voxel_size_m": report.voxel_size_m,
            "hull_voxels": report.hull_voxels,
            "candidate_bricks": report.candidate_bricks,
            "bricks": report.bricks,
            "apron_bricks": report.apron_bricks,
            "voxels": report.voxels,
            "lt_voxels": report.lt_voxels,
            "brick_density_threshold_per_m": dense.sigma_min_per_m,
        },
        "pca": {
            "rank": rank,
            "energy_kept": report.energy_kept,
            "data_rank": data_rank,
            "encoding": encoding.name(),
            "quantization_min_step": min_step,
            "weighting": "sum over the capture's views of the visibility weights (nelf-render), plus weight_floor × their mean",
            "eigenvalues": pca.eigenvalues.iter().take(top_rank.max(rank)).collect::<Vec<_>>(),
        },
        "rank_choice": {
            "forced": config.rank.is_some(),
            "max_loss_db": config.max_loss_db,
            "loss_db": report.loss_db,
            "met_target": met_target,
            "reference": reference_json,
            "test_environments": envs.iter().map(|e| e.name.clone()).collect::<Vec<_>>(),
            "render_size": config.render_size,
            "candidates": candidates,
            "loss_definition": "worst over test environments of 10·log10((m0 + mK)/m0), mK = Σ(I_K − I_0)²/Σ I_0² over the capture's views",
        },
    });
    let asset = Asset {
        pca: model.truncated(rank),
        coefficients: Coefficients::quantize_with_min_step(&truncated, rank, encoding, min_step)?,
        metadata,
        density: stored_density,
        ..full
    };
    asset.validate()?;
    Ok(BakeOutput { asset, report })
}

/// A capture's grid, before the bake proper: the visual hull of its masks, the box
/// where the field is dense inside it, the voxel size the configuration asks for,
/// and the bricks over the hull within that box.
#[derive(Debug, Clone)]
pub struct CapturePlan {
    /// Bricks over the hull.
    pub plan: GridPlan,
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
    /// The hull's box `(min, max)`, metres.
    pub hull_box_m: (DVec3, DVec3),
    /// The box the grid covers `(min, max)`, metres: where `probe` is dense inside
    /// the hull box ([`occupied_box`]), or the hull box when `--voxel-size-m` is given.
    pub grid_box_m: (DVec3, DVec3),
    /// Seconds carving the hull and probing the density.
    pub hull_secs: f64,
}

/// Carves the visual hull of a capture's masks and lays bricks over it. With
/// `--resolution`, the voxel size is the longest side of the region where `probe`
/// is dense ([`occupied_box`]) over the resolution, and the grid covers that region;
/// with `--voxel-size-m` the grid covers the hull's box.
pub fn plan_capture(
    capture: &LoadedCapture,
    config: &BakeConfig,
    probe: &dyn FieldSource,
    progress: &Progress,
) -> Result<CapturePlan> {
    config.validate()?;
    let t = Instant::now();
    let carver = HullCarver::new(&capture.cameras, &capture.masks, config.dilate_px)?;
    let (lo, hi) = hull_bounds(&carver, capture.head_centre_m)?;
    let (grid_lo, grid_hi) = match config.voxel_size_m {
        Some(_) => (lo, hi),
        None => occupied_box(Some(&carver), lo, hi, probe, config.min_brick_opacity, progress)?,
    };
    let voxel = voxel_size_for(grid_hi - grid_lo, config.resolution, config.voxel_size_m)?;
    let plan = plan_from_hull(&carver, geometry_for_box(grid_lo, grid_hi, voxel)?);
    Ok(CapturePlan {
        plan,
        voxel_size_m: voxel,
        hull_box_m: (lo, hi),
        grid_box_m: (grid_lo, grid_hi),
        hull_secs: t.elapsed().as_secs_f64(),
    })
}

/// Bakes any field source over a capture's plan: the capture's cameras are the
/// views the PCA is weighted by and the rank is judged at; its images under its
/// lighting (when the capture names an env map) measure the grid's own error.
/// `field_provenance` describes the field in the metadata.
pub fn bake_capture_field(
    capture: &LoadedCapture,
    planned: CapturePlan,
    field: &dyn FieldSource,
    view_policy: ViewPolicy,
    field_provenance: &serde_json::Value,
    config: &BakeConfig,
    progress: &Progress,
) -> Result<BakeOutput> {
    let reference = match capture.source_envmap_path() {
        Some(path) => Reference::Images {
            images: capture.images.clone(),
            masks: capture.masks.clone(),
            lighting: load_envmap(&path)?,
        },
        None => Reference::AssumedSnrDb(config.reference_snr_db),
    };
    let (lo, hi) = planned.hull_box_m;
    let (grid_lo, grid_hi) = planned.grid_box_m;
    let provenance = serde_json::json!({
        "kind": "capture",
        "capture": capture.dir.display().to_string(),
        "camera_file": capture.camera_file.display().to_string(),
        "views": capture.names,
        "head_centre_m": capture.head_centre_m.to_array(),
        "hull_box_m": [lo.to_array(), hi.to_array()],
        "grid_box_m": [grid_lo.to_array(), grid_hi.to_array()],
        "source": field_provenance,
    });
    let job = FieldBake {
        field,
        plan: planned.plan,
        cameras: capture.cameras.clone(),
        view_policy,
        reference,
        provenance,
    };
    let prior = StageTimings {
        hull_secs: planned.hull_secs,
        ..StageTimings::default()
    };
    bake_field(&job, config, progress, prior)
}

/// Bakes a capture's ground-truth field: visual hull of its masks, the mesh of
/// `truth` as the field, the capture's cameras as the views.
pub fn bake_capture(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    config: &BakeConfig,
    progress: &Progress,
) -> Result<BakeOutput> {
    let mesh = truth.mesh()?;
    let trace = config.trace.apply(truth.trace_settings());
    // Occupancy only: any voxel size will do for the probe's shell.
    let probe = mesh_field(
        &mesh,
        trace,
        config.voxel_size_m.unwrap_or(1e-3),
        ShellPlacement::Inside,
        config.shell_voxels,
        config.lead_voxels,
    )?;
    let planned = plan_capture(capture, config, probe.as_ref(), progress)?;
    let field = mesh_field(
        &mesh,
        trace,
        planned.voxel_size_m,
        config.shell_placement,
        config.shell_voxels,
        config.lead_voxels,
    )?;
    let centres: Vec<DVec3> = capture.cameras.iter().map(PinholeCamera::centre).collect();
    let view_policy = view_policy_for(config.view_policy, &centres)?;
    let field_provenance = serde_json::json!({
        "ground_truth": truth.describe(),
        "field": describe_trace(&trace, config),
    });
    bake_capture_field(
        capture,
        planned,
        field.as_ref(),
        view_policy,
        &field_provenance,
        config,
        progress,
    )
}

/// The synthetic cameras a mesh bake is judged by: the frontal cone of a default
/// synthetic capture (`nelf_scene::synth::source_viewpoints`) around the mesh's
/// bounding sphere, `size × size` pixels.
pub fn mesh_cameras(mesh: &Mesh, size: u32) -> Vec<PinholeCamera> {
    let (centre, radius) = mesh.bounding_sphere();
    let config = SynthConfig {
        width: size,
        height: size,
        ..SynthConfig::default()
    };
    source_viewpoints(&config)
        .iter()
        .map(|v| camera_for(v, centre, radius, &config))
        .collect()
}

/// The test environment the path-traced references of a mesh bake are lit by
/// (index into [`test_environments`]: the first outdoor map, with a sun).
pub const MESH_REFERENCE_ENV: usize = 1;

/// Bakes a mesh directly: the grid covers the mesh's field (its occupancy is the
/// hull) and the views are [`mesh_cameras`]. The rank is chosen against
/// ground-truth images of those views path-traced from the mesh (at the render
/// size, under the test environment [`MESH_REFERENCE_ENV`]), so the unquantized
/// grid's own error is measured, as for a synthetic capture. `description` goes
/// into the metadata.
pub fn bake_mesh(
    mesh: &Mesh,
    description: &serde_json::Value,
    config: &BakeConfig,
    progress: &Progress,
) -> Result<BakeOutput> {
    config.validate()?;
    let t = Instant::now();
    let (lo, hi) = mesh.bounds();
    let voxel = voxel_size_for((hi - lo).as_dvec3(), config.resolution, config.voxel_size_m)?;
    let trace = config.trace.apply(TraceSettings::default());
    let field = mesh_field(
        mesh,
        trace,
        voxel,
        config.shell_placement,
        config.shell_voxels,
        config.lead_voxels,
    )?;
    let (flo, fhi) = field.bounds();
    let plan = plan_all_bricks(geometry_for_box(flo.as_dvec3(), fhi.as_dvec3(), voxel)?);
    let hull_secs = t.elapsed().as_secs_f64();
    let cameras = mesh_cameras(mesh, config.render_size);
    let centres: Vec<DVec3> = cameras.iter().map(PinholeCamera::centre).collect();
    let view_policy = view_policy_for(config.view_policy, &centres)?;

    // Ground-truth references: the mesh path-traced at the (already reduced) views.
    let t = Instant::now();
    let lighting = test_environments().swap_remove(MESH_REFERENCE_ENV).map;
    let tracer = LtTracer::new(mesh, trace)?;
    let light = light_texels(&lighting, tracer.settings().world_from_light)?;
    let bar = progress.bar("reference", cameras.len() as u64, "views");
    let mut images = Vec::with_capacity(cameras.len());
    let mut masks = Vec::with_capacity(cameras.len());
    for cam in &cameras {
        let image = render_lt_image(&tracer, cam, &light, None)?;
        images.push(image.over([0.0; 3]));
        masks.push(image.alpha);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let reference_secs = t.elapsed().as_secs_f64();
    let provenance = serde_json::json!({
        "kind": "mesh",
        "mesh": description,
        "triangles": mesh.triangles.len(),
        "field": describe_trace(&trace, config),
        "reference_views": format!("{} path-traced views under {}", cameras.len(), test_environments()[MESH_REFERENCE_ENV].name),
    });
    let job = FieldBake {
        field: field.as_ref(),
        plan,
        cameras,
        view_policy,
        reference: Reference::Images {
            images,
            masks,
            lighting,
        },
        provenance,
    };
    let prior = StageTimings {
        hull_secs,
        reference_secs,
        ..StageTimings::default()
    };
    bake_field(&job, config, progress, prior)
}

/// Where the bake's settings and report are saved beside an asset: the asset's path
/// with its extension replaced by `bake.json` (`head.nelf` → `head.bake.json`).
pub fn sidecar_path(asset_path: &Path) -> PathBuf {
    asset_path.with_extension("bake.json")
}

/// Writes the asset atomically (default [`WriteOptions`]) and, beside it,
/// `<asset>.bake.json` with the configuration and the report (timings included).
/// Fills in `write_secs` and `file_size`.
pub fn write_bake(output: &mut BakeOutput, config: &BakeConfig, path: &Path) -> Result<WriteReport> {
    let t = Instant::now();
    let written = write_asset(path, &output.asset, &WriteOptions::default())?;
    output.report.timings.write_secs = t.elapsed().as_secs_f64();
    output.report.file_size = written.file_size;
    let sidecar = sidecar_path(path);
    let json = serde_json::json!({
        "asset": path.display().to_string(),
        "config": config,
        "source": output.asset.metadata.get("source"),
        "report": output.report,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| BakeError::Json {
        path: sidecar.clone(),
        message: e.to_string(),
    })?;
    std::fs::write(&sidecar, text + "\n").map_err(|e| io_error(&sidecar, e))?;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantization_step_spreads_the_share_over_the_kept_components() {
        let pca = WeightedPca {
            mean: vec![0.0; LT_DIM],
            eigenvalues: vec![4.0, 1.0, 0.5, 0.25, 0.25],
            components: Vec::new(),
            total_weight: 1.0,
            count: 10,
        };
        // K = 2 drops 1.0 of variance: K δ²/12 = share · 1.0.
        let step = f64::from(quantization_step(&pca, 2, 0.1));
        assert!((2.0 * step * step / 12.0 - 0.1).abs() < 1e-6, "{step}");
        assert_eq!(quantization_step(&pca, 5, 0.1), 0.0, "nothing dropped");
        assert_eq!(quantization_step(&pca, 2, 0.0), 0.0, "share 0: per-range steps");
        let bad = BakeConfig {
            quantization_share: -1.0,
            ..BakeConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
