//! The loss of a training step (Sun et al. 2021, §4.3).
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
//! under the targets' lightings and fixed probe lightings ([`super::shape_probe_lightings`]):
//! the truth's colour relit by the network's transport ([`relit_by_shape`]).

use std::time::Instant;

use candle_core::{DType, Tensor};
use glam::DVec3;
use nelf_field::{Model, Stage};
use nelf_format::conventions::ENV_TEXELS;
use rand::Rng;
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};

use super::prepare::{PreparedHead, PreparedTarget};
use super::sampling::{Jitter, pick_pixels, render_passes, target_rays};
use crate::config::TrainConfig;
use crate::data::TargetMode;
use crate::error::TrainError;
use crate::forward::{self, encode, irradiance, l1, log_l1};

/// Depth normaliser of the depth loss (the paper's 200 mm).
const DEPTH_SCALE_MM: f64 = 200.0;

/// How far in front of the true depth a foreground ray's samples count as free
/// space, mm: beyond a pixel's footprint at the training sizes (~5 mm at 64²) and the
/// spread of the sub-pixel depths it averages.
pub const FREE_SPACE_MARGIN_MM: f32 = 15.0;

/// Floor of the network's radiance under the source lighting in the shape term's
/// ratio `(T·L)/(T·L_S + ε)`, in the images' units (linear radiance ~0.05–1).
const SHAPE_RATIO_FLOOR: f64 = 0.01;

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
pub(super) fn scalar(t: &Tensor) -> Result<f64, TrainError> {
    Ok(f64::from(t.to_dtype(DType::F32)?.to_scalar::<f32>()?))
}

/// The first `take` values of each of `rows`, in order, of a row-major `table` of
/// `width` values per row (a distillation table's rows at the points a pass kept).
fn leading_of_rows(table: &[f32], width: usize, take: usize, rows: impl Iterator<Item = usize>) -> Vec<f32> {
    rows.flat_map(|row| &table[row * width..row * width + take])
        .copied()
        .collect()
}

/// Elapsed seconds since `start`.
pub fn secs_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64()
}
