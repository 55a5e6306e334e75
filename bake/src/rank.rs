//! Per-scene choice of the PCA rank `K` by rendered-image loss.
//!
//! The capture's own views (at reduced resolution) are rendered by the reference
//! renderer (`nelf-render`) under a fixed set of test environments: a constant
//! white map and four procedural maps (`nelf_scene::envgen`, [`TEST_ENVS`]: two
//! outdoor with a sun, one indoor, one studio), plus the capture's own lighting when
//! it is known (the pipeline adds it). For each
//! environment `e`, `I⁰_e` is the render of the **unquantized** grid (each voxel
//! shaded from its raw 384-vector) and `Iᴷ_e` that of the candidate (rank-`K` PCA,
//! quantized coefficients, exactly what the file will hold). Summing over views,
//! pixels and channels:
//!
//! * candidate error, relative to the signal: `m_K,e = Σ (Iᴷ_e − I⁰_e)² / Σ (I⁰_e)²`;
//! * baseline error `m₀`, the unquantized grid's own relative error against ground
//!   truth: measured against the capture's images under the capture's lighting,
//!   `m₀ = Σ w (I⁰ − image)² / Σ w image²` with `w` the mask (both at the reduced
//!   resolution), when the lighting is known; otherwise assumed from a reference
//!   signal-to-noise ratio, `m₀ = 10^(−SNR/10)`;
//! * **loss** `L_e(K) = 10 log₁₀((m₀ + m_K,e)/m₀)` dB: how much the grid's SNR
//!   against ground truth drops if the compression error adds to its own error
//!   independently (in expectation). The loss of `K` is the worst over `e`.
//!
//! The rank chosen is the smallest candidate in [`RANK_CANDIDATES`] (capped at the
//! data's numerical rank and the largest rank allowed) whose loss is at most the
//! target (0.1 dB by default); if none is, the largest candidate, flagged.
//!
//! Candidate images are not marched one by one: [`component_images`] renders each
//! view once with per-voxel features `[1, c_0 … c_{K−1}]` and every candidate image
//! is a `K`-term sum per pixel (rendering is linear in the radiance).

use glam::DMat3;
use nelf_format::Asset;
use nelf_format::conventions::{LT_DIM, LatLong, PinholeCamera, project_envmap, shade};
use nelf_render::{
    BrickGrid, Image, MarchSettings, project_light_texels, radiance_from_lt, render_features, render_volume,
};
use nelf_scene::envgen::{EnvFamily, EnvGenParams, procedural_envmap};
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};

/// Ranks tried, in increasing order.
pub const RANK_CANDIDATES: [usize; 12] = [1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64];
/// Families and seeds of the procedural test environments.
pub const TEST_ENVS: [(EnvFamily, u64); 4] = [
    (EnvFamily::Outdoor, 9001),
    (EnvFamily::Outdoor, 9002),
    (EnvFamily::Indoor, 9003),
    (EnvFamily::Studio, 9004),
];

/// One lighting the candidates are judged under.
#[derive(Debug, Clone, PartialEq)]
pub struct TestEnv {
    /// Name for the report (`constant`, `outdoor-9001`, …).
    pub name: String,
    /// The map, lat-long in the world frame, any resolution.
    pub map: LatLong,
}

/// The fixed test environments: a constant white map and one procedural map per
/// `(family, seed)` of [`TEST_ENVS`] (two outdoor maps with a sun, an indoor room,
/// a studio). The same for every scene, so ranks compare across scenes.
pub fn test_environments() -> Vec<TestEnv> {
    let mut envs = vec![TestEnv {
        name: "constant".into(),
        map: LatLong::constant(16, 8, [1.0; 3]),
    }];
    for (family, seed) in TEST_ENVS {
        let params = EnvGenParams {
            family: Some(family),
            ..EnvGenParams::default()
        };
        envs.push(TestEnv {
            name: format!("{}-{seed}", format!("{family:?}").to_lowercase()),
            map: procedural_envmap(seed, &params),
        });
    }
    envs
}

/// The camera for rendering `camera`'s view at `1/factor` of its resolution (whole
/// pixels; a remainder at the right and bottom is dropped), with the factor: the
/// smallest integer making the longer side at most `max_side`.
pub fn reduced_camera(camera: &PinholeCamera, max_side: u32) -> (PinholeCamera, u32) {
    let longest = camera.width.max(camera.height);
    let factor = longest.div_ceil(max_side.max(1)).max(1);
    let f = f64::from(factor);
    let reduced = PinholeCamera {
        width: (camera.width / factor).max(1),
        height: (camera.height / factor).max(1),
        fx: camera.fx / f,
        fy: camera.fy / f,
        cx: camera.cx / f,
        cy: camera.cy / f,
        ..*camera
    };
    (reduced, factor)
}

/// Box-filters a `width × height` image of `T` by `factor` (output `⌊w/f⌋ × ⌊h/f⌋`).
pub fn box_downsample<const C: usize>(
    values: &[[f32; C]],
    width: u32,
    height: u32,
    factor: u32,
) -> Vec<[f32; C]> {
    let f = factor.max(1) as usize;
    let (w, h) = (width as usize, height as usize);
    let (ow, oh) = ((w / f).max(1), (h / f).max(1));
    let mut out = vec![[0.0f32; C]; ow * oh];
    for (oy, row) in out.chunks_mut(ow).enumerate() {
        for (ox, o) in row.iter_mut().enumerate() {
            let mut acc = [0.0f64; C];
            let mut n = 0usize;
            for y in oy * f..((oy + 1) * f).min(h) {
                for x in ox * f..((ox + 1) * f).min(w) {
                    for c in 0..C {
                        acc[c] += f64::from(values[y * w + x][c]);
                    }
                    n += 1;
                }
            }
            *o = acc.map(|a| (a / n.max(1) as f64) as f32);
        }
    }
    out
}

/// What rank choice needs about the baked grid.
#[derive(Debug, Clone, Copy)]
pub struct RankScene<'a> {
    /// Kept bricks.
    pub grid: &'a BrickGrid,
    /// Density per voxel (1/m, as stored).
    pub density: &'a [f32],
    /// Cameras of the views to render (already reduced).
    pub views: &'a [PinholeCamera],
    /// Ray-marching settings.
    pub march: MarchSettings,
    /// Rotation from the light frame to the world.
    pub world_from_light: DMat3,
}

/// Per-voxel radiance of the unquantized grid under `light` (8 × 16, light frame):
/// voxels in `lt_voxels` shaded from their raw vectors, the others from `mean`.
pub fn unquantized_radiance(
    voxel_count: usize,
    lt_voxels: &[usize],
    lt: &[f32],
    mean: &[f32],
    light: &LatLong,
) -> Vec<[f32; 3]> {
    let mut out = vec![shade(mean, light); voxel_count];
    for (&v, rgb) in lt_voxels.iter().zip(radiance_from_lt(lt, light)) {
        out[v] = rgb;
    }
    out
}

fn render_all(scene: &RankScene<'_>, radiance: &[[f32; 3]]) -> Result<Vec<Image>> {
    scene
        .views
        .iter()
        .map(|cam| {
            Ok(render_volume(
                scene.grid,
                scene.density,
                radiance,
                cam,
                &scene.march,
            )?)
        })
        .collect()
}

/// The unquantized renders under one test environment.
#[derive(Debug, Clone)]
pub struct EnvReference {
    /// Environment name.
    pub name: String,
    /// The map in the asset's 8 × 16 light texels.
    pub light: LatLong,
    /// One render per view.
    pub images: Vec<Image>,
    /// `Σ (I⁰)²` over views, pixels, channels.
    pub signal: f64,
}

/// Projects `env` into the light frame's 8 × 16 texels.
pub fn light_texels(env: &LatLong, world_from_light: DMat3) -> Result<LatLong> {
    project_envmap(env, world_from_light).map_err(|e| BakeError::Settings(format!("lighting: {e}")))
}

/// Renders the unquantized grid under every test environment.
pub fn reference_renders(
    scene: &RankScene<'_>,
    envs: &[TestEnv],
    lt_voxels: &[usize],
    lt: &[f32],
    mean: &[f32],
) -> Result<Vec<EnvReference>> {
    envs.iter()
        .map(|env| {
            let light = light_texels(&env.map, scene.world_from_light)?;
            let radiance = unquantized_radiance(scene.grid.voxel_count(), lt_voxels, lt, mean, &light);
            let images = render_all(scene, &radiance)?;
            let signal = images
                .iter()
                .flat_map(|im| im.rgb.iter())
                .map(|p| p.iter().map(|&x| f64::from(x) * f64::from(x)).sum::<f64>())
                .sum();
            Ok(EnvReference {
                name: env.name.clone(),
                light,
                images,
                signal,
            })
        })
        .collect()
}

/// `m₀` against ground-truth images: `Σ w (I⁰ − image)² / Σ w image²` over views,
/// with renders of the unquantized grid under `light` (8 × 16, light frame) and
/// `images`/`weights` already at the views' resolution.
pub fn relative_error_vs_images(
    scene: &RankScene<'_>,
    radiance: &[[f32; 3]],
    images: &[Vec<[f32; 3]>],
    weights: &[Vec<f32>],
) -> Result<f64> {
    let renders = render_all(scene, radiance)?;
    let (mut err, mut sig) = (0.0f64, 0.0f64);
    for ((r, img), w) in renders.iter().zip(images).zip(weights) {
        if r.rgb.len() != img.len() || img.len() != w.len() {
            return Err(BakeError::Settings(format!(
                "reference image of {} pixels for a {}×{} render",
                img.len(),
                r.width,
                r.height
            )));
        }
        for ((a, b), &wp) in r.rgb.iter().zip(img).zip(w) {
            let wp = f64::from(wp);
            for c in 0..3 {
                err += wp * (f64::from(a[c]) - f64::from(b[c])).powi(2);
                sig += wp * f64::from(b[c]).powi(2);
            }
        }
    }
    if sig <= 0.0 || sig.is_nan() {
        return Err(BakeError::Settings(
            "the reference images are black under their masks".into(),
        ));
    }
    Ok(err / sig)
}

/// The loss of one candidate rank.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateLoss {
    /// Rank `K`.
    pub rank: usize,
    /// Worst loss over the test environments, dB.
    pub loss_db: f64,
    /// Loss per test environment, dB (same order as the environments).
    pub per_env_db: Vec<f64>,
    /// Energy kept by the first `K` components.
    pub energy_kept: f64,
}

/// Loss in dB from relative errors: `10 log₁₀((m₀ + m)/m₀)`.
pub fn loss_db(m0: f64, m: f64) -> f64 {
    10.0 * ((m0 + m) / m0).log10()
}

/// The asset's stored coefficients rendered once per view as features `[1, c_0 … c_{K−1}]`
/// (`nelf_render::render_features`): a render is linear in the radiance, so the
/// image of rank `r` under any lighting is `F_0 · P_mean + Σ_{k<r} F_{k+1} · P_k`
/// per pixel (`P` the lighting projected onto the basis), with no further marching.
#[derive(Debug, Clone)]
pub struct ComponentImages {
    /// Floats per pixel, `K + 1`.
    pub dim: usize,
    /// Per view, `pixels × dim`, row-major.
    pub views: Vec<Vec<f32>>,
}

/// Renders the features of every view of `scene` (see [`ComponentImages`]).
pub fn component_images(scene: &RankScene<'_>, asset: &Asset) -> Result<ComponentImages> {
    let rank = asset.coefficients.rank();
    let dim = rank + 1;
    let voxels = scene.grid.voxel_count();
    let mut features = vec![0.0f32; voxels * dim];
    for (v, f) in features.chunks_exact_mut(dim).enumerate() {
        f[0] = 1.0;
        asset.coefficients.voxel_f32(v, &mut f[1..]);
    }
    let views = scene
        .views
        .iter()
        .map(|cam| {
            Ok(render_features(
                scene.grid,
                scene.density,
                &features,
                dim,
                cam,
                &scene.march,
            )?)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(ComponentImages { dim, views })
}

/// Loss (dB) of keeping the first `rank` components of `asset` (whose features
/// `components` holds), per test environment: `L_e(K)` of the module docs, with the
/// candidate images formed from `components`.
pub fn candidate_loss(
    references: &[EnvReference],
    components: &ComponentImages,
    asset: &Asset,
    rank: usize,
    m0: f64,
) -> Result<Vec<f64>> {
    let used = rank.min(components.dim - 1);
    references
        .iter()
        .map(|r| {
            let light = project_light_texels(&asset.pca, &r.light)?;
            let mut err = 0.0f64;
            for (features, reference) in components.views.iter().zip(&r.images) {
                for (f, truth) in features.chunks_exact(components.dim).zip(&reference.rgb) {
                    for (c, &t) in truth.iter().enumerate() {
                        let mut value = f[0] * light.mean_rgb[c];
                        for (fk, p) in f[1..=used].iter().zip(&light.component_rgb) {
                            value += fk * p[c];
                        }
                        err += (f64::from(value) - f64::from(t)).powi(2);
                    }
                }
            }
            let m = if r.signal > 0.0 {
                err / r.signal
            } else if err > 0.0 {
                f64::INFINITY
            } else {
                0.0
            };
            Ok(loss_db(m0, m))
        })
        .collect()
}

/// The ranks to try: [`RANK_CANDIDATES`] up to `max_rank` and the data's `data_rank`
/// (at least rank 1, and `max_rank` itself when it is not a listed candidate).
pub fn candidate_ranks(max_rank: usize, data_rank: usize) -> Vec<usize> {
    let cap = max_rank.min(data_rank).clamp(1, LT_DIM);
    let mut out: Vec<usize> = RANK_CANDIDATES.iter().copied().filter(|&k| k <= cap).collect();
    if out.last() != Some(&cap) {
        out.push(cap);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn candidates_respect_caps() {
        assert_eq!(candidate_ranks(64, 384), RANK_CANDIDATES.to_vec());
        assert_eq!(candidate_ranks(64, 3), vec![1, 2, 3]);
        assert_eq!(candidate_ranks(10, 384), vec![1, 2, 3, 4, 6, 8, 10]);
        assert_eq!(candidate_ranks(64, 0), vec![1]);
    }

    #[test]
    fn loss_is_zero_for_no_error_and_grows() {
        assert_eq!(loss_db(1e-3, 0.0), 0.0);
        assert!((loss_db(1e-3, 1e-3) - 10.0 * 2f64.log10()).abs() < 1e-12);
        assert!(loss_db(1e-3, 1e-5) < loss_db(1e-3, 1e-4));
    }

    #[test]
    fn reduced_camera_matches_box_filter() {
        let cam = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO, DVec3::Y, 250, 100, 0.7);
        let (r, f) = reduced_camera(&cam, 64);
        assert_eq!((f, r.width, r.height), (4, 62, 25));
        // A point lands in the low-resolution pixel that covers its high-resolution pixel.
        let p = DVec3::new(0.03, -0.02, 0.1);
        let hi = cam.project(p).unwrap();
        let lo = r.project(p).unwrap();
        assert!((hi / 4.0 - lo).length() < 1e-9);
        let img: Vec<[f32; 1]> = (0..8).map(|i| [i as f32]).collect();
        assert_eq!(box_downsample(&img, 4, 2, 2), vec![[2.5], [4.5]]);
    }
}
