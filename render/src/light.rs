//! Relighting: per-voxel radiance of an asset under an environment map.
//!
//! A voxel's outgoing radiance is the per-channel dot product of its light-transport
//! vector with the 8 × 16 lighting (`docs/CONVENTIONS.md`, SPEC.md §8; solid angles are folded into
//! `T`): `radiance_c = Σ_j T[c·128 + j] · L[j][c]`. The asset stores
//! `T = m + Σ_k c_k B_k` (PCA mean `m`, basis `B_k`), and shading is linear in `T`, so
//!
//! `radiance_c = P_mean,c + Σ_k c_k · P_k,c`, with `P_mean,c = Σ_j m[c·128+j] L[j][c]`
//! and `P_k,c = Σ_j B_k[c·128+j] L[j][c]`.
//!
//! Projecting the lighting onto the basis once per lighting change ([`project_light`],
//! `3(K + 1)` dot products of length 128, computed in `f64`) is therefore exact, and each
//! voxel then costs `K` multiply-adds per channel ([`voxel_radiance`], in `f32`, summed
//! `k = 0, 1, …` like the spec's reconstruction). A user's map of any resolution, turned
//! by `world_from_env`, is first resampled into the asset's light texels with
//! [`project_envmap`] through `env_from_light = world_from_envᵀ · world_from_light`.
//!
//! No clamping anywhere: a truncated PCA may give slightly negative radiance, which is
//! kept so that a GPU mirror and the reference agree; images clamp when written as 8-bit.

use glam::DMat3;
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LT_DIM, LatLong, is_rotation, project_envmap, shade,
};
use nelf_format::{Asset, PcaModel};
use rayon::prelude::*;

use crate::error::RenderError;

/// Voxels per parallel work item in [`voxel_radiance`] (one brick).
const VOXELS_PER_TASK: usize = 512;

/// The lighting projected onto an asset's PCA basis: the radiance of voxel `v` with
/// coefficients `c_vk` is `mean_rgb + Σ_k c_vk · component_rgb[k]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectedLight {
    /// `P_mean,c`: the PCA mean shaded by the lighting.
    pub mean_rgb: [f32; 3],
    /// `P_k,c` for `k = 0..K`: each basis vector shaded by the lighting.
    pub component_rgb: Vec<[f32; 3]>,
}

impl ProjectedLight {
    /// Rank `K` of the projection.
    pub fn rank(&self) -> usize {
        self.component_rgb.len()
    }

    /// Radiance of a voxel with dequantized coefficients `coefficients` (first
    /// `min(len, K)` used): `mean_rgb + Σ_k c_k · component_rgb[k]` in `f32`, `k` ascending.
    pub fn radiance(&self, coefficients: &[f32]) -> [f32; 3] {
        let mut rgb = self.mean_rgb;
        for (c, p) in coefficients.iter().zip(&self.component_rgb) {
            for ch in 0..3 {
                rgb[ch] += c * p[ch];
            }
        }
        rgb
    }
}

/// Projects `env` — a lat-long map (any resolution) in the world frame, turned by
/// `world_from_env` (a rotation; identity = as stored) — into the asset's 8 × 16 light
/// texels with `project_envmap(env, world_from_envᵀ · world_from_light)`, then onto the
/// PCA mean and basis ([`project_light_texels`]).
pub fn project_light(
    pca: &PcaModel,
    world_from_light: DMat3,
    env: &LatLong,
    world_from_env: DMat3,
) -> Result<ProjectedLight, RenderError> {
    for (what, m) in [
        ("world_from_light", world_from_light),
        ("world_from_env", world_from_env),
    ] {
        if !is_rotation(m, 1e-5) {
            return Err(RenderError::NotARotation {
                what,
                matrix: m.to_cols_array(),
            });
        }
    }
    pca.validate()?;
    let light = project_envmap(env, world_from_env.transpose() * world_from_light)?;
    project_light_texels(pca, &light)
}

/// Projects an 8 × 16 map already in the asset's light frame onto the PCA mean and basis:
/// `P_c = Σ_j v[c·128 + j] · light[j][c]` for `v` the mean and each basis vector, in `f64`.
pub fn project_light_texels(pca: &PcaModel, light: &LatLong) -> Result<ProjectedLight, RenderError> {
    pca.validate()?;
    if light.width() != ENV_W || light.height() != ENV_H {
        return Err(RenderError::Convention(
            nelf_format::conventions::ConventionError::BadImageSize {
                width: light.width(),
                height: light.height(),
                len: ENV_TEXELS,
            },
        ));
    }
    let texels = light.texels();
    let shade_f64 = |v: &[f32]| -> [f32; 3] {
        std::array::from_fn(|c| {
            v[c * ENV_TEXELS..(c + 1) * ENV_TEXELS]
                .iter()
                .zip(texels)
                .map(|(&t, l)| f64::from(t) * f64::from(l[c]))
                .sum::<f64>() as f32
        })
    };
    Ok(ProjectedLight {
        mean_rgb: shade_f64(&pca.mean),
        component_rgb: (0..pca.rank()).map(|k| shade_f64(pca.component(k))).collect(),
    })
}

/// Per-voxel radiance of an asset under projected lighting, from its dequantized
/// coefficients, using the first `rank` components (default: all; clamped to the asset's
/// and the projection's rank). One entry per voxel, voxel order.
pub fn voxel_radiance(asset: &Asset, light: &ProjectedLight, rank: Option<usize>) -> Vec<[f32; 3]> {
    let stored_rank = asset.coefficients.rank();
    let used = rank.unwrap_or(stored_rank).min(stored_rank).min(light.rank());
    // A valid asset has exactly voxel_count × K coefficients; never read past what is there.
    let voxels = asset
        .voxel_count()
        .min(asset.coefficients.len() / stored_rank.max(1));
    let mut out = vec![light.mean_rgb; voxels];
    if used == 0 {
        return out;
    }
    out.par_chunks_mut(VOXELS_PER_TASK)
        .enumerate()
        .for_each(|(task, chunk)| {
            let mut coefficients = vec![0.0f32; stored_rank];
            for (i, rgb) in chunk.iter_mut().enumerate() {
                asset
                    .coefficients
                    .voxel_f32(task * VOXELS_PER_TASK + i, &mut coefficients);
                *rgb = light.radiance(&coefficients[..used]);
            }
        });
    out
}

/// Per-voxel radiance from raw light-transport vectors (`n × 384`, channel-major; a
/// trailing partial vector is ignored) under an 8 × 16 map already in the light frame:
/// [`shade`] per voxel, the unquantized reference. A map of another resolution is first
/// resampled with `project_envmap(light, I)`.
pub fn radiance_from_lt(lt: &[f32], light: &LatLong) -> Vec<[f32; 3]> {
    let resampled;
    let basis = if light.width() == ENV_W && light.height() == ENV_H {
        light
    } else {
        // The identity is a rotation, so this projection cannot fail.
        resampled = project_envmap(light, DMat3::IDENTITY)
            .unwrap_or_else(|_| LatLong::constant(ENV_W, ENV_H, [0.0; 3]));
        &resampled
    };
    lt.par_chunks_exact(LT_DIM).map(|t| shade(t, basis)).collect()
}
