//! The NeLF forward pass with gradients (Sun et al. 2021, §4; NeRF-style volume
//! rendering, Mildenhall et al. 2020), built from the same modules as inference
//! (`nelf_field`), so that a trained network bakes exactly as it was trained:
//!
//! * the encoder runs on the source views as one graph; the per-patch light
//!   estimates are aligned with view 0 by fixed bilinear taps (a `128 × 128` matrix
//!   per view, [`nelf_field::light::alignment_taps`]) and confidence-weighted, as
//!   [`nelf_field::light::aggregate_light`] does on the host;
//! * the latent of a point is gathered from the feature maps with the bilinear taps
//!   of its projections (`Σ_k w_k · rows[index_k]`, differentiable in the features);
//!   colours, directions and the visual-hull test stay on the host;
//! * compositing matches [`nelf_field::render::composite_ray`]: `δ_0 = d_1 − d_0`,
//!   `δ_i = (d_{i+1} − d_{i−1})/2`, `δ_last = d_last − d_{last−1}`,
//!   `w_i = (1 − e^{−σ_i δ_i})·e^{−Σ_{j<i} σ_j δ_j}`, colour `Σ w c`, alpha
//!   `1 − e^{−Σ σδ}`, depth `Σ w d / (alpha + 10⁻⁶)`.

use candle_core::{Device, Tensor};
use nelf_field::light::{alignment_taps, net_solid_angles};
use nelf_field::nelfnet::{NelfNet, NelfNetTrace, PointInputs};
use nelf_field::render::{NetRay, sample_delta};
use nelf_field::{EncodedViews, Model, SourceViews, Stage};
use nelf_format::conventions::ENV_TEXELS;

use crate::config::ColourLoss;
use crate::error::TrainError;

/// The encoder's outputs that carry gradients.
#[derive(Debug, Clone)]
pub struct Encoded {
    /// `(V·H/2·W/2, F)`: the source features, one row per feature-map pixel
    /// (view-major, channel-last).
    pub feature_rows: Tensor,
    /// `(384)`: the estimated source light, network layout `(3, 8, 16)`.
    pub source_light: Tensor,
}

/// Runs the encoder and the light aggregation on `views` with gradients.
pub fn encode(model: &Model, views: &SourceViews) -> Result<Encoded, TrainError> {
    views.validate()?;
    let device = model.device();
    let (v, h, w) = (views.views(), views.height, views.width);
    let images = Tensor::from_slice(&views.images, (v, h, w, 3), device)?
        .permute((0, 3, 1, 2))?
        .contiguous()?;
    let out = model.encoder().forward(&images)?;
    let channels = out.feature.dim(1)?;
    let feature_rows = out
        .feature
        .permute((0, 2, 3, 1))?
        .reshape((v * (h / 2) * (w / 2), channels))?;
    let rotations: Vec<_> = views
        .cameras
        .iter()
        .map(nelf_field::geometry::NetCamera::rotation)
        .collect();
    let source_light = aggregate_light(&out.light_feature, &rotations, device)?;
    Ok(Encoded {
        feature_rows,
        source_light,
    })
}

/// The confidence-weighted light estimate of a light feature `(V, 512, h, w)`.
fn aggregate_light(
    light_feature: &Tensor,
    rotations: &[[[f32; 3]; 3]],
    device: &Device,
) -> Result<Tensor, TrainError> {
    let (v, _, h, w) = light_feature.dims4()?;
    let (_, taps) = alignment_taps(rotations);
    // align[v][s][t]: weight of view v's texel s in view-0 texel t.
    let mut align = vec![0.0f32; v * ENV_TEXELS * ENV_TEXELS];
    for (i, tap) in taps.iter().enumerate() {
        let (view, t) = (i / ENV_TEXELS, i % ENV_TEXELS);
        for (index, weight) in tap.index.iter().zip(tap.weight) {
            align[(view * ENV_TEXELS + *index as usize) * ENV_TEXELS + t] += weight;
        }
    }
    let align = Tensor::from_vec(align, (v, ENV_TEXELS, ENV_TEXELS), device)?;
    let patches = light_feature
        .permute((0, 2, 3, 1))?
        .reshape((v, h * w * 4, ENV_TEXELS))?
        .contiguous()?;
    let aligned = patches.matmul(&align)?.reshape((v, h * w, 4, ENV_TEXELS))?;
    let confidence = aligned.narrow(2, 3, 1)?;
    let total = confidence.sum_keepdim(1)?.sum_keepdim(0)?;
    let weight = confidence.broadcast_div(&total)?;
    let estimate = aligned.narrow(2, 0, 3)?;
    Ok(estimate.broadcast_mul(&weight)?.sum(1)?.sum(0)?.flatten_all()?)
}

/// The per-point network's pass over the points of a batch that lie inside the hull.
#[derive(Debug)]
pub struct PointPass {
    /// Indices (into the batch) of the points inside the hull.
    pub inside: Vec<u32>,
    /// Every intermediate of the network, for the inside points.
    pub trace: NelfNetTrace,
    /// `(N_in, V, 3)`: source colours.
    pub source_rgb: Tensor,
}

/// Runs `stage`'s network on the points (mm) inside the hull, seen along unit
/// `target_dirc` (point → viewer); `None` when no point is inside.
pub fn run_points(
    model: &Model,
    encoded: &Encoded,
    geometry: &EncodedViews,
    points: &[[f32; 3]],
    target_dirc: &[[f32; 3]],
    stage: Stage,
) -> Result<Option<PointPass>, TrainError> {
    let hull = geometry.hull(points);
    let inside: Vec<u32> = (0..points.len() as u32)
        .filter(|&i| hull.inside[i as usize])
        .collect();
    if inside.is_empty() {
        return Ok(None);
    }
    let chosen: Vec<[f32; 3]> = inside.iter().map(|&i| points[i as usize]).collect();
    let dirs: Vec<[f32; 3]> = inside.iter().map(|&i| target_dirc[i as usize]).collect();
    let inputs = point_inputs(model, encoded, geometry, &chosen, &dirs, stage)?;
    let source_rgb = inputs.source_rgb.clone();
    let mut trace = model.forward_points(stage, &inputs)?;
    // The normals come from the network's density without gradients: the prior
    // shapes the transport, it does not train the geometry.
    if let Some(lt) =
        model.shading_prior_transport(geometry, &chosen, &dirs, &trace.lt_scale, |probes, probe_dirs| {
            let inputs = point_inputs(model, encoded, geometry, probes, probe_dirs, stage)?;
            Ok::<_, TrainError>(
                model
                    .net(stage)
                    .density(&inputs)?
                    .detach()
                    .flatten_all()?
                    .to_vec1::<f32>()?,
            )
        })?
    {
        trace.lt_scale = lt;
    }
    Ok(Some(PointPass {
        inside,
        trace,
        source_rgb,
    }))
}

/// The network inputs of `points` (mm) seen along `target_dirc`, their latents
/// gathered from `encoded`'s feature rows with gradients. No hull test.
fn point_inputs(
    model: &Model,
    encoded: &Encoded,
    geometry: &EncodedViews,
    points: &[[f32; 3]],
    target_dirc: &[[f32; 3]],
    stage: Stage,
) -> Result<PointInputs, TrainError> {
    let device = model.device();
    let dirs: Vec<f32> = target_dirc.iter().flatten().copied().collect();
    let taps = geometry.gather_taps(points);
    let (n, v) = (points.len(), geometry.views());
    let channels = encoded.feature_rows.dim(1)?;
    let latent_channels = channels / 2;
    let rows = encoded
        .feature_rows
        .narrow(1, stage.feature_offset(latent_channels), latent_channels)?
        .contiguous()?;
    let mut latent: Option<Tensor> = None;
    for k in 0..4 {
        let index = Tensor::from_slice(&taps.rows[k], n * v, device)?;
        let weight = Tensor::from_slice(&taps.weights[k], (n * v, 1), device)?;
        let term = rows.index_select(&index, 0)?.broadcast_mul(&weight)?;
        latent = Some(match latent {
            Some(sum) => (sum + term)?,
            None => term,
        });
    }
    let latent = latent
        .ok_or_else(|| TrainError::Settings("no taps".into()))?
        .reshape((n, v, latent_channels))?;
    let source_rgb = Tensor::from_slice(&taps.source_rgb, (n, v, 3), device)?;
    Ok(PointInputs {
        source_rgb,
        latent,
        source_dirc: Tensor::from_slice(&taps.source_dirc, (n, v, 3), device)?,
        target_dirc: Tensor::from_vec(dirs, (n, 3), device)?,
    })
}

/// One composited pass over `R` rays.
#[derive(Debug)]
pub struct RayPass {
    /// `(R, 3)` colour.
    pub rgb: Tensor,
    /// `(R)` accumulated opacity.
    pub alpha: Tensor,
    /// `(R)` depth along the ray (mm).
    pub depth: Tensor,
    /// `(R, S)` compositing weights on the host (for importance sampling).
    pub weights: Vec<f32>,
    /// `(R, S)` σ at the samples, 1/mm (0 outside the hull).
    pub sigma: Tensor,
    /// `(R, S)` the samples' depths along their rays, mm, on the host.
    pub depths: Vec<f32>,
}

/// Renders `rays` with `samples` sorted depths each (`depths`, `(R, S)`, mm) through
/// `stage`'s network under `irradiance` (`(3, 128)`, `L·Ω`, network layout).
pub fn render_rays(
    model: &Model,
    encoded: &Encoded,
    geometry: &EncodedViews,
    rays: &[NetRay],
    depths: &[f32],
    stage: Stage,
    irradiance: &Tensor,
) -> Result<RayPass, TrainError> {
    let device = model.device();
    let r = rays.len();
    let s = depths.len() / r.max(1);
    if r == 0 || s < 2 || depths.len() != r * s {
        return Err(TrainError::Settings(format!(
            "{} depths for {r} rays: need at least 2 per ray",
            depths.len()
        )));
    }
    let mut points = Vec::with_capacity(r * s);
    let mut dirs = Vec::with_capacity(r * s);
    for (i, ray) in rays.iter().enumerate() {
        for &d in &depths[i * s..(i + 1) * s] {
            points.push(ray.at(d));
            dirs.push(ray.toward_camera());
        }
    }
    let (sigma, rgb) = match run_points(model, encoded, geometry, &points, &dirs, stage)? {
        Some(pass) => {
            let shaded = NelfNet::shade(&pass.trace, &pass.source_rgb, irradiance)?;
            let index = Tensor::from_slice(&pass.inside, pass.inside.len(), device)?;
            let sigma = Tensor::zeros((r * s, 1), candle_core::DType::F32, device)?.index_add(
                &index,
                &pass.trace.density,
                0,
            )?;
            let rgb = Tensor::zeros((r * s, 3), candle_core::DType::F32, device)?.index_add(
                &index,
                &shaded.rgb,
                0,
            )?;
            (sigma, rgb)
        }
        None => (
            Tensor::zeros((r * s, 1), candle_core::DType::F32, device)?,
            Tensor::zeros((r * s, 3), candle_core::DType::F32, device)?,
        ),
    };
    let sigma = sigma.reshape((r, s))?;
    let rgb = rgb.reshape((r, s, 3))?;
    let delta: Vec<f32> = depths
        .chunks(s)
        .flat_map(|ray| (0..ray.len()).map(|i| sample_delta(ray, i)))
        .collect();
    let delta = Tensor::from_vec(delta, (r, s), device)?;
    let depth_t = Tensor::from_slice(depths, (r, s), device)?;
    let optical = (&sigma * delta)?;
    let cumulative = optical.cumsum(1)?;
    let transmittance = (&cumulative - &optical)?.neg()?.exp()?;
    let opacity = (1.0 - optical.neg()?.exp()?)?;
    let weights = (opacity * transmittance)?;
    let colour = rgb.broadcast_mul(&weights.unsqueeze(2)?)?.sum(1)?;
    let alpha = (1.0 - cumulative.narrow(1, s - 1, 1)?.squeeze(1)?.neg()?.exp()?)?;
    let depth = ((&weights * depth_t)?.sum(1)? / (&alpha + 1e-6)?)?;
    let weights_host = weights.detach().flatten_all()?.to_vec1::<f32>()?;
    Ok(RayPass {
        rgb: colour,
        alpha,
        depth,
        weights: weights_host,
        sigma,
        depths: depths.to_vec(),
    })
}

/// `(3, 128)`: irradiance `L·Ω` of a network-layout light `(384)` on `device`.
pub fn irradiance(light: &[f32], device: &Device) -> Result<Tensor, TrainError> {
    Ok(Tensor::from_vec(
        nelf_field::model::irradiance_values(light)?,
        (3, ENV_TEXELS),
        device,
    )?)
}

/// The light-transport vectors `(N, 384)` of a point pass (network layout, the
/// network's solid angles folded in, as [`NelfNet::light_transport`]).
pub fn light_transport(pass: &PointPass, device: &Device) -> Result<Tensor, TrainError> {
    let omega = Tensor::from_slice(&net_solid_angles(), ENV_TEXELS, device)?;
    Ok(NelfNet::light_transport(&pass.trace, &pass.source_rgb, &omega)?)
}

/// Mean absolute difference of two tensors of one shape.
pub fn l1(a: &Tensor, b: &Tensor) -> Result<Tensor, TrainError> {
    Ok((a - b)?.abs()?.mean_all()?)
}

/// Linear colours clamped to [0, 1] and encoded as sRGB: the differentiable twin of
/// `nelf_scene::mesh_io::linear_to_srgb` (tested equal; the power branch never sees
/// values below its threshold, so no gradient is NaN).
pub fn srgb_encode(t: &Tensor) -> Result<Tensor, TrainError> {
    const KNEE: f64 = 0.003_130_8;
    let x = t.clamp(0.0f32, 1.0f32)?;
    let linear = (&x * 12.92)?;
    let power = ((x.maximum(KNEE as f32)?.powf(1.0 / 2.4)? * 1.055)? - 0.055)?;
    Ok(x.le(KNEE)?.where_cond(&linear, &power)?)
}

/// `mean (srgb(a) − srgb(b))²` over colours clamped to [0, 1] ([`srgb_encode`]).
pub fn srgb_l2(a: &Tensor, b: &Tensor) -> Result<Tensor, TrainError> {
    Ok((srgb_encode(a)? - srgb_encode(b)?)?.sqr()?.mean_all()?)
}

/// The colour loss `kind` between colours `a` and `b` ([`l1`] or [`srgb_l2`]).
pub fn colour_loss(kind: ColourLoss, a: &Tensor, b: &Tensor) -> Result<Tensor, TrainError> {
    match kind {
        ColourLoss::L1 => l1(a, b),
        ColourLoss::SrgbL2 => srgb_l2(a, b),
    }
}

/// `log(1 + max(t, 0))`, elementwise.
pub fn log1p_relu(t: &Tensor) -> Result<Tensor, TrainError> {
    Ok((t.relu()? + 1.0)?.log()?)
}

/// `mean |log(1 + a) − log(1 + b)|` (the paper's log-L1 lighting loss).
pub fn log_l1(a: &Tensor, b: &Tensor) -> Result<Tensor, TrainError> {
    l1(&log1p_relu(a)?, &log1p_relu(b)?)
}
