//! The bake, stage by stage, one file each, in the order they run:
//!
//! 1. [`plan`]: what is baked: the field, the views, the view policy, the reference
//!    the grid's own error is measured against ([`plan::FieldBake`]);
//! 2. [`hull`]: where the field can be: a capture's visual hull and the bricks over
//!    it, or a mesh's box;
//! 3. [`occupancy`]: density at every candidate voxel, bricks below the opacity
//!    threshold dropped;
//! 4. [`transport`]: visibility in the views, light transport on the band that shows;
//! 5. [`rank`]: the weighted PCA, then the rank chosen by rendered-image loss (the
//!    crate's one rank chooser);
//! 6. [`quantize`]: the asset at that rank, coefficients quantized, with its metadata;
//! 7. [`view`]: view dependence, kept where it gains on the judging views;
//! 8. [`fine`]: the density again on a finer lattice (`--fine-density`, format 1.4);
//! 9. [`write`]: the file and its `.bake.json` sidecar (called by whoever asked for
//!    the bake, after it returns).
//!
//! The functions below run them in that order: [`with_truth_job`] (plan, hull) and
//! [`run_mesh`] set a job up, [`run_job`] bakes it ([`sample`]: occupancy, transport,
//! PCA; [`finish`]: rank, quantize; then view and fine density). The settings are [`crate::config`]'s,
//! checked once by the public entry points ([`crate::jobs`]) before any stage runs.
//! [`outputs`] holds what the stages hand on.
//!
//! The asset written depends only on the inputs and the [`BakeConfig`]: every stage
//! is deterministic (fixed chunking, sums in a fixed order), and timings are kept out
//! of the file (they go to the `.bake.json` beside it), so baking twice gives
//! byte-identical files.

pub mod fine;
pub mod hull;
pub mod occupancy;
pub mod outputs;
pub mod plan;
pub mod quantize;
pub mod rank;
pub mod transport;
pub mod view;
pub mod write;

use nelf_scene::mesh::Mesh;

use crate::capture_in::LoadedCapture;
use crate::config::{BakeConfig, ShellPlacement};
use crate::error::Result;
use crate::progress::Progress;
use crate::source::{GroundTruth, mesh_field};
use outputs::{BakeOutput, SampledField, StageTimings};
use plan::FieldBake;

/// Plan and hull of a capture's ground-truth bake, then `run` on the job: a probe of
/// the mesh's field finds where it is dense, the visual hull of the masks and the
/// bricks over it ([`hull::capture_hull`]), the mesh of `truth` as the field at the
/// voxel size found, the capture's cameras as the views ([`plan::capture_job`]).
pub(crate) fn with_truth_job<R>(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    config: &BakeConfig,
    progress: Progress,
    run: impl FnOnce(&FieldBake<'_>, StageTimings) -> Result<R>,
) -> Result<R> {
    let mesh = truth.mesh()?;
    let trace = plan::truth_trace(truth, config);
    // Occupancy only: any voxel size will do for the probe's shell.
    let probe = mesh_field(
        &mesh,
        trace,
        config.voxel_size_m.unwrap_or(1e-3),
        ShellPlacement::Inside,
        config,
    )?;
    let planned = hull::capture_hull(capture, config, probe.as_ref(), progress)?;
    let field = mesh_field(&mesh, trace, planned.voxel_size_m, config.shell_placement, config)?;
    let fine = fine::fine_mesh_field(&mesh, trace, planned.voxel_size_m, config)?;
    let view_policy = plan::capture_view_policy(capture, config)?;
    let field_provenance = plan::truth_provenance(truth, &trace, config);
    let (mut job, prior) = plan::capture_job(
        capture,
        planned,
        field.as_ref(),
        view_policy,
        &field_provenance,
        config,
    )?;
    job.fine_field = fine.as_deref();
    run(&job, prior)
}

/// A mesh baked directly: its box and field ([`hull::mesh_grid`]), its synthetic
/// views and path-traced references ([`plan::mesh_job`]), then [`run_job`].
pub(crate) fn run_mesh(
    mesh: &Mesh,
    description: &serde_json::Value,
    config: &BakeConfig,
    progress: Progress,
) -> Result<BakeOutput> {
    let (field, grid) = hull::mesh_grid(mesh, config)?;
    let fine = fine::fine_mesh_field(mesh, grid.trace, grid.plan.geometry.voxel_size_m, config)?;
    let (mut job, prior) = plan::mesh_job(mesh, description, field.as_ref(), grid, config, progress)?;
    job.fine_field = fine.as_deref();
    run_job(&job, config, progress, prior)
}

/// Bakes a planned job: [`sample`], [`finish`], then the view-dependence stage.
/// `prior` holds the seconds of the stages already run (hull, references).
pub(crate) fn run_job(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: Progress,
    prior: StageTimings,
) -> Result<BakeOutput> {
    let sampled = sample(job, config, progress, prior)?;
    let mut output = finish(job, config, progress, &sampled)?;
    view::add_view_dependence(job, config, &progress, &sampled, &mut output)?;
    fine::add_fine_density(job, config, progress, &mut output)?;
    Ok(output)
}

/// Occupancy, transport and PCA: the field sampled on its grid, from which any
/// rank and encoding can be made.
pub(crate) fn sample(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: Progress,
    prior: StageTimings,
) -> Result<SampledField> {
    let mut timings = prior;
    let dense = occupancy::dense_grid(job, config, progress, &mut timings)?;
    let transport = transport::band_transport(job, &dense, config, progress, &mut timings)?;
    rank::weighted_pca(job, config, dense, transport, timings)
}

/// The rank chosen by rendered loss and the asset quantized at it, with its metadata.
pub(crate) fn finish(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: Progress,
    sampled: &SampledField,
) -> Result<BakeOutput> {
    let choice = rank::choose_rank(job, config, progress, sampled)?;
    quantize::asset_at_rank(job, config, sampled, &choice)
}
