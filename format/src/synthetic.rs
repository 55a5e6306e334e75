//! A seeded generator of smooth, realistic-looking light-transport fields, for tests,
//! the codec benchmark and end-to-end tests of `nelf`. Not ground truth (that is
//! `nelf-scene`'s path tracer): an analytic stand-in with the structure of a baked head.
//!
//! Scene: a sphere of radius `R = 0.1 m` ("head") centred at the origin; bricks are
//! those meeting a shell of half-thickness two voxels around it. At a voxel at `p`
//! with normal `n = p/|p|` the transport to light texel `k` (direction `ω_k` in the
//! world, solid angle `Ω_k`) in channel `c` is
//!
//! `T[c][k] = ρ_c(p)/π · wrap_c(n·ω_k) · V(p, ω_k) · Ω_k · (1 + 0.01·ξ)`,
//!
//! with `wrap_c(x) = max(0, x + w_c)/(1 + w_c)²` (energy-conserving wrap lighting: a
//! little subsurface scattering, strongest in red), `V` a soft shadow of the shoulders for low points and a soft
//! occluder on one side, `ρ` a skin-like albedo with smooth spatial variation and 3 %
//! per-voxel noise, and `ξ ∈ [−1, 1]` per-voxel, per-texel noise. Density is
//! `σ = 2000 1/m · exp(−((|p| − R)/(1.5 voxels))²)`.
//!
//! The PCA fit (mean, covariance of a subsample, orthogonal iteration, then a
//! Rayleigh–Ritz rotation so components come in order of variance) is a simple one for
//! this generator; the production fit belongs to the baker.

use std::f64::consts::PI;

use glam::DVec3;

use crate::asset::{
    Asset, CoefficientEncoding, Coefficients, GridGeometry, PcaModel, Reflection, ViewDependence,
    encode_density,
};
use crate::conventions::{
    ENV_H, ENV_W, LT_DIM, VIEW_HARMONICS, lt_index, rotation_y, texel_center_direction, texel_solid_angle,
};
use crate::error::{FormatError, Result};
use crate::spec::{BRICK_SIZE, BRICK_VOXELS};

/// Radius of the synthetic head, metres.
pub const HEAD_RADIUS_M: f64 = 0.1;
/// Peak density of the shell, 1/m.
pub const PEAK_DENSITY_PER_M: f64 = 2000.0;
/// Light-frame rotation of synthetic assets (about +y), radians.
pub const LIGHT_ROTATION_RAD: f64 = 0.3;

/// A synthetic light-transport field on a sparse brick grid.
#[derive(Debug, Clone)]
pub struct SyntheticField {
    grid: GridGeometry,
    bricks: Vec<[u16; 3]>,
    seed: u64,
    /// World direction and solid angle of each light texel.
    texels: Vec<(DVec3, f64)>,
}

impl SyntheticField {
    /// The field with the fewest bricks holding at least `voxels_target` voxels
    /// (grids of 1 … 1024 bricks a side), noise from `seed`.
    pub fn new(voxels_target: usize, seed: u64) -> Self {
        let bricks_target = voxels_target.div_ceil(BRICK_VOXELS).max(1);
        let mut n = 1u32;
        let (grid, bricks) = loop {
            let grid = grid_for(n);
            let bricks = shell_bricks(&grid);
            if bricks.len() >= bricks_target || n >= 1024 {
                break (grid, bricks);
            }
            n += 1;
        };
        let world_from_light = rotation_y(LIGHT_ROTATION_RAD);
        let texels = (0..ENV_H)
            .flat_map(|row| (0..ENV_W).map(move |col| (row, col)))
            .map(|(row, col)| {
                (
                    world_from_light * texel_center_direction(row, col, ENV_H, ENV_W),
                    texel_solid_angle(row, ENV_H, ENV_W),
                )
            })
            .collect();
        Self {
            grid,
            bricks,
            seed,
            texels,
        }
    }

    /// Grid geometry.
    pub fn grid(&self) -> GridGeometry {
        self.grid
    }

    /// Brick coordinates, sorted by (z, y, x).
    pub fn bricks(&self) -> &[[u16; 3]] {
        &self.bricks
    }

    /// Voxels in all bricks.
    pub fn voxel_count(&self) -> usize {
        self.bricks.len() * BRICK_VOXELS
    }

    /// World position (metres) of voxel `voxel`'s centre.
    pub fn position(&self, voxel: usize) -> DVec3 {
        let brick = self.bricks[voxel / BRICK_VOXELS];
        self.grid
            .voxel_center_m(brick, crate::asset::local_voxel_coords(voxel % BRICK_VOXELS))
    }

    /// Density σ (1/m) of every voxel.
    pub fn density(&self) -> Vec<f32> {
        let width = 1.5 * self.grid.voxel_size_m;
        (0..self.voxel_count())
            .map(|v| {
                let r = self.position(v).length();
                (PEAK_DENSITY_PER_M * (-((r - HEAD_RADIUS_M) / width).powi(2)).exp()) as f32
            })
            .collect()
    }

    /// Exact light-transport vector of voxel `voxel` into `out[..384]`.
    pub fn lt(&self, voxel: usize, out: &mut [f32]) {
        let p = self.position(voxel);
        let n = p.normalize_or(DVec3::Y);
        let h = splitmix(self.seed ^ (voxel as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let albedo_noise = 1.0 + 0.03 * unit(h);
        let pattern = 1.0 + 0.15 * (40.0 * p.x).sin() * (30.0 * p.y).cos() + 0.1 * (25.0 * p.z).sin();
        let albedo = [0.75, 0.50, 0.40].map(|a| a * pattern * albedo_noise);
        let wrap = [0.35, 0.2, 0.15];
        // Low points are shadowed from below by the shoulders; one side by a soft occluder.
        let low = smoothstep(0.3 * HEAD_RADIUS_M, -0.6 * HEAD_RADIUS_M, p.y);
        let side = smoothstep(-0.2 * HEAD_RADIUS_M, 0.8 * HEAD_RADIUS_M, p.x);
        for (k, &(w, omega)) in self.texels.iter().enumerate() {
            let cos = n.dot(w);
            let shoulders = 1.0 - 0.85 * low * smoothstep(-0.1, -0.6, w.y);
            let occluder = 1.0 - 0.5 * side * smoothstep(0.2, 0.9, w.x) * smoothstep(-0.3, 0.5, w.y);
            let noise = 1.0 + 0.01 * unit(splitmix(h ^ (k as u64 + 1)));
            let common = shoulders * occluder * noise * omega / PI;
            for c in 0..3 {
                let wrapped = (cos + wrap[c]).max(0.0) / ((1.0 + wrap[c]) * (1.0 + wrap[c]));
                out[lt_index(c, k / ENV_W, k % ENV_W)] = (albedo[c] * wrapped * common) as f32;
            }
        }
    }

    /// Fits a rank-`rank` PCA to the light-transport vectors of about `samples` voxels
    /// spread evenly over the field.
    pub fn fit_pca(&self, rank: usize, samples: usize) -> PcaModel {
        let rank = rank.clamp(1, LT_DIM);
        let stride = (self.voxel_count() / samples.max(1)).max(1);
        let chosen: Vec<usize> = (0..self.voxel_count()).step_by(stride).collect();
        let mut x = vec![0.0f32; LT_DIM];
        let mut mean = vec![0.0f64; LT_DIM];
        let mut rows: Vec<Vec<f64>> = Vec::with_capacity(chosen.len());
        for &v in &chosen {
            self.lt(v, &mut x);
            let row: Vec<f64> = x.iter().map(|&t| f64::from(t)).collect();
            for (m, t) in mean.iter_mut().zip(&row) {
                *m += t;
            }
            rows.push(row);
        }
        let count = chosen.len().max(1) as f64;
        for m in &mut mean {
            *m /= count;
        }
        // Covariance, upper triangle then mirrored.
        let mut cov = vec![0.0f64; LT_DIM * LT_DIM];
        for row in &mut rows {
            for (t, m) in row.iter_mut().zip(&mean) {
                *t -= m;
            }
            for i in 0..LT_DIM {
                let ri = row[i];
                if ri == 0.0 {
                    continue;
                }
                let target = &mut cov[i * LT_DIM + i..(i + 1) * LT_DIM];
                for (c, &rj) in target.iter_mut().zip(&row[i..]) {
                    *c += ri * rj;
                }
            }
        }
        for i in 0..LT_DIM {
            for j in i..LT_DIM {
                let v = cov[i * LT_DIM + j] / count;
                cov[i * LT_DIM + j] = v;
                cov[j * LT_DIM + i] = v;
            }
        }
        let basis = top_eigenvectors(&cov, rank, self.seed);
        PcaModel {
            mean: mean.iter().map(|&m| m as f32).collect(),
            basis: basis.iter().map(|&b| b as f32).collect(),
        }
    }

    /// Exact coefficients `c_k = B_k · (T − mean)` of every voxel, voxel-major.
    pub fn project(&self, pca: &PcaModel) -> Vec<f32> {
        let rank = pca.rank();
        let mut out = vec![0.0f32; self.voxel_count() * rank];
        let mut x = vec![0.0f32; LT_DIM];
        for (v, coefficients) in out.chunks_exact_mut(rank.max(1)).enumerate() {
            self.lt(v, &mut x);
            for (t, m) in x.iter_mut().zip(&pca.mean) {
                *t -= m;
            }
            for (k, c) in coefficients.iter_mut().enumerate() {
                *c = pca.component(k).iter().zip(&x).map(|(b, t)| b * t).sum();
            }
        }
        out
    }

    /// A complete asset: this field's density, a rank-`rank` PCA fitted to 4096
    /// sampled voxels, and coefficients quantized with `encoding`.
    pub fn asset(&self, rank: usize, encoding: CoefficientEncoding) -> Result<Asset> {
        let pca = self.fit_pca(rank, 4096);
        let coefficients = Coefficients::quantize(&self.project(&pca), pca.rank(), encoding)?;
        self.asset_with(pca, coefficients)
    }

    /// An asset with this field's grid and density and the given PCA model and coefficients.
    pub fn asset_with(&self, pca: PcaModel, coefficients: Coefficients) -> Result<Asset> {
        Ok(Asset {
            grid: self.grid,
            world_from_light: rotation_y(LIGHT_ROTATION_RAD),
            bricks: self.bricks.clone(),
            density: encode_density(&self.density())?,
            pca,
            coefficients,
            view: None,
            reflection: None,
            fine_density: None,
            metadata: serde_json::json!({
                "provenance": {
                    "generator": "nelf_format::synthetic",
                    "seed": self.seed,
                    "head_radius_m": HEAD_RADIUS_M,
                },
                "bake": { "voxel_size_m": self.grid.voxel_size_m, "bricks": self.bricks.len() },
            }),
        })
    }
}

/// A synthetic asset of at least `voxels_target` voxels (see [`SyntheticField`]).
pub fn synthetic_asset(
    voxels_target: usize,
    rank: usize,
    encoding: CoefficientEncoding,
    seed: u64,
) -> Result<Asset> {
    SyntheticField::new(voxels_target, seed).asset(rank, encoding)
}

/// A deterministic view-dependent part for `asset` (format 1.2, [`ViewDependence`]), for
/// tests of everything that reads one: `lobes` lobes (`J`, 1..=[`VIEW_HARMONICS`]), a
/// view basis of rank `rank` (`K_v`, `J·K_v ≤ 384`) and `asset.voxel_count()` voxels of
/// coefficients quantized with `encoding`, all a function of the arguments (and the
/// asset's voxel positions).
///
/// Not a physical model, but shaped like one: lobe `j` is mostly harmonic `j` (modulo
/// [`VIEW_HARMONICS`]) plus a seeded ±0.25 mix of the others; basis vector `i` is a
/// glossy highlight around a seeded light direction, `Ω_k · max(0, ω_k·a_i)⁴`, tinted
/// per channel, with 5 % seeded noise, then orthonormalised; the coefficients `d_ji` are
/// smooth in space (about 0.02 / (i + 1), a few percent of `T`), with 10 % per-voxel
/// noise. Set it with `asset.view = Some(synthetic_view(&asset, …)?)`.
pub fn synthetic_view(
    asset: &Asset,
    lobes: usize,
    rank: usize,
    encoding: CoefficientEncoding,
    seed: u64,
) -> Result<ViewDependence> {
    if !(1..=VIEW_HARMONICS).contains(&lobes) || rank == 0 || lobes * rank > LT_DIM {
        return Err(FormatError::InvalidAsset(format!(
            "a view part needs 1 to {VIEW_HARMONICS} lobes and rank ≥ 1 with lobes × rank ≤ {LT_DIM}, \
             not {lobes} × {rank}"
        )));
    }
    let hash = |a: u64, b: u64, c: u64| {
        unit(splitmix(
            seed ^ splitmix(a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ splitmix(b ^ (c << 32))),
        ))
    };
    let lobe_weights: Vec<f32> = (0..lobes * VIEW_HARMONICS)
        .map(|n| {
            let (j, l) = (n / VIEW_HARMONICS, n % VIEW_HARMONICS);
            let main = if l == j % VIEW_HARMONICS { 1.0 } else { 0.0 };
            (main + 0.25 * hash(1, j as u64, l as u64)) as f32
        })
        .collect();
    let world_from_light = asset.world_from_light;
    let mut basis = vec![0.0f64; rank * LT_DIM];
    for (i, vector) in basis.chunks_exact_mut(LT_DIM).enumerate() {
        let iu = i as u64;
        let axis = DVec3::new(hash(2, iu, 0), hash(2, iu, 1), hash(2, iu, 2)).normalize_or(DVec3::Y);
        for row in 0..ENV_H {
            for col in 0..ENV_W {
                let k = row * ENV_W + col;
                let omega = texel_solid_angle(row, ENV_H, ENV_W);
                let d = world_from_light * texel_center_direction(row, col, ENV_H, ENV_W);
                let gloss = d.dot(axis).max(0.0).powi(4);
                for c in 0..3 {
                    let tint = 1.0 + 0.2 * c as f64;
                    let noise = 0.05 * hash(3, iu, (c * 128 + k) as u64);
                    vector[lt_index(c, row, col)] = omega * (tint * gloss + noise);
                }
            }
        }
    }
    orthonormalize(&mut basis, LT_DIM);
    let per_voxel = lobes * rank;
    let values: Vec<f32> = (0..asset.voxel_count() * per_voxel)
        .map(|n| {
            let (v, m) = (n / per_voxel, n % per_voxel);
            let (j, i) = ((m / rank) as f64, (m % rank) as f64);
            let p = asset.voxel_position_m(v);
            let smooth = 0.5 + 0.5 * (17.0 * p.x + 1.3 * j + 0.7 * i).sin() * (13.0 * p.y - 0.9 * j).cos();
            let noise = 0.1 * hash(4, v as u64, m as u64);
            (0.02 / (1.0 + i) * (smooth + noise)) as f32
        })
        .collect();
    Ok(ViewDependence {
        lobes: lobe_weights,
        basis: basis.iter().map(|&b| b as f32).collect(),
        coefficients: Coefficients::quantize(&values, per_voxel, encoding)?,
    })
}

/// A deterministic reflection part for `asset` (format 1.3, [`Reflection`]), for tests of
/// everything that reads one: lobe exponent `exponent`, five eyes on an arc 0.6 m in
/// front of the head (+z), each voxel's normal pointing away from the head's centre
/// (turned by a seeded ±10°) and a scale smooth in space, about 0.05 (a few percent of
/// `T`, as a sheen's), with 10 % seeded noise and zero on a quarter of the voxels (the
/// part is fitted on the bake's band only). Set it with
/// `asset.reflection = Some(synthetic_reflection(&asset, …)?)`.
pub fn synthetic_reflection(asset: &Asset, exponent: f32, seed: u64) -> Result<Reflection> {
    let hash = |a: u64, b: u64| {
        unit(splitmix(
            seed ^ splitmix(a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b),
        ))
    };
    let eyes_m: Vec<[f32; 3]> = (0..5)
        .map(|e| {
            let angle = (e as f64 - 2.0) * 0.3;
            [(0.6 * angle.sin()) as f32, 0.05, (0.6 * angle.cos()) as f32]
        })
        .collect();
    let voxels = asset.voxel_count();
    let mut normals = Vec::with_capacity(voxels);
    let mut scales = Vec::with_capacity(voxels);
    for v in 0..voxels {
        let p = asset.voxel_position_m(v);
        let turn = DVec3::new(
            hash(1, 3 * v as u64),
            hash(1, 3 * v as u64 + 1),
            hash(1, 3 * v as u64 + 2),
        );
        let n = (p.normalize_or(DVec3::Y) + 0.17 * turn).normalize_or(DVec3::Y);
        normals.push(n.as_vec3().to_array());
        let smooth = 0.5 + 0.5 * (11.0 * p.x).sin() * (7.0 * p.y + 1.0).cos();
        let keep = hash(2, v as u64) > -0.5;
        scales.push(if keep {
            (0.05 * (smooth + 0.1 * hash(3, v as u64))).max(0.0) as f32
        } else {
            0.0
        });
    }
    Reflection::new(exponent, eyes_m, &normals, &scales)
}

/// A grid of `n³` bricks around the head with a 20 % margin.
fn grid_for(n: u32) -> GridGeometry {
    let half = 1.2 * HEAD_RADIUS_M;
    GridGeometry {
        bbox_min_m: [-half; 3],
        voxel_size_m: 2.0 * half / f64::from(n * BRICK_SIZE as u32),
        grid_bricks: [n; 3],
    }
}

/// Bricks whose box meets the shell `| |p| − R | ≤ 2 voxels`, in (z, y, x) order.
fn shell_bricks(grid: &GridGeometry) -> Vec<[u16; 3]> {
    let h = 2.0 * grid.voxel_size_m;
    let edge = BRICK_SIZE as f64 * grid.voxel_size_m;
    let n = grid.grid_bricks;
    let mut out = Vec::new();
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let lo = DVec3::from_array(grid.bbox_min_m)
                    + DVec3::new(f64::from(x), f64::from(y), f64::from(z)) * edge;
                let hi = lo + DVec3::splat(edge);
                let nearest = DVec3::ZERO.clamp(lo, hi).length();
                let farthest = lo.abs().max(hi.abs()).length();
                if nearest <= HEAD_RADIUS_M + h && farthest >= HEAD_RADIUS_M - h {
                    out.push([x as u16, y as u16, z as u16]);
                }
            }
        }
    }
    out
}

/// Top `rank` eigenvectors (rows, by decreasing eigenvalue) of the symmetric `LT_DIM²`
/// matrix `cov`: orthogonal iteration from a seeded start, then Rayleigh–Ritz.
fn top_eigenvectors(cov: &[f64], rank: usize, seed: u64) -> Vec<f64> {
    let d = LT_DIM;
    let mut q: Vec<f64> = (0..rank * d)
        .map(|i| unit(splitmix(seed.wrapping_add(i as u64 + 7))))
        .collect();
    orthonormalize(&mut q, d);
    let mut z = vec![0.0f64; rank * d];
    for _ in 0..60 {
        multiply(cov, &q, &mut z, d);
        std::mem::swap(&mut q, &mut z);
        orthonormalize(&mut q, d);
    }
    // Rayleigh–Ritz: eigen-decompose the small matrix H = Q C Qᵀ and rotate Q.
    multiply(cov, &q, &mut z, d);
    let mut h = vec![0.0f64; rank * rank];
    for a in 0..rank {
        for b in 0..rank {
            h[a * rank + b] = (0..d).map(|i| q[a * d + i] * z[b * d + i]).sum();
        }
    }
    let (values, vectors) = jacobi_eigen(&mut h, rank);
    let mut order: Vec<usize> = (0..rank).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let mut out = vec![0.0f64; rank * d];
    for (row, &e) in order.iter().enumerate() {
        for a in 0..rank {
            let w = vectors[a * rank + e];
            for i in 0..d {
                out[row * d + i] += w * q[a * d + i];
            }
        }
        // Fix the sign: largest-magnitude element positive (deterministic output).
        let v = &mut out[row * d..(row + 1) * d];
        let pivot = v
            .iter()
            .copied()
            .fold(0.0f64, |m, x| if x.abs() > m.abs() { x } else { m });
        if pivot < 0.0 {
            for x in v.iter_mut() {
                *x = -*x;
            }
        }
    }
    out
}

/// `z_r = C q_r` for each row `r` of `q`.
fn multiply(cov: &[f64], q: &[f64], z: &mut [f64], d: usize) {
    for (qr, zr) in q.chunks_exact(d).zip(z.chunks_exact_mut(d)) {
        for (i, zi) in zr.iter_mut().enumerate() {
            *zi = cov[i * d..(i + 1) * d].iter().zip(qr).map(|(c, x)| c * x).sum();
        }
    }
}

/// Modified Gram–Schmidt on the rows of `q` (twice, for stability).
fn orthonormalize(q: &mut [f64], d: usize) {
    let rank = q.len() / d;
    for _ in 0..2 {
        for r in 0..rank {
            for s in 0..r {
                let dot: f64 = (0..d).map(|i| q[r * d + i] * q[s * d + i]).sum();
                for i in 0..d {
                    q[r * d + i] -= dot * q[s * d + i];
                }
            }
            let norm = q[r * d..(r + 1) * d].iter().map(|x| x * x).sum::<f64>().sqrt();
            let scale = if norm > 1e-300 { 1.0 / norm } else { 0.0 };
            q[r * d..(r + 1) * d].iter_mut().for_each(|x| *x *= scale);
        }
    }
}

/// Cyclic Jacobi eigen-decomposition of the symmetric `n × n` matrix `a` (destroyed):
/// returns eigenvalues and eigenvectors as columns of a row-major matrix.
fn jacobi_eigen(a: &mut [f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![0.0f64; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _ in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * n + j] * a[i * n + j])
            .sum();
        let total: f64 = a.iter().map(|x| x * x).sum();
        if off <= 1e-30 * total.max(1e-300) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq.abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ((0..n).map(|i| a[i * n + i]).collect(), v)
}

/// Hermite smoothstep from `edge0` to `edge1` (either order).
fn smoothstep(edge0: f64, edge1: f64, x: f64) -> f64 {
    let t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The `SplitMix64` finaliser: a well-mixed 64-bit hash.
fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A hash mapped to `[−1, 1)`.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conventions::{LatLong, shade};

    #[test]
    fn field_is_deterministic_and_sized() {
        let a = SyntheticField::new(3000, 5);
        let b = SyntheticField::new(3000, 5);
        assert!(a.voxel_count() >= 3000);
        assert_eq!(a.bricks(), b.bricks());
        let (mut x, mut y) = (vec![0.0; LT_DIM], vec![0.0; LT_DIM]);
        a.lt(17, &mut x);
        b.lt(17, &mut y);
        assert_eq!(x, y);
        let d = a.density();
        assert!(d.iter().all(|&s| s >= 0.0) && d.iter().any(|&s| s > 1000.0));
    }

    #[test]
    fn lambertian_white_light_gives_plausible_radiance() {
        // Under uniform unit radiance, a wrapped-Lambertian point reflects about its
        // albedo (≤ 1, > 0.2 for unshadowed upper points).
        let f = SyntheticField::new(2000, 1);
        let top = (0..f.voxel_count())
            .max_by(|&a, &b| f.position(a).y.total_cmp(&f.position(b).y))
            .unwrap();
        let mut t = vec![0.0; LT_DIM];
        f.lt(top, &mut t);
        let rgb = shade(&t, &LatLong::constant(ENV_W, ENV_H, [1.0; 3]));
        assert!(rgb.iter().all(|&v| v > 0.2 && v < 1.0), "{rgb:?}");
    }

    #[test]
    fn synthetic_view_is_deterministic_valid_and_small() {
        let field = SyntheticField::new(1500, 3);
        let asset = field.asset(4, CoefficientEncoding::U8Affine).unwrap();
        for (lobes, rank, encoding) in [
            (1, 1, CoefficientEncoding::U8Affine),
            (3, 2, CoefficientEncoding::F16),
            (8, 48, CoefficientEncoding::U8Affine),
        ] {
            let view = synthetic_view(&asset, lobes, rank, encoding, 9).unwrap();
            assert!(view == synthetic_view(&asset, lobes, rank, encoding, 9).unwrap());
            assert!(view != synthetic_view(&asset, lobes, rank, encoding, 10).unwrap());
            assert_eq!((view.lobe_count(), view.rank()), (lobes, rank));
            assert_eq!(view.coefficients.encoding(), encoding);
            view.validate(asset.voxel_count()).unwrap();
            // A few percent of T: the view part of a voxel is well below its PCA part.
            let v = asset.voxel_count() / 2;
            let mut d = vec![0.0f32; lobes * rank];
            view.coefficients.voxel_f32(v, &mut d);
            let mut extra = [0.0f32; LT_DIM];
            view.add_to(&d, [0.3, 0.5, 0.8], &mut extra);
            let norm = |t: &[f32]| t.iter().map(|x| x * x).sum::<f32>().sqrt();
            let t = asset.reconstruct_lt(v);
            assert!(
                norm(&extra) > 0.0 && norm(&extra) < 0.5 * norm(&t),
                "{} vs {}",
                norm(&extra),
                norm(&t)
            );
        }
        assert!(synthetic_view(&asset, 0, 1, CoefficientEncoding::F16, 1).is_err());
        assert!(synthetic_view(&asset, VIEW_HARMONICS + 1, 1, CoefficientEncoding::F16, 1).is_err());
        assert!(synthetic_view(&asset, 2, 193, CoefficientEncoding::F16, 1).is_err());
    }

    #[test]
    fn pca_is_orthonormal_ordered_and_accurate() {
        let f = SyntheticField::new(4000, 2);
        let pca = f.fit_pca(8, 1000);
        for a in 0..8 {
            for b in 0..8 {
                let dot: f32 = pca
                    .component(a)
                    .iter()
                    .zip(pca.component(b))
                    .map(|(x, y)| x * y)
                    .sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-4, "{a} {b} {dot}");
            }
        }
        let coefficients = f.project(&pca);
        let variance = |k: usize| coefficients.iter().skip(k).step_by(8).map(|c| c * c).sum::<f32>();
        assert!(variance(0) >= variance(1) && variance(1) >= variance(7));
        // Reconstruction with 8 components explains most of the signal.
        let (mut err, mut total) = (0.0f64, 0.0f64);
        let (mut t, mut r) = (vec![0.0; LT_DIM], vec![0.0; LT_DIM]);
        for v in (0..f.voxel_count()).step_by(7) {
            f.lt(v, &mut t);
            pca.reconstruct_into(&coefficients[v * 8..(v + 1) * 8], &mut r);
            for (a, b) in t.iter().zip(&r) {
                err += f64::from(a - b).powi(2);
                total += f64::from(*a).powi(2);
            }
        }
        assert!(err < 0.03 * total, "relative error² {}", err / total);
    }
}
