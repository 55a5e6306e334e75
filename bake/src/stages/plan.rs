//! Stage 1, **plan**: what is baked. A job ([`FieldBake`]) is a field source, the
//! bricks laid over its hull ([`super::hull`]), the views the asset is judged by,
//! the outgoing direction of the light transport ([`view_policy_for`]), how the
//! unquantized grid's own error is known ([`Reference`]) and the provenance for the
//! metadata. Two kinds: a **capture** (its cameras, its images under its lighting
//! when it names an env map, its held-aside targets) and a **mesh** baked directly
//! (synthetic cameras, path-traced references).

use std::time::Instant;

use glam::{DVec3, Vec3};
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_scene::envmap::load_envmap;
use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::mesh::Mesh;
use nelf_scene::render::render_lt_image;
use nelf_scene::synth::{SynthConfig, camera_for, source_viewpoints};
use nelf_scene::tracer::{LtTracer, MAX_AVERAGED_DIRECTIONS, TraceSettings};

use crate::capture_in::LoadedCapture;
use crate::config::{BakeConfig, ViewPolicyChoice};
use crate::error::{BakeError, Result};
use crate::eval::{HeldAside, load_held_aside};
use crate::grid::GridPlan;
use crate::progress::Progress;
use crate::rank::{light_texels, test_environments};
use crate::source::{GroundTruth, describe_trace, mesh_field};
use crate::stages::hull::{CapturePlan, MeshPlan};
use crate::stages::outputs::StageTimings;

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
    /// The field that gives the fine density (`--fine-density`) when it is not `field`
    /// itself: a mesh's field with its ramp and lead scaled to the fine voxel
    /// ([`crate::source::mesh_field`] at `Δ/F`). `None`: `field`'s own density.
    pub fine_field: Option<&'a dyn FieldSource>,
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

/// The view policy as the metadata records it.
pub(crate) fn policy_json(policy: &ViewPolicy, choice: ViewPolicyChoice) -> serde_json::Value {
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

/// The job of any field source over a capture's plan: the capture's cameras are the
/// views the PCA is weighted by and the rank is judged at; its images under its
/// lighting (when the capture names an env map) measure the grid's own error.
/// `field_provenance` describes the field in the metadata. Returns the job and the
/// seconds already spent (the hull).
pub(crate) fn capture_job<'a>(
    capture: &LoadedCapture,
    planned: CapturePlan,
    field: &'a dyn FieldSource,
    view_policy: ViewPolicy,
    field_provenance: &serde_json::Value,
    config: &BakeConfig,
) -> Result<(FieldBake<'a>, StageTimings)> {
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
    let held = match capture.description() {
        Some(description) => load_held_aside(description, &capture.dir)?,
        None => HeldAside::default(),
    };
    let job = FieldBake {
        field,
        plan: planned.plan,
        cameras: capture.cameras.clone(),
        view_policy,
        reference,
        provenance,
        held,
        fine_field: None,
    };
    let prior = StageTimings {
        hull_secs: planned.hull_secs,
        ..StageTimings::default()
    };
    Ok((job, prior))
}

/// The view policy of `config` for a capture's cameras.
pub(crate) fn capture_view_policy(capture: &LoadedCapture, config: &BakeConfig) -> Result<ViewPolicy> {
    let centres: Vec<DVec3> = capture.cameras.iter().map(PinholeCamera::centre).collect();
    view_policy_for(config.view_policy, &centres)
}

/// How a capture's ground-truth field is described in the metadata.
pub(crate) fn truth_provenance(
    truth: &GroundTruth,
    trace: &TraceSettings,
    config: &BakeConfig,
) -> serde_json::Value {
    serde_json::json!({
        "ground_truth": truth.describe(),
        "field": describe_trace(trace, config),
    })
}

/// The trace settings of `truth`'s field under `config`'s overrides.
pub(crate) fn truth_trace(truth: &GroundTruth, config: &BakeConfig) -> TraceSettings {
    config.trace.apply_to_field(truth.trace_settings())
}

/// The ground-truth mesh field of `truth` at voxel size `voxel_size_m`, its trace
/// settings changed by `adjust` (`config`'s shell placement).
pub(crate) fn truth_field_traced(
    truth: &GroundTruth,
    config: &BakeConfig,
    voxel_size_m: f64,
    adjust: impl FnOnce(&mut TraceSettings),
) -> Result<Box<dyn FieldSource>> {
    let mesh = truth.mesh()?;
    let mut trace = truth_trace(truth, config);
    adjust(&mut trace);
    mesh_field(&mesh, trace, voxel_size_m, config.shell_placement, config)
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

/// The job of a mesh baked directly over its grid ([`super::hull::mesh_grid`], whose
/// field is `field`): the
/// views are [`mesh_cameras`], and the rank is chosen against ground-truth images of
/// those views path-traced from the mesh (at the render size, under the test
/// environment [`MESH_REFERENCE_ENV`]), so the unquantized grid's own error is
/// measured, as for a synthetic capture. `description` goes into the metadata.
pub(crate) fn mesh_job<'a>(
    mesh: &Mesh,
    description: &serde_json::Value,
    field: &'a dyn FieldSource,
    grid: MeshPlan,
    config: &BakeConfig,
    progress: Progress,
) -> Result<(FieldBake<'a>, StageTimings)> {
    let cameras = mesh_cameras(mesh, config.render_size);
    let centres: Vec<DVec3> = cameras.iter().map(PinholeCamera::centre).collect();
    let view_policy = view_policy_for(config.view_policy, &centres)?;

    // Ground-truth references: the mesh path-traced at the (already reduced) views.
    let t = Instant::now();
    let lighting = test_environments().swap_remove(MESH_REFERENCE_ENV).map;
    let tracer = LtTracer::new(mesh, config.trace.apply(TraceSettings::default()))?;
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
        "field": describe_trace(&grid.trace, config),
        "reference_views": format!("{} path-traced views under {}", cameras.len(), test_environments()[MESH_REFERENCE_ENV].name),
    });
    let job = FieldBake {
        field,
        plan: grid.plan,
        cameras,
        view_policy,
        reference: Reference::Images {
            images,
            masks,
            lighting,
        },
        provenance,
        held: HeldAside::default(),
        fine_field: None,
    };
    let prior = StageTimings {
        hull_secs: grid.hull_secs,
        reference_secs,
        ..StageTimings::default()
    };
    Ok((job, prior))
}
