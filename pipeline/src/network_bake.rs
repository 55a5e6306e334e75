//! A network's field baked over a capture's hull ([`bake_network_field`]): box-
//! filtered over voxels, its density signed and carved to the masks' visual hull,
//! optionally with a part swapped for the ground truth's; [`bake_network`] does it
//! all from the weights.

use std::path::Path;

use nelf_bake::{BakeOutput, GroundTruth, HullCarved, HullDistance, LoadedCapture, Progress};
use nelf_field::NelfField;
use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::signed_density::SignedLogDensity;

use crate::config::PipelineConfig;
use crate::error::{Context as _, Result};
use crate::network::{SourceFit, load_network, network_field, network_provenance};
use crate::truth_split::{FromTruth, with_truth_part};
use crate::voxel_filter::VoxelFiltered;

/// Sub-points per voxel edge where a network's field is baked
/// ([`VoxelFiltered`]): a trained network's skin is a shell thinner than a voxel,
/// which point samples at voxel centres alias into stripes. Measured with `nelf eval
/// network` on held-out heads (docs/measurements/2026-11-26-network-bake.md).
pub const NETWORK_VOXEL_FILTER: usize = 2;

/// How one network bake is sampled, where it departs from `nelf bake capture`'s.
#[derive(Debug, Clone)]
pub struct NetworkSampling<'a> {
    /// Sub-points per voxel edge ([`NETWORK_VOXEL_FILTER`] by default).
    pub voxel_filter: usize,
    /// The outgoing direction of the light transport (`None`: the network's
    /// recommended policy).
    pub view_policy: Option<ViewPolicy>,
    /// A part of the field taken from this ground truth (`nelf eval network --split`).
    pub from_truth: Option<(&'a GroundTruth, FromTruth)>,
}

impl Default for NetworkSampling<'_> {
    fn default() -> Self {
        Self {
            voxel_filter: NETWORK_VOXEL_FILTER,
            view_policy: None,
            from_truth: None,
        }
    }
}

/// The network's field over the capture's hull: the views are encoded once, then
/// density and light transport are evaluated at the voxels (toward the mean camera,
/// the policy measured best in field/README.md). `weights`: the shipped network when
/// `None`.
pub fn bake_network(
    capture: &LoadedCapture,
    weights: Option<&Path>,
    config: &PipelineConfig,
    progress: Progress,
) -> Result<BakeOutput> {
    config.validate()?;
    let (model, weights_name) = load_network(weights)?;
    let model_size = model.working_image_size();
    let (prepared, field) = network_field(capture, model, SourceFit::of_config(config))?;
    let encoded_size = prepared.cameras.first().map(|c| [c.width, c.height]);
    let mut provenance = network_provenance(&field, &weights_name);
    provenance["working_image_size"] = serde_json::json!(model_size);
    provenance["encoded_image_size"] = serde_json::json!(encoded_size);
    provenance["device"] = serde_json::json!(nelf_field::device_name(&nelf_field::default_device()));
    provenance["view_policy"] = serde_json::json!("toward the mean camera");
    bake_network_field(
        capture,
        &field,
        &provenance,
        config,
        progress,
        &NetworkSampling::default(),
    )
}

/// Bakes `field` (the network over `capture`'s views) as `sampling` says (by
/// default toward the network's recommended view policy, box-filtered over voxels by
/// [`NETWORK_VOXEL_FILTER`]), its density stored as a signed function of `ln σ`
/// ([`SignedLogDensity`]) unless `config.network_skin_mm` is 0; `provenance` goes
/// into the asset's metadata.
pub fn bake_network_field(
    capture: &LoadedCapture,
    field: &NelfField,
    provenance: &serde_json::Value,
    config: &PipelineConfig,
    progress: Progress,
    sampling: &NetworkSampling<'_>,
) -> Result<BakeOutput> {
    config.validate()?;
    let NetworkSampling {
        voxel_filter,
        view_policy,
        from_truth,
    } = sampling.clone();
    let bake = &config.bake;
    let planned = nelf_bake::plan_capture(capture, bake, field, &progress)?;
    let view_policy = view_policy.unwrap_or_else(|| field.recommended_view_policy());
    let voxel_size_m = planned.voxel_size_m;
    let voxel_m = voxel_size_m as f32;
    let filtered = VoxelFiltered::new(field, voxel_m, voxel_filter)?;
    let (signed, carved);
    let source: &dyn FieldSource = if config.network_skin_mm > 0.0 {
        signed = SignedLogDensity::with_skin(
            &filtered,
            config.network_skin_mm / 1000.0,
            bake.ramp_voxels * voxel_m,
            voxel_m,
        )?;
        if config.no_network_hull_carve {
            &signed
        } else {
            let hull = HullDistance::new(
                &capture.cameras,
                &capture.masks,
                f64::from(config.network_hull_margin_px),
            )
            .with_context(|| format!("the visual hull of {}", capture.dir.display()))?;
            carved = HullCarved::new(&signed, hull);
            &carved
        }
    } else {
        &filtered
    };
    let finish = |source: &dyn FieldSource| {
        Ok(nelf_bake::bake_capture_field(
            capture,
            planned,
            source,
            view_policy,
            provenance,
            bake,
            &progress,
        )?)
    };
    match from_truth {
        None => finish(source),
        Some((ground_truth, part)) => {
            with_truth_part(capture, ground_truth, part, config, voxel_size_m, source, finish)
        }
    }
}
