//! Lighting for a reconstruction: the environment map the capture names
//! (`cameras.json`'s `envmap`, in the photographs' units), else an estimate whose
//! scale (and colour) relative to the photographs is unknown: a fit of the
//! photographs' shading on the reconstructed surface ([`fit_lighting`], the
//! default) or the NeLF network's estimate ([`crate::light::estimate_light`]). All
//! are 8 × 16 maps in the world frame (`nelf_format::conventions::project_envmap`,
//! the identity rotation), the frame the reconstructed surface is traced in.

use std::path::Path;
use std::time::Instant;

use glam::DMat3;
use nalgebra::{DMatrix, DVector};
use nelf_bake::LoadedCapture;
use nelf_format::conventions::{ENV_H, ENV_TEXELS, ENV_W, LatLong, project_envmap};
use rayon::prelude::*;
use serde::Serialize;

use crate::config::{PhotoSettings, UnnamedLighting};
use crate::error::{Result, invalid};
use crate::light::{LightRequest, estimate_light};
use crate::network::capture_source_lighting;
use crate::photo::reflectance::Observations;

/// Where the lighting came from.
#[derive(Debug, Clone, Serialize)]
pub struct LightingReport {
    /// Whether the capture named it (else it was estimated).
    pub named: bool,
    /// The map's file, the weights that estimated it, or `fit`.
    pub source: String,
    /// Mean radiance of the 8 × 16 map (`Σ Ω L / 4π`, mean over channels).
    pub mean_radiance: f64,
    /// The fit, when the lighting was fitted.
    pub fit: Option<LightingFitReport>,
    /// Seconds.
    pub seconds: f64,
}

/// The capture's lighting as an 8 × 16 world-frame map (see the module
/// documentation): the map it names, else estimated as `settings.photo_lighting` says from the
/// photographs (`observations` of the reconstructed surface for the fit, `weights`
/// for the network).
pub fn capture_lighting(
    capture: &LoadedCapture,
    weights: Option<&Path>,
    settings: &PhotoSettings,
    observations: &Observations,
    triangles: &[[u32; 3]],
) -> Result<(LatLong, LightingReport)> {
    let start = Instant::now();
    let named = capture_source_lighting(capture.description(), &capture.dir)?;
    let mut fit = None;
    let (basis, source) = if let Some(map) = &named {
        let path = capture.source_envmap_path();
        (
            project_envmap(map, DMat3::IDENTITY)?,
            path.map_or_else(String::new, |p| p.display().to_string()),
        )
    } else {
        match settings.photo_lighting {
            UnnamedLighting::Fit => {
                let fit_settings = LightingFitSettings {
                    region_step: settings.photo_light_region_step,
                    ..LightingFitSettings::default()
                };
                let (map, report) = fit_lighting(observations, &fit_settings, triangles)?;
                fit = Some(report);
                (map, "fit".to_string())
            }
            UnnamedLighting::Network => {
                let estimate = estimate_light(&LightRequest {
                    capture_dir: &capture.dir,
                    weights,
                    width: 64,
                    light_frame: false,
                })?;
                (
                    project_envmap(&estimate.map, DMat3::IDENTITY)?,
                    estimate.weights_name,
                )
            }
        }
    };
    let report = LightingReport {
        named: named.is_some(),
        source,
        mean_radiance: basis.mean_radiance(),
        fit,
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((basis, report))
}

/// How the lighting of a capture that names none is fitted ([`fit_lighting`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightingFitSettings {
    /// Alternations between the albedo and the lighting.
    pub iterations: usize,
    /// Materials: the seen vertices are grouped by the chromaticity of their observed
    /// colour (k-means) into this many groups, each given one albedo while the
    /// lighting is fitted. Shading changes a colour's brightness, not its
    /// chromaticity (under a light of one colour); skin, hair, lips and eyes differ
    /// in chromaticity.
    pub materials: usize,
    /// Weight of the lighting's smoothness between neighbouring texels, relative to
    /// the data's mean diagonal.
    pub smoothness: f64,
    /// At most this many vertices in each lighting solve (evenly spaced among those
    /// seen).
    pub max_vertices: usize,
    /// Material groups as regions of the surface instead of chromaticity clusters:
    /// neighbouring seen vertices are one region where their colours differ by
    /// less than this in log luminance (and [`MIN_CHROMA_SEPARATION`] in
    /// chromaticity) — shading changes smoothly between neighbours, albedo at an
    /// edge. 0: chromaticity clusters ([`Self::materials`]).
    pub region_step: f64,
    /// Regions with fewer seen vertices are left out of the fit.
    pub region_min_vertices: usize,
    /// The kept regions must hold at least this share of the seen vertices, else
    /// the fit uses chromaticity clusters: a light fitted to a few regions is
    /// free in the directions only the rest face (a finely textured surface).
    pub region_min_coverage: f64,
}

impl Default for LightingFitSettings {
    fn default() -> Self {
        Self {
            iterations: 8,
            materials: 8,
            smoothness: 0.01,
            max_vertices: 12_000,
            region_step: 0.0,
            region_min_vertices: 200,
            region_min_coverage: 0.5,
        }
    }
}

/// What the lighting fit did.
#[derive(Debug, Clone, Serialize)]
pub struct LightingFitReport {
    /// Vertices in each solve.
    pub vertices: usize,
    /// `‖c − a·S(L)‖ / ‖c‖` over them after each alternation (a smooth albedo times the
    /// shading against the photographs' colours).
    pub relative_residual: Vec<f64>,
    /// Texels held at zero radiance (the unconstrained solve wanted them negative), per channel.
    pub texels_at_zero: [usize; 3],
    /// Seen vertices per material group.
    pub material_vertices: Vec<usize>,
    /// Each group's albedo (in the fitted light's units) after the last alternation.
    pub material_albedo: Vec<[f32; 3]>,
    /// Share of the seen vertices in regions large enough to fit to (`None`:
    /// regions not asked for); the groups are regions when it reaches
    /// [`LightingFitSettings::region_min_coverage`], else chromaticity clusters.
    pub region_coverage: Option<f64>,
}

/// Fits an 8 × 16 lighting to `observations` of a surface, for a capture that
/// names none.
///
/// The photographs' colours are `c_i = a_i ⊙ (T_i · L)` with `T_i` the white
/// transport (direct light with the surface's own shadows) and `a_i` the albedo; a
/// colour alone cannot tell albedo from shading, but shading changes with the
/// normal and the shadows while skin, hair and lips are each nearly one colour.
/// So, alternately:
/// 1. one albedo per material group (regions of the surface without an albedo
///    edge, [`LightingFitSettings::region_step`], or vertices of like chromaticity,
///    [`LightingFitSettings::materials`]), `a_g = Σ_{i∈g} c_i S_i / Σ_{i∈g} S_i²` with `S_i = T_i · L`
///    (least squares), so that whatever varies within a group must be shading;
/// 2. per channel, `L = argmin Σ_i (c_i − a_i T_i·L)² + λ Σ_{k~k'} (L_k − L_k')²`
///    subject to `L ≥ 0` (normal equations, 128 × 128, Cholesky; texels the solve
///    wants negative are held at zero and the rest solved again);
/// 3. `L` is scaled to mean radiance 1 with equal mean in each channel (grey world):
///    neither the exposure nor the light's colour can be told from the albedo's, so
///    the albedo takes the colour and the asset is scored after one gain.
///
/// Starts from a uniform white light.
pub fn fit_lighting(
    observations: &Observations,
    settings: &LightingFitSettings,
    triangles: &[[u32; 3]],
) -> Result<(LatLong, LightingFitReport)> {
    let mut seen: Vec<usize> = (0..observations.colour.len())
        .filter(|&i| observations.colour[i].is_some())
        .collect();
    if seen.is_empty() {
        return Err(invalid("no view sees the reconstructed surface".to_string()));
    }
    let colour = |i: usize| observations.colour[i].unwrap_or([0.0; 3]);
    let regions = (settings.region_step > 0.0 && !triangles.is_empty()).then(|| {
        albedo_regions(
            observations,
            triangles,
            settings.region_step,
            settings.region_min_vertices,
        )
    });
    let region_coverage = regions
        .as_ref()
        .map(|(_, sizes)| sizes.iter().sum::<usize>() as f64 / seen.len() as f64);
    let regions =
        regions.filter(|_| region_coverage.is_some_and(|c| c >= settings.region_min_coverage.max(1e-9)));
    // Regions where the surface has them; else (regions too small or too few: a
    // surface of fine texture, or regions not asked for) chromaticity clusters.
    let (group, material_vertices) = if let Some((group, sizes)) = regions {
        seen.retain(|&i| group[i] != usize::MAX);
        (group, sizes)
    } else {
        let chroma: Vec<[f32; 2]> = seen.iter().map(|&i| chromaticity(colour(i))).collect();
        let (group_of_seen, sizes) = chroma_groups(&chroma, settings.materials.max(1));
        let mut group = vec![usize::MAX; observations.colour.len()];
        for (k, &i) in seen.iter().enumerate() {
            group[i] = group_of_seen[k];
        }
        (group, sizes)
    };
    let groups = material_vertices.len();
    let stride = seen.len().div_ceil(settings.max_vertices.max(1));
    let sample: Vec<usize> = seen.iter().copied().step_by(stride.max(1)).collect();
    let smoothness = smoothness_matrix();
    let mut light = LatLong::constant(ENV_W, ENV_H, [1.0; 3]);
    let mut residuals = Vec::new();
    let mut at_zero = [0usize; 3];
    let mut material_albedo = Vec::new();
    for _ in 0..settings.iterations.max(1) {
        // 1. One albedo per material group under the current light.
        let mut sums = vec![([0.0f64; 3], [0.0f64; 3]); groups];
        for &i in &seen {
            let shading = observations.shading(i, &light);
            let c = colour(i);
            let (cs, ss) = &mut sums[group[i]];
            for ch in 0..3 {
                cs[ch] += f64::from(c[ch]) * f64::from(shading[ch]);
                ss[ch] += f64::from(shading[ch]).powi(2);
            }
        }
        let group_albedo: Vec<[f32; 3]> = sums
            .iter()
            .map(|(cs, ss)| std::array::from_fn(|ch| (cs[ch] / ss[ch].max(1e-30)) as f32))
            .collect();
        material_albedo.clone_from(&group_albedo);
        let albedo: Vec<[f32; 3]> = group
            .iter()
            .map(|&g| {
                if g == usize::MAX {
                    [0.0; 3]
                } else {
                    group_albedo[g]
                }
            })
            .collect();
        // 2. The light per channel, given the albedo.
        let mut texels = vec![[0.0f32; 3]; ENV_TEXELS];
        for ch in 0..3 {
            let (ata, atb) = sample
                .par_iter()
                .fold(
                    || (vec![0.0f64; ENV_TEXELS * ENV_TEXELS], vec![0.0f64; ENV_TEXELS]),
                    |(mut ata, mut atb), &i| {
                        let a = f64::from(albedo[i][ch]);
                        let c = f64::from(colour(i)[ch]);
                        let t = &observations.transport[i];
                        for k in 0..ENV_TEXELS {
                            let tk = a * f64::from(t[k]);
                            if tk == 0.0 {
                                continue;
                            }
                            atb[k] += tk * c;
                            let row = &mut ata[k * ENV_TEXELS..(k + 1) * ENV_TEXELS];
                            for (m, r) in row.iter_mut().enumerate() {
                                *r += tk * a * f64::from(t[m]);
                            }
                        }
                        (ata, atb)
                    },
                )
                .reduce(
                    || (vec![0.0f64; ENV_TEXELS * ENV_TEXELS], vec![0.0f64; ENV_TEXELS]),
                    |(mut a1, mut b1), (a2, b2)| {
                        a1.iter_mut().zip(&a2).for_each(|(x, y)| *x += y);
                        b1.iter_mut().zip(&b2).for_each(|(x, y)| *x += y);
                        (a1, b1)
                    },
                );
            let ata = DMatrix::from_row_slice(ENV_TEXELS, ENV_TEXELS, &ata);
            let scale = ata.trace() / ENV_TEXELS as f64;
            let system = &ata
                + &smoothness * (settings.smoothness * scale)
                + DMatrix::identity(ENV_TEXELS, ENV_TEXELS) * (1e-6 * scale.max(1e-30));
            let solution = nonnegative_solve(&system, &DVector::from_vec(atb));
            at_zero[ch] = solution.iter().filter(|&&v| v <= 0.0).count();
            for (k, v) in solution.iter().enumerate() {
                texels[k][ch] = *v as f32;
            }
        }
        // 3. Grey world, mean radiance 1.
        let mut fitted = LatLong::new(ENV_W, ENV_H, texels).map_err(|e| invalid(e.to_string()))?;
        let integral = fitted.integral();
        let mean = (integral[0] + integral[1] + integral[2]) / 3.0;
        if !(mean.is_finite() && mean > 0.0) {
            return Err(invalid(
                "the lighting fit found no light that explains the photographs".to_string(),
            ));
        }
        for t in fitted.texels_mut() {
            for ch in 0..3 {
                let channel = integral[ch].max(1e-12 * mean);
                t[ch] = (f64::from(t[ch]) * 4.0 * std::f64::consts::PI / channel) as f32;
            }
        }
        light = fitted;
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for &i in &sample {
            let s = observations.shading(i, &light);
            let c = colour(i);
            for ch in 0..3 {
                num += f64::from(c[ch] - albedo[i][ch] * s[ch]).powi(2);
                den += f64::from(c[ch]).powi(2);
            }
        }
        // The albedo was fitted to the previous light; the residual is that of
        // the pair, up to the grey-world scale (which the albedo absorbs next round).
        residuals.push((num / den.max(1e-30)).sqrt());
    }
    Ok((
        light,
        LightingFitReport {
            vertices: sample.len(),
            relative_residual: residuals,
            texels_at_zero: at_zero,
            material_vertices,
            material_albedo,
            region_coverage,
        },
    ))
}

/// Regions of like albedo on the surface (see [`LightingFitSettings::region_step`]):
/// each vertex's region (`usize::MAX` for unseen vertices and regions smaller than
/// `min_vertices`) and the kept regions' sizes. Union-find over the triangles'
/// edges; deterministic.
pub(crate) fn albedo_regions(
    observations: &Observations,
    triangles: &[[u32; 3]],
    step: f64,
    min_vertices: usize,
) -> (Vec<usize>, Vec<usize>) {
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let n = observations.colour.len();
    let mut parent: Vec<usize> = (0..n).collect();
    let describe = |i: usize| {
        observations
            .colour
            .get(i)
            .copied()
            .flatten()
            .map(|c| (f64::from((c[0] + c[1] + c[2]).max(1e-6)).ln(), chromaticity(c)))
    };
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (a, b) = (a as usize, b as usize);
            if a >= n || b >= n {
                continue;
            }
            let (Some((la, ca)), Some((lb, cb))) = (describe(a), describe(b)) else {
                continue;
            };
            let chroma = ((ca[0] - cb[0]).powi(2) + (ca[1] - cb[1]).powi(2)).sqrt();
            if (la - lb).abs() < step && chroma < MIN_CHROMA_SEPARATION {
                let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                if ra != rb {
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
    }
    // Each seen vertex's region, and the regions' sizes.
    let roots: Vec<Option<usize>> = (0..n)
        .map(|i| observations.colour[i].is_some().then(|| root(&mut parent, i)))
        .collect();
    let mut size = vec![0usize; n];
    for r in roots.iter().flatten() {
        size[*r] += 1;
    }
    let mut id = vec![usize::MAX; n];
    let mut sizes = Vec::new();
    let mut group = vec![usize::MAX; n];
    for (g, r) in group.iter_mut().zip(&roots) {
        let Some(r) = *r else { continue };
        if size[r] < min_vertices.max(1) {
            continue;
        }
        if id[r] == usize::MAX {
            id[r] = sizes.len();
            sizes.push(size[r]);
        }
        *g = id[r];
    }
    (group, sizes)
}

/// A colour's chromaticity `(r, g) / (r + g + b)`.
fn chromaticity(c: [f32; 3]) -> [f32; 2] {
    let sum = (c[0] + c[1] + c[2]).max(1e-6);
    [c[0] / sum, c[1] / sum]
}

/// Chromaticities closer than this are one material.
const MIN_CHROMA_SEPARATION: f32 = 0.02;

/// Groups 2-D chromaticities by k-means (Lloyd, 30 rounds; the first centre the
/// mean, each next the point farthest from the centres so far while it is farther
/// than [`MIN_CHROMA_SEPARATION`]: deterministic);
/// returns each point's group and the groups' sizes (empty groups dropped).
fn chroma_groups(points: &[[f32; 2]], k: usize) -> (Vec<usize>, Vec<usize>) {
    let dist2 = |a: &[f32; 2], b: &[f32; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let n = points.len() as f32;
    let mut centres = vec![[
        points.iter().map(|p| p[0]).sum::<f32>() / n,
        points.iter().map(|p| p[1]).sum::<f32>() / n,
    ]];
    while centres.len() < k {
        let farthest = points
            .iter()
            .map(|p| centres.iter().map(|c| dist2(p, c)).fold(f32::INFINITY, f32::min))
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match farthest {
            Some((i, d)) if d > MIN_CHROMA_SEPARATION * MIN_CHROMA_SEPARATION => centres.push(points[i]),
            _ => break,
        }
    }
    let nearest = |p: &[f32; 2], centres: &[[f32; 2]]| {
        (0..centres.len())
            .min_by(|&a, &b| dist2(p, &centres[a]).total_cmp(&dist2(p, &centres[b])))
            .unwrap_or(0)
    };
    let mut assignment = vec![0usize; points.len()];
    for _ in 0..30 {
        assignment = points.par_iter().map(|p| nearest(p, &centres)).collect();
        let mut sums = vec![([0.0f64; 2], 0usize); centres.len()];
        for (p, &g) in points.iter().zip(&assignment) {
            sums[g].0[0] += f64::from(p[0]);
            sums[g].0[1] += f64::from(p[1]);
            sums[g].1 += 1;
        }
        for (c, (s, count)) in centres.iter_mut().zip(&sums) {
            if *count > 0 {
                *c = [(s[0] / *count as f64) as f32, (s[1] / *count as f64) as f32];
            }
        }
    }
    // Renumber without empty groups.
    let mut sizes = vec![0usize; centres.len()];
    for &g in &assignment {
        sizes[g] += 1;
    }
    let mut renumber = vec![usize::MAX; centres.len()];
    let mut kept = Vec::new();
    for (g, &size) in sizes.iter().enumerate() {
        if size > 0 {
            renumber[g] = kept.len();
            kept.push(size);
        }
    }
    (assignment.iter().map(|&g| renumber[g]).collect(), kept)
}

/// `DᵀD` for the differences between texels that share an edge (azimuth wraps).
fn smoothness_matrix() -> DMatrix<f64> {
    let mut m = DMatrix::zeros(ENV_TEXELS, ENV_TEXELS);
    let mut pair = |a: usize, b: usize| {
        m[(a, a)] += 1.0;
        m[(b, b)] += 1.0;
        m[(a, b)] -= 1.0;
        m[(b, a)] -= 1.0;
    };
    for row in 0..ENV_H {
        for col in 0..ENV_W {
            let k = row * ENV_W + col;
            pair(k, row * ENV_W + (col + 1) % ENV_W);
            if row + 1 < ENV_H {
                pair(k, (row + 1) * ENV_W + col);
            }
        }
    }
    m
}

/// `argmin ‖A x − b‖`-style solve of the symmetric positive definite `system · x =
/// rhs` with `x ≥ 0`: solved, the negative entries held at zero, the rest solved
/// again (until none is negative, at most `n` rounds).
fn nonnegative_solve(system: &DMatrix<f64>, rhs: &DVector<f64>) -> Vec<f64> {
    let n = rhs.len();
    let mut free: Vec<usize> = (0..n).collect();
    let mut x = vec![0.0f64; n];
    for _ in 0..n {
        let sub = DMatrix::from_fn(free.len(), free.len(), |r, c| system[(free[r], free[c])]);
        let sub_rhs = DVector::from_fn(free.len(), |r, _| rhs[free[r]]);
        let Some(solution) = sub.cholesky().map(|c| c.solve(&sub_rhs)) else {
            break;
        };
        x.fill(0.0);
        for (r, &k) in free.iter().enumerate() {
            x[k] = solution[r];
        }
        let before = free.len();
        free.retain(|&k| x[k] > 0.0);
        if free.len() == before || free.is_empty() {
            break;
        }
    }
    x.iter().map(|v| v.max(0.0)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::test_support::{convex_observations, sun_and_sky, texel_direction};
    use glam::DVec3;
    use nelf_format::conventions::{direction, texel_solid_angle};

    /// The fitted light's brightness-weighted direction, degrees from texel `sun`'s.
    fn centre_angle_deg(fitted: &LatLong, sun: usize) -> f64 {
        let mut mean = DVec3::ZERO;
        for (k, t) in fitted.texels().iter().enumerate() {
            mean += texel_direction(k)
                * f64::from(t[0] + t[1] + t[2])
                * texel_solid_angle(k / ENV_W, ENV_H, ENV_W);
        }
        mean.normalize().dot(texel_direction(sun)).acos().to_degrees()
    }

    #[test]
    fn regions_tell_a_dark_material_of_the_same_hue_from_shading() {
        // A latitude-longitude grid over most of a unit sphere (convex, no shadows),
        // triangulated; skin, with a band of hair of the same hue five times
        // darker from pole to pole (no chromaticity tells them apart), lit by a
        // sun and a dim sky.
        let (rows, cols) = (40usize, 80usize);
        let sun = 2 * ENV_W + 12;
        let points = (0..rows).flat_map(|i| {
            (0..cols).map(move |j| {
                let theta = std::f64::consts::PI * (i as f64 + 0.5) / rows as f64 * 0.8;
                let phi = std::f64::consts::TAU * j as f64 / cols as f64;
                let albedo = if (20..50).contains(&j) {
                    [0.12, 0.08, 0.06]
                } else {
                    [0.6, 0.4, 0.3]
                };
                (direction(theta, phi), albedo)
            })
        });
        let observations = convex_observations(points, &sun_and_sky(sun));
        let mut triangles = Vec::new();
        for i in 0..rows - 1 {
            for j in 0..cols {
                let v = |i: usize, j: usize| (i * cols + j % cols) as u32;
                triangles.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                triangles.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        let regions = LightingFitSettings {
            region_step: 0.05,
            region_min_vertices: 50,
            ..LightingFitSettings::default()
        };
        let (fitted, report) = fit_lighting(&observations, &regions, &triangles).expect("a fit");
        // At least the two materials (steep shading splits a material too).
        assert!(report.material_vertices.len() >= 2, "{report:?}");
        let angle = centre_angle_deg(&fitted, sun);
        assert!(
            angle < 20.0,
            "with regions the fitted light's centre is {angle}° from the sun"
        );
        // The alternation explains the photographs (8 rounds leave a few per cent).
        let residual = &report.relative_residual;
        assert!(
            residual[residual.len() - 1] < 0.5 * residual[0] && residual[residual.len() - 1] < 0.1,
            "{residual:?}"
        );
        // Chromaticity clusters put both materials in one group, whose one albedo
        // cannot explain the photographs.
        let (_, report) =
            fit_lighting(&observations, &LightingFitSettings::default(), &triangles).expect("a fit");
        assert_eq!(report.material_vertices.len(), 1, "{report:?}");
        let clustered_residual = report.relative_residual.last().copied().unwrap_or(0.0);
        assert!(
            clustered_residual > 2.0 * residual[residual.len() - 1],
            "chromaticity clusters leave {clustered_residual} unexplained, regions {residual:?}"
        );
    }

    #[test]
    fn a_sun_over_two_materials_is_found_where_it_shines() {
        // Points over the upper half of a unit sphere, convex (no shadows): a white
        // Lambertian surface's transport per texel is Ω_k max(0, n·d_k) / π. Left
        // half reddish (skin), right half greenish; lit by one bright texel and a dim
        // uniform sky.
        let sun = 2 * ENV_W + 5;
        let points = (0..40).flat_map(|i| {
            (0..80).map(move |j| {
                let theta = std::f64::consts::FRAC_PI_2 * (i as f64 + 0.5) / 40.0 * 1.6;
                let phi = std::f64::consts::TAU * (j as f64 + 0.5) / 80.0;
                let n = direction(theta, phi);
                let albedo = if n.x < 0.0 {
                    [0.6, 0.4, 0.3]
                } else {
                    [0.3, 0.5, 0.2]
                };
                (n, albedo)
            })
        });
        let observations = convex_observations(points, &sun_and_sky(sun));
        let (fitted, report) =
            fit_lighting(&observations, &LightingFitSettings::default(), &[]).expect("a fit");
        assert_eq!(report.material_vertices.len(), 2, "{report:?}");
        // The brightest fitted texel is the sun's or touches it; the light's
        // brightness-weighted direction is within 20° of the sun's.
        let lum = |t: &[f32; 3]| t[0] + t[1] + t[2];
        let brightest = (0..ENV_TEXELS)
            .max_by(|&a, &b| lum(&fitted.texels()[a]).total_cmp(&lum(&fitted.texels()[b])))
            .expect("texels");
        let (br, bc) = (brightest / ENV_W, brightest % ENV_W);
        let (sr, sc) = (sun / ENV_W, sun % ENV_W);
        assert!(
            br.abs_diff(sr) <= 1 && bc.abs_diff(sc) <= 1,
            "brightest texel {br},{bc}, sun {sr},{sc}"
        );
        let angle = centre_angle_deg(&fitted, sun);
        assert!(angle < 20.0, "the fitted light's centre is {angle}° from the sun");
        // Grey world: the fit's channels have equal power.
        let [r, g, b] = fitted.integral();
        assert!(
            (r - g).abs() < 1e-3 * r && (g - b).abs() < 1e-3 * g,
            "{r} {g} {b}"
        );
        // The photographs are explained: the residual falls below 5 %.
        let last = report.relative_residual.last().copied().unwrap_or(1.0);
        assert!(last < 0.05, "{:?}", report.relative_residual);
    }
}
