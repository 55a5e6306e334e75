//! Stage 5, **PCA and rank**: the band's light transport reduced by a PCA weighted
//! by visibility in the views ([`crate::pca`]), its coefficients at the largest rank
//! allowed, and then the rank `K` chosen per scene by rendered-image loss: the one
//! rank chooser of the crate ([`choose_rank`]; the loss and its renders are
//! [`crate::rank`]'s). A bake and each candidate of `--target-psnr`
//! ([`crate::choose`], which forces the rank it tries) both go through it.

use std::time::Instant;

use nelf_format::encode_density;

use crate::config::BakeConfig;
use crate::error::{BakeError, Result};
use crate::grid::DensityGrid;
use crate::pca::{fit_weighted_pca, project_coefficients};
use crate::progress::Progress;
use crate::rank::{
    CandidateLoss, RankScene, TestEnv, box_downsample, candidate_loss, candidate_ranks, component_images,
    light_texels, reference_renders, relative_error_vs_images, test_environments, unquantized_radiance,
};
use crate::stages::outputs::{RankChoice, SampledField, StageTimings};
use crate::stages::plan::{FieldBake, Reference};
use crate::stages::quantize::quantization_step;
use crate::stages::transport::Transport;

/// The weighted PCA of the band's transport (weights: visibility plus
/// `--weight-floor` × its mean), the coefficients at the top rank (`--rank` when
/// forced, else `min(--max-rank, data rank)`) and the 8-bit step floor for it; fills
/// `timings.pca_secs`.
pub(crate) fn weighted_pca(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    dense: DensityGrid,
    transport: Transport,
    mut timings: StageTimings,
) -> Result<SampledField> {
    let Transport {
        views,
        reduced,
        visibility,
        lt_voxels,
        lt,
    } = transport;
    let voxels = dense.grid.voxel_count();
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
    let stored_density = encode_density(&dense.density)?;
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

/// `m₀`, the unquantized grid's relative error against ground truth (see
/// [`crate::rank`]), and how it was known, for the metadata.
fn reference_error(
    job: &FieldBake<'_>,
    scene: &RankScene<'_>,
    sampled: &SampledField,
) -> Result<(f64, serde_json::Value)> {
    let (m0, reference_json) = match &job.reference {
        Reference::Images {
            images,
            masks,
            lighting,
        } => {
            let mean = &sampled.pca.model(sampled.top_rank).mean;
            let light = light_texels(lighting, sampled.world_from_light)?;
            let radiance = unquantized_radiance(
                sampled.dense.grid.voxel_count(),
                &sampled.lt_voxels,
                &sampled.lt,
                mean,
                &light,
            );
            let mut small_images = Vec::with_capacity(images.len());
            let mut small_masks = Vec::with_capacity(images.len());
            for ((img, mask), (cam, (_, factor))) in images
                .iter()
                .zip(masks)
                .zip(job.cameras.iter().zip(&sampled.reduced))
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
            let m0 = relative_error_vs_images(scene, &radiance, &small_images, &small_masks)?;
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
    Ok((m0, reference_json))
}

/// Chooses the rank by rendered-image loss: the smallest of
/// [`crate::rank::candidate_ranks`] whose worst loss over the test environments
/// (plus the capture's own lighting when known) is at most `--max-loss-db`, else the
/// largest, flagged; with `--rank` only that rank, judged. The candidates are the
/// asset at the top rank in `--encoding`, truncated; fills `timings.rank_secs`.
pub(crate) fn choose_rank(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: Progress,
    sampled: &SampledField,
) -> Result<RankChoice> {
    let full = sampled.asset(sampled.top_rank, config.encoding.encoding())?;
    let mut timings = sampled.timings;
    let t = Instant::now();
    let scene = RankScene {
        grid: &sampled.dense.grid,
        density: &sampled.dense.density,
        views: &sampled.views,
        march: config.march(),
        world_from_light: sampled.world_from_light,
    };
    let (m0, reference_json) = reference_error(job, &scene, sampled)?;
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
    let mean = &sampled.pca.model(sampled.top_rank).mean;
    let references = reference_renders(&scene, &envs, &sampled.lt_voxels, &sampled.lt, mean)?;
    let components = component_images(&scene, &full)?;
    let ranks = match config.rank {
        Some(k) => vec![k],
        None => candidate_ranks(config.max_rank, sampled.data_rank),
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
            energy_kept: sampled.pca.energy_kept(k),
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
    timings.rank_secs = t.elapsed().as_secs_f64();
    Ok(RankChoice {
        rank: candidates[pick].rank,
        candidates,
        pick,
        met_target,
        reference_relative_error: m0,
        reference_json,
        environments: envs.iter().map(|e| e.name.clone()).collect(),
        timings,
    })
}
