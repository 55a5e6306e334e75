//! Stage 2, **hull**: where the field can be. A capture's visual hull is carved from
//! its masks ([`crate::hull`]), the grid's box is where a probe of the field is dense
//! inside it ([`crate::grid::occupied_box`]) and bricks are laid over the hull; a mesh
//! baked directly takes its field's box, every brick a candidate.

use std::time::Instant;

use glam::DVec3;
use nelf_scene::field::FieldSource;
use nelf_scene::mesh::Mesh;
use nelf_scene::tracer::TraceSettings;

use crate::capture_in::LoadedCapture;
use crate::config::BakeConfig;
use crate::error::Result;
use crate::grid::{
    GridPlan, geometry_for_box, occupied_box, plan_all_bricks, plan_from_hull, voxel_size_for,
};
use crate::hull::{HullCarver, hull_bounds};
use crate::progress::Progress;
use crate::source::mesh_field;

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
pub(crate) fn capture_hull(
    capture: &LoadedCapture,
    config: &BakeConfig,
    probe: &dyn FieldSource,
    progress: Progress,
) -> Result<CapturePlan> {
    let t = Instant::now();
    let carver = HullCarver::new(&capture.cameras, &capture.masks, config.dilate_px)?;
    let (lo, hi) = hull_bounds(&carver, capture.head_centre_m, config.max_hull_radius_m)?;
    let (grid_lo, grid_hi) = match config.voxel_size_m {
        Some(_) => (lo, hi),
        None => occupied_box(Some(&carver), lo, hi, probe, config.min_brick_opacity, &progress)?,
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

/// A mesh's grid: every brick of its field's box, the trace settings of that field
/// and the seconds spent.
#[derive(Debug, Clone)]
pub(crate) struct MeshPlan {
    /// Every brick of the field's box.
    pub plan: GridPlan,
    /// The field's trace settings.
    pub trace: TraceSettings,
    /// Seconds building the field and the bricks.
    pub hull_secs: f64,
}

/// A mesh baked directly: the voxel size from its box, its ground-truth field at that
/// size, and every brick of the field's box (the field's occupancy is the hull).
pub(crate) fn mesh_grid(mesh: &Mesh, config: &BakeConfig) -> Result<(Box<dyn FieldSource>, MeshPlan)> {
    let t = Instant::now();
    let (lo, hi) = mesh.bounds();
    let voxel = voxel_size_for((hi - lo).as_dvec3(), config.resolution, config.voxel_size_m)?;
    let trace = config.trace.apply_to_field(TraceSettings::default());
    let field = mesh_field(mesh, trace, voxel, config.shell_placement, config)?;
    let (flo, fhi) = field.bounds();
    let plan = plan_all_bricks(geometry_for_box(flo.as_dvec3(), fhi.as_dvec3(), voxel)?);
    let hull_secs = t.elapsed().as_secs_f64();
    Ok((
        field,
        MeshPlan {
            plan,
            trace,
            hull_secs,
        },
    ))
}
