//! The bake proper, stage by stage, for any field source over a planned grid:
//! density pass and brick drop → visibility weights → light transport on the band
//! that shows → weighted PCA → rank choice by rendered loss → quantize → write.
//! Planning the grid of a capture or a mesh and choosing its field is
//! [`crate::jobs`]'s; the settings are [`crate::config`]'s.
//!
//! The asset written depends only on the inputs and the [`BakeConfig`]: every
//! stage is deterministic (fixed chunking, sums in a fixed order), and timings are
//! kept out of the file (they go to the `.bake.json` beside it), so baking twice
//! gives byte-identical files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec3, Vec3};
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::{Asset, Coefficients, WriteOptions, WriteReport, encode_density, write_asset};
use nelf_render::visibility_weights;
use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::tracer::MAX_AVERAGED_DIRECTIONS;
use serde::{Deserialize, Serialize};

use crate::config::{BakeConfig, ViewPolicyChoice};
use crate::error::{BakeError, Result, io_error};
use crate::eval::HeldAside;
use crate::grid::{GridPlan, evaluate_density, evaluate_light_transport, light_transport_band};
use crate::pca::{WeightedPca, fit_weighted_pca, project_coefficients};
use crate::progress::Progress;
use crate::rank::{
    CandidateLoss, RankScene, TestEnv, box_downsample, candidate_loss, candidate_ranks, component_images,
    light_texels, reduced_camera, reference_renders, relative_error_vs_images, test_environments,
    unquantized_radiance,
};
use crate::view::{ReflectionTarget, ViewChoice, ViewReport, ViewSettings, choose_view};

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
    /// View dependence: sampling many directions, fitting, judging.
    #[serde(default)]
    pub view_secs: f64,
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
    /// The view-dependence stage (`None` when `--view-dependence off`).
    #[serde(default)]
    pub view: Option<ViewReport>,
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
    /// Held-aside views (the capture's targets) that judge the view-dependence choice;
    /// empty when the capture has none (the reference images judge it then).
    pub held: HeldAside,
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

/// A field sampled on its grid: everything a bake computes before it chooses the
/// rank and the encoding (density, visibility, light transport on the band, the
/// weighted PCA, the coefficients at the largest rank allowed). Any number of
/// assets (rank × encoding) can be made from one, with no further field
/// evaluation ([`SampledField::asset`]): `nelf bake --target-psnr` and
/// `nelf eval pareto` try many.
#[derive(Debug, Clone)]
pub struct SampledField {
    /// Kept bricks, densities and the brick-drop figures.
    pub dense: crate::grid::DensityGrid,
    /// Density as the file stores it (f16).
    pub stored_density: Vec<half::f16>,
    /// The capture's views at the reduced resolution of the weights and rank renders.
    pub views: Vec<PinholeCamera>,
    /// `(reduced camera, factor)` per capture view.
    pub reduced: Vec<(PinholeCamera, u32)>,
    /// Voxels whose light transport was evaluated.
    pub lt_voxels: Vec<usize>,
    /// Their light transport, `LT_DIM` floats each.
    pub lt: Vec<f32>,
    /// Their PCA weights (visibility in the views plus the floor).
    pub lt_weights: Vec<f64>,
    /// The weighted PCA of `lt`.
    pub pca: WeightedPca,
    /// The data's numerical rank.
    pub data_rank: usize,
    /// Rank of [`Self::coefficients`]: `--rank` when forced, else `min(--max-rank, data rank)`.
    pub top_rank: usize,
    /// Coefficients at `top_rank`, `voxels × top_rank` (zero outside the band).
    pub coefficients: Vec<f32>,
    /// The 8-bit step floor for `top_rank` ([`quantization_step`]).
    pub min_step: f32,
    /// Rotation from the light frame to the world.
    pub world_from_light: glam::DMat3,
    /// Seconds per stage so far (rank and write still 0).
    pub timings: StageTimings,
}

impl SampledField {
    /// The asset holding the first `rank` components (`rank ≤ top_rank`) in
    /// `encoding`, with empty metadata: exactly what a bake with that rank and
    /// encoding writes, less its metadata.
    pub fn asset(&self, rank: usize, encoding: nelf_format::CoefficientEncoding) -> Result<Asset> {
        if rank == 0 || rank > self.top_rank {
            return Err(BakeError::Settings(format!(
                "rank {rank} is outside 1..={} (the rank the field was sampled for)",
                self.top_rank
            )));
        }
        let truncated: Vec<f32> = if rank == self.top_rank {
            self.coefficients.clone()
        } else {
            self.coefficients
                .chunks_exact(self.top_rank)
                .flat_map(|c| c[..rank].iter().copied())
                .collect()
        };
        let asset = Asset {
            grid: *self.dense.grid.geometry(),
            world_from_light: self.world_from_light,
            bricks: self.dense.grid.bricks().to_vec(),
            density: self.stored_density.clone(),
            pca: self.pca.model(self.top_rank).truncated(rank),
            coefficients: Coefficients::quantize_with_min_step(&truncated, rank, encoding, self.min_step)?,
            view: None,
            reflection: None,
            metadata: serde_json::json!({}),
        };
        Ok(asset)
    }
}

/// Samples `job`'s field with `config`: density and brick drop, visibility weights,
/// light transport on the band, weighted PCA, coefficients at the top rank. `prior`
/// holds the seconds of the stages the caller ran (planning the grid, rendering
/// references).
pub fn sample_field(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    prior: StageTimings,
) -> Result<SampledField> {
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
    let min_step = quantization_step(&pca, top_rank, config.quantization_share);
    let world_from_light = job.field.world_from_light();
    let stored_density = encode_density(density)?;
    timings.pca_secs = t.elapsed().as_secs_f64();
    Ok(SampledField {
        dense,
        stored_density,
        views,
        reduced,
        lt_voxels,
        lt,
        lt_weights: weights,
        pca,
        data_rank,
        top_rank,
        coefficients,
        min_step,
        world_from_light,
        timings,
    })
}

/// Bakes `job` with `config`: [`sample_field`], then the rank chosen by rendered
/// loss ([`crate::rank`]) and the asset at that rank.
pub fn bake_field(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    prior: StageTimings,
) -> Result<BakeOutput> {
    let sampled = sample_field(job, config, progress, prior)?;
    let mut output = finish_bake(job, config, progress, &sampled)?;
    add_view_dependence(job, config, progress, &sampled, &mut output)?;
    Ok(output)
}

/// What the reflection part is fitted against under `policy`: the points it averages
/// toward (at most [`nelf_format::asset::MAX_REFLECTION_EYES`], subsampled evenly), or
/// `None` for a policy of fixed directions, where the part cannot say what `T̄` holds.
pub fn reflection_target(policy: &ViewPolicy, world_from_light: glam::DMat3) -> Option<ReflectionTarget> {
    let points = match policy {
        ViewPolicy::TowardPoint(p) => vec![*p],
        ViewPolicy::AverageTowardPoints(list) => list.clone(),
        ViewPolicy::Direction(_) | ViewPolicy::AverageDirections(_) => return None,
    };
    let n = points.len();
    let m = n.min(nelf_format::asset::MAX_REFLECTION_EYES);
    (m > 0).then(|| ReflectionTarget {
        eyes: (0..m).map(|i| points[i * n / m]).collect(),
        world_from_light,
    })
}

/// The view-dependence stage ([`crate::view`]): fits the residual of the field toward
/// many directions, judges the candidates at the held-aside views (else the reference
/// images), attaches the chosen part to the asset and records the decision in its
/// metadata (`view_dependence`) and the report.
pub fn add_view_dependence(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    sampled: &SampledField,
    output: &mut BakeOutput,
) -> Result<()> {
    if config.view_dependence == ViewChoice::Off {
        return Ok(());
    }
    let from_reference;
    let judge = if job.held.is_empty() {
        match &job.reference {
            Reference::Images {
                images,
                masks,
                lighting,
            } => {
                from_reference = HeldAside {
                    names: (0..images.len()).map(|i| format!("view {i}")).collect(),
                    cameras: job.cameras.clone(),
                    images: images.clone(),
                    masks: masks.clone(),
                    envs: vec![lighting.clone(); images.len()],
                };
                (&from_reference, "the capture's own views")
            }
            Reference::AssumedSnrDb(_) => (&job.held, "none"),
        }
    } else {
        (&job.held, "the capture's held-aside targets")
    };
    let settings = ViewSettings {
        choice: config.view_dependence,
        min_gain_db: config.view_min_gain_db,
        rank: config.view_rank,
        max_rank: config.max_view_rank,
        step_voxels: config.step_voxels,
    };
    let reflect = reflection_target(&job.view_policy, output.asset.world_from_light);
    let report = choose_view(
        &mut output.asset,
        job.field,
        &sampled.dense.grid,
        &sampled.dense.density,
        &sampled.lt_voxels,
        &sampled.lt,
        &sampled.lt_weights,
        &job.cameras.iter().map(PinholeCamera::centre).collect::<Vec<_>>(),
        reflect.as_ref(),
        &settings,
        judge,
        progress,
    )?;
    output.report.timings.view_secs = report.secs;
    if let Some(meta) = output.asset.metadata.as_object_mut() {
        // Timings stay out of the file (they go to the .bake.json), so bakes repeat
        // byte for byte.
        let mut recorded = serde_json::to_value(&report).unwrap_or_default();
        if let Some(fields) = recorded.as_object_mut() {
            fields.remove("secs");
        }
        meta.insert("view_dependence".into(), recorded);
    }
    output.report.view = Some(report);
    output.asset.validate()?;
    Ok(())
}

/// The rank choice and the asset at the chosen rank, from a sampled field.
pub fn finish_bake(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    sampled: &SampledField,
) -> Result<BakeOutput> {
    let SampledField {
        dense,
        views,
        reduced,
        lt_voxels,
        lt,
        pca,
        data_rank,
        top_rank,
        min_step,
        world_from_light,
        timings,
        ..
    } = sampled;
    let (data_rank, top_rank, min_step, world_from_light) =
        (*data_rank, *top_rank, *min_step, *world_from_light);
    let mut timings = *timings;
    let grid = &dense.grid;
    let density = &dense.density;
    let voxels = grid.voxel_count();
    let march = config.march();
    let encoding = config.encoding.encoding();
    let model = pca.model(top_rank);
    let full = sampled.asset(top_rank, encoding)?;

    // Rank choice.
    let t = Instant::now();
    let scene = RankScene {
        grid,
        density,
        views,
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
            let radiance = unquantized_radiance(voxels, lt_voxels, lt, &model.mean, &light);
            let mut small_images = Vec::with_capacity(images.len());
            let mut small_masks = Vec::with_capacity(images.len());
            for ((img, mask), (cam, (_, factor))) in
                images.iter().zip(masks).zip(job.cameras.iter().zip(reduced))
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
    let references = reference_renders(&scene, &envs, lt_voxels, lt, &model.mean)?;
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
        view: None,
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
        metadata,
        ..sampled.asset(rank, encoding)?
    };
    asset.validate()?;
    Ok(BakeOutput { asset, report })
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
        "choice": output.asset.metadata.get("choice"),
        "report": output.report,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| BakeError::Json {
        path: sidecar.clone(),
        message: e.to_string(),
    })?;
    nelf_format::atomic::write_bytes_atomically(&sidecar, (text + "\n").as_bytes())
        .map_err(|e| io_error(&sidecar, e))?;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use nelf_format::conventions::LT_DIM;

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
