//! Stage 4, **transport**: how much each voxel shows in the capture's views
//! (visibility weights at the reduced resolution of the rank renders,
//! `nelf_render::visibility_weights`) and the light transport of the band of voxels
//! that can show ([`crate::grid::light_transport_band`]), evaluated from the field
//! toward the job's view policy.

use std::time::Instant;

use nelf_format::conventions::PinholeCamera;
use nelf_render::visibility_weights;

use crate::config::BakeConfig;
use crate::error::{BakeError, Result};
use crate::grid::{DensityGrid, evaluate_light_transport, light_transport_band};
use crate::progress::Progress;
use crate::rank::reduced_camera;
use crate::stages::outputs::StageTimings;
use crate::stages::plan::FieldBake;

/// The views' visibility of every voxel and the band's light transport.
#[derive(Debug, Clone)]
pub(crate) struct Transport {
    /// The capture's views at the reduced resolution of the weights and rank renders.
    pub views: Vec<PinholeCamera>,
    /// `(reduced camera, factor)` per capture view.
    pub reduced: Vec<(PinholeCamera, u32)>,
    /// Per voxel, the sum of its visibility weights over the views.
    pub visibility: Vec<f32>,
    /// Voxels whose light transport was evaluated.
    pub lt_voxels: Vec<usize>,
    /// Their light transport, `LT_DIM` floats each.
    pub lt: Vec<f32>,
}

/// Visibility weights and the band's light transport over `dense`; fills
/// `timings.weights_secs` and `timings.lt_secs`.
pub(crate) fn band_transport(
    job: &FieldBake<'_>,
    dense: &DensityGrid,
    config: &BakeConfig,
    progress: Progress,
    timings: &mut StageTimings,
) -> Result<Transport> {
    let grid = &dense.grid;
    let density = &dense.density;

    // Visibility weights at reduced resolution.
    let t = Instant::now();
    let march = config.march();
    let reduced: Vec<(PinholeCamera, u32)> = job
        .cameras
        .iter()
        .map(|c| reduced_camera(c, config.render_size))
        .collect();
    let views: Vec<PinholeCamera> = reduced.iter().map(|(c, _)| *c).collect();
    let mut visibility = vec![0.0f32; grid.voxel_count()];
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
    let (lt, _) = evaluate_light_transport(grid, &lt_voxels, job.field, &job.view_policy, &progress)?;
    timings.lt_secs = t.elapsed().as_secs_f64();
    Ok(Transport {
        views,
        reduced,
        visibility,
        lt_voxels,
        lt,
    })
}
