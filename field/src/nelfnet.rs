//! The per-point NeLF network (official `NelfNet`, one each for the coarse and fine
//! passes; Sun et al. 2021, §4.2). For `N` points seen by `V` source views:
//!
//! * `dircs = [source_dirc, target_dirc]` (6); `f = dirc_mlp(dircs) + [rgb, latent]` (35);
//! * `geometry_mlp([f, mean_v f, var_v f])` (105 → 65, `var` unbiased ÷(V−1));
//!   `feature = out[..64]`, view weight `w = sigmoid(out[64])`;
//! * `density = softplus(density_mlp([Σ_v w·feature, Σ_v w·feature² − (Σ_v w·feature)²]))`
//!   (1/mm; the moments are not normalised by `Σ w`);
//! * light transport per view `lt = softplus(lt_mlp([rgb, latent, source_dirc, feature]))`
//!   (102 → 384, read as `(3, 128)`, channel-major);
//! * per-view colour `rgb ⊙ Σ_p lt[c,p]·E[c,p]` under irradiance `E = L·Ω`, blended by
//!   `softmax_v(blend_mlp([dircs, feature]))` (70 → 32 → 16 → 1).
//!
//! Everything but the blend is linear in the light, so the point's light-transport
//! vector in the project's convention (`radiance_c = Σ_p T[c,p]·L[c,p]`) is
//! `T[c,p] = Σ_v softmax_v · rgb_{v,c} · lt_v[c,p] · Ω_p` ([`NelfNet::light_transport`]).

use candle_core::{D, Module, Tensor};
use candle_nn::VarBuilder;
use nelf_format::conventions::{ENV_TEXELS, LT_DIM};

use crate::architecture::Architecture;
use crate::error::NetError;
use crate::layers::{Mlp, ResMlp, softplus};

/// Latent channels per point and view (half of the source feature), official widths;
/// others: [`Architecture::latent_channels`].
pub const LATENT_CHANNELS: usize = 32;
/// Width of the geometry feature, official widths; others:
/// [`Architecture::geometry_features`].
pub const GEOMETRY_FEATURES: usize = 64;

/// The inputs of one batch of points: `N` points, `V` views, all `f32` on the model's device.
#[derive(Debug, Clone)]
pub struct PointInputs {
    /// `(N, V, 3)`: source colours at the projections.
    pub source_rgb: Tensor,
    /// `(N, V, 32)`: source features at the projections (coarse or fine half).
    pub latent: Tensor,
    /// `(N, V, 3)`: unit directions from the point to each source camera.
    pub source_dirc: Tensor,
    /// `(N, 3)`: unit direction from the point to the target camera.
    pub target_dirc: Tensor,
}

/// Every intermediate of a [`NelfNet`] pass, named as in the fixtures
/// (`output.points.{coarse,fine}.*`).
#[derive(Debug, Clone)]
pub struct NelfNetTrace {
    /// `(N,V,6)`.
    pub dirc_mlp_in: Tensor,
    /// `(N,V,35)`.
    pub dirc_mlp_out: Tensor,
    /// `(N,V,35)`.
    pub input_feature: Tensor,
    /// `(N,V,105)`.
    pub geometry_in: Tensor,
    /// `(N,V,65)`.
    pub geometry_out: Tensor,
    /// `(N,V,1)`.
    pub view_weight: Tensor,
    /// `(N,64)`.
    pub weight_mean: Tensor,
    /// `(N,64)`.
    pub weight_var: Tensor,
    /// `(N,128)`.
    pub density_in: Tensor,
    /// `(N,1)`, before softplus.
    pub density_raw: Tensor,
    /// `(N,1)`, σ in 1/mm.
    pub density: Tensor,
    /// `(N,V,384)`, after softplus.
    pub lt_scale: Tensor,
    /// `(N,V,70)`.
    pub blend_in: Tensor,
    /// `(N,V,1)`.
    pub blend_logits: Tensor,
    /// `(N,V,1)`.
    pub blend_softmax: Tensor,
}

impl NelfNetTrace {
    /// The intermediates with their fixture names (without the `output.points.{m}.` prefix).
    pub fn named(&self) -> Vec<(&'static str, &Tensor)> {
        vec![
            ("dirc_mlp_in", &self.dirc_mlp_in),
            ("dirc_mlp_out", &self.dirc_mlp_out),
            ("input_feature", &self.input_feature),
            ("geometry_in", &self.geometry_in),
            ("geometry_out", &self.geometry_out),
            ("view_weight", &self.view_weight),
            ("weight_mean", &self.weight_mean),
            ("weight_var", &self.weight_var),
            ("density_in", &self.density_in),
            ("density_raw", &self.density_raw),
            ("density", &self.density),
            ("lt_scale", &self.lt_scale),
            ("blend_in", &self.blend_in),
            ("blend_logits", &self.blend_logits),
            ("blend_softmax", &self.blend_softmax),
        ]
    }
}

/// The density path's intermediates.
#[derive(Debug)]
struct Trunk {
    dirc_mlp_in: Tensor,
    dirc_mlp_out: Tensor,
    input_feature: Tensor,
    geometry_in: Tensor,
    geometry_out: Tensor,
    feature: Tensor,
    view_weight: Tensor,
    weight_mean: Tensor,
    weight_var: Tensor,
    density_in: Tensor,
    density_raw: Tensor,
    density: Tensor,
}

/// Shaded colours of a pass.
#[derive(Debug, Clone)]
pub struct Shaded {
    /// `(N,V,3)`.
    pub rgb_perview: Tensor,
    /// `(N,3)`.
    pub rgb: Tensor,
}

/// Smallest source shading `lt_v·(L_S·Ω)` a view's light transport is divided by
/// in [`normalise_to_source`] (the ideal is 1): a point the network thinks the
/// source light barely reaches is raised at most 50×.
pub const MIN_SOURCE_SHADING: f64 = 0.02;

/// Per-point source normalisation: `lt_v[c, ·] / max(lt_v[c, ·]·E_S[c, ·], ε)` for
/// `lt` `(N, V, 384)` and the source irradiance `E_S = L_S·Ω` `(3, 128)`.
///
/// A view's colour is `rgb_v ⊙ (lt_v·E)`, so under the lighting `L_S` the source
/// photos were taken in, the ideal `lt_v·E_S` is exactly 1 (the photo itself):
/// for a Lambertian point `lt_v ∝ max(0, n·ω)·V(ω)` divided by the point's source
/// irradiance. The division imposes that, point by point and channel by channel,
/// leaving the network only the *shape* of `lt_v` over the 128 directions (the
/// ratio of target to source shading) and taking its overall scale — which five
/// photos cannot tell apart from albedo — from the known lighting. The same
/// consistency is fitted as one gain per capture by [`crate::calibrate`].
pub fn normalise_to_source(lt: &Tensor, source_irradiance: &Tensor) -> Result<Tensor, NetError> {
    let (n, v, _) = lt.dims3()?;
    let lt4 = lt.reshape((n, v, 3, ENV_TEXELS))?;
    let e = source_irradiance.reshape((1, 1, 3, ENV_TEXELS))?;
    let shading = lt4
        .broadcast_mul(&e)?
        .sum_keepdim(3)?
        .maximum(MIN_SOURCE_SHADING)?;
    Ok(lt4.broadcast_div(&shading)?.reshape((n, v, LT_DIM))?)
}

/// One per-point network (`coarse_appearance_encoder` or `fine_appearance_encoder`).
#[derive(Debug, Clone)]
#[allow(
    clippy::struct_field_names,
    reason = "the fields are the checkpoint's module names"
)]
pub struct NelfNet {
    dirc_mlp: Mlp,
    geometry_mlp: ResMlp,
    density_mlp: Mlp,
    lt_mlp: ResMlp,
    blend_mlp: Mlp,
    /// Latent channels per view.
    latent: usize,
    /// Width of the geometry feature.
    geometry: usize,
}

impl NelfNet {
    /// Loads the network of widths `arch` from `vb` (e.g. the
    /// `fine_appearance_encoder` prefix).
    pub fn new(vb: &VarBuilder, arch: &Architecture) -> Result<Self, NetError> {
        let (latent, g) = (arch.latent_channels, arch.geometry_features);
        let f = 3 + latent;
        Ok(Self {
            dirc_mlp: Mlp::new(&[6, 16, f], &vb.pp("dirc_mlp"))?,
            geometry_mlp: ResMlp::new(3 * f, g, g + 1, 2, &vb.pp("geometry_mlp"))?,
            density_mlp: Mlp::new(&[2 * g, 32, 1], &vb.pp("density_mlp"))?,
            lt_mlp: ResMlp::new(f + 3 + g, arch.lt_hidden, LT_DIM, 2, &vb.pp("lt_mlp"))?,
            blend_mlp: Mlp::new(&[6 + g, 32, 16, 1], &vb.pp("blend_mlp"))?,
            latent,
            geometry: g,
        })
    }

    /// The density path: directions, geometry and weighted moments, σ.
    fn trunk(&self, input: &PointInputs) -> Result<Trunk, NetError> {
        let (n, v, _) = input.source_rgb.dims3()?;
        if v < 2 {
            return Err(NetError::input(format!(
                "the network needs at least 2 views, got {v}"
            )));
        }
        let f = 3 + self.latent;
        let rows = n * v;
        let target = input.target_dirc.unsqueeze(1)?.broadcast_as((n, v, 3))?;
        let dirc_mlp_in = Tensor::cat(&[&input.source_dirc, &target], 2)?;
        let dirc_mlp_out = self
            .dirc_mlp
            .forward(&dirc_mlp_in.reshape((rows, 6))?)?
            .reshape((n, v, f))?;
        let rgb_latent = Tensor::cat(&[&input.source_rgb, &input.latent], 2)?;
        let input_feature = (&dirc_mlp_out + &rgb_latent)?;
        let mean = input_feature.mean_keepdim(1)?;
        let centred = input_feature.broadcast_sub(&mean)?;
        let var = (centred.sqr()?.sum_keepdim(1)? / (v - 1) as f64)?;
        let geometry_in = Tensor::cat(
            &[
                &input_feature,
                &mean.broadcast_as((n, v, f))?,
                &var.broadcast_as((n, v, f))?,
            ],
            2,
        )?;
        let geometry_out = self
            .geometry_mlp
            .forward(&geometry_in.reshape((rows, 3 * f))?)?
            .reshape((n, v, self.geometry + 1))?;
        let feature = geometry_out.narrow(2, 0, self.geometry)?;
        let view_weight = candle_nn::ops::sigmoid(&geometry_out.narrow(2, self.geometry, 1)?)?;
        let weighted = feature.broadcast_mul(&view_weight)?;
        let weight_mean = weighted.sum(1)?;
        let weight_var = ((&weighted * &feature)?.sum(1)? - weight_mean.sqr()?)?;
        let density_in = Tensor::cat(&[&weight_mean, &weight_var], 1)?;
        let density_raw = self.density_mlp.forward(&density_in)?;
        let density = softplus(&density_raw)?;
        Ok(Trunk {
            dirc_mlp_in,
            dirc_mlp_out,
            input_feature,
            geometry_in,
            geometry_out,
            feature,
            view_weight,
            weight_mean,
            weight_var,
            density_in,
            density_raw,
            density,
        })
    }

    /// σ `(N, 1)` (1/mm) only, skipping the light-transport and blend networks.
    pub fn density(&self, input: &PointInputs) -> Result<Tensor, NetError> {
        Ok(self.trunk(input)?.density)
    }

    /// Runs the network on a batch (`V ≥ 2`), returning every intermediate.
    pub fn forward(&self, input: &PointInputs) -> Result<NelfNetTrace, NetError> {
        let t = self.trunk(input)?;
        let (n, v, _) = input.source_rgb.dims3()?;
        let rows = n * v;
        let f = 3 + self.latent;
        let lt_in = Tensor::cat(
            &[&input.source_rgb, &input.latent, &input.source_dirc, &t.feature],
            2,
        )?;
        let lt_scale = softplus(
            &self
                .lt_mlp
                .forward(&lt_in.reshape((rows, f + 3 + self.geometry))?)?,
        )?
        .reshape((n, v, LT_DIM))?;
        let blend_in = Tensor::cat(&[&t.dirc_mlp_in, &t.feature], 2)?;
        let blend_logits = self
            .blend_mlp
            .forward(&blend_in.reshape((rows, 6 + self.geometry))?)?
            .reshape((n, v, 1))?;
        let blend_softmax = candle_nn::ops::softmax(&blend_logits, 1)?;
        Ok(NelfNetTrace {
            dirc_mlp_in: t.dirc_mlp_in,
            dirc_mlp_out: t.dirc_mlp_out,
            input_feature: t.input_feature,
            geometry_in: t.geometry_in,
            geometry_out: t.geometry_out,
            view_weight: t.view_weight,
            weight_mean: t.weight_mean,
            weight_var: t.weight_var,
            density_in: t.density_in,
            density_raw: t.density_raw,
            density: t.density,
            lt_scale,
            blend_in,
            blend_logits,
            blend_softmax,
        })
    }

    /// Colours under `irradiance` (`(3, 128)`, network layout, `L·Ω`).
    pub fn shade(trace: &NelfNetTrace, source_rgb: &Tensor, irradiance: &Tensor) -> Result<Shaded, NetError> {
        let (n, v, _) = source_rgb.dims3()?;
        let dots = if crate::cpu::fused_for(&trace.lt_scale) {
            let weights = irradiance.flatten_all()?.to_vec1::<f32>()?;
            crate::cpu::channel_dots(&trace.lt_scale, &weights)?
        } else if crate::cpu::fused_trainable(&trace.lt_scale) && !irradiance.track_op() {
            let weights = irradiance.flatten_all()?.to_vec1::<f32>()?;
            crate::cpu::channel_dots_trainable(&trace.lt_scale, &weights)?
        } else {
            let lt = trace.lt_scale.reshape((n, v, 3, ENV_TEXELS))?;
            let irradiance = irradiance.reshape((1, 1, 3, ENV_TEXELS))?;
            lt.broadcast_mul(&irradiance)?.sum(D::Minus1)?
        };
        let rgb_perview = (dots * source_rgb)?;
        let rgb = rgb_perview.broadcast_mul(&trace.blend_softmax)?.sum(1)?;
        Ok(Shaded { rgb_perview, rgb })
    }

    /// The light-transport vectors `(N, 384)` (network layout, solid angle `Ω`
    /// `(128)` folded in): `T[c,p] = Σ_v softmax_v · rgb_{v,c} · lt_v[c,p] · Ω_p`.
    pub fn light_transport(
        trace: &NelfNetTrace,
        source_rgb: &Tensor,
        solid_angle: &Tensor,
    ) -> Result<Tensor, NetError> {
        let (n, v, _) = source_rgb.dims3()?;
        let per_view = source_rgb.broadcast_mul(&trace.blend_softmax)?;
        if crate::cpu::fused_for(&trace.lt_scale) {
            let omega = solid_angle.flatten_all()?.to_vec1::<f32>()?;
            return Ok(crate::cpu::blend_light_transport(
                &trace.lt_scale,
                &per_view,
                &omega,
            )?);
        }
        let lt = trace.lt_scale.reshape((n, v, 3, ENV_TEXELS))?;
        let t = lt.broadcast_mul(&per_view.unsqueeze(3)?)?.sum(1)?;
        let omega = solid_angle.reshape((1, 1, ENV_TEXELS))?;
        Ok(t.broadcast_mul(&omega)?.reshape((n, LT_DIM))?)
    }
}
