//! A Lambertian shading prior for the network's light transport, from the network's
//! own geometry: the quotient-image relighting of classical portrait relighting
//! (Shashua and Riklin-Raviv, "The Quotient Image", PAMI 2001; Wen, Liu and Huang,
//! "Face Relighting with Radiance Environment Maps", CVPR 2003), written as a NeLF
//! light-transport vector.
//!
//! At a point `x` with unit normal `n(x) = −∇σ/|∇σ|` (the network's density σ,
//! central differences of step `h`), the prior's transport over the network's 128
//! texel directions `ω_p` is the clamped cosine `lt(ω_p) = max(0, n·ω_p)`, the same
//! for every view and channel. Normalised to the capture's known source lighting
//! ([`crate::nelfnet::normalise_to_source`]) the network's colour under a lighting `L`
//! becomes
//!
//! `c(x) = Σ_v w_v · rgb_v(x) · (lt·(L·Ω)) / (lt·(L_S·Ω))`,
//!
//! the source photos' colour times the ratio of the target to the source irradiance
//! of a Lambertian surface with that normal: no shadows, no interreflection, no
//! sheen, but the right direction of the shading wherever the density is right.
//! Where `|∇σ|` vanishes (inside a solid region, or in empty space) the prior is
//! uniform (`lt = 1`): the ratio of the total irradiances.
//!
//! [`shading_prior`] mixes that prior with the network's own (normalised) transport,
//! `lt = (1 − α)·lt_net + α·lt_prior` after normalisation, so `α = 1` is the prior
//! alone and `α = 0` the network alone.

use candle_core::Tensor;
use nelf_format::conventions::{ENV_H, ENV_TEXELS, ENV_W, LT_DIM};

use crate::error::NetError;
use crate::light::net_texel_direction;

/// Default gradient step, mm: the step whose bakes scored best on held-out heads of
/// the sunlit test protocol at 128², chosen together with [`DEFAULT_WEIGHT`]; the
/// sweeps, the heads and the commands are in `field/README.md` ("Shading prior").
pub const DEFAULT_STEP_MM: f32 = 3.0;

/// Default weight of the prior in bakes and renders, chosen with [`DEFAULT_STEP_MM`]
/// (`field/README.md`). The shipped weights were trained through [`TRAINING_WEIGHT`].
pub const DEFAULT_WEIGHT: f32 = 0.7;

/// Weight of the prior `nelf train run --shading-prior-mm` trains through by default,
/// the one the shipped weights' last steps used (a run continues with the weight it
/// began with).
pub const TRAINING_WEIGHT: f32 = 0.5;

/// How the network's light transport is shaped by the Lambertian prior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingPrior {
    /// Central-difference step of the density gradient, mm.
    pub step_mm: f32,
    /// Weight of the prior against the network's own transport, in `[0, 1]`.
    pub weight: f32,
}

impl Default for ShadingPrior {
    fn default() -> Self {
        Self {
            step_mm: DEFAULT_STEP_MM,
            weight: DEFAULT_WEIGHT,
        }
    }
}

impl ShadingPrior {
    /// The prior of a command-line step and weight: `None` for a step of 0 mm (off).
    pub fn from_step_mm(step_mm: f32, weight: f32) -> Option<Self> {
        (step_mm > 0.0).then_some(Self { step_mm, weight })
    }

    /// Checks the step and weight.
    pub fn validate(&self) -> Result<(), NetError> {
        if !(self.step_mm.is_finite() && self.step_mm > 0.0) {
            return Err(NetError::input(format!(
                "the shading prior's gradient step must be a positive number of mm, got {}",
                self.step_mm
            )));
        }
        if !(0.0..=1.0).contains(&self.weight) {
            return Err(NetError::input(format!(
                "the shading prior's weight must be in [0, 1], got {}",
                self.weight
            )));
        }
        Ok(())
    }
}

/// Smallest density gradient, 1/mm², that gives a normal; below it the prior is
/// uniform.
pub const MIN_GRADIENT: f32 = 1e-6;

/// Unit normals `−∇σ/|∇σ|` (network frame) of `points` (mm) from `density`, a
/// function of a batch of points returning σ per point; `None` where the gradient
/// is below [`MIN_GRADIENT`].
pub fn density_normals<E: From<NetError>>(
    points: &[[f32; 3]],
    step_mm: f32,
    density: impl Fn(&[[f32; 3]]) -> Result<Vec<f32>, E>,
) -> Result<Vec<Option<[f32; 3]>>, E> {
    let mut probes = Vec::with_capacity(points.len() * 6);
    for p in points {
        for axis in 0..3 {
            for sign in [1.0f32, -1.0] {
                let mut q = *p;
                q[axis] += sign * step_mm;
                probes.push(q);
            }
        }
    }
    let sigma = density(&probes)?;
    if sigma.len() != probes.len() {
        return Err(NetError::input(format!("{} densities for {} probes", sigma.len(), probes.len())).into());
    }
    Ok(sigma
        .chunks_exact(6)
        .map(|s| {
            let g = [0, 1, 2].map(|a| (s[2 * a] - s[2 * a + 1]) / (2.0 * step_mm));
            let norm = g.iter().map(|x| x * x).sum::<f32>().sqrt();
            (norm > MIN_GRADIENT).then(|| g.map(|x| -x / norm))
        })
        .collect())
}

/// The prior's per-point transport `(N, 384)` (network layout, channel-major): the
/// clamped cosine about each normal turned into view-0 camera coordinates by
/// `cam0_from_net` (rows), uniform where there is no normal.
pub fn lambert_transport(normals: &[Option<[f32; 3]>], cam0_from_net: [[f32; 3]; 3]) -> Vec<f32> {
    let directions: Vec<[f32; 3]> = (0..ENV_TEXELS)
        .map(|t| net_texel_direction(t / ENV_W, t % ENV_W))
        .collect();
    debug_assert_eq!(directions.len(), ENV_H * ENV_W);
    let mut out = vec![1.0f32; normals.len() * LT_DIM];
    for (row, normal) in out.chunks_exact_mut(LT_DIM).zip(normals) {
        if let Some(n) = normal {
            let n0 = cam0_from_net.map(|r| r[0] * n[0] + r[1] * n[1] + r[2] * n[2]);
            for (t, d) in directions.iter().enumerate() {
                let cos = (n0[0] * d[0] + n0[1] * d[1] + n0[2] * d[2]).max(0.0);
                for c in 0..3 {
                    row[c * ENV_TEXELS + t] = cos;
                }
            }
        }
    }
    out
}

/// The network's (normalised) per-view transport `lt` `(N, V, 384)` mixed with the
/// prior ([`ShadingPrior`]) about `normals` ([`density_normals`], network frame;
/// `cam0_from_net` the view-0 camera's rotation), the prior normalised to the source
/// irradiance `source_irradiance` `(3, 128)`.
pub fn shading_prior(
    prior: &ShadingPrior,
    lt: &Tensor,
    source_irradiance: &Tensor,
    normals: &[Option<[f32; 3]>],
    cam0_from_net: [[f32; 3]; 3],
) -> Result<Tensor, NetError> {
    prior.validate()?;
    let (n, v, _) = lt.dims3()?;
    if normals.len() != n {
        return Err(NetError::input(format!(
            "{} normals for {n} points",
            normals.len()
        )));
    }
    let lobe = Tensor::from_vec(
        lambert_transport(normals, cam0_from_net),
        (n, 1, LT_DIM),
        lt.device(),
    )?
    .broadcast_as((n, v, LT_DIM))?
    .contiguous()?;
    let lobe = crate::nelfnet::normalise_to_source(&lobe, source_irradiance)?;
    let weight = f64::from(prior.weight);
    Ok(((lt * (1.0 - weight))? + (lobe * weight)?)?)
}
