//! A dataset head made ready for training steps: its source views, target views,
//! lightings and the distillation's ground truth at the training resolution, in the
//! network's units (millimetres, network frame, network light layout), with the
//! true radiance the distillation compares with precomputed under each lighting;
//! and a prepared head with fewer source views ([`select_views`]).

use glam::DVec3;
use nelf_field::capture::{
    box_down, default_net_from_world, down_rgb, down_scalar, reduce_views, scaled_camera,
};
use nelf_field::geometry::NetCamera;
use nelf_field::light::latlong_to_net_light;
use nelf_field::{EncodedViews, NetCapture};
use nelf_format::conventions::{ENV_TEXELS, LatLong, project_envmap};

use crate::data::{Dataset, TargetMode, TrainingSample};
use crate::error::TrainError;

/// A target view at the training resolution, in the network's units.
#[derive(Debug, Clone)]
pub struct PreparedTarget {
    /// Self-rotation or novel light.
    pub mode: TargetMode,
    /// The camera (millimetres, network frame).
    pub camera: NetCamera,
    /// `(H·W)` linear RGB.
    pub image: Vec<[f32; 3]>,
    /// `(H·W)` coverage.
    pub alpha: Vec<f32>,
    /// `(H·W)` depth along the optical axis, millimetres (0: background).
    pub depth_mm: Vec<f32>,
    /// The target lighting, network layout `(3, 8, 16)`.
    pub light_net: Vec<f32>,
}

/// A training head at the training resolution, ready for steps.
#[derive(Debug, Clone)]
pub struct PreparedHead {
    /// The source views and frames.
    pub capture: NetCapture,
    /// Hull and projections of the source views.
    pub geometry: EncodedViews,
    /// The true source lighting, network layout.
    pub source_light_net: Vec<f32>,
    /// The target views.
    pub targets: Vec<PreparedTarget>,
    /// Ground-truth points (mm, network frame) and σ (1/mm) for distillation.
    pub distill_points: Vec<[f32; 3]>,
    /// σ at [`PreparedHead::distill_points`], 1/mm.
    pub distill_sigma: Vec<f32>,
    /// Unit directions (point → viewer, network frame) the true `T` is for.
    pub distill_dirs: Vec<[f32; 3]>,
    /// The head's lightings (source and targets), network layout: the true `T` is
    /// distilled through the radiance it gives under each.
    pub distill_lights: Vec<Vec<f32>>,
    /// `(N, lights, 3)`: true radiance `Σ_k T[c, k]·L[c, k]` under each lighting.
    pub distill_radiance: Vec<f32>,
    /// The lightings the transport-shape term relights under, network layout: the
    /// targets' (as in [`PreparedHead::distill_lights`]) and the
    /// [`SHAPE_PROBES`] probe lightings ([`shape_probe_lightings`]).
    pub shape_lights: Vec<Vec<f32>>,
    /// `(N, shape lights, 3)`: true radiance under each of
    /// [`PreparedHead::shape_lights`] (the probes at the source's mean radiance).
    pub shape_radiance: Vec<f32>,
}

/// Probe lightings of the transport-shape term ([`TrainConfig::distill_shape_weight`]).
pub const SHAPE_PROBES: usize = 12;

/// Procedural seed of probe lighting 0; probe `k` is `SHAPE_PROBE_SEED + k`. In the
/// training range (below `data::plan::VAL_SEED_BIT`), so no held-out lighting is a probe.
const SHAPE_PROBE_SEED: u64 = 0x5348_4150_4500;
const _: () = assert!(SHAPE_PROBE_SEED + SHAPE_PROBES as u64 <= crate::data::plan::VAL_SEED_BIT);

/// The transport-shape term's fixed probe lightings, world frame, each scaled to mean
/// radiance `power` (`LatLong::mean_radiance`): [`SHAPE_PROBES`] procedural maps
/// (`nelf_scene::envgen`: suns, rooms, studios) at 32 × 16, fine enough for the 8 × 16
/// transport they are projected onto.
pub fn shape_probe_lightings(power: f64) -> Vec<LatLong> {
    let params = nelf_scene::envgen::EnvGenParams {
        width: 32,
        height: 16,
        family: None,
    };
    (0..SHAPE_PROBES as u64)
        .map(|k| {
            let mut map = nelf_scene::envgen::procedural_envmap(SHAPE_PROBE_SEED + k, &params);
            let mean = map.mean_radiance();
            let scale = if mean > 0.0 { (power / mean) as f32 } else { 0.0 };
            for texel in map.texels_mut() {
                *texel = texel.map(|v| v * scale);
            }
            map
        })
        .collect()
}

/// Depth down-sampled as the mean of the block's foreground depths (0 if none).
fn down_depth(depth: &[f32], width: usize, factor: usize) -> Vec<f32> {
    let pairs: Vec<[f32; 2]> = depth
        .iter()
        .map(|&d| if d > 0.0 { [d, 1.0] } else { [0.0, 0.0] })
        .collect();
    box_down(
        &pairs,
        width,
        factor,
        [0.0f32; 2],
        |a, b| [a[0] + b[0], a[1] + b[1]],
        |a, _| a,
    )
    .into_iter()
    .map(|[s, n]| if n > 0.0 { s / n } else { 0.0 })
    .collect()
}

/// A world-frame lighting map in the network's layout for `capture`'s light frame.
fn net_light(map: &LatLong, capture: &NetCapture) -> Result<Vec<f32>, TrainError> {
    let light = project_envmap(map, capture.world_from_light())
        .map_err(|e| TrainError::Settings(format!("lighting: {e}")))?;
    Ok(latlong_to_net_light(&light)?)
}

/// Prepares `sample` at `size × size` pixels (its size divided by a whole factor).
///
/// With `source_relative_light` every lighting the network is given (the source
/// light its estimate is compared with, the targets' lightings, the distillation's)
/// is divided by the source lighting's mean radiance `p_A`
/// ([`LatLong::mean_radiance`]): the images stay as rendered, so the network learns
/// `T·p_A` and a relit image is `T·p_A · L/p_A`, the same truth
/// (`TrainConfig::source_relative_light`).
pub fn prepare(
    sample: &TrainingSample,
    size: usize,
    source_relative_light: bool,
) -> Result<PreparedHead, TrainError> {
    let full = sample.source_cameras.first().map_or(0, |c| c.width as usize);
    if size == 0 || full % size != 0 || full / size == 0 {
        return Err(TrainError::Settings(format!(
            "head {}: images of {full} pixels cannot be reduced to {size} by a whole factor",
            sample.id
        )));
    }
    let factor = full / size;
    let (cameras, images, masks) = reduce_views(
        &sample.source_cameras,
        &sample.source_images,
        &sample.source_masks,
        factor,
    );
    let capture = NetCapture::new(
        &cameras,
        &images,
        &masks,
        sample.head_centre_m,
        default_net_from_world(),
    )?;
    let geometry = EncodedViews::geometry_only(&capture.views)?;
    let light_unit = if source_relative_light {
        let power = sample.source_light.mean_radiance();
        if !(power.is_finite() && power > 0.0) {
            return Err(TrainError::Settings(format!(
                "head {}: its source lighting has mean radiance {power}: no unit to relate lightings to",
                sample.id
            )));
        }
        power as f32
    } else {
        1.0
    };
    let net_light = |map: &LatLong| -> Result<Vec<f32>, TrainError> {
        Ok(net_light(map, &capture)?
            .into_iter()
            .map(|v| v / light_unit)
            .collect())
    };
    let source_light_net = net_light(&sample.source_light)?;
    let mut targets = Vec::with_capacity(sample.targets.len());
    for t in &sample.targets {
        let tw = t.camera.width as usize;
        if tw % factor != 0 || t.camera.height as usize % factor != 0 {
            return Err(TrainError::Settings(format!(
                "head {}: a target of {}×{} cannot be reduced by {factor}",
                sample.id, t.camera.width, t.camera.height
            )));
        }
        targets.push(PreparedTarget {
            mode: t.mode,
            camera: capture.net_camera(&scaled_camera(&t.camera, factor)),
            image: down_rgb(&t.image, tw, factor),
            alpha: down_scalar(&t.alpha, tw, factor),
            depth_mm: down_depth(&t.depth_m, tw, factor)
                .iter()
                .map(|d| d * 1000.0)
                .collect(),
            light_net: net_light(&t.light)?,
        });
    }
    let distill_points = sample
        .distill
        .points_m
        .iter()
        .map(|p| capture.to_net_point(DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))))
        .collect();
    let distill_sigma = sample.distill.sigma_per_m.iter().map(|s| s / 1000.0).collect();
    let distill_dirs = sample
        .distill
        .view_dirs
        .iter()
        .map(|d| capture.to_net_direction(DVec3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]))))
        .collect();
    // The lightings as 8 × 16 maps in the world (the ground truth's light frame) and
    // in the network's layout.
    let mut world_lights = Vec::with_capacity(1 + sample.targets.len());
    for light in std::iter::once(&sample.source_light).chain(sample.targets.iter().map(|t| &t.light)) {
        world_lights.push(
            project_envmap(light, glam::DMat3::IDENTITY)
                .map_err(|e| TrainError::Settings(format!("lighting: {e}")))?,
        );
    }
    let mut distill_lights = vec![source_light_net.clone()];
    distill_lights.extend(targets.iter().map(|t| t.light_net.clone()));
    let distill_radiance = true_radiance(&sample.distill, &world_lights);
    // The shape term's lightings: the targets' and the probes, these at the source's
    // mean radiance so that the relit colours are in the images' range.
    let probes = shape_probe_lightings(sample.source_light.mean_radiance());
    let mut shape_world = world_lights[1..].to_vec();
    let mut shape_lights: Vec<Vec<f32>> = distill_lights[1..].to_vec();
    for probe in &probes {
        shape_world.push(
            project_envmap(probe, glam::DMat3::IDENTITY)
                .map_err(|e| TrainError::Settings(format!("probe lighting: {e}")))?,
        );
        shape_lights.push(net_light(probe)?);
    }
    let shape_radiance = true_radiance(&sample.distill, &shape_world);
    Ok(PreparedHead {
        capture,
        geometry,
        source_light_net,
        targets,
        distill_points,
        distill_sigma,
        distill_dirs,
        distill_lights,
        distill_radiance,
        shape_lights,
        shape_radiance,
    })
}

/// `(N, lights, 3)`: the true radiance `Σ_k T*[c, k]·L[c, k]` of each of `distill`'s
/// points under each of `world_lights` (8 × 16, world frame, as `T*`).
fn true_radiance(distill: &crate::data::Distill, world_lights: &[LatLong]) -> Vec<f32> {
    let mut radiance = Vec::with_capacity(distill.len() * world_lights.len() * 3);
    for i in 0..distill.len() {
        let t = distill.lt_of(i);
        for map in world_lights {
            for c in 0..3 {
                radiance.push(
                    (0..ENV_TEXELS)
                        .map(|k| t[c * ENV_TEXELS + k] * map.get(k / map.width(), k % map.width())[c])
                        .sum(),
                );
            }
        }
    }
    radiance
}

/// Loads and prepares heads `ids` of `dataset` at `size`.
/// (`source_relative_light`: see [`prepare`]).
pub fn prepare_heads(
    dataset: &Dataset,
    ids: &[u32],
    size: usize,
    source_relative_light: bool,
) -> Result<Vec<PreparedHead>, TrainError> {
    ids.iter()
        .map(|&id| prepare(&dataset.load(id)?, size, source_relative_light))
        .collect()
}

/// `head` with only the source views `keep` (in that order; targets and the rest as
/// they are), its hull and projections recomputed.
pub fn select_views(head: &PreparedHead, keep: &[usize]) -> Result<PreparedHead, TrainError> {
    let sv = &head.capture.views;
    let (all, pixels) = (sv.views(), sv.width * sv.height);
    if let Some(bad) = keep.iter().find(|&&k| k >= all) {
        return Err(TrainError::Settings(format!(
            "source view {bad} asked for; the head has {all}"
        )));
    }
    let mut out = head.clone();
    let views = &mut out.capture.views;
    views.images = keep
        .iter()
        .flat_map(|&k| sv.images[k * pixels * 3..(k + 1) * pixels * 3].iter().copied())
        .collect();
    views.masks = keep
        .iter()
        .flat_map(|&k| sv.masks[k * pixels..(k + 1) * pixels].iter().copied())
        .collect();
    views.cameras = keep.iter().map(|&k| sv.cameras[k]).collect();
    out.capture.cameras = keep
        .iter()
        .filter_map(|&k| head.capture.cameras.get(k).copied())
        .collect();
    out.geometry = EncodedViews::geometry_only(&out.capture.views)?;
    Ok(out)
}
