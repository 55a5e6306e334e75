//! `nelf light`: the NeLF network's estimate of the lighting a capture was taken
//! under (`nelf_field`: per-view estimates from the encoder's light head, rotated
//! into view 0 and confidence-weighted), in the world frame or the network's own.
//!
//! The network's 8 × 16 estimate lives in the light frame `world_from_light =
//! R₀ᵀ·diag(−1, −1, 1)` (view 0's camera; `nelf_field::light`). In the world frame it
//! is resampled at `width × width/2` by looking up that piecewise-constant map (4 × 4
//! equal-area sub-samples per output texel, `nelf_field::light::light_map_in_world`),
//! so projecting the map back into the light frame recovers the estimate. Radiance is
//! the network's (linear, the images' scale).

use std::path::Path;
use std::time::Instant;

use glam::DMat3;
use nelf_field::capture::{default_net_from_world, load_capture_dir_for_model};
use nelf_field::light::{light_map_in_world, net_light_to_latlong};
use nelf_format::conventions::LatLong;

use crate::error::{Context as _, Result};
use crate::network::load_network;

/// What [`estimate_light`] estimates from.
#[derive(Debug, Clone, Copy)]
pub struct LightRequest<'a> {
    /// The capture folder (cameras.json, images, masks).
    pub capture_dir: &'a Path,
    /// The network's weights (`None`: the shipped network).
    pub weights: Option<&'a Path>,
    /// Width of the world-frame map (its height is half; at least 2).
    pub width: u32,
    /// The raw 8 × 16 map in the network's light frame instead of the world frame.
    pub light_frame: bool,
}

/// The network's estimate of a capture's lighting.
#[derive(Debug, Clone)]
pub struct LightEstimate {
    /// The map, in the frame [`LightEstimate::frame`] names.
    pub map: LatLong,
    /// `"world"` or `"light"` (the network's light frame).
    pub frame: &'static str,
    /// The network's light frame in the world.
    pub world_from_light: DMat3,
    /// Source views the estimate came from.
    pub views: usize,
    /// The views' size as the network saw them, `[width, height]`.
    pub image_size: [usize; 2],
    /// The weights' name.
    pub weights_name: String,
    /// Whether these weights estimate lightings relative to their own power (mean
    /// radiance about 1), so that the map's scale is not the capture's.
    pub source_relative: bool,
    /// The device the network ran on.
    pub device: String,
    /// Seconds from loading the weights to the finished map.
    pub seconds: f64,
}

/// Estimates the lighting of the capture in `request.capture_dir` with the network.
pub fn estimate_light(request: &LightRequest<'_>) -> Result<LightEstimate> {
    let start = Instant::now();
    let (model, weights_name) = load_network(request.weights)?;
    let (capture, _) = load_capture_dir_for_model(request.capture_dir, default_net_from_world(), &model)
        .with_context(|| format!("loading the capture {}", request.capture_dir.display()))?;
    let encoded = model.encode(&capture.views).context("running the encoder")?;
    let light = net_light_to_latlong(&encoded.light().source_light)?;
    let world_from_light = capture.world_from_light();
    let map = if request.light_frame {
        light
    } else {
        let width = request.width.max(2) as usize;
        light_map_in_world(&light, world_from_light, width, width / 2)?
    };
    Ok(LightEstimate {
        map,
        frame: if request.light_frame { "light" } else { "world" },
        world_from_light,
        views: capture.cameras.len(),
        image_size: [capture.views.width, capture.views.height],
        source_relative: model.source_relative_light(),
        device: nelf_field::device_name(model.device()).to_string(),
        weights_name,
        seconds: start.elapsed().as_secs_f64(),
    })
}
