//! Stage 6, **quantize**: the asset at a rank. The first `rank` components of the
//! sampled field's coefficients quantized in the chosen encoding with one step floor
//! for every component ([`quantization_step`]), and, for a bake, the asset at the rank
//! chosen with its report and metadata ([`asset_at_rank`]).

use nelf_format::{Asset, CoefficientEncoding, Coefficients};

use crate::config::BakeConfig;
use crate::error::{BakeError, Result};
use crate::pca::WeightedPca;
use crate::stages::outputs::{BakeOutput, BakeReport, RankChoice, SampledField};
use crate::stages::plan::{FieldBake, policy_json};

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

impl SampledField {
    /// The asset holding the first `rank` components (`rank ≤ top_rank`) in
    /// `encoding`, with empty metadata: exactly what a bake with that rank and
    /// encoding writes, less its metadata.
    pub fn asset(&self, rank: usize, encoding: CoefficientEncoding) -> Result<Asset> {
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
            fine_density: None,
            metadata: serde_json::json!({}),
        };
        Ok(asset)
    }
}

/// The asset at the rank `choice` names in `--encoding`, with the bake's report and
/// the metadata the file carries (source, view policy, settings, grid, PCA, rank
/// choice).
pub(crate) fn asset_at_rank(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    sampled: &SampledField,
    choice: &RankChoice,
) -> Result<BakeOutput> {
    let dense = &sampled.dense;
    let grid = &dense.grid;
    let pca = &sampled.pca;
    let rank = choice.rank;
    let encoding = config.encoding.encoding();
    let report = BakeReport {
        voxel_size_m: grid.geometry().voxel_size_m,
        grid_bricks: grid.geometry().grid_bricks,
        hull_voxels: job.plan.hull_voxels,
        candidate_bricks: dense.candidate_bricks,
        bricks: grid.bricks().len(),
        apron_bricks: dense.apron_bricks,
        voxels: grid.voxel_count(),
        lt_voxels: sampled.lt_voxels.len(),
        rank,
        energy_kept: pca.energy_kept(rank),
        loss_db: choice.candidates[choice.pick].loss_db,
        met_target: choice.met_target,
        reference_relative_error: choice.reference_relative_error,
        candidates: choice.candidates.clone(),
        timings: choice.timings,
        file_size: 0,
        view: None,
        notes: Vec::new(),
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
            "data_rank": sampled.data_rank,
            "encoding": encoding.name(),
            "quantization_min_step": sampled.min_step,
            "weighting": "sum over the capture's views of the visibility weights (nelf-render), plus weight_floor × their mean",
            "eigenvalues": pca.eigenvalues.iter().take(sampled.top_rank.max(rank)).collect::<Vec<_>>(),
        },
        "rank_choice": {
            "forced": config.rank.is_some(),
            "max_loss_db": config.max_loss_db,
            "loss_db": report.loss_db,
            "met_target": choice.met_target,
            "reference": choice.reference_json,
            "test_environments": choice.environments,
            "render_size": config.render_size,
            "candidates": choice.candidates,
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
