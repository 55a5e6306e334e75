//! Training steps and the resumable loop (Sun et al. 2021, §4.3).
//!
//! A step draws a training head and a mode (novel light with probability
//! `novel_light_share`, else self-rotation), encodes the head's source views, renders
//! `rays` pixels of the mode's target view through the coarse network and, with
//! importance samples, the fine one, under the target's *true* lighting, and
//! minimises
//!
//! `L = |c_c − c| + |c_f − c| + λ_d·|d − d*|/200 mm + λ_a·|a − a*| + λ_l·|log(1+L̂) − log(1+L)|`
//!
//! (colours L1 over rays, or with `--colour-loss srgb-l2` the squared error of their
//! clamped sRGB encodings; depth along the ray inside the true mask; alpha of the
//! fine pass; the log-L1 lighting loss on the encoder's source-light estimate)
//! plus, when either of its weights is positive, the 3D distillation loss at ground-truth points
//! near the surface, `λ_σ·|log(1 + σ·1 mm) − log(1 + σ*·1 mm)| + λ_s·|Σ T·L − Σ T*·L|`
//! (with `--distill-radiance-loss srgb-l2` the radiance term is
//! `λ_s·(srgb(Σ T·L) − srgb(Σ T*·L))²`; `λ_σ` = `distill_sigma_weight`, by default `λ_s`) and the
//! light transport compared through the radiance it gives, toward the direction the
//! true `T*` is for, under each of the head's lightings (its source lighting and its
//! targets'): `T` lives in the network's light frame and `T*` in the world's, and
//! radiance is what both must agree on. With `--distill-shape-weight` the distillation
//! adds a term on the transport's shape alone, `λ_t·|(T*·L_S)·(T·L)/(T·L_S + ε) − T*·L|`
//! under the targets' lightings and fixed probe lightings ([`shape_probe_lightings`]):
//! the truth's colour relit by the network's transport ([`relit_by_shape`]). Every random choice of step `k` comes from a generator seeded by
//! `(seed, k)`, so the state of a run is its weights, its Adam moments and its step
//! count: a checkpoint holds exactly those, and a resumed run continues bit for bit.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use glam::DVec3;
use nelf_field::capture::{
    box_down, default_net_from_world, down_rgb, down_scalar, reduce_views, scaled_camera,
};
use nelf_field::geometry::NetCamera;
use nelf_field::light::latlong_to_net_light;
use nelf_field::render::{NetRay, importance_depths};
use nelf_field::{EncodedViews, Model, NetCapture, Stage};
use nelf_format::conventions::{ENV_TEXELS, LatLong, project_envmap};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};

use crate::adam::Adam;
use crate::config::TrainConfig;
use crate::data::{Dataset, TargetMode, TrainingSample};
use crate::domain::{RealImages, ReproduceHead, is_head_variable, reproduction_loss};
use crate::error::TrainError;
use crate::forward::{self, Encoded, RayPass, encode, irradiance, l1, log_l1, render_rays};

/// Depth normaliser of the depth loss (the paper's 200 mm).
const DEPTH_SCALE_MM: f64 = 200.0;

/// How far in front of the true depth a foreground ray's samples count as free
/// space, mm: beyond a pixel's footprint at the training sizes (~5 mm at 64²) and the
/// spread of the sub-pixel depths it averages.
pub const FREE_SPACE_MARGIN_MM: f32 = 15.0;

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

/// Floor of the network's radiance under the source lighting in the shape term's
/// ratio `(T·L)/(T·L_S + ε)`, in the images' units (linear radiance ~0.05–1).
const SHAPE_RATIO_FLOOR: f64 = 0.01;

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

/// The transport-shape term's relit colours (`TrainConfig::distill_shape_weight`):
/// `(T*·L_S)·(T·L_k)/(T·L_S + ε)` for transports `lt` `(N, 3, 128)`, the source
/// lighting `source_light` `(3, 128)`, lightings `lights` `(K, 3, 128)` and the
/// truth's colours under the source lighting `true_source` `(N, 1, 3)`; `(N, K, 3)`.
/// Up to `ε` ([`SHAPE_RATIO_FLOOR`]) it depends on `lt` only through its shape: the
/// same for `lt` scaled by any positive factor per point and channel.
pub fn relit_by_shape(
    lt: &Tensor,
    source_light: &Tensor,
    lights: &Tensor,
    true_source: &Tensor,
) -> Result<Tensor, TrainError> {
    let (n, channels, texels) = lt.dims3()?;
    let lt = lt.reshape((n, 1, channels, texels))?;
    let relit = lt.broadcast_mul(&lights.unsqueeze(0)?)?.sum(3)?;
    let source = (lt
        .broadcast_mul(&source_light.unsqueeze(0)?.unsqueeze(0)?)?
        .sum(3)?
        + SHAPE_RATIO_FLOOR)?;
    Ok(relit.broadcast_div(&source)?.broadcast_mul(true_source)?)
}

/// The value of a one-element tensor.
fn scalar(t: &Tensor) -> Result<f64, TrainError> {
    Ok(f64::from(t.to_dtype(DType::F32)?.to_scalar::<f32>()?))
}

/// The first `take` values of each of `rows`, in order, of a row-major `table` of
/// `width` values per row (a distillation table's rows at the points a pass kept).
fn leading_of_rows(table: &[f32], width: usize, take: usize, rows: impl Iterator<Item = usize>) -> Vec<f32> {
    rows.flat_map(|row| &table[row * width..row * width + take])
        .copied()
        .collect()
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

/// The parts of a step's loss (plain numbers, for logs).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct LossParts {
    /// Weighted total.
    pub total: f64,
    /// L1 colour of the coarse pass.
    pub rgb_coarse: f64,
    /// L1 colour of the fine pass (the coarse one when there is none).
    pub rgb_fine: f64,
    /// Depth loss (÷ 200 mm).
    pub depth: f64,
    /// Alpha loss.
    pub alpha: f64,
    /// Log-L1 lighting loss.
    pub light: f64,
    /// Distillation loss on σ (1/mm).
    pub distill: f64,
    /// The domain-adaptation hook's reproduction loss (0 without the hook;
    /// [`crate::domain`]).
    #[serde(default)]
    pub real: f64,
    /// Seconds of the step's phases: encoder, rendering (coarse and fine passes),
    /// losses (with distillation), backward, Adam (what limits a step).
    #[serde(default)]
    pub phase_secs: [f64; 5],
}

/// The generator of step `step`'s random choices.
pub fn step_rng(seed: u64, step: u64) -> Pcg64 {
    Pcg64::seed_from_u64(seed ^ step.wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Picks `count` pixels of a target: 80 % inside the padded box around its
/// foreground, the rest anywhere.
fn pick_pixels(target: &PreparedTarget, width: usize, count: usize, rng: &mut Pcg64) -> Vec<usize> {
    let height = target.alpha.len() / width.max(1);
    let (mut x0, mut y0, mut x1, mut y1) = (width, height, 0usize, 0usize);
    for (i, a) in target.alpha.iter().enumerate() {
        if *a > 0.0 {
            let (x, y) = (i % width, i / width);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
    }
    let pad = width / 16;
    let boxed = x1 > x0 && y1 > y0;
    let (x0, y0) = (x0.saturating_sub(pad), y0.saturating_sub(pad));
    let (x1, y1) = ((x1 + pad).min(width), (y1 + pad).min(height));
    (0..count)
        .map(|_| {
            if boxed && rng.random::<f32>() < 0.8 {
                rng.random_range(y0..y1) * width + rng.random_range(x0..x1)
            } else {
                rng.random_range(0..width * height)
            }
        })
        .collect()
}

/// Where samples fall in their bins: drawn at random (training) or at the middle
/// of each bin with evenly spaced CDF levels (validation: no noise).
#[derive(Debug)]
pub enum Jitter<'a> {
    /// Uniform draws from this generator.
    Random(&'a mut Pcg64),
    /// Bin middles, levels `(k + ½)/n`.
    Centred,
}

impl Jitter<'_> {
    /// `n` offsets in `[0, 1)` within bins.
    fn offsets(&mut self, n: usize) -> Vec<f32> {
        match self {
            Self::Random(rng) => (0..n).map(|_| rng.random::<f32>()).collect(),
            Self::Centred => vec![0.5; n],
        }
    }

    /// `n` CDF levels in `[0, 1)`.
    fn levels(&mut self, n: usize) -> Vec<f32> {
        match self {
            Self::Random(rng) => (0..n).map(|_| rng.random::<f32>()).collect(),
            Self::Centred => (0..n).map(|k| (k as f32 + 0.5) / n as f32).collect(),
        }
    }
}

/// The rays of `target`'s pixels `pixels` (through their centres).
pub fn target_rays(
    target: &PreparedTarget,
    pixels: &[usize],
    centre: [f32; 3],
    radius_mm: f32,
) -> Vec<NetRay> {
    let width = target.camera.width;
    pixels
        .iter()
        .map(|&p| {
            NetRay::through_pixel(
                &target.camera,
                (p % width) as f64 + 0.5,
                (p / width) as f64 + 0.5,
                centre,
                radius_mm,
            )
        })
        .collect()
}

/// Coarse depths `(R, S)` of `rays`, one per bin of `[near, far]`.
fn coarse_depths(rays: &[NetRay], samples: usize, jitter: &mut Jitter<'_>) -> Vec<f32> {
    rays.iter()
        .flat_map(|ray| {
            let offsets = jitter.offsets(samples);
            (0..samples)
                .map(|k| {
                    let z = (k as f32 + offsets[k]) / samples as f32;
                    ray.near * (1.0 - z) + ray.far * z
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The fine pass's depths: coarse ones plus `fine` importance samples, sorted.
fn fine_depths(
    rays: &[NetRay],
    coarse: &[f32],
    weights: &[f32],
    fine: usize,
    jitter: &mut Jitter<'_>,
) -> Vec<f32> {
    let s = coarse.len() / rays.len().max(1);
    let mut out = Vec::with_capacity(rays.len() * (s + fine));
    for (r, ray) in rays.iter().enumerate() {
        let u = jitter.levels(fine);
        let offsets = jitter.offsets(fine);
        let mut d = importance_depths(&weights[r * s..(r + 1) * s], ray.near, ray.far, &u, &offsets);
        d.extend_from_slice(&coarse[r * s..(r + 1) * s]);
        d.sort_by(f32::total_cmp);
        out.extend(d);
    }
    out
}

/// The coarse pass over `rays` and, when the configuration has importance samples,
/// the fine pass, under `irradiance` (`(3, 128)`).
pub fn render_passes(
    model: &Model,
    encoded: &Encoded,
    head: &PreparedHead,
    rays: &[NetRay],
    irradiance: &Tensor,
    config: &TrainConfig,
    jitter: &mut Jitter<'_>,
) -> Result<(RayPass, Option<RayPass>), TrainError> {
    let coarse_d = coarse_depths(rays, config.coarse_samples, jitter);
    let coarse = render_rays(
        model,
        encoded,
        &head.geometry,
        rays,
        &coarse_d,
        Stage::Coarse,
        irradiance,
    )?;
    let fine = if config.fine_samples > 0 {
        let d = fine_depths(rays, &coarse_d, &coarse.weights, config.fine_samples, jitter);
        Some(render_rays(
            model,
            encoded,
            &head.geometry,
            rays,
            &d,
            Stage::Fine,
            irradiance,
        )?)
    } else {
        None
    };
    Ok((coarse, fine))
}

/// The loss of one step on `head` (module docs), with the graph for its gradients.
pub fn step_loss(
    model: &Model,
    head: &PreparedHead,
    config: &TrainConfig,
    rng: &mut Pcg64,
) -> Result<(Tensor, LossParts), TrainError> {
    let want_mode = if rng.random::<f64>() < config.novel_light_share {
        TargetMode::NovelLight
    } else {
        TargetMode::SelfRotation
    };
    let target = head
        .targets
        .iter()
        .find(|t| t.mode == want_mode)
        .or_else(|| head.targets.first())
        .ok_or_else(|| TrainError::Settings("a head without target views".into()))?;
    step_loss_on(model, head, target, config, rng)
}

/// The loss of one step that renders `target` from `head`'s source views (module
/// docs), with the graph for its gradients; `target` need not be one of `head`'s
/// (test-time fine-tuning renders the source views themselves).
pub fn step_loss_on(
    model: &Model,
    head: &PreparedHead,
    target: &PreparedTarget,
    config: &TrainConfig,
    rng: &mut Pcg64,
) -> Result<(Tensor, LossParts), TrainError> {
    let device = model.device();
    let clock = Instant::now();
    let encoded = encode(model, &head.capture.views)?;
    let encode_secs = secs_since(clock);
    let width = target.camera.width;
    let pixels = pick_pixels(target, width, config.rays, rng);
    let rays = target_rays(
        target,
        &pixels,
        head.capture.head_centre_net(),
        model.config().head_radius_mm,
    );
    let irr = irradiance(&target.light_net, device)?;
    let (coarse, fine) = render_passes(
        model,
        &encoded,
        head,
        &rays,
        &irr,
        config,
        &mut Jitter::Random(rng),
    )?;
    let render_secs = secs_since(clock) - encode_secs;
    let last = fine.as_ref().unwrap_or(&coarse);
    let r = rays.len();
    let want_rgb: Vec<f32> = pixels.iter().flat_map(|&p| target.image[p]).collect();
    let want_rgb = Tensor::from_vec(want_rgb, (r, 3), device)?;
    let want_alpha: Vec<f32> = pixels.iter().map(|&p| target.alpha[p]).collect();
    // Depth along each ray from depth along the optical axis; only where the
    // pixel is mostly foreground.
    let axis = target.camera.rotation_f64().row(2);
    let mut depth_mask = Vec::with_capacity(r);
    let mut want_depth = Vec::with_capacity(r);
    for (ray, &p) in rays.iter().zip(&pixels) {
        let cos = axis.dot(DVec3::new(
            f64::from(ray.dir[0]),
            f64::from(ray.dir[1]),
            f64::from(ray.dir[2]),
        ));
        let z = f64::from(target.depth_mm[p]);
        let ok = target.alpha[p] > 0.5 && z > 0.0 && cos > 1e-3;
        depth_mask.push(if ok { 1.0f32 } else { 0.0 });
        want_depth.push(if ok { (z / cos) as f32 } else { 0.0 });
    }
    let colour = |rgb: &Tensor| forward::colour_loss(config.colour_loss, rgb, &want_rgb);
    let rgb_coarse = colour(&coarse.rgb)?;
    let rgb_fine = match &fine {
        Some(f) => colour(&f.rgb)?,
        None => rgb_coarse.clone(),
    };
    let alpha = l1(&last.alpha, &Tensor::from_vec(want_alpha, r, device)?)?;
    let masked = depth_mask.iter().sum::<f32>();
    let depth = if masked > 0.0 {
        let mask = Tensor::from_slice(&depth_mask, r, device)?;
        let diff = ((&last.depth - Tensor::from_slice(&want_depth, r, device)?)?.abs()? * mask)?;
        ((diff.sum_all()? / f64::from(masked))? / DEPTH_SCALE_MM)?
    } else {
        Tensor::zeros((), DType::F32, device)?
    };
    // Free space: samples the truth knows are empty (background rays whole, foreground
    // ones up to the margin in front of the true depth).
    let mut free_space = Tensor::zeros((), DType::F32, device)?;
    if config.free_space_weight > 0.0 {
        for pass in std::iter::once(&coarse).chain(fine.as_ref()) {
            let s = pass.depths.len() / r.max(1);
            let mask: Vec<f32> = (0..r * s)
                .map(|k| {
                    let (ray, p) = (k / s, pixels[k / s]);
                    let free = target.alpha[p] <= 0.0
                        || (depth_mask[ray] > 0.0
                            && target.alpha[p] >= 1.0
                            && pass.depths[k] < want_depth[ray] - FREE_SPACE_MARGIN_MM);
                    if free { 1.0 } else { 0.0 }
                })
                .collect();
            let count = mask.iter().sum::<f32>();
            if count > 0.0 {
                let mask = Tensor::from_vec(mask, (r, s), device)?;
                let penalty = (forward::log1p_relu(&pass.sigma)? * mask)?.sum_all()?;
                free_space = (free_space + (penalty / f64::from(count))?)?;
            }
        }
    }
    let light = log_l1(
        &encoded.source_light,
        &Tensor::from_slice(&head.source_light_net, head.source_light_net.len(), device)?,
    )?;
    let mut total =
        (((&rgb_fine + &rgb_coarse)? + (&depth * config.depth_weight)?)? + (&alpha * config.alpha_weight)?)?;
    total = (total + (&light * config.light_weight)?)?;
    if config.free_space_weight > 0.0 {
        total = (total + (&free_space * config.free_space_weight)?)?;
    }
    let mut distill_value = 0.0;
    let shape_on = config.distill_shape_weight > 0.0;
    if shape_on && head.shape_lights.is_empty() {
        return Err(TrainError::Settings(
            "--distill-shape-weight is on but the head has no lightings for it (shape_lights is empty)"
                .into(),
        ));
    }
    if (config.distill_weight > 0.0 || config.distill_sigma_weight() > 0.0 || shape_on)
        && !head.distill_points.is_empty()
    {
        let n = config.distill_points.min(head.distill_points.len());
        let chosen: Vec<usize> = (0..n)
            .map(|_| rng.random_range(0..head.distill_points.len()))
            .collect();
        let points: Vec<[f32; 3]> = chosen.iter().map(|&i| head.distill_points[i]).collect();
        let dirs: Vec<[f32; 3]> = chosen.iter().map(|&i| head.distill_dirs[i]).collect();
        if let Some(pass) = forward::run_points(model, &encoded, &head.geometry, &points, &dirs, Stage::Fine)?
        {
            let n_in = pass.inside.len();
            // The distillation point of each point the pass kept (inside the hull).
            let kept = || pass.inside.iter().map(|&i| chosen[i as usize]);
            let want = Tensor::from_vec(
                leading_of_rows(&head.distill_sigma, 1, 1, kept()),
                (n_in, 1),
                device,
            )?;
            // σ (1/mm) compared as `log(1 + σ)`, whose gradient `1/(1 + σ)` never
            // vanishes. An opacity `1 − e^{−σ·δ}` saturates: run `nelf-small-run` sat at
            // σ ≈ 17/mm everywhere inside the hull for 3,000 steps with no gradient
            // through its 12.5 mm ray steps (an early mis-scaled loss put it there).
            let sigma_loss = log_l1(&pass.trace.density, &want)?;
            // T through the radiance under each of the head's lightings.
            let lights = head.distill_lights.len();
            let lt = forward::light_transport(&pass, device)?;
            let light_matrix: Vec<f32> = head.distill_lights.iter().flatten().copied().collect();
            let light_matrix = Tensor::from_vec(light_matrix, (lights, 3, ENV_TEXELS), device)?;
            let predicted = lt
                .reshape((n_in, 1, 3, ENV_TEXELS))?
                .broadcast_mul(&light_matrix.unsqueeze(0)?)?
                .sum(3)?;
            let want_radiance = Tensor::from_vec(
                leading_of_rows(&head.distill_radiance, lights * 3, lights * 3, kept()),
                (n_in, lights, 3),
                device,
            )?;
            let radiance_loss =
                forward::colour_loss(config.distill_radiance_loss, &predicted, &want_radiance)?;
            let mut distill_sum = (&sigma_loss + &radiance_loss)?;
            let mut weighted =
                ((sigma_loss * config.distill_sigma_weight())? + (radiance_loss * config.distill_weight)?)?;
            if shape_on {
                // The truth's colour under the source lighting, relit by the network's
                // transport: `(T*·L_S)·(T·L)/(T·L_S + ε)` against `T*·L`.
                let probes = head.shape_lights.len();
                let probe_matrix: Vec<f32> = head.shape_lights.iter().flatten().copied().collect();
                let probe_matrix = Tensor::from_vec(probe_matrix, (probes, 3, ENV_TEXELS), device)?;
                let source_light = Tensor::from_slice(&head.source_light_net, (3, ENV_TEXELS), device)?;
                // Lighting 0 of the distillation's is the source lighting.
                let true_source = Tensor::from_vec(
                    leading_of_rows(&head.distill_radiance, lights * 3, 3, kept()),
                    (n_in, 1, 3),
                    device,
                )?;
                let shaped = relit_by_shape(
                    &lt.reshape((n_in, 3, ENV_TEXELS))?,
                    &source_light,
                    &probe_matrix,
                    &true_source,
                )?;
                let want_shaped = Tensor::from_vec(
                    leading_of_rows(&head.shape_radiance, probes * 3, probes * 3, kept()),
                    (n_in, probes, 3),
                    device,
                )?;
                let shape_loss = forward::colour_loss(config.distill_radiance_loss, &shaped, &want_shaped)?;
                distill_sum = (distill_sum + &shape_loss)?;
                weighted = (weighted + (shape_loss * config.distill_shape_weight)?)?;
            }
            distill_value = scalar(&distill_sum)?;
            total = (total + weighted)?;
        }
    }
    let parts = LossParts {
        total: scalar(&total)?,
        rgb_coarse: scalar(&rgb_coarse)?,
        rgb_fine: scalar(&rgb_fine)?,
        depth: scalar(&depth)?,
        alpha: scalar(&alpha)?,
        light: scalar(&light)?,
        distill: distill_value,
        real: 0.0,
        phase_secs: [
            encode_secs,
            render_secs,
            secs_since(clock) - encode_secs - render_secs,
            0.0,
            0.0,
        ],
    };
    Ok((total, parts))
}

/// A network being trained: its variables and the model that reads them.
pub struct Trainable {
    /// The variables, by their official names.
    pub varmap: VarMap,
    /// The model over [`Trainable::varmap`].
    pub model: Model,
    /// The domain-adaptation hook's decoder head, when the run has one (its
    /// variables are in [`Trainable::varmap`] under [`crate::domain::HEAD_PREFIX`]).
    pub reproduce: Option<ReproduceHead>,
}

impl std::fmt::Debug for Trainable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainable")
            .field("model", &self.model)
            .finish_non_exhaustive()
    }
}

impl Trainable {
    /// A network of `config`'s widths with seeded initial weights: PyTorch's default
    /// `U(±1/√fan_in)` for matrices and biases, unit `GroupNorm` scales, zero
    /// shifts, `PReLU` slopes 0.25.
    pub fn init(config: &TrainConfig, device: &Device) -> Result<Self, TrainError> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
        let model = Model::new(&vb, config.nelf_config()?)?;
        let mut rng = Pcg64::seed_from_u64(config.seed ^ 0x5EED_1417);
        init_variables(&sorted_vars(&varmap)?, &mut rng, device)?;
        // The hook's head is made after the network's variables are drawn, from a
        // stream of its own, so the network starts as it does without the hook.
        let reproduce = if config.domain_adaptation() {
            let head = ReproduceHead::new(&vb, &config.architecture()?)?;
            let vars: Vec<_> = sorted_vars(&varmap)?
                .into_iter()
                .filter(|(n, _)| is_head_variable(n))
                .collect();
            let mut rng = Pcg64::seed_from_u64(config.seed ^ 0x5245_5052_4F44);
            init_variables(&vars, &mut rng, device)?;
            Some(head)
        } else {
            None
        };
        Ok(Self {
            varmap,
            model,
            reproduce,
        })
    }

    /// A network to go on training from the weights in `bytes` (a safetensors file,
    /// official key names, as [`Model::from_safetensors_bytes`] reads it: its widths,
    /// working image size and light units come from the file; `origin` names it in
    /// errors).
    pub fn from_safetensors_bytes(
        bytes: &[u8],
        origin: &Path,
        config: nelf_field::NelfConfig,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let read = Model::from_safetensors_bytes(bytes, origin, config, device)?;
        let tensors = candle_core::safetensors::load_buffer(bytes, device)
            .map_err(|e| TrainError::file(origin, format!("not a safetensors file: {e}")))?;
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
        let model = Model::new(&vb, *read.config())?
            .with_working_image_size(read.working_image_size())
            .with_source_relative_light(read.source_relative_light());
        let trainable = Self {
            varmap,
            model,
            reproduce: None,
        };
        trainable.load_weights(&tensors, "")?;
        Ok(trainable)
    }

    /// The variables with the step size of their module (encoder or MLPs).
    pub fn optimizer(&self, config: &TrainConfig) -> Result<Adam, TrainError> {
        let vars = sorted_vars(&self.varmap)?
            .into_iter()
            .map(|(name, var)| {
                let lr = if name.starts_with("image_encoder.") {
                    config.lr_encoder
                } else {
                    config.lr_mlp
                };
                (name, var, lr)
            })
            .collect();
        Adam::new(vars, (config.ema_decay > 0.0).then_some(config.ema_decay))
    }

    /// The weights as named tensors (the official key names).
    pub fn weights(&self) -> Result<Vec<(String, Tensor)>, TrainError> {
        Ok(sorted_vars(&self.varmap)?
            .into_iter()
            .map(|(n, v)| (n, v.as_tensor().clone()))
            .collect())
    }

    /// The network with a copy of the current weights as plain tensors: it builds no
    /// gradient graph and takes the fused inference kernels (validation: a graph
    /// over a full image held ~24 GB here).
    pub fn snapshot(&self) -> Result<Model, TrainError> {
        self.snapshot_of(self.weights()?)
    }

    /// The network with a copy of `weights` (named as [`Trainable::weights`], for
    /// example [`Adam::averaged_weights`]) as plain tensors.
    pub fn snapshot_of(&self, weights: Vec<(String, Tensor)>) -> Result<Model, TrainError> {
        let tensors = weights
            .into_iter()
            .map(|(n, t)| Ok((n, t.detach().copy()?)))
            .collect::<Result<HashMap<_, _>, TrainError>>()?;
        let vb = VarBuilder::from_tensors(tensors, DType::F32, self.model.device());
        Ok(Model::new(&vb, *self.model.config())?
            .with_working_image_size(self.model.working_image_size())
            .with_source_relative_light(self.model.source_relative_light()))
    }

    /// Sets the weights from named tensors (every variable must be present, but for
    /// the domain-adaptation head, which keeps its values where a file saved without
    /// the hook lacks it).
    pub fn load_weights(&self, tensors: &HashMap<String, Tensor>, prefix: &str) -> Result<(), TrainError> {
        for (name, var) in sorted_vars(&self.varmap)? {
            let key = format!("{prefix}{name}");
            if is_head_variable(&name) && !tensors.contains_key(&key) {
                continue;
            }
            let t = crate::adam::checkpoint_tensor(tensors, &key, var.dims())?;
            var.set(&t.to_device(var.device())?)?;
        }
        Ok(())
    }
}

/// Draws the initial values of `vars` as [`Trainable::init`] describes.
fn init_variables(vars: &[(String, Var)], rng: &mut Pcg64, device: &Device) -> Result<(), TrainError> {
    // Fan-in of each bias: its sibling weight's.
    let fans: HashMap<String, usize> = vars
        .iter()
        .filter(|(n, v)| n.ends_with(".weight") && v.dims().len() >= 2)
        .map(|(n, v)| {
            (
                n.trim_end_matches(".weight").to_string(),
                v.dims()[1..].iter().product(),
            )
        })
        .collect();
    for (name, var) in vars {
        let dims = var.dims().to_vec();
        let count: usize = dims.iter().product();
        let (stem, leaf) = name.rsplit_once('.').unwrap_or(("", name.as_str()));
        let norm = stem.ends_with("norm");
        let values: Vec<f32> = if dims.len() >= 2 {
            let fan: usize = dims[1..].iter().product();
            let bound = 1.0 / (fan.max(1) as f32).sqrt();
            (0..count).map(|_| rng.random_range(-bound..bound)).collect()
        } else if norm && leaf == "weight" {
            vec![1.0; count]
        } else if norm && leaf == "bias" {
            vec![0.0; count]
        } else if leaf == "bias" {
            let bound = 1.0 / (fans.get(stem).copied().unwrap_or(1).max(1) as f32).sqrt();
            (0..count).map(|_| rng.random_range(-bound..bound)).collect()
        } else {
            vec![0.25; count]
        };
        var.set(&Tensor::from_vec(values, dims, device)?)?;
    }
    Ok(())
}

/// The variables of `varmap`, sorted by name.
fn sorted_vars(varmap: &VarMap) -> Result<Vec<(String, Var)>, TrainError> {
    let data = varmap
        .data()
        .lock()
        .map_err(|_| TrainError::Settings("the variable map's lock is poisoned".into()))?;
    let mut vars: Vec<(String, Var)> = data.iter().map(|(n, v)| (n.clone(), v.clone())).collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(vars)
}

/// What a checkpoint records beside its tensors (`checkpoint.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckpointInfo {
    /// Steps taken.
    pub step: u64,
    /// Seconds of training so far, over all sessions.
    pub train_secs: f64,
    /// The run's configuration.
    pub config: TrainConfig,
    /// The last step's losses.
    pub last_loss: LossParts,
}

/// File names inside a run folder.
pub const CHECKPOINT_TENSORS: &str = "checkpoint.safetensors";
/// The checkpoint's metadata.
pub const CHECKPOINT_INFO: &str = "checkpoint.json";

/// Writes `bytes` to `path` through a temporary file and a rename.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|source| TrainError::Io {
        path: tmp.clone(),
        source,
    })?;
    std::fs::rename(&tmp, path).map_err(|source| TrainError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `tensors` to `path` (safetensors) through a temporary file and a rename.
fn save_tensors_atomic(tensors: &HashMap<String, Tensor>, path: &Path) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    candle_core::safetensors::save(tensors, &tmp)?;
    std::fs::rename(&tmp, path).map_err(|source| TrainError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Saves weights, Adam moments and the step to `dir` (tensors first, then the
/// metadata that names the step: a crash between the two leaves the older
/// metadata, which a resume then rejects as not matching, never a silent mix).
pub fn save_checkpoint(
    dir: &Path,
    trainable: &Trainable,
    adam: &Adam,
    info: &CheckpointInfo,
) -> Result<(), TrainError> {
    std::fs::create_dir_all(dir).map_err(|source| TrainError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut tensors: HashMap<String, Tensor> = trainable
        .weights()?
        .into_iter()
        .map(|(n, t)| (format!("param.{n}"), t))
        .collect();
    tensors.extend(adam.state_tensors());
    tensors.insert("step".into(), Tensor::new(&[info.step as f64], &Device::Cpu)?);
    let path = dir.join(CHECKPOINT_TENSORS);
    save_tensors_atomic(&tensors, &path)?;
    let json = serde_json::to_vec_pretty(info).map_err(|e| TrainError::Settings(e.to_string()))?;
    write_atomic(&dir.join(CHECKPOINT_INFO), &json)
}

/// Reads a checkpoint's description (`checkpoint.json`) without its tensors.
pub fn read_checkpoint_info(dir: &Path) -> Result<CheckpointInfo, TrainError> {
    let info_path = dir.join(CHECKPOINT_INFO);
    let text = std::fs::read(&info_path).map_err(|source| TrainError::Io {
        path: info_path.clone(),
        source,
    })?;
    serde_json::from_slice(&text).map_err(|e| TrainError::File {
        path: info_path,
        message: format!("not a checkpoint description: {e}"),
    })
}

/// Loads a checkpoint saved by [`save_checkpoint`] into `trainable` and `adam`.
pub fn load_checkpoint(
    dir: &Path,
    trainable: &Trainable,
    adam: &mut Adam,
) -> Result<CheckpointInfo, TrainError> {
    let info_path = dir.join(CHECKPOINT_INFO);
    let info = read_checkpoint_info(dir)?;
    let path = dir.join(CHECKPOINT_TENSORS);
    let tensors =
        candle_core::safetensors::load(&path, trainable.model.device()).map_err(|e| TrainError::File {
            path: path.clone(),
            message: format!("not a checkpoint: {e}"),
        })?;
    let saved_step = tensors
        .get("step")
        .and_then(|t| t.to_vec1::<f64>().ok())
        .and_then(|v| v.first().copied())
        .ok_or_else(|| TrainError::File {
            path: path.clone(),
            message: "no step".into(),
        })?;
    if saved_step != info.step as f64 {
        return Err(TrainError::File {
            path,
            message: format!(
                "holds step {saved_step}, {} says {}",
                info_path.display(),
                info.step
            ),
        });
    }
    trainable
        .load_weights(&tensors, "param.")
        .map_err(|e| TrainError::File {
            path: path.clone(),
            message: e.to_string(),
        })?;
    adam.restore(&tensors, info.step).map_err(|e| TrainError::File {
        path: path.clone(),
        message: e.to_string(),
    })?;
    Ok(info)
}

/// What [`reset_density_heads`] changed.
#[derive(Debug, Clone, PartialEq)]
pub struct DensityReset {
    /// The checkpoint's step (unchanged).
    pub step: u64,
    /// The output layers reset, one per density head (coarse, fine).
    pub layers: Vec<String>,
}

/// Re-initialises the output layer of each density head (`*density_mlp.layers.N`, the
/// last `N`) in the checkpoint in `dir`: its weights scaled by `weight_scale`, its bias
/// set so that `softplus(bias) = sigma_per_mm`, its Adam moments zeroed; every other
/// tensor and the step stay as they were.
///
/// For a run whose density saturated: with `σ·δ ≫ 1` over every ray step inside the
/// hull, alpha is 1 wherever the hull is and `∂α/∂σ = δ·e^{−σδ}` is 0, so neither the
/// colour nor the alpha loss can carve the hull again (`nelf-small-run` sat at
/// σ ≈ 17/mm with 12.5 mm steps from step ~300 to 3514).
pub fn reset_density_heads(
    dir: &Path,
    sigma_per_mm: f64,
    weight_scale: f64,
) -> Result<DensityReset, TrainError> {
    if !(sigma_per_mm > 0.0 && sigma_per_mm.is_finite() && weight_scale.is_finite()) {
        return Err(TrainError::Settings(format!(
            "density reset: σ must be positive and finite (got {sigma_per_mm}/mm), the weight scale finite (got {weight_scale})"
        )));
    }
    let info = read_checkpoint_info(dir)?;
    let path = dir.join(CHECKPOINT_TENSORS);
    let mut tensors = candle_core::safetensors::load(&path, &Device::Cpu).map_err(|e| TrainError::File {
        path: path.clone(),
        message: format!("not a checkpoint: {e}"),
    })?;
    // The last layer of each density head: the highest `N` among its biases.
    let mut last: HashMap<String, usize> = HashMap::new();
    for key in tensors.keys() {
        let Some(rest) = key.strip_prefix("param.") else {
            continue;
        };
        let Some((head, tail)) = rest.split_once("density_mlp.layers.") else {
            continue;
        };
        let Some(n) = tail.strip_suffix(".bias").and_then(|n| n.parse::<usize>().ok()) else {
            continue;
        };
        let entry = last.entry(format!("{head}density_mlp.layers")).or_insert(n);
        *entry = (*entry).max(n);
    }
    if last.is_empty() {
        return Err(TrainError::File {
            path,
            message: "no density head (`*density_mlp.layers.N.bias`) in this checkpoint".into(),
        });
    }
    // softplus⁻¹(σ) = ln(e^σ − 1).
    let bias_value = sigma_per_mm.exp_m1().ln() as f32;
    let mut layers: Vec<String> = last.iter().map(|(stem, n)| format!("{stem}.{n}")).collect();
    layers.sort();
    let missing = |key: &str| TrainError::File {
        path: path.clone(),
        message: format!("{key} is missing"),
    };
    for layer in &layers {
        for leaf in ["weight", "bias"] {
            // The parameter, then its two Adam moments (zeroed).
            for kind in ["param", "adam_m", "adam_v"] {
                let key = format!("{kind}.{layer}.{leaf}");
                let old = tensors.get(&key).ok_or_else(|| missing(&key))?;
                let new = match (kind, leaf) {
                    ("param", "weight") => (old * weight_scale)?,
                    ("param", _) => Tensor::full(bias_value, old.dims(), &Device::Cpu)?,
                    _ => old.zeros_like()?,
                };
                tensors.insert(key, new);
            }
        }
    }
    save_tensors_atomic(&tensors, &path)?;
    Ok(DensityReset {
        step: info.step,
        layers,
    })
}

/// One optimiser step on the head the step's generator draws.
///
/// With the domain-adaptation hook (`trainable` made with a real-portrait folder,
/// `real` its portraits) the step adds the reproduction loss of one portrait
/// ([`crate::domain`]), drawn from a stream of its own.
pub fn train_step(
    trainable: &Trainable,
    adam: &mut Adam,
    heads: &[PreparedHead],
    real: Option<&RealImages>,
    config: &TrainConfig,
) -> Result<LossParts, TrainError> {
    match (&trainable.reproduce, real) {
        (Some(_), None) => {
            return Err(TrainError::Settings(
                "the network has a domain-adaptation head but no real portraits were given".into(),
            ));
        }
        (None, Some(_)) => {
            return Err(TrainError::Settings(
                "real portraits were given to a network made without --real-images".into(),
            ));
        }
        _ => {}
    }
    let mut rng = step_rng(config.seed, adam.steps());
    if heads.is_empty() {
        return Err(TrainError::Settings("no training heads".into()));
    }
    let head = &heads[rng.random_range(0..heads.len())];
    let model = config.model_for_head(&trainable.model, &head.source_light_net)?;
    let (mut loss, mut parts) = step_loss(&model, head, config, &mut rng)?;
    if let (Some(decoder), Some(real)) = (&trainable.reproduce, real)
        && config.real_weight > 0.0
    {
        let pick = real.pick(config.seed, adam.steps());
        let (_, pixels) = real
            .get(pick)
            .ok_or_else(|| TrainError::Settings("no real portraits".into()))?;
        let term = reproduction_loss(&model, decoder, pixels, real.size())?;
        parts.real = scalar(&term)?;
        parts.total += config.real_weight * parts.real;
        loss = (loss + (term * config.real_weight)?)?;
    }
    let clock = Instant::now();
    let grads = loss.backward()?;
    parts.phase_secs[3] = secs_since(clock);
    adam.step(&grads)?;
    // Values are read back (a device sync) so the time is the update's own.
    adam.sync()?;
    parts.phase_secs[4] = secs_since(clock) - parts.phase_secs[3];
    Ok(parts)
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

/// Where a run keeps its files.
#[derive(Debug, Clone)]
pub struct RunPaths {
    /// The run folder.
    pub dir: PathBuf,
}

impl RunPaths {
    /// The validation log.
    pub fn log(&self) -> PathBuf {
        self.dir.join("validation.csv")
    }

    /// The exported weights (official key names).
    pub fn weights(&self) -> PathBuf {
        self.dir.join("weights.safetensors")
    }
}

/// Elapsed seconds since `start`.
pub fn secs_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64()
}
