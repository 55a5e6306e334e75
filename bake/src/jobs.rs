//! The two kinds of bake job: a **capture** (visual hull of its masks, the box
//! where the field is dense, its cameras as the views) and a **mesh** baked
//! directly (its box, synthetic cameras, path-traced references). Each plans the
//! grid, builds the field (the ground-truth mesh field of [`crate::source`], or any
//! [`FieldSource`]) and hands both to [`crate::pipeline::bake_field`].

use std::time::Instant;

use glam::DVec3;
use nelf_format::conventions::PinholeCamera;
use nelf_scene::envmap::load_envmap;
use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::mesh::Mesh;
use nelf_scene::render::render_lt_image;
use nelf_scene::synth::{SynthConfig, camera_for, source_viewpoints};
use nelf_scene::tracer::{LtTracer, TraceSettings};

use crate::capture_in::LoadedCapture;
use crate::config::{BakeConfig, ShellPlacement};
use crate::error::Result;
use crate::eval::{HeldAside, load_held_aside};
use crate::grid::{
    GridPlan, geometry_for_box, occupied_box, plan_all_bricks, plan_from_hull, voxel_size_for,
};
use crate::hull::{HullCarver, hull_bounds};
use crate::pipeline::{BakeOutput, FieldBake, Reference, StageTimings, bake_field, view_policy_for};
use crate::progress::Progress;
use crate::rank::{light_texels, test_environments};
use crate::source::{GroundTruth, describe_trace, mesh_field};

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
    let (lo, hi) = hull_bounds(&carver, capture.head_centre_m, config.max_hull_radius_m)?;
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

/// The bake job of any field source over a capture's plan: the capture's cameras
/// are the views the PCA is weighted by and the rank is judged at; its images under
/// its lighting (when the capture names an env map) measure the grid's own error.
/// `field_provenance` describes the field in the metadata. Returns the job and the
/// seconds already spent (the hull).
pub fn capture_field_job<'a>(
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
    };
    let prior = StageTimings {
        hull_secs: planned.hull_secs,
        ..StageTimings::default()
    };
    Ok((job, prior))
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
    let (job, prior) = capture_field_job(capture, planned, field, view_policy, field_provenance, config)?;
    bake_field(&job, config, progress, prior)
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
    let mesh = truth.mesh()?;
    let trace = config.trace.apply_to_field(truth.trace_settings());
    // Occupancy only: any voxel size will do for the probe's shell.
    let probe = mesh_field(
        &mesh,
        trace,
        config.voxel_size_m.unwrap_or(1e-3),
        ShellPlacement::Inside,
        config,
    )?;
    let planned = plan_capture(capture, config, probe.as_ref(), progress)?;
    let field = mesh_field(&mesh, trace, planned.voxel_size_m, config.shell_placement, config)?;
    let centres: Vec<DVec3> = capture.cameras.iter().map(PinholeCamera::centre).collect();
    let view_policy = view_policy_for(config.view_policy, &centres)?;
    let field_provenance = serde_json::json!({
        "ground_truth": truth.describe(),
        "field": describe_trace(&trace, config),
    });
    let (job, prior) = capture_field_job(
        capture,
        planned,
        field.as_ref(),
        view_policy,
        &field_provenance,
        config,
    )?;
    run(&job, prior)
}

/// The ground-truth mesh field of `truth` at voxel size `voxel_size_m`, as a
/// capture's ground-truth bake samples it (`config`'s shell placement and trace).
pub fn truth_field(
    truth: &GroundTruth,
    config: &BakeConfig,
    voxel_size_m: f64,
) -> Result<Box<dyn FieldSource>> {
    truth_field_traced(truth, config, voxel_size_m, |_| {})
}

/// [`truth_field`] with its trace settings changed by `adjust` (e.g. direct light
/// only, no glossy lobe: the ground truth's Lambertian shading with its shadows).
pub fn truth_field_traced(
    truth: &GroundTruth,
    config: &BakeConfig,
    voxel_size_m: f64,
    adjust: impl FnOnce(&mut TraceSettings),
) -> Result<Box<dyn FieldSource>> {
    let mesh = truth.mesh()?;
    let mut trace = config.trace.apply_to_field(truth.trace_settings());
    adjust(&mut trace);
    mesh_field(&mesh, trace, voxel_size_m, config.shell_placement, config)
}

/// Bakes a capture's ground-truth field: visual hull of its masks, the mesh of
/// `truth` as the field, the capture's cameras as the views.
pub fn bake_capture(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    config: &BakeConfig,
    progress: &Progress,
) -> Result<BakeOutput> {
    with_capture_job(capture, truth, config, progress, |job, prior| {
        bake_field(job, config, progress, prior)
    })
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
    let trace = config.trace.apply_to_field(TraceSettings::default());
    let field = mesh_field(mesh, trace, voxel, config.shell_placement, config)?;
    let (flo, fhi) = field.bounds();
    let plan = plan_all_bricks(geometry_for_box(flo.as_dvec3(), fhi.as_dvec3(), voxel)?);
    let hull_secs = t.elapsed().as_secs_f64();
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
        held: HeldAside::default(),
    };
    let prior = StageTimings {
        hull_secs,
        reference_secs,
        ..StageTimings::default()
    };
    bake_field(&job, config, progress, prior)
}
