//! View-dependent light transport (format 1.2): fitting
//! `T(x, ω) ≈ T̄(x) + Σ_j Y_j(ω) Σ_i d_ji(x) V_i` to a field's transport toward many
//! outgoing directions, and choosing the lobes `Y_j` per scene.
//!
//! `T̄` is the bake's view-independent vector (the view policy's mean over the directions
//! toward the capture's cameras), stored as today by the PCA part, so a reader that
//! ignores the view part still renders the asset a view-independent bake would have.
//! The view part models the **residual** `R(x, ω) = T(x, ω) − T̄(x)`:
//!
//! 1. **Samples.** Every band voxel's transport toward `D` fixed world directions (a
//!    Fibonacci sphere, [`VIEW_DIRECTIONS`]), from
//!    [`nelf_scene::field::FieldSource::evaluate_directions`]. A direction counts with
//!    weight `max(0, n·ω)`, `n` the outward normal of the density (`−∇σ`, central
//!    differences of the trilinear grid): the directions the voxel can be seen from.
//! 2. **Harmonics fit.** Per voxel, weighted least squares of `R` on the nine real
//!    spherical harmonics of degrees 0–2 (`view_harmonics`; the constant corrects `T̄`
//!    for the directions the voxel is seen from, which need not be the cameras'), with a
//!    small ridge (`λ = 10⁻³ · tr G / J`) so that directions never seen stay near zero.
//! 3. **View basis.** On an evenly strided subsample of the band ([`BASIS_SAMPLE`]
//!    voxels) the fitted harmonic vectors are pooled, weighted by how much the voxel
//!    shows in the capture's views, and their uncentred principal directions become the
//!    basis `V` (rank ≤ `--max-view-rank`). Then every voxel's residual is projected on
//!    `V` first and fitted second (the fit is linear, so the order does not matter), and
//!    only the per-voxel normal equations (`G`, 9 × 9, and `h`, 9 × `K_v`) are kept: any
//!    choice of lobes is then an exact weighted least-squares fit without new samples.
//! 4. **Lobes** (`--view-dependence`): `sh1` (the four harmonics of degrees 0–1), `sh2`
//!    (all nine), or `N` lobes learned per asset: the top `N` eigenvectors of the
//!    visibility-weighted second moment of the fitted harmonic coefficients (a small
//!    per-asset decoder as in Hedman et al. 2021, "Baking neural radiance fields", kept linear so relighting
//!    stays a dot product).
//!    `auto` fits the candidates, renders each at the judging views (the capture's
//!    held-aside targets, else its own views) and keeps the best only when it gains more
//!    than `--view-min-gain-db` over the view-independent asset.

use std::fmt;
use std::str::FromStr;

use glam::{DVec3, Vec3};
use nalgebra::{DMatrix, SymmetricEigen};
use nelf_format::conventions::{ENV_TEXELS, LT_DIM, VIEW_HARMONICS, view_harmonics};
use nelf_format::{CoefficientEncoding, Coefficients, Reflection, ViewDependence};
use nelf_render::BrickGrid;
use nelf_scene::field::FieldSource;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};
use crate::grid::voxel_position;
use crate::progress::Progress;

/// Lobe exponents the reflection part tries (`--view-dependence reflect` and `auto`); the
/// normal is chosen with the middle one.
pub const REFLECT_EXPONENTS: [f32; 3] = [10.0, 20.0, 40.0];

/// How far (degrees) from the density's normal the reflection fit looks for the normal
/// whose lobe explains most: a mesh shaded with interpolated normals differs from its
/// flat triangles' density gradient by a few degrees, and a highlight moves by twice
/// that (the scan: 96 % of the exact view dependence with it, 73 % without).
pub const REFLECT_NORMAL_SEARCH_DEG: f32 = 12.0;

/// Outgoing directions sampled per voxel.
pub const VIEW_DIRECTIONS: usize = 64;

/// Band voxels the view basis is fitted on (evenly strided).
pub const BASIS_SAMPLE: usize = 2048;

/// Band voxels (evenly strided) `auto`'s probe fits ([`FitScope::Sample`]): one batch.
pub const PROBE_SAMPLE: usize = 512;

/// Concentration of the direction weights around the directions toward the views'
/// eyes: `exp(κ (c·ω − 1))`, κ = 4 (a von Mises–Fisher kernel ≈ 30° wide).
const VIEW_KERNEL: f64 = 8.0;

/// Weight every seen direction keeps however far from the views (relative to a
/// direction right at one).
const VIEW_WEIGHT_FLOOR: f64 = 0.02;

/// Points per field call.
const BATCH: usize = 512;

/// Ridge of the per-voxel fit, relative to the mean diagonal of its normal matrix.
const RIDGE: f64 = 1e-3;

/// Numbers in one voxel's normal matrix `G`.
const G_LEN: usize = VIEW_HARMONICS * VIEW_HARMONICS;

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

/// The fixed outgoing directions (a Fibonacci sphere of [`VIEW_DIRECTIONS`] points).
/// Sampling only a cap around the capture's views was measured no better (glossy tiny
/// head, held-aside targets: +0.64 dB against +0.88 dB for three learned lobes).
pub fn sample_directions() -> Vec<Vec3> {
    let n = VIEW_DIRECTIONS as f64;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..VIEW_DIRECTIONS)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), y, r * phi.sin()).as_vec3()
        })
        .collect()
}

/// The first `rows` rows of the identity of size `width` (row-major).
fn identity_rows(rows: usize, width: usize) -> Vec<f64> {
    (0..rows * width)
        .map(|i| if i / width == i % width { 1.0 } else { 0.0 })
        .collect()
}

/// Outward unit normal `−∇σ/|∇σ|` of the trilinear density at `p` (zero where flat).
fn density_normal(grid: &BrickGrid, density: &[f32], p: DVec3) -> DVec3 {
    let h = 0.5 * grid.geometry().voxel_size_m;
    let mut corners = [(0usize, 0.0f32); 8];
    let mut sample = |q: DVec3| -> f64 {
        let n = grid.trilinear(q, &mut corners);
        corners[..n].iter().map(|&(v, w)| f64::from(w * density[v])).sum()
    };
    let gradient = DVec3::new(
        sample(p + DVec3::X * h) - sample(p - DVec3::X * h),
        sample(p + DVec3::Y * h) - sample(p - DVec3::Y * h),
        sample(p + DVec3::Z * h) - sample(p - DVec3::Z * h),
    );
    (-gradient).normalize_or_zero()
}

/// One voxel's weighted normal equations over the harmonics: `G = Σ_d w_d y_d y_dᵀ`
/// (9 × 9, row-major) and `h = Σ_d w_d y_d r_dᵀ` (9 × `dim`, row-major) for residuals
/// `r_d` of `dim` numbers.
fn normal_equations(
    weights: &[f64],
    harmonics: &[[f32; VIEW_HARMONICS]],
    residuals: &[f64],
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
                *o += wy * x;
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
    /// Per band voxel, the reflection part's normal and its scale under each of
    /// [`REFLECT_EXPONENTS`] (empty unless asked for and fitted).
    pub reflection: Vec<([f32; 3], Vec<f32>)>,
}

/// What the reflection part is fitted against: the eyes `T̄` averages over and the light
/// frame.
#[derive(Debug, Clone)]
pub struct ReflectionTarget {
    /// The eyes (world, metres), at most [`nelf_format::asset::MAX_REFLECTION_EYES`].
    pub eyes: Vec<Vec3>,
    /// The asset's light frame.
    pub world_from_light: glam::DMat3,
}

/// How much each outgoing direction counts at a voxel at `x` with outward normal `n`
/// (zero: unknown, every direction faces): `max(0, n·ω) · (mean_e exp(κ (e·ω − 1)) +
/// floor)`, `e` the directions toward `eyes`: the directions the voxel is seen from, most
/// near the views.
pub fn seen_weights(x: DVec3, n: DVec3, eyes: &[DVec3], directions: &[Vec3]) -> Vec<f64> {
    let toward: Vec<DVec3> = eyes.iter().map(|e| (*e - x).normalize_or_zero()).collect();
    directions
        .iter()
        .map(|d| {
            let d = d.as_dvec3();
            let facing = if n == DVec3::ZERO { 1.0 } else { n.dot(d).max(0.0) };
            let near: f64 = toward
                .iter()
                .map(|c| (VIEW_KERNEL * (c.dot(d) - 1.0)).exp())
                .sum();
            facing * (near / toward.len().max(1) as f64 + VIEW_WEIGHT_FLOOR)
        })
        .collect()
}

/// A voxel's reflection-lobe fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectionFit {
    /// The scales `s_c ≥ 0` (all three equal for a colourless fit).
    pub scales: [f32; 3],
    /// How much of the weighted squared residual they remove (`Σ_c s_c · num_c`, the
    /// least-squares reduction): comparable between normals of one voxel.
    pub explained: f64,
}

/// `n` and, for a search angle `deg > 0`, six normals at `deg / 2` and six at `deg`
/// around it.
pub fn normal_candidates(n: Vec3, deg: f32) -> Vec<Vec3> {
    let mut out = vec![n];
    if deg > 0.0 {
        let (t, b) = n.any_orthonormal_pair();
        for ring in [0.5 * deg, deg] {
            let (sin, cos) = ring.to_radians().sin_cos();
            for k in 0..6 {
                let phi = k as f32 * std::f32::consts::TAU / 6.0 + ring.to_radians();
                out.push((cos * n + sin * (phi.cos() * t + phi.sin() * b)).normalize());
            }
        }
    }
    out
}

/// The reflection part's per-voxel fit ([`nelf_render::reflection`]): the scales
/// `s_c ≥ 0` minimising `Σ_d w_d Σ_i (R_d[c·128 + i] − s_c (h_i(ω_d) − h̄_i))²`, `R_d` the
/// residual `T(x, ω_d) − T̄(x)` toward `directions[d]` (`residual`, `D × 384`), `h` the
/// lobe at a surface of unit outward normal `n`, `h̄` its mean over the directions toward
/// `eyes` (those `T̄` averages over) and `w_d` = `weights[d]` ([`seen_weights`]). Zero
/// where nothing is seen or the lobe explains nothing. `colourless`: one scale for the
/// three channels (the sum of their squared errors), as the format stores.
#[allow(clippy::too_many_arguments)] // a voxel, its samples and the lobe
pub fn fit_reflection(
    lobe: &nelf_render::ReflectionLobe,
    x: Vec3,
    n: Vec3,
    eyes: &[Vec3],
    directions: &[Vec3],
    weights: &[f64],
    residual: &[f32],
    colourless: bool,
) -> ReflectionFit {
    if colourless {
        let summed = channel_sums(residual);
        let (scale, explained) = fit_summed_scale(lobe, x, n, eyes, directions, weights, &summed);
        return ReflectionFit {
            scales: [scale; 3],
            explained,
        };
    }
    let mean = lobe.mean_transport(x, n, eyes);
    let (mut num, mut den) = ([0.0f64; 3], [0.0f64; 3]);
    for ((d, w), r) in directions.iter().zip(weights).zip(residual.chunks_exact(LT_DIM)) {
        if *w <= 0.0 {
            continue;
        }
        let h = lobe.transport(*d, n);
        for c in 0..3 {
            for (i, (h, m)) in h.iter().zip(&mean).enumerate() {
                let dh = f64::from(h - m);
                num[c] += w * dh * f64::from(r[c * ENV_TEXELS + i]);
                den[c] += w * dh * dh;
            }
        }
    }
    let scales: [f64; 3] = std::array::from_fn(|c| {
        if den[c] > 0.0 {
            (num[c] / den[c]).max(0.0)
        } else {
            0.0
        }
    });
    ReflectionFit {
        scales: scales.map(|s| s as f32),
        explained: (0..3).map(|c| scales[c] * num[c]).sum(),
    }
}

/// Per direction, the residual summed over the three channels (`D × 128` of `D × 384`).
fn channel_sums(residual: &[f32]) -> Vec<f32> {
    residual
        .chunks_exact(LT_DIM)
        .flat_map(|r| (0..ENV_TEXELS).map(move |i| r[i] + r[ENV_TEXELS + i] + r[2 * ENV_TEXELS + i]))
        .collect()
}

/// The colourless fit of [`fit_reflection`] from channel-summed residuals (`D × 128`):
/// `s = Σ w dh·ΣR / (3 Σ w dh²)`, clamped at 0, and what it explains.
fn fit_summed_scale(
    lobe: &nelf_render::ReflectionLobe,
    x: Vec3,
    n: Vec3,
    eyes: &[Vec3],
    directions: &[Vec3],
    weights: &[f64],
    summed: &[f32],
) -> (f32, f64) {
    let mean = lobe.mean_transport(x, n, eyes);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for ((d, w), r) in directions
        .iter()
        .zip(weights)
        .zip(summed.chunks_exact(ENV_TEXELS))
    {
        if *w <= 0.0 {
            continue;
        }
        let h = lobe.transport(*d, n);
        let (mut a, mut b) = (0.0f32, 0.0f32);
        for ((h, m), r) in h.iter().zip(&mean).zip(r) {
            let dh = h - m;
            a += dh * r;
            b += dh * dh;
        }
        num += w * f64::from(a);
        den += w * f64::from(b);
    }
    den *= 3.0;
    let scale = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
    (scale as f32, scale * num)
}

/// One band voxel's reflection part: the normal (of the density's and those around it,
/// [`normal_candidates`], the one whose lobe at the middle exponent explains most) and
/// its scale under each of `lobes`.
#[allow(clippy::too_many_arguments)] // a voxel, its samples and the lobes
fn fit_reflection_voxel(
    lobes: &[nelf_render::ReflectionLobe],
    x: Vec3,
    density_normal: Vec3,
    eyes: &[Vec3],
    directions: &[Vec3],
    weights: &[f64],
    summed: &[f32],
) -> ([f32; 3], Vec<f32>) {
    if density_normal == Vec3::ZERO || lobes.is_empty() {
        return ([0.0, 0.0, 1.0], vec![0.0; lobes.len()]);
    }
    let middle = &lobes[lobes.len() / 2];
    let mut best = (density_normal, f64::NEG_INFINITY);
    // Rings at 6° and 12° around the density's normal, then at 1.5° and 3° around the
    // best of those (measured on a sphere whose normal is known: 0.9° median error
    // against 2.8° with the first search alone).
    let try_normals = |candidates: Vec<Vec3>, best: &mut (Vec3, f64)| {
        for n in candidates {
            let (_, explained) = fit_summed_scale(middle, x, n, eyes, directions, weights, summed);
            if explained > best.1 {
                *best = (n, explained);
            }
        }
    };
    try_normals(
        normal_candidates(density_normal, REFLECT_NORMAL_SEARCH_DEG),
        &mut best,
    );
    let coarse = best.0;
    try_normals(
        normal_candidates(coarse, 0.25 * REFLECT_NORMAL_SEARCH_DEG)[1..].to_vec(),
        &mut best,
    );
    let n = best.0;
    let scales = lobes
        .iter()
        .map(|lobe| fit_summed_scale(lobe, x, n, eyes, directions, weights, summed).0)
        .collect();
    (n.to_array(), scales)
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
/// `max_rank` caps the view basis; `scope` says which voxels' equations are kept.
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
    // Transport toward every direction of a batch of band entries, minus T̄, in f64.
    let residuals = |entries: &[usize]| -> Result<Vec<f64>> {
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
        Ok(out
            .par_chunks_exact(VIEW_DIRECTIONS * LT_DIM)
            .zip(entries.par_iter())
            .flat_map_iter(|(t, &e)| {
                let mean = &lt[e * LT_DIM..(e + 1) * LT_DIM];
                t.chunks_exact(LT_DIM)
                    .flat_map(move |td| td.iter().zip(mean).map(|(a, b)| f64::from(a - b)))
            })
            .collect())
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
    let mut kept: Vec<Vec<f64>> = Vec::new();
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
                            .map(|x| x * x)
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
            reflection: Vec::new(),
        });
    }

    // 2. Every band voxel in scope: project the residual on V, keep the normal equations.
    let entries: Vec<usize> = match scope {
        FitScope::Band => (0..n).collect(),
        FitScope::Sample => sample,
    };
    let m = entries.len();
    let bar = progress.bar("view", m as u64, "voxels");
    let mut normal = vec![0.0f64; m * VIEW_HARMONICS * VIEW_HARMONICS];
    let mut projected = vec![0.0f64; m * VIEW_HARMONICS * k_max];
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
                            (0..ENV_TEXELS)
                                .map(move |i| (r[i] + r[ENV_TEXELS + i] + r[2 * ENV_TEXELS + i]) as f32)
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
                let mut p = vec![0.0f64; VIEW_DIRECTIONS * k_max];
                for (d, pd) in p.chunks_exact_mut(k_max).enumerate() {
                    let rd = &rv[d * LT_DIM..(d + 1) * LT_DIM];
                    for (k, o) in pd.iter_mut().enumerate() {
                        *o = basis_f64[k * LT_DIM..(k + 1) * LT_DIM]
                            .iter()
                            .zip(rd)
                            .map(|(a, b)| a * b)
                            .sum();
                    }
                }
                (normal_equations(&w, &harmonics, &p, k_max), fitted)
            })
            .collect();
        for (i, ((g, h), fitted)) in per.into_iter().enumerate() {
            reflection.extend(fitted);
            let e = c * BATCH + i;
            normal[e * G_LEN..(e + 1) * G_LEN].copy_from_slice(&g);
            projected[e * VIEW_HARMONICS * k_max..(e + 1) * VIEW_HARMONICS * k_max].copy_from_slice(&h);
        }
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
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
    fn choices_parse_and_print() {
        for s in ["auto", "off", "reflect", "sh1", "sh2", "1", "3", "9"] {
            assert_eq!(s.parse::<ViewChoice>().unwrap().to_string(), s);
        }
        for s in ["0", "10", "sh3", ""] {
            assert!(s.parse::<ViewChoice>().is_err(), "{s}");
        }
    }

    #[test]
    fn directions_cover_the_sphere_evenly() {
        let d = sample_directions();
        let mean: Vec3 = d.iter().copied().sum::<Vec3>() / d.len() as f32;
        assert!(mean.length() < 0.02, "{mean}");
        for v in &d {
            assert!((v.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn the_reflection_scale_recovers_a_known_lobe() {
        // A voxel facing +z seen from three eyes in front; its residual toward every
        // direction is exactly a lobe of scales (0.3, 0.2, 0.1) about the mirror
        // direction, minus the lobe's mean over the eyes.
        let lobe = nelf_render::ReflectionLobe::new(20.0, glam::DMat3::IDENTITY);
        let (x, n) = (Vec3::ZERO, Vec3::Z);
        let eyes = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.5, 0.1, 0.9),
            Vec3::new(-0.4, -0.2, 0.9),
        ];
        let dirs = sample_directions();
        let weights = seen_weights(x.as_dvec3(), n.as_dvec3(), &eyes.map(Vec3::as_dvec3), &dirs);
        let scales = [0.3f32, 0.2, 0.1];
        let mean = lobe.mean_transport(x, n, &eyes);
        let residual: Vec<f32> = dirs
            .iter()
            .flat_map(|d| {
                let h = lobe.transport(*d, n);
                let mean = &mean;
                scales
                    .into_iter()
                    .flat_map(move |s| (0..ENV_TEXELS).map(move |i| s * (h[i] - mean[i])))
            })
            .collect();
        let fit = fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &residual, false).scales;
        for (a, b) in fit.iter().zip(scales) {
            assert!((a - b).abs() < 1e-4 * b, "{fit:?}");
        }
        // The true normal explains more of the residual than one turned 10° away.
        let turned = (Vec3::Z + 0.176 * Vec3::X).normalize();
        let at = |m: Vec3| fit_reflection(&lobe, x, m, &eyes, &dirs, &weights, &residual, false).explained;
        assert!(at(n) > 1.2 * at(turned), "{} vs {}", at(n), at(turned));
        // One scale for all three: their mean here (the channels' lobes are the same).
        let grey = fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &residual, true).scales;
        assert!(grey.iter().all(|g| (g - 0.2).abs() < 1e-4), "{grey:?}");
        // A view-independent voxel (no residual) gets no lobe; nor does a lobe pointing
        // the other way (negative scales clamp to zero).
        let zero = vec![0.0f32; residual.len()];
        assert_eq!(
            fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &zero, false).scales,
            [0.0; 3]
        );
        let negative: Vec<f32> = residual.iter().map(|r| -r).collect();
        assert_eq!(
            fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &negative, false).scales,
            [0.0; 3]
        );
    }

    #[test]
    fn the_extrapolated_gain_scales_the_removed_error() {
        // The whole band probed: the gain itself.
        assert!((extrapolated_gain_db(30.0, 0.4, 1.0) - 0.4).abs() < 1e-12);
        // No gain, or a loss, stays so.
        assert!(extrapolated_gain_db(30.0, 0.0, 0.05).abs() < 1e-12);
        assert!(extrapolated_gain_db(30.0, -0.01, 0.05) < 0.0);
        // A tenth of the band removing 1 % of the error: the band removes 10 %.
        let base = 10f64.powf(-3.0);
        let probe = 10.0 * (base / (0.99 * base)).log10();
        let full = extrapolated_gain_db(30.0, probe, 0.1);
        assert!((full - 10.0 * (1.0 / 0.9f64).log10()).abs() < 1e-9, "{full}");
        // All the error or more: capped at 30 dB, finite, so the band is fitted.
        let capped = extrapolated_gain_db(30.0, probe, 0.005);
        assert!((capped - 30.0).abs() < 1e-9, "{capped}");
        // Monotonic in the probe's gain.
        assert!(extrapolated_gain_db(25.0, 0.02, 0.04) < extrapolated_gain_db(25.0, 0.03, 0.04));
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

/// Rays per pixel (squared) of the judging renders: the gain is a difference of two
/// renders with the same sampling, so fewer rays than [`crate::eval::EVAL_PIXEL_GRID`]
/// do.
pub const JUDGE_PIXEL_GRID: u32 = 2;

/// One view-part candidate as judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewCandidate {
    /// `sh1`, `sh2` or the number of learned lobes.
    pub choice: ViewChoice,
    /// Lobes `J`.
    pub lobes: usize,
    /// View basis rank `K_v`.
    pub rank: usize,
    /// The lobe exponent λ of a `reflect` candidate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exponent: Option<f32>,
    /// Mean PSNR at the judging views, dB (`None` without judging views).
    pub psnr_db: Option<f64>,
    /// Gain over the view-independent asset, dB.
    pub gain_db: Option<f64>,
    /// Bytes of the asset with this view part (written with default options).
    pub bytes: u64,
}

/// What the view-dependence stage decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewReport {
    /// `--view-dependence`.
    pub requested: ViewChoice,
    /// What the asset holds (`off` when no view part was kept).
    pub chosen: ViewChoice,
    /// Index of the kept candidate in [`Self::candidates`].
    pub chosen_index: Option<usize>,
    /// Relative RMS of the residual `T(ω) − T̄` over the directions each voxel is seen
    /// from, on the basis subsample.
    pub residual_ratio: f64,
    /// Mean PSNR of the view-independent asset at the judging views, dB.
    pub base_psnr_db: Option<f64>,
    /// Bytes of the view-independent asset.
    pub base_bytes: u64,
    /// Every candidate tried.
    pub candidates: Vec<ViewCandidate>,
    /// Where the judging views came from.
    pub judged_at: String,
    /// `auto`'s probe on a subsample of the band, where it ran ([`ViewProbe`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe: Option<ViewProbe>,
    /// Seconds spent (sampling, fitting, judging).
    pub secs: f64,
}

/// How far below `--view-min-gain-db` the probe's extrapolated gain may be and the
/// band still be fitted: twice the largest undersell measured
/// ([`extrapolated_gain_db`]).
pub const PROBE_MARGIN: f64 = 4.0;

impl ViewReport {
    /// The largest gain of the judged candidates, dB (−∞ when none was judged).
    pub fn best_gain_db(&self) -> f64 {
        self.candidates
            .iter()
            .filter_map(|c| c.gain_db)
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// `auto`'s probe: the candidates fitted on [`PROBE_SAMPLE`] band voxels only, basis
/// included (the rest of the band without a view part), and judged, their gains extrapolated to the whole band
/// ([`extrapolated_gain_db`]). Where no extrapolated gain reaches
/// `--view-min-gain-db / PROBE_MARGIN` the band is not fitted and the asset stays
/// view-independent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewProbe {
    /// Band voxels the probe fitted.
    pub voxels: usize,
    /// Band voxels.
    pub band_voxels: usize,
    /// The candidates as judged with the probe's view part.
    pub candidates: Vec<ViewCandidate>,
    /// The largest extrapolated gain, dB.
    pub best_extrapolated_gain_db: f64,
    /// Whether the band was then fitted.
    pub band_fitted: bool,
}

/// The gain a view part fitted on every band voxel could reach, estimated from the
/// gain `probe_gain_db` of one fitted on a fraction `fraction` of them, over a
/// view-independent asset of PSNR `base_psnr_db`: the squared error the probe removed,
/// scaled by `1/fraction`. An estimate, not a bound: measured, it undersells the band's
/// fit about twice (the probe's basis comes from fewer voxels, and a voxel's correction
/// reaches a pixel only through its neighbours' interpolation). Extrapolated +0.257,
/// +1.665 and +0.009 dB where the band's fit gained +0.553, +2.124 and +0.016 dB (the
/// tiny ground-truth head with sheen 0.04 and 0.3, `bake/tests/view.rs` `sheen_gains`;
/// the shipped network on validation head h00200): hence [`PROBE_MARGIN`]. Capped at
/// 30 dB (99.9 % of the error removed).
pub fn extrapolated_gain_db(base_psnr_db: f64, probe_gain_db: f64, fraction: f64) -> f64 {
    let mse = |psnr: f64| 10f64.powf(-psnr / 10.0);
    let base = mse(base_psnr_db);
    // At most 99.9 % of the error (30 dB), so that the figure stays finite in JSON.
    let removed = ((base - mse(base_psnr_db + probe_gain_db)) / fraction.clamp(1e-9, 1.0)).min(0.999 * base);
    10.0 * (base / (base - removed)).log10()
}

/// Mean PSNR of `asset` over `views` with [`JUDGE_PIXEL_GRID`]² rays per pixel.
pub fn judge_psnr(
    asset: &nelf_format::Asset,
    views: &crate::eval::HeldAside,
    step_voxels: f32,
) -> Result<f64> {
    crate::eval::held_aside_psnr(asset, views, step_voxels, JUDGE_PIXEL_GRID)
}

/// View-basis rank of an explicit `--view-dependence` without `--view-rank`, and the
/// middle rank `auto` tries (it tries half and the largest too).
pub const DEFAULT_VIEW_RANK: usize = 8;

/// `auto` takes the smallest candidate whose gain is within this of the best (dB).
pub const AUTO_GAIN_SLACK_DB: f64 = 0.1;

/// Residual ratios below this mean the field has no view dependence (a matte surface
/// traced with the same random streams toward every direction gives exactly 0).
pub const NO_VIEW_DEPENDENCE: f64 = 1e-4;

/// Settings of [`choose_view`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSettings {
    /// `--view-dependence`.
    pub choice: ViewChoice,
    /// `--view-min-gain-db`.
    pub min_gain_db: f64,
    /// `--view-rank`.
    pub rank: Option<usize>,
    /// `--max-view-rank`.
    pub max_rank: usize,
    /// March step of the judging renders, voxels.
    pub step_voxels: f32,
}

/// One judged candidate and the part it would attach (a view part or a reflection part).
type JudgedPart = (ViewCandidate, (Option<ViewDependence>, Option<Reflection>));

/// Builds and judges the view part of each of `choices` and, with `reflect`, the
/// reflection part of each exponent, from `fit` (whose [`ViewFit::entries`] index
/// `lt_voxels`) on top of `asset`; `base_psnr_db` is the view-independent asset's.
#[allow(clippy::too_many_arguments)] // the asset, the fit and its band, what to judge and where
fn judge_candidates(
    asset: &nelf_format::Asset,
    fit: &ViewFit,
    lt_voxels: &[usize],
    choices: &[(ViewChoice, usize)],
    reflect: Option<&ReflectionTarget>,
    views: &crate::eval::HeldAside,
    base_psnr_db: Option<f64>,
    step_voxels: f32,
) -> Result<Vec<JudgedPart>> {
    let encoding = asset.coefficients.encoding();
    let voxels = asset.voxel_count();
    let judge = |with: &nelf_format::Asset| -> Result<Option<f64>> {
        if views.is_empty() {
            Ok(None)
        } else {
            Ok(Some(judge_psnr(with, views, step_voxels)?))
        }
    };
    let mut out = Vec::new();
    for &(choice, rank) in choices {
        let lobes = fit.lobes(choice);
        let part = if fit.skipped {
            // A field without view dependence asked for one explicitly: an all-zero part.
            ViewDependence {
                lobes: lobes.iter().map(|&x| x as f32).collect(),
                basis: fit.basis[..LT_DIM].to_vec(),
                coefficients: Coefficients::quantize(
                    &vec![0.0; voxels * lobes.len() / VIEW_HARMONICS],
                    lobes.len() / VIEW_HARMONICS,
                    encoding,
                )?,
            }
        } else {
            fit.view_part(&lobes, rank, voxels, lt_voxels, encoding)?
        };
        let mut with = asset.clone();
        with.view = Some(part);
        let psnr_db = judge(&with)?;
        let candidate = ViewCandidate {
            choice,
            lobes: with.view.as_ref().map_or(0, ViewDependence::lobe_count),
            rank: with.view.as_ref().map_or(0, ViewDependence::rank),
            exponent: None,
            psnr_db,
            gain_db: psnr_db.zip(base_psnr_db).map(|(a, b)| a - b),
            bytes: crate::eval::encoded_bytes(&with)?,
        };
        out.push((candidate, (with.view, None)));
    }
    // The reflection part, one candidate per exponent (only the middle one without
    // judging views).
    if let Some(target) = reflect {
        let exponents: Vec<usize> = if views.is_empty() {
            vec![REFLECT_EXPONENTS.len() / 2]
        } else {
            (0..REFLECT_EXPONENTS.len()).collect()
        };
        let eyes_m: Vec<[f32; 3]> = target.eyes.iter().map(Vec3::to_array).collect();
        for k in exponents {
            let mut normals = vec![[0.0f32, 0.0, 1.0]; voxels];
            let mut scales = vec![0.0f32; voxels];
            for ((n, s), &e) in fit.reflection.iter().zip(&fit.entries) {
                if let Some(&v) = lt_voxels.get(e) {
                    normals[v] = *n;
                    scales[v] = s[k];
                }
            }
            let part = Reflection::new(REFLECT_EXPONENTS[k], eyes_m.clone(), &normals, &scales)?;
            let mut with = asset.clone();
            with.view = None;
            with.reflection = Some(part);
            let psnr_db = judge(&with)?;
            let candidate = ViewCandidate {
                choice: ViewChoice::Reflect,
                lobes: 1,
                rank: 0,
                exponent: Some(REFLECT_EXPONENTS[k]),
                psnr_db,
                gain_db: psnr_db.zip(base_psnr_db).map(|(a, b)| a - b),
                bytes: crate::eval::encoded_bytes(&with)?,
            };
            out.push((candidate, (None, with.reflection)));
        }
    }
    Ok(out)
}

/// Fits, judges and attaches the view part to `asset` (the bake's view-independent
/// asset) per `settings`; `judge` are the judging views (empty: none, then `auto` keeps
/// nothing and an explicit choice is kept unjudged).
///
/// `auto` first probes ([`ViewProbe`]): the candidates fitted on [`PROBE_SAMPLE`] band
/// voxels alone and judged. Only where one of them, extrapolated to the whole band, could
/// gain `--view-min-gain-db` is the band fitted (most of the stage's cost: every band
/// voxel's transport toward [`VIEW_DIRECTIONS`] directions).
#[allow(clippy::too_many_arguments)]
pub fn choose_view(
    asset: &mut nelf_format::Asset,
    field: &dyn FieldSource,
    grid: &BrickGrid,
    density: &[f32],
    lt_voxels: &[usize],
    lt: &[f32],
    weights: &[f64],
    eyes: &[DVec3],
    reflect: Option<&ReflectionTarget>,
    settings: &ViewSettings,
    judge: (&crate::eval::HeldAside, &str),
    progress: &Progress,
) -> Result<ViewReport> {
    let start = std::time::Instant::now();
    let (views, judged_at) = judge;
    if settings.choice == ViewChoice::Reflect && reflect.is_none() {
        return Err(BakeError::Settings(
            "--view-dependence reflect needs the view policy that averages toward the cameras (--view-policy average-cameras)".into(),
        ));
    }
    let reflect = match settings.choice {
        ViewChoice::Reflect | ViewChoice::Auto => reflect,
        _ => None,
    };
    let explicit = !matches!(settings.choice, ViewChoice::Auto | ViewChoice::Off);
    // `auto` with judging views probes first where the band is larger than the sample.
    let probing = settings.choice == ViewChoice::Auto && !views.is_empty() && lt_voxels.len() > PROBE_SAMPLE;
    let fit_in = |scope: FitScope| {
        fit_view(
            field,
            grid,
            density,
            lt_voxels,
            lt,
            weights,
            eyes,
            settings.max_rank,
            reflect,
            scope,
            progress,
        )
    };
    let mut fit = fit_in(if probing { FitScope::Sample } else { FitScope::Band })?;
    let base_bytes = crate::eval::encoded_bytes(asset)?;
    let mut report = ViewReport {
        requested: settings.choice,
        chosen: ViewChoice::Off,
        chosen_index: None,
        residual_ratio: fit.residual_ratio,
        base_psnr_db: None,
        base_bytes,
        candidates: Vec::new(),
        judged_at: judged_at.to_string(),
        probe: None,
        secs: 0.0,
    };
    if settings.choice == ViewChoice::Off || (!explicit && (fit.skipped || views.is_empty())) {
        report.secs = start.elapsed().as_secs_f64();
        return Ok(report);
    }
    let max_rank = fit.max_rank();
    let default_rank = DEFAULT_VIEW_RANK.min(max_rank);
    let choices: Vec<(ViewChoice, usize)> = if settings.choice == ViewChoice::Reflect {
        Vec::new()
    } else if explicit {
        vec![(
            settings.choice,
            settings.rank.unwrap_or(default_rank).min(max_rank),
        )]
    } else if let Some(rank) = settings.rank {
        [ViewChoice::Sh1, ViewChoice::Learned(3), ViewChoice::Sh2]
            .into_iter()
            .map(|c| (c, rank.min(max_rank)))
            .collect()
    } else {
        let mut list = vec![
            (ViewChoice::Learned(3), (default_rank / 2).max(1)),
            (ViewChoice::Learned(3), default_rank),
            (ViewChoice::Learned(3), max_rank),
            (ViewChoice::Sh1, default_rank),
            (ViewChoice::Sh2, default_rank),
        ];
        list.dedup();
        list
    };
    if !views.is_empty() {
        report.base_psnr_db = Some(judge_psnr(asset, views, settings.step_voxels)?);
    }
    let base_psnr_db = report.base_psnr_db;
    let judge_fit = |fit: &ViewFit| {
        judge_candidates(
            asset,
            fit,
            lt_voxels,
            &choices,
            reflect,
            views,
            base_psnr_db,
            settings.step_voxels,
        )
    };
    if probing {
        let probed = judge_fit(&fit)?;
        let fraction = fit.entries.len() as f64 / lt_voxels.len() as f64;
        let best = probed
            .iter()
            .filter_map(|(c, _)| c.gain_db.zip(report.base_psnr_db))
            .map(|(gain, base)| extrapolated_gain_db(base, gain, fraction))
            .fold(f64::NEG_INFINITY, f64::max);
        let band_fitted = best > settings.min_gain_db / PROBE_MARGIN;
        report.probe = Some(ViewProbe {
            voxels: fit.entries.len(),
            band_voxels: lt_voxels.len(),
            candidates: probed.into_iter().map(|(c, _)| c).collect(),
            best_extrapolated_gain_db: best,
            band_fitted,
        });
        if !band_fitted {
            report.secs = start.elapsed().as_secs_f64();
            return Ok(report);
        }
        fit = fit_in(FitScope::Band)?;
    }
    let (candidates, mut parts): (Vec<ViewCandidate>, Vec<_>) = judge_fit(&fit)?.into_iter().unzip();
    report.candidates = candidates;
    let best_psnr = |list: &[ViewCandidate]| {
        (0..list.len()).max_by(|&a, &b| {
            let psnr = |i: usize| list[i].psnr_db.unwrap_or(f64::NEG_INFINITY);
            psnr(a).total_cmp(&psnr(b))
        })
    };
    let pick = if settings.choice == ViewChoice::Reflect {
        best_psnr(&report.candidates)
    } else if explicit {
        Some(0)
    } else {
        // The best gain; a candidate within AUTO_GAIN_SLACK_DB of it with fewer bytes wins.
        let best = report.best_gain_db();
        if best > settings.min_gain_db {
            report
                .candidates
                .iter()
                .enumerate()
                .filter(|(_, c)| c.gain_db.is_some_and(|g| g >= best - AUTO_GAIN_SLACK_DB))
                .min_by_key(|(_, c)| c.bytes)
                .map(|(i, _)| i)
        } else {
            None
        }
    };
    if let Some(i) = pick {
        report.chosen = report.candidates[i].choice;
        report.chosen_index = Some(i);
        (asset.view, asset.reflection) = parts.swap_remove(i);
    }
    report.secs = start.elapsed().as_secs_f64();
    Ok(report)
}
