//! View-dependent relighting (format 1.2, SPEC.md §6 `VDEP`/`VCOF`): the radiance a
//! voxel sends toward an eye at `e`.
//!
//! A view-dependent asset's transport is `T(x, ω) = T_pca(x) + Σ_j Y_j(ω) Σ_i d_ji(x) V_i`
//! ([`nelf_format::ViewDependence`]). Shading is linear in `T`, so as for the PCA part
//! ([`crate::light`]) the lighting is projected once per lighting change onto the view
//! basis, `P^v_i,c = Σ_k V_i[c·128 + k] L[k][c]` ([`project_view_light`]), each voxel's
//! `J` lobe colours `c_j = Σ_i d_ji P^v_i` follow ([`voxel_lobe_radiance`], also once
//! per lighting change), and a camera then costs `J` multiply-adds per channel per voxel:
//!
//! `radiance(x) = radiance_pca(x) + Σ_j Y_j(ω_x) c_j(x)`, `ω_x = normalize(e − x)`
//!
//! with `x` the voxel's centre ([`radiance_seen_from`]). The direction is taken per voxel,
//! not per sample: trilinear interpolation then blends radiances as for any asset, and a
//! GPU needs one per-voxel pass per camera move and no extra fetch per sample. Neighbouring
//! voxels' directions differ by `voxel / distance` (under 0.3° for a 2 mm voxel at 0.5 m).

use glam::{DMat3, DVec3};
use nelf_format::conventions::{LatLong, is_rotation, project_envmap};
use nelf_format::{Asset, PcaModel, ViewDependence};
use rayon::prelude::*;

use crate::error::RenderError;
use crate::light::project_light_texels;

/// Voxels per parallel work item (one brick).
const VOXELS_PER_TASK: usize = 512;

/// The lighting `env` (turned by `world_from_env`) projected onto the view basis of
/// `view`: `P^v_i` (rgb) for every basis vector `i`, in `f64` summed, as the PCA part's.
pub fn project_view_light(
    view: &ViewDependence,
    world_from_light: DMat3,
    env: &LatLong,
    world_from_env: DMat3,
) -> Result<Vec<[f32; 3]>, RenderError> {
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
    let light = project_envmap(env, world_from_env.transpose() * world_from_light)?;
    project_view_light_texels(view, &light)
}

/// [`project_view_light`] for an 8 × 16 map already in the asset's light frame.
pub fn project_view_light_texels(
    view: &ViewDependence,
    light: &LatLong,
) -> Result<Vec<[f32; 3]>, RenderError> {
    // The view basis has no mean: project it as a PCA model with a zero mean.
    let as_pca = PcaModel {
        mean: vec![0.0; nelf_format::conventions::LT_DIM],
        basis: view.basis.clone(),
    };
    Ok(project_light_texels(&as_pca, light)?.component_rgb)
}

/// Each voxel's `J` lobe colours `c_j = Σ_i d_ji P^v_i` (`f32`, `i` ascending), voxel-major
/// (`voxels × J`).
pub fn voxel_lobe_radiance(view: &ViewDependence, view_light: &[[f32; 3]], voxels: usize) -> Vec<[f32; 3]> {
    let lobes = view.lobe_count();
    let rank = view.rank().min(view_light.len());
    let per_voxel = view.coefficients.rank();
    let voxels = voxels.min(view.coefficients.len() / per_voxel.max(1));
    let mut out = vec![[0.0f32; 3]; voxels * lobes];
    if lobes == 0 {
        return out;
    }
    out.par_chunks_mut(VOXELS_PER_TASK * lobes)
        .enumerate()
        .for_each(|(task, chunk)| {
            let mut d = vec![0.0f32; per_voxel];
            for (i, voxel_lobes) in chunk.chunks_exact_mut(lobes).enumerate() {
                view.coefficients.voxel_f32(task * VOXELS_PER_TASK + i, &mut d);
                for (j, rgb) in voxel_lobes.iter_mut().enumerate() {
                    for (k, p) in view_light[..rank].iter().enumerate() {
                        let c = d[j * view.rank() + k];
                        for ch in 0..3 {
                            rgb[ch] += c * p[ch];
                        }
                    }
                }
            }
        });
    out
}

/// Per-voxel radiance toward an eye at `eye` (metres, world): `base[v] + Σ_j Y_j(ω_v)
/// lobes[v·J + j]` with `ω_v = normalize(eye − centre_v)` in `f32` (the difference taken in
/// `f64`). `base` is the PCA part's radiance ([`crate::voxel_radiance`]); an asset without
/// view dependence gets `base` back.
pub fn radiance_seen_from(asset: &Asset, base: &[[f32; 3]], lobes: &[[f32; 3]], eye: DVec3) -> Vec<[f32; 3]> {
    let Some(view) = &asset.view else {
        return base.to_vec();
    };
    let count = view.lobe_count();
    let mut out = base.to_vec();
    if count == 0 || lobes.len() < base.len() * count {
        return out;
    }
    out.par_chunks_mut(VOXELS_PER_TASK)
        .enumerate()
        .for_each(|(task, chunk)| {
            for (i, rgb) in chunk.iter_mut().enumerate() {
                let v = task * VOXELS_PER_TASK + i;
                let omega = (eye - asset.voxel_position_m(v)).as_vec3().to_array();
                for (y, c) in view
                    .lobe_values(omega)
                    .iter()
                    .zip(&lobes[v * count..(v + 1) * count])
                {
                    for ch in 0..3 {
                        rgb[ch] += y * c[ch];
                    }
                }
            }
        });
    out
}
