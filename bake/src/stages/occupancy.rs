//! Stage 3, **occupancy**: the field's density at every candidate voxel of the plan,
//! and the bricks below the opacity threshold dropped (an apron kept around dense
//! ones) ([`crate::grid::evaluate_density`]).

use std::time::Instant;

use crate::config::BakeConfig;
use crate::error::Result;
use crate::grid::{DensityGrid, evaluate_density};
use crate::progress::Progress;
use crate::stages::outputs::StageTimings;
use crate::stages::plan::FieldBake;

/// Density and brick drop over `job`'s plan; fills `timings.density_secs`.
pub(crate) fn dense_grid(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: Progress,
    timings: &mut StageTimings,
) -> Result<DensityGrid> {
    let t = Instant::now();
    let dense = evaluate_density(&job.plan, job.field, config.min_brick_opacity, &progress)?;
    timings.density_secs = t.elapsed().as_secs_f64();
    Ok(dense)
}
