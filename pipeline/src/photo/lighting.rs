//! Lighting for a reconstruction: the environment map the capture names
//! (`cameras.json`'s `envmap`, in the photographs' units), else the NeLF network's
//! estimate from the photographs ([`crate::light::estimate_light`]), whose scale
//! relative to the photographs is unknown. Either is projected onto the 8 × 16
//! light basis in the world frame (`nelf_format::conventions::project_envmap`, the
//! identity rotation), the frame the reconstructed surface is traced in.

use std::path::Path;
use std::time::Instant;

use glam::DMat3;
use nelf_bake::LoadedCapture;
use nelf_format::conventions::{LatLong, project_envmap};
use serde::Serialize;

use crate::error::Result;
use crate::light::{LightRequest, estimate_light};
use crate::network::capture_source_lighting;

/// Where the lighting came from.
#[derive(Debug, Clone, Serialize)]
pub struct LightingReport {
    /// Whether the capture named it (else the network estimated it).
    pub named: bool,
    /// The map's file, or the weights that estimated it.
    pub source: String,
    /// Mean radiance of the 8 × 16 map (`Σ Ω L / 4π`, mean over channels).
    pub mean_radiance: f64,
    /// Seconds.
    pub seconds: f64,
}

/// The capture's lighting as an 8 × 16 world-frame map (see the module documentation).
pub fn capture_lighting(
    capture: &LoadedCapture,
    weights: Option<&Path>,
) -> Result<(LatLong, LightingReport)> {
    let start = Instant::now();
    let named = capture_source_lighting(capture.description(), &capture.dir)?;
    let (map, source) = if let Some(map) = named.clone() {
        let path = capture.source_envmap_path();
        (map, path.map_or_else(String::new, |p| p.display().to_string()))
    } else {
        let estimate = estimate_light(&LightRequest {
            capture_dir: &capture.dir,
            weights,
            width: 64,
            light_frame: false,
        })?;
        (estimate.map, estimate.weights_name)
    };
    let named = named.is_some();
    let basis = project_envmap(&map, DMat3::IDENTITY)?;
    let report = LightingReport {
        named,
        source,
        mean_radiance: basis.mean_radiance(),
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((basis, report))
}
