//! The bake's public entry points, where a [`BakeConfig`] comes in and is checked,
//! once, before any stage of [`crate::stages`] runs: a capture's ground truth
//! ([`bake_capture`], [`with_capture_job`]), any field over a capture's hull
//! ([`plan_capture`], then [`bake_capture_field`]), a mesh baked directly
//! ([`bake_mesh`]), and a planned job ([`bake_field`], or [`sample_field`] then
//! [`finish_bake`] for many assets from one sample).

use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::mesh::Mesh;
use nelf_scene::tracer::TraceSettings;

use crate::capture_in::LoadedCapture;
use crate::config::BakeConfig;
use crate::error::Result;
use crate::progress::Progress;
use crate::source::GroundTruth;
use crate::stages;
pub use crate::stages::hull::CapturePlan;
use crate::stages::outputs::{BakeOutput, SampledField, StageTimings};
use crate::stages::plan::FieldBake;
pub use crate::stages::plan::{MESH_REFERENCE_ENV, mesh_cameras};

/// Carves the visual hull of a capture's masks and lays bricks over it. With
/// `--resolution`, the voxel size is the longest side of the region where `probe`
/// is dense ([`crate::grid::occupied_box`]) over the resolution, and the grid covers
/// that region; with `--voxel-size-m` the grid covers the hull's box.
pub fn plan_capture(
    capture: &LoadedCapture,
    config: &BakeConfig,
    probe: &dyn FieldSource,
    progress: &Progress,
) -> Result<CapturePlan> {
    config.validate()?;
    stages::hull::capture_hull(capture, config, probe, *progress)
}

/// The bake job of any field source over a capture's plan: the capture's cameras
/// are the views the PCA is weighted by and the rank is judged at; its images under
/// its lighting (when the capture names an env map) measure the grid's own error.
/// `field_provenance` describes the field in the metadata. Returns the job and the
/// seconds already spent (the hull). Runs no stage: [`bake_field`] checks `config`.
pub fn capture_field_job<'a>(
    capture: &LoadedCapture,
    planned: CapturePlan,
    field: &'a dyn FieldSource,
    view_policy: ViewPolicy,
    field_provenance: &serde_json::Value,
    config: &BakeConfig,
) -> Result<(FieldBake<'a>, StageTimings)> {
    stages::plan::capture_job(capture, planned, field, view_policy, field_provenance, config)
}

/// Bakes any field source over a capture's plan ([`capture_field_job`], then
/// [`bake_field`]).
pub fn bake_capture_field(
    capture: &LoadedCapture,
    planned: CapturePlan,
    field: &dyn FieldSource,
    view_policy: ViewPolicy,
    field_provenance: &serde_json::Value,
    config: &BakeConfig,
    progress: &Progress,
) -> Result<BakeOutput> {
    config.validate()?;
    let (job, prior) =
        stages::plan::capture_job(capture, planned, field, view_policy, field_provenance, config)?;
    stages::run_job(&job, config, *progress, prior)
}

/// Runs `run` on the ground-truth bake job of a capture: visual hull of its masks,
/// the mesh of `truth` as the field (at `config`'s voxel size), the capture's
/// cameras as the views.
pub fn with_capture_job<R>(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    config: &BakeConfig,
    progress: &Progress,
    run: impl FnOnce(&FieldBake<'_>, StageTimings) -> Result<R>,
) -> Result<R> {
    config.validate()?;
    stages::with_truth_job(capture, truth, config, *progress, run)
}

/// The ground-truth mesh field of `truth` at voxel size `voxel_size_m`, as a
/// capture's ground-truth bake samples it (`config`'s shell placement and trace).
pub fn truth_field(
    truth: &GroundTruth,
    config: &BakeConfig,
    voxel_size_m: f64,
) -> Result<Box<dyn FieldSource>> {
    stages::plan::truth_field_traced(truth, config, voxel_size_m, |_| {})
}

/// [`truth_field`] with its trace settings changed by `adjust` (e.g. direct light
/// only, no glossy lobe: the ground truth's Lambertian shading with its shadows).
pub fn truth_field_traced(
    truth: &GroundTruth,
    config: &BakeConfig,
    voxel_size_m: f64,
    adjust: impl FnOnce(&mut TraceSettings),
) -> Result<Box<dyn FieldSource>> {
    stages::plan::truth_field_traced(truth, config, voxel_size_m, adjust)
}

/// Bakes a capture's ground-truth field: visual hull of its masks, the mesh of
/// `truth` as the field, the capture's cameras as the views.
pub fn bake_capture(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    config: &BakeConfig,
    progress: &Progress,
) -> Result<BakeOutput> {
    config.validate()?;
    stages::with_truth_job(capture, truth, config, *progress, |job, prior| {
        stages::run_job(job, config, *progress, prior)
    })
}

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
    stages::run_mesh(mesh, description, config, *progress)
}

/// Bakes `job` with `config`: [`sample_field`], then the rank chosen by rendered
/// loss ([`crate::stages::rank`]), the asset at that rank and its view dependence.
/// `prior` holds the seconds of the stages the caller ran (planning the grid,
/// rendering references).
pub fn bake_field(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    prior: StageTimings,
) -> Result<BakeOutput> {
    config.validate()?;
    stages::run_job(job, config, *progress, prior)
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
    stages::sample(job, config, *progress, prior)
}

/// The rank choice and the asset at the chosen rank, from a sampled field (no view
/// dependence: [`crate::stages::view::add_view_dependence`] adds it).
pub fn finish_bake(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: &Progress,
    sampled: &SampledField,
) -> Result<BakeOutput> {
    config.validate()?;
    stages::finish(job, config, *progress, sampled)
}
