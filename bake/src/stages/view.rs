//! Stage 7, **view dependence** (`--view-dependence`, [`crate::view`]): the residual
//! of the field toward many directions fitted, the candidates judged at the
//! held-aside views (else the reference images), the chosen part attached to the
//! asset and the decision recorded in its metadata and the report.

use nelf_format::conventions::PinholeCamera;
use nelf_scene::field::ViewPolicy;

use crate::config::BakeConfig;
use crate::error::Result;
use crate::eval::HeldAside;
use crate::progress::Progress;
use crate::stages::outputs::{BakeOutput, SampledField};
use crate::stages::plan::{FieldBake, Reference};
use crate::view::{ReflectionTarget, ViewChoice, ViewSettings, choose_view};

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
            if let Some(probe) = fields.get_mut("probe").and_then(|p| p.as_object_mut()) {
                probe.remove("secs");
            }
        }
        meta.insert("view_dependence".into(), recorded);
    }
    output.report.view = Some(report);
    output.asset.validate()?;
    Ok(())
}
