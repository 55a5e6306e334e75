//! The harmonic view part (`--view-dependence sh1|sh2|N`, format 1.2): the residual
//! `T(x, ω) − T̄(x)` sampled toward the directions of [`super::directions`], fitted per
//! voxel on the real spherical harmonics of degrees 0–2 with a small ridge, a view
//! basis from the pooled fits, and lobes fixed (`sh1`, `sh2`) or learned per asset.
//! One pass over the band ([`fit_view`]) also fits the reflection part when asked.

use std::fmt;
use std::str::FromStr;

use glam::{DVec3, Vec3};
use nalgebra::{DMatrix, SymmetricEigen};
use nelf_format::conventions::{ENV_TEXELS, LT_DIM, VIEW_HARMONICS, view_harmonics};
use nelf_format::{CoefficientEncoding, Coefficients, ViewDependence};
use nelf_render::BrickGrid;
use nelf_scene::field::FieldSource;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};
use crate::grid::voxel_position;
use crate::progress::Progress;
use crate::view::directions::{VIEW_DIRECTIONS, density_normal, sample_directions, seen_weights};
use crate::view::reflection::{REFLECT_EXPONENTS, ReflectionTarget, fit_reflection_voxel};

/// Band voxels the view basis is fitted on (evenly strided).
pub const BASIS_SAMPLE: usize = 2048;

/// Band voxels (evenly strided) `auto`'s probe fits ([`FitScope::Sample`]): eight
/// batches. With 512 the extrapolated gain ranged from half to twice the band's on
/// three fields; with 4096 it oversells it 1.05–3.6× on seven, never undersells
/// (`docs/measurements/settings.md`).
pub const PROBE_SAMPLE: usize = 4096;

/// Points per field call.
const BATCH: usize = 512;

/// Ridge of the per-voxel fit, relative to the mean diagonal of its normal matrix.
const RIDGE: f64 = 1e-3;

/// Numbers in one voxel's normal matrix `G`.
const G_LEN: usize = VIEW_HARMONICS * VIEW_HARMONICS;

/// Residual ratios below this mean the field has no view dependence (a matte surface
/// traced with the same random streams toward every direction gives exactly 0).
pub const NO_VIEW_DEPENDENCE: f64 = 1e-4;

/// `--view-dependence`: whether and how the bake keeps view-dependent light transport.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum ViewChoice {
    /// No view part (a 1.1 file).
    Off,
    /// Fit the candidates, keep the best if it gains more than the threshold.
    #[default]
    Auto,
    /// The four harmonics of degrees 0 and 1.
    Sh1,
    /// All nine harmonics of degrees 0 to 2.
    Sh2,
    /// This many lobes (1..=9) learned per asset from the degree-0–2 fit.
    Learned(u8),
    /// One glossy lobe about the mirror direction per voxel (format 1.3), its exponent
    /// chosen among [`REFLECT_EXPONENTS`] at the judging views.
    Reflect,
}

impl FromStr for ViewChoice {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "off" => Ok(Self::Off),
            "auto" => Ok(Self::Auto),
            "sh1" => Ok(Self::Sh1),
            "sh2" => Ok(Self::Sh2),
            "reflect" => Ok(Self::Reflect),
            _ => match s.parse::<u8>() {
                Ok(n) if (1..=VIEW_HARMONICS as u8).contains(&n) => Ok(Self::Learned(n)),
                _ => Err(format!(
                    "'{s}' is not a view dependence: auto, off, reflect, sh1, sh2, or a number of learned lobes 1..=9"
                )),
            },
        }
    }
}

impl fmt::Display for ViewChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Off => f.write_str("off"),
            Self::Auto => f.write_str("auto"),
            Self::Sh1 => f.write_str("sh1"),
            Self::Sh2 => f.write_str("sh2"),
            Self::Reflect => f.write_str("reflect"),
            Self::Learned(n) => write!(f, "{n}"),
        }
    }
}

impl From<ViewChoice> for String {
    fn from(v: ViewChoice) -> Self {
        v.to_string()
    }
}

impl TryFrom<String> for ViewChoice {
    type Error = String;

    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

/// The first `rows` rows of the identity of size `width` (row-major).
fn identity_rows(rows: usize, width: usize) -> Vec<f64> {
    (0..rows * width)
        .map(|i| if i / width == i % width { 1.0 } else { 0.0 })
        .collect()
}

/// One voxel's weighted normal equations over the harmonics: `G = Σ_d w_d y_d y_dᵀ`
/// (9 × 9, row-major) and `h = Σ_d w_d y_d r_dᵀ` (9 × `dim`, row-major) for residuals
/// `r_d` of `dim` numbers.
fn normal_equations<R: Copy + Into<f64>>(
    weights: &[f64],
    harmonics: &[[f32; VIEW_HARMONICS]],
    residuals: &[R],
    dim: usize,
) -> (Vec<f64>, Vec<f64>) {
    let mut g = vec![0.0f64; VIEW_HARMONICS * VIEW_HARMONICS];
    let mut h = vec![0.0f64; VIEW_HARMONICS * dim];
    for (d, (&w, y)) in weights.iter().zip(harmonics).enumerate() {
        if w <= 0.0 {
            continue;
        }
        let r = &residuals[d * dim..(d + 1) * dim];
        for a in 0..VIEW_HARMONICS {
            let wy = w * f64::from(y[a]);
            for b in 0..VIEW_HARMONICS {
                g[a * VIEW_HARMONICS + b] += wy * f64::from(y[b]);
            }
            for (o, &x) in h[a * dim..(a + 1) * dim].iter_mut().zip(r) {
                *o += wy * x.into();
            }
        }
    }
    (g, h)
}

/// Solves the ridge-regularised fit for lobes `lobes` (`J × 9`, row-major):
/// `(A G Aᵀ + λI) b = A h`, returning `b` (`J × dim`); zero when the voxel is never seen.
fn solve_lobes(g: &[f64], h: &[f64], dim: usize, lobes: &[f64]) -> Vec<f64> {
    let j = lobes.len() / VIEW_HARMONICS;
    let a = DMatrix::from_row_slice(j, VIEW_HARMONICS, lobes);
    let g = DMatrix::from_row_slice(VIEW_HARMONICS, VIEW_HARMONICS, g);
    let h = DMatrix::from_row_slice(VIEW_HARMONICS, dim, h);
    let mut lhs = &a * g * a.transpose();
    let trace = lhs.trace();
    if !(trace > 0.0 && trace.is_finite()) {
        return vec![0.0; j * dim];
    }
    let ridge = RIDGE * trace / j as f64;
    for i in 0..j {
        lhs[(i, i)] += ridge;
    }
    let rhs = &a * h;
    match lhs.cholesky() {
        Some(c) => {
            let b = c.solve(&rhs);
            // Row-major out.
            (0..j)
                .flat_map(|r| (0..dim).map(move |c| (r, c)))
                .map(|(r, c)| b[(r, c)])
                .collect()
        }
        None => vec![0.0; j * dim],
    }
}

/// Everything the view part of any lobe choice needs, from one pass over the band.
#[derive(Debug, Clone)]
pub struct ViewFit {
    /// The view basis `V` (`K_max × 384`), principal directions of the residual.
    pub basis: Vec<f32>,
    /// Eigenvalues of the basis (weighted second moment of the fitted harmonic vectors).
    pub eigenvalues: Vec<f64>,
    /// Per band voxel: `G` (81 numbers).
    normal: Vec<f64>,
    /// Per band voxel: `h` (9 × `K_max`).
    projected: Vec<f64>,
    /// Per fitted voxel: weight (visibility) for the learned lobes.
    weights: Vec<f64>,
    /// The band entries (indices into the band's voxel list) the per-voxel arrays
    /// cover, in order: the whole band, or a probe's [`PROBE_SAMPLE`] voxels
    /// ([`FitScope::Sample`]); empty when skipped.
    pub entries: Vec<usize>,
    /// Relative RMS of the residual over the subsample (`|R| / |T̄|`, weighted).
    pub residual_ratio: f64,
    /// Seconds spent.
    pub secs: f64,
    /// Whether the residual was below [`NO_VIEW_DEPENDENCE`] on the subsample, so the
    /// band was not fitted (the per-voxel equations are empty).
    pub skipped: bool,
    /// Whether the harmonic normal equations were kept (`false`: only the reflection
    /// part was fitted, and [`ViewFit::view_part`] has nothing to solve).
    pub harmonic: bool,
    /// Per band voxel, the reflection part's normal and its scale under each of
    /// [`REFLECT_EXPONENTS`] (empty unless asked for and fitted).
    pub reflection: Vec<([f32; 3], Vec<f32>)>,
}

/// Stride of the lattice the reflection part is sampled and fitted on over the band
/// ([`reflection_lattice`]): every other voxel per axis. A voxel's lobe normal and
/// scales change little between neighbours (the surface's normal turns about 1° per
/// 1.9 mm voxel on a head), while each fitted voxel costs its transport toward
/// [`VIEW_DIRECTIONS`] directions and a normal search: on the CGAL head this takes the
/// band's fit from 115 k voxels to 21 k (`docs/measurements/2026-12-07-view-cost.md`).
pub const REFLECT_LATTICE_STRIDE: i64 = 2;

/// Bands smaller than this (voxels) fit the reflection part at every voxel: seconds at
/// most, and exact for a scale that changes from voxel to voxel (`bake/tests/view.rs`'s
/// glossy sphere, whose scale is white noise in space, 1,040 surface voxels: normals
/// 1.1° median off at every voxel against 1.9° from the lattice).
pub const REFLECT_LATTICE_MIN_BAND: usize = 32_768;

/// Which band voxels the reflection part is fitted at, and how the others take theirs.
#[derive(Debug, Clone)]
struct ReflectionLattice {
    /// Band entries fitted: those on the lattice of [`REFLECT_LATTICE_STRIDE`], and those
    /// with no lattice voxel of the band among their 26 neighbours. Ascending.
    fitted: Vec<usize>,
    /// Per band entry: `None` when fitted, else the indices into `fitted` of its fitted
    /// neighbours (26-neighbourhood).
    from: Vec<Option<Vec<usize>>>,
}

/// The lattice of the band voxels `lt_voxels` (of the grid of `bricks`) that the
/// reflection part is fitted at ([`ReflectionLattice`]).
fn reflection_lattice(bricks: &[[u16; 3]], lt_voxels: &[usize]) -> ReflectionLattice {
    let coords: Vec<[i64; 3]> = lt_voxels
        .iter()
        .map(|&v| crate::grid::voxel_coords(bricks, v))
        .collect();
    let on_lattice = |c: &[i64; 3]| c.iter().all(|&x| x.rem_euclid(REFLECT_LATTICE_STRIDE) == 0);
    let index: std::collections::HashMap<[i64; 3], usize> =
        coords.iter().enumerate().map(|(e, &c)| (c, e)).collect();
    let neighbours = |c: &[i64; 3]| -> Vec<usize> {
        let mut out = Vec::new();
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if (dx, dy, dz) != (0, 0, 0) && on_lattice(&q) {
                        if let Some(&e) = index.get(&q) {
                            out.push(e);
                        }
                    }
                }
            }
        }
        out
    };
    let lattice_neighbours: Vec<Option<Vec<usize>>> = coords
        .iter()
        .map(|c| {
            if on_lattice(c) {
                return None;
            }
            let list = neighbours(c);
            (!list.is_empty()).then_some(list)
        })
        .collect();
    let fitted: Vec<usize> = (0..coords.len())
        .filter(|&e| lattice_neighbours[e].is_none())
        .collect();
    let position_in_fitted: std::collections::HashMap<usize, usize> =
        fitted.iter().enumerate().map(|(i, &e)| (e, i)).collect();
    let from = lattice_neighbours
        .into_iter()
        .map(|list| {
            list.map(|l| {
                l.iter()
                    .filter_map(|e| position_in_fitted.get(e).copied())
                    .collect()
            })
        })
        .collect();
    ReflectionLattice { fitted, from }
}

impl ReflectionLattice {
    /// Every band entry's reflection fit from those of [`Self::fitted`] (`fits`, in its
    /// order): a filled voxel takes the mean of the scales of its fitted neighbours that
    /// have a lobe (some scale > 0) and their normals' normalised sum (`fallback(entry)`,
    /// the density's normal, where they cancel or none has a lobe: then all scales 0).
    fn fill(
        &self,
        fits: &[([f32; 3], Vec<f32>)],
        fallback: impl Fn(usize) -> Vec3,
    ) -> Vec<([f32; 3], Vec<f32>)> {
        let mut next = 0;
        self.from
            .iter()
            .enumerate()
            .map(|(e, from)| match from {
                None => {
                    let fit = fits.get(next).cloned().unwrap_or(([0.0, 0.0, 1.0], Vec::new()));
                    next += 1;
                    fit
                }
                Some(list) => {
                    // Neighbours without a lobe (no density gradient, deep in a solid, or
                    // nothing to explain) say nothing about this voxel's.
                    let neighbours: Vec<&([f32; 3], Vec<f32>)> = list
                        .iter()
                        .filter_map(|&i| fits.get(i))
                        .filter(|f| f.1.iter().any(|&s| s > 0.0))
                        .collect();
                    let lobes = fits.first().map_or(0, |f| f.1.len());
                    let mut normal = Vec3::ZERO;
                    let mut scales = vec![0.0f32; lobes];
                    for (n, fitted_scales) in &neighbours {
                        normal += Vec3::from_array(*n);
                        for (s, t) in scales.iter_mut().zip(fitted_scales) {
                            *s += t / neighbours.len() as f32;
                        }
                    }
                    let normal = normal.try_normalize().unwrap_or_else(|| fallback(e)).to_array();
                    (normal, scales)
                }
            })
            .collect()
    }
}

/// One band voxel's fit in the view stage's second pass: its harmonic normal equations
/// `(G, h)` and, when asked for, its reflection normal and scales.
type PerVoxel = ((Vec<f64>, Vec<f64>), Option<([f32; 3], Vec<f32>)>);

/// Which band voxels [`fit_view`] keeps normal equations for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitScope {
    /// Every band voxel: the view part of the asset.
    Band,
    /// Only an evenly strided subsample of [`PROBE_SAMPLE`] voxels, which also gives
    /// the basis: a probe of what a view part could gain, at `PROBE_SAMPLE / band` of
    /// the cost of [`FitScope::Band`] (each voxel's transport is sampled once).
    Sample,
}

/// Samples and fits the residual of `field` over the band voxels `lt_voxels` (whose
/// view-independent vectors are `lt`, `384` each, and visibility weights `weights`).
/// `max_rank` caps the view basis; `scope` says which voxels' equations are kept;
/// `harmonic: false` keeps none (only the reflection part with `reflect`: `auto` after
/// a probe that ruled the harmonic parts out), skipping their projection.
#[allow(clippy::too_many_arguments)] // the band's five arrays, where and how to sample
pub fn fit_view(
    field: &dyn FieldSource,
    grid: &BrickGrid,
    density: &[f32],
    lt_voxels: &[usize],
    lt: &[f32],
    weights: &[f64],
    eyes: &[DVec3],
    max_rank: usize,
    reflect: Option<&ReflectionTarget>,
    harmonic: bool,
    scope: FitScope,
    progress: &Progress,
) -> Result<ViewFit> {
    let start = std::time::Instant::now();
    let reflect_lobes: Vec<nelf_render::ReflectionLobe> = reflect.map_or_else(Vec::new, |t| {
        REFLECT_EXPONENTS
            .iter()
            .map(|&l| nelf_render::ReflectionLobe::new(l, t.world_from_light))
            .collect()
    });
    if lt_voxels.is_empty() || lt.len() != lt_voxels.len() * LT_DIM || weights.len() != lt_voxels.len() {
        return Err(BakeError::Settings(format!(
            "view fit: {} band voxels, {} transport floats, {} weights",
            lt_voxels.len(),
            lt.len(),
            weights.len()
        )));
    }
    let geometry = *grid.geometry();
    let directions = sample_directions();
    let harmonics: Vec<[f32; VIEW_HARMONICS]> =
        directions.iter().map(|d| view_harmonics(d.to_array())).collect();
    let position = |v: usize| voxel_position(&geometry, grid.bricks(), v);
    let direction_weights = |v: usize| -> Vec<f64> {
        let x = position(v);
        seen_weights(x, density_normal(grid, density, x), eyes, &directions)
    };
    // Transport toward every direction of a batch of band entries, minus T̄ (in place:
    // 512 voxels × 64 directions × 384 floats, 50 MB a batch).
    let residuals = |entries: &[usize]| -> Result<Vec<f32>> {
        let points: Vec<Vec3> = entries
            .iter()
            .map(|&e| position(lt_voxels[e]).as_vec3())
            .collect();
        let mut sigma = vec![0.0f32; points.len()];
        let mut out = vec![0.0f32; points.len() * VIEW_DIRECTIONS * LT_DIM];
        field.evaluate_directions(&points, &directions, &mut sigma, &mut out)?;
        if let Some(i) = out.iter().position(|x| !x.is_finite()) {
            return Err(BakeError::Pca(format!(
                "the field returned a non-finite light-transport value toward direction {} at {}",
                (i / LT_DIM) % VIEW_DIRECTIONS,
                points[i / (LT_DIM * VIEW_DIRECTIONS)]
            )));
        }
        out.par_chunks_exact_mut(VIEW_DIRECTIONS * LT_DIM)
            .zip(entries.par_iter())
            .for_each(|(t, &e)| {
                let mean = &lt[e * LT_DIM..(e + 1) * LT_DIM];
                for td in t.chunks_exact_mut(LT_DIM) {
                    for (a, b) in td.iter_mut().zip(mean) {
                        *a -= b;
                    }
                }
            });
        Ok(out)
    };

    // 1. The basis, from the harmonic fit of a strided subsample.
    let n = lt_voxels.len();
    let sample_size = match scope {
        FitScope::Band => BASIS_SAMPLE,
        FitScope::Sample => PROBE_SAMPLE,
    };
    let sample: Vec<usize> = if n <= sample_size {
        (0..n).collect()
    } else {
        (0..sample_size).map(|i| i * n / sample_size).collect()
    };
    // A probe fits the same voxels twice: the first pass's residuals are kept.
    let mut kept: Vec<Vec<f32>> = Vec::new();
    let mut rows: Vec<f64> = Vec::with_capacity(sample.len() * VIEW_HARMONICS * LT_DIM);
    let (mut residual_energy, mut mean_energy) = (0.0f64, 0.0f64);
    let identity = identity_rows(VIEW_HARMONICS, VIEW_HARMONICS);
    for (c, chunk) in sample.chunks(BATCH).enumerate() {
        let quiet = NO_VIEW_DEPENDENCE * NO_VIEW_DEPENDENCE * mean_energy;
        if c == 1 && (residual_energy.is_nan() || residual_energy < quiet) {
            // No view dependence in the first batch (a matte field gives exactly 0):
            // the rest is not sampled.
            let k_max = max_rank.clamp(1, LT_DIM);
            return Ok(ViewFit {
                basis: identity_rows(k_max, LT_DIM)
                    .into_iter()
                    .map(|x| x as f32)
                    .collect(),
                eigenvalues: vec![0.0; LT_DIM],
                normal: Vec::new(),
                projected: Vec::new(),
                weights: Vec::new(),
                entries: Vec::new(),
                residual_ratio: (residual_energy / mean_energy.max(1e-300)).sqrt(),
                secs: start.elapsed().as_secs_f64(),
                skipped: true,
                harmonic,
                reflection: Vec::new(),
            });
        }
        let r = residuals(chunk)?;
        let fitted: Vec<(Vec<f64>, f64, f64)> = chunk
            .par_iter()
            .enumerate()
            .map(|(i, &e)| {
                let w = direction_weights(lt_voxels[e]);
                let rv = &r[i * VIEW_DIRECTIONS * LT_DIM..(i + 1) * VIEW_DIRECTIONS * LT_DIM];
                let (g, h) = normal_equations(&w, &harmonics, rv, LT_DIM);
                let b = solve_lobes(&g, &h, LT_DIM, &identity);
                let wsum: f64 = w.iter().sum();
                let res: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(d, wd)| {
                        wd * rv[d * LT_DIM..(d + 1) * LT_DIM]
                            .iter()
                            .map(|&x| f64::from(x) * f64::from(x))
                            .sum::<f64>()
                    })
                    .sum::<f64>()
                    / wsum.max(1e-30);
                let m: f64 = lt[e * LT_DIM..(e + 1) * LT_DIM]
                    .iter()
                    .map(|&x| f64::from(x).powi(2))
                    .sum();
                let scale = weights[e].sqrt();
                (
                    b.into_iter().map(|x| x * scale).collect(),
                    weights[e] * res,
                    weights[e] * m,
                )
            })
            .collect();
        for (b, res, m) in fitted {
            rows.extend(b);
            residual_energy += res;
            mean_energy += m;
        }
        if scope == FitScope::Sample {
            kept.push(r);
        }
    }
    let count = rows.len() / LT_DIM;
    let x = DMatrix::from_row_slice(count, LT_DIM, &rows);
    let moment = x.transpose() * &x;
    let eigen = SymmetricEigen::new(moment);
    let mut order: Vec<usize> = (0..LT_DIM).collect();
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let k_max = max_rank.clamp(1, LT_DIM);
    let mut basis = Vec::with_capacity(k_max * LT_DIM);
    let mut eigenvalues = Vec::with_capacity(LT_DIM);
    for &i in &order {
        eigenvalues.push(eigen.eigenvalues[i].max(0.0));
    }
    for &i in order.iter().take(k_max) {
        basis.extend(eigen.eigenvectors.column(i).iter().map(|&v| v as f32));
    }
    let basis_f64: Vec<f64> = basis.iter().map(|&v| f64::from(v)).collect();
    let residual_ratio = (residual_energy / mean_energy.max(1e-300)).sqrt();
    if residual_ratio.is_nan() || residual_ratio < NO_VIEW_DEPENDENCE {
        return Ok(ViewFit {
            basis,
            eigenvalues,
            normal: Vec::new(),
            projected: Vec::new(),
            weights: Vec::new(),
            entries: Vec::new(),
            residual_ratio,
            secs: start.elapsed().as_secs_f64(),
            skipped: true,
            harmonic,
            reflection: Vec::new(),
        });
    }

    // 2. Every band voxel in scope: project the residual on V, keep the normal equations.
    // The reflection part alone over the band: sampled and fitted on a lattice of every
    // other voxel, the rest filled from it (`reflection_lattice`).
    let lattice =
        (scope == FitScope::Band && !harmonic && reflect.is_some() && n >= REFLECT_LATTICE_MIN_BAND)
            .then(|| reflection_lattice(grid.bricks(), lt_voxels));
    let entries: Vec<usize> = match (&lattice, scope) {
        (Some(lattice), _) => lattice.fitted.clone(),
        (None, FitScope::Band) => (0..n).collect(),
        (None, FitScope::Sample) => sample,
    };
    let m = entries.len();
    let bar = progress.bar("view", m as u64, "voxels");
    let kept_equations = if harmonic { m } else { 0 };
    let mut normal = vec![0.0f64; kept_equations * G_LEN];
    let mut projected = vec![0.0f64; kept_equations * VIEW_HARMONICS * k_max];
    let mut reflection = Vec::with_capacity(if reflect.is_some() { m } else { 0 });
    for (c, chunk) in entries.chunks(BATCH).enumerate() {
        let r = match kept.get_mut(c) {
            Some(r) => std::mem::take(r),
            None => residuals(chunk)?,
        };
        let per: Vec<PerVoxel> = chunk
            .par_iter()
            .enumerate()
            .map(|(i, &e)| {
                let x = position(lt_voxels[e]);
                let normal = density_normal(grid, density, x);
                let w = seen_weights(x, normal, eyes, &directions);
                let rv = &r[i * VIEW_DIRECTIONS * LT_DIM..(i + 1) * VIEW_DIRECTIONS * LT_DIM];
                let fitted = reflect.map(|t| {
                    let summed: Vec<f32> = rv
                        .chunks_exact(LT_DIM)
                        .flat_map(|r| {
                            (0..ENV_TEXELS).map(move |i| {
                                (f64::from(r[i])
                                    + f64::from(r[ENV_TEXELS + i])
                                    + f64::from(r[2 * ENV_TEXELS + i])) as f32
                            })
                        })
                        .collect();
                    fit_reflection_voxel(
                        &reflect_lobes,
                        x.as_vec3(),
                        normal.as_vec3(),
                        &t.eyes,
                        &directions,
                        &w,
                        &summed,
                    )
                });
                if !harmonic {
                    return ((Vec::new(), Vec::new()), fitted);
                }
                let mut p = vec![0.0f64; VIEW_DIRECTIONS * k_max];
                for (d, pd) in p.chunks_exact_mut(k_max).enumerate() {
                    let rd = &rv[d * LT_DIM..(d + 1) * LT_DIM];
                    for (k, o) in pd.iter_mut().enumerate() {
                        *o = basis_f64[k * LT_DIM..(k + 1) * LT_DIM]
                            .iter()
                            .zip(rd)
                            .map(|(a, &b)| a * f64::from(b))
                            .sum();
                    }
                }
                (normal_equations(&w, &harmonics, &p, k_max), fitted)
            })
            .collect();
        for (i, ((g, h), fitted)) in per.into_iter().enumerate() {
            reflection.extend(fitted);
            if !harmonic {
                continue;
            }
            let e = c * BATCH + i;
            normal[e * G_LEN..(e + 1) * G_LEN].copy_from_slice(&g);
            projected[e * VIEW_HARMONICS * k_max..(e + 1) * VIEW_HARMONICS * k_max].copy_from_slice(&h);
        }
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
    let (entries, reflection) = match lattice {
        Some(lattice) => (
            (0..n).collect::<Vec<usize>>(),
            lattice.fill(&reflection, |e| {
                density_normal(grid, density, position(lt_voxels[e])).as_vec3()
            }),
        ),
        None => (entries, reflection),
    };
    Ok(ViewFit {
        basis,
        eigenvalues,
        normal,
        projected,
        weights: entries.iter().map(|&e| weights[e]).collect(),
        entries,
        residual_ratio,
        secs: start.elapsed().as_secs_f64(),
        skipped: false,
        harmonic,
        reflection,
    })
}

impl ViewFit {
    /// Largest view rank available.
    pub fn max_rank(&self) -> usize {
        self.basis.len() / LT_DIM
    }

    /// Lobe weights (`J × 9`, row-major) for a choice (not `Off`/`Auto`): identity rows
    /// for `sh1`/`sh2`, the top eigenvectors of the weighted second moment of the fitted
    /// harmonic coefficients for learned lobes.
    pub fn lobes(&self, choice: ViewChoice) -> Vec<f64> {
        let rows = |j: usize| identity_rows(j, VIEW_HARMONICS);
        match choice {
            ViewChoice::Off | ViewChoice::Auto | ViewChoice::Reflect => Vec::new(),
            ViewChoice::Sh1 => rows(4),
            ViewChoice::Sh2 => rows(VIEW_HARMONICS),
            ViewChoice::Learned(_) if !self.harmonic => Vec::new(),
            ViewChoice::Learned(j) => {
                let identity = rows(VIEW_HARMONICS);
                let k = self.max_rank();
                let mut moment = DMatrix::<f64>::zeros(VIEW_HARMONICS, VIEW_HARMONICS);
                for (e, w) in self.weights.iter().enumerate() {
                    let g = &self.normal[e * G_LEN..(e + 1) * G_LEN];
                    let h = &self.projected[e * VIEW_HARMONICS * k..(e + 1) * VIEW_HARMONICS * k];
                    let b = DMatrix::from_row_slice(VIEW_HARMONICS, k, &solve_lobes(g, h, k, &identity));
                    moment += (&b * b.transpose()) * *w;
                }
                let eigen = SymmetricEigen::new(moment);
                let mut order: Vec<usize> = (0..VIEW_HARMONICS).collect();
                order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
                order
                    .iter()
                    .take(usize::from(j))
                    .flat_map(|&i| eigen.eigenvectors.column(i).iter().copied().collect::<Vec<_>>())
                    .collect()
            }
        }
    }

    /// The view part for lobes `lobes` (`J × 9`) at view rank `rank` over a grid of
    /// `voxels` voxels whose band is `lt_voxels` (voxels off the band, or outside the
    /// fit's [`ViewFit::entries`], get 0).
    pub fn view_part(
        &self,
        lobes: &[f64],
        rank: usize,
        voxels: usize,
        lt_voxels: &[usize],
        encoding: CoefficientEncoding,
    ) -> Result<ViewDependence> {
        if !self.harmonic && !self.skipped {
            return Err(BakeError::Settings(
                "view fit: the harmonic parts were not fitted (only the reflection part)".into(),
            ));
        }
        let j = lobes.len() / VIEW_HARMONICS;
        let k_max = self.max_rank();
        let rank = rank.clamp(1, k_max);
        if j == 0 || j * rank > LT_DIM {
            return Err(BakeError::Settings(format!(
                "a view part of {j} lobes × rank {rank} is not storable (1..=9 lobes, at most {LT_DIM} values per voxel)"
            )));
        }
        let per_voxel = j * rank;
        let solved: Vec<Vec<f64>> = (0..self.entries.len())
            .into_par_iter()
            .map(|e| {
                let g = &self.normal[e * G_LEN..(e + 1) * G_LEN];
                let h = &self.projected[e * VIEW_HARMONICS * k_max..(e + 1) * VIEW_HARMONICS * k_max];
                // Fit at full rank, keep the first `rank` (the basis is orthonormal).
                solve_lobes(g, h, k_max, lobes)
            })
            .collect();
        let mut values = vec![0.0f32; voxels * per_voxel];
        for (b, &e) in solved.iter().zip(&self.entries) {
            let v = *lt_voxels.get(e).ok_or_else(|| {
                BakeError::Settings(format!(
                    "view fit: entry {e} is outside a band of {}",
                    lt_voxels.len()
                ))
            })?;
            for l in 0..j {
                for i in 0..rank {
                    values[v * per_voxel + l * rank + i] = b[l * k_max + i] as f32;
                }
            }
        }
        let view = ViewDependence {
            lobes: lobes.iter().map(|&x| x as f32).collect(),
            basis: self.basis[..rank * LT_DIM].to_vec(),
            coefficients: Coefficients::quantize(&values, per_voxel, encoding)?,
        };
        view.validate(voxels)?;
        Ok(view)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reflection_lattice_fits_every_other_voxel_and_fills_the_rest() {
        use nelf_format::asset::local_voxel_index;
        // One brick at the origin; the band: a 3-voxel-thick slab z = 2..5 over x, y < 6,
        // plus one voxel (7, 7, 7) with no lattice voxel of the band beside it.
        let bricks = [[0u16, 0, 0]];
        let mut band: Vec<usize> = Vec::new();
        for z in 2..5 {
            for y in 0..6 {
                for x in 0..6 {
                    band.push(local_voxel_index(x, y, z));
                }
            }
        }
        band.push(local_voxel_index(7, 7, 7));
        let lattice = reflection_lattice(&bricks, &band);
        let coords: Vec<[i64; 3]> = band
            .iter()
            .map(|&v| crate::grid::voxel_coords(&bricks, v))
            .collect();
        let even = |c: &[i64; 3]| c.iter().all(|x| x % 2 == 0);
        // Fitted: the lattice voxels (x, y even, z = 2 or 4: 3 × 3 × 2) and the lone voxel.
        let fitted: Vec<[i64; 3]> = lattice.fitted.iter().map(|&e| coords[e]).collect();
        assert_eq!(fitted.len(), 3 * 3 * 2 + 1);
        assert!(fitted.iter().all(|c| even(c) || *c == [7, 7, 7]));
        // Every other voxel takes its fit from fitted lattice neighbours (≤ 8 of them).
        for (e, from) in lattice.from.iter().enumerate() {
            match from {
                None => assert!(lattice.fitted.contains(&e)),
                Some(list) => {
                    assert!(!list.is_empty() && list.len() <= 8);
                    for &i in list {
                        let (a, b) = (coords[e], coords[lattice.fitted[i]]);
                        assert!(even(&b) && (0..3).all(|k| (a[k] - b[k]).abs() <= 1));
                    }
                }
            }
        }
        // Fill: the neighbours' mean scales and normalised normal sum; fitted voxels keep theirs.
        let fits: Vec<([f32; 3], Vec<f32>)> = lattice
            .fitted
            .iter()
            .map(|&e| {
                let c = coords[e];
                let tilt = if c[0] == 0 { 0.2 } else { -0.2 };
                (
                    Vec3::new(tilt, 0.0, 1.0).normalize().to_array(),
                    vec![c[0] as f32, 1.0],
                )
            })
            .collect();
        let filled = lattice.fill(&fits, |_| Vec3::Z);
        assert_eq!(filled.len(), band.len());
        for (e, (normal, scales)) in filled.iter().enumerate() {
            let c = coords[e];
            if let Some(i) = lattice.fitted.iter().position(|&f| f == e) {
                assert_eq!((normal, scales), (&fits[i].0, &fits[i].1));
            } else if c[0] == 1 {
                // Between x = 0 and x = 2: tilts cancel, scales average to 1.
                assert!(
                    (Vec3::from_array(*normal) - Vec3::Z).length() < 1e-6,
                    "{normal:?}"
                );
                assert!((scales[0] - 1.0).abs() < 1e-6 && (scales[1] - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn choices_parse_and_print() {
        for s in ["auto", "off", "reflect", "sh1", "sh2", "1", "3", "9"] {
            assert_eq!(s.parse::<ViewChoice>().unwrap().to_string(), s);
        }
        for s in ["0", "10", "sh3", ""] {
            assert!(s.parse::<ViewChoice>().is_err(), "{s}");
        }
    }

    #[test]
    fn lobe_fit_recovers_an_exact_harmonic() {
        // r(ω) = 2·y_1(ω) − y_5(ω) (+ nothing else) for dim = 1, all directions weighted.
        let dirs = sample_directions();
        let harmonics: Vec<_> = dirs.iter().map(|d| view_harmonics(d.to_array())).collect();
        let r: Vec<f64> = harmonics
            .iter()
            .map(|y| 2.0 * f64::from(y[1]) - f64::from(y[5]))
            .collect();
        let w = vec![1.0; dirs.len()];
        let (g, h) = normal_equations(&w, &harmonics, &r, 1);
        let b = solve_lobes(&g, &h, 1, &identity_rows(VIEW_HARMONICS, VIEW_HARMONICS));
        assert!((b[1] - 2.0).abs() < 0.01 && (b[5] + 1.0).abs() < 0.01, "{b:?}");
        for (i, x) in b.iter().enumerate() {
            if i != 1 && i != 5 {
                assert!(x.abs() < 0.01, "{b:?}");
            }
        }
    }
}
