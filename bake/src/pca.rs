//! Weighted principal component analysis of light-transport vectors (Pearson 1901;
//! the weighted form as in Jolliffe, *Principal Component Analysis*, 2nd ed., §14.2).
//!
//! With vectors `T_v` (384 numbers) and weights `w_v > 0`:
//!
//! * mean `μ = Σ w_v T_v / Σ w_v`;
//! * covariance `C = Σ w_v (T_v − μ)(T_v − μ)ᵀ / Σ w_v` (384 × 384, accumulated in
//!   `f64` over fixed chunks of vectors whose partial sums are added in chunk order,
//!   so the result does not depend on thread scheduling);
//! * `C = V Λ Vᵀ` by a symmetric eigendecomposition (nalgebra's `SymmetricEigen`),
//!   eigenvalues sorted in decreasing order; each eigenvector's sign is fixed so that
//!   its entry of largest magnitude is positive (first such entry on ties);
//! * the rank-`K` model keeps the first `K` eigenvectors `B_k`; coefficients are
//!   `c_vk = B_k · (T_v − μ)` and `T_v ≈ μ + Σ_k c_vk B_k`;
//! * energy kept `E(K) = Σ_{k<K} λ_k / Σ_k λ_k` (negative round-off eigenvalues count 0):
//!   the weighted share of variance about the mean that the model reproduces.
//!
//! The baker weights each voxel by how much it shows in the capture's images, so
//! the basis spends its components where pixels are.

use nalgebra::{DMatrix, SymmetricEigen};
use nelf_format::PcaModel;
use nelf_format::conventions::LT_DIM;
use rayon::prelude::*;

use crate::error::{BakeError, Result};

/// Vectors per chunk of the covariance and projection passes.
const CHUNK: usize = 2048;
/// Eigenvalues at most this fraction of the largest count as zero (numerical rank).
pub const RANK_TOLERANCE: f64 = 1e-9;

/// A fitted weighted PCA, every component kept (384).
#[derive(Debug, Clone, PartialEq)]
pub struct WeightedPca {
    /// Weighted mean, 384 numbers.
    pub mean: Vec<f64>,
    /// Eigenvalues of the weighted covariance, decreasing.
    pub eigenvalues: Vec<f64>,
    /// Unit eigenvectors, component `k` at `k·384 .. (k+1)·384`.
    pub components: Vec<f64>,
    /// Σ w over the vectors.
    pub total_weight: f64,
    /// Vectors fitted.
    pub count: usize,
}

/// Fits the weighted PCA of `lt` (`n × 384`, channel-major) with weights `weights` (`n`,
/// finite, ≥ 0, positive sum).
pub fn fit_weighted_pca(lt: &[f32], weights: &[f64]) -> Result<WeightedPca> {
    let n = weights.len();
    if lt.len() != n * LT_DIM || n == 0 {
        return Err(BakeError::Pca(format!(
            "{} light-transport floats for {n} weights (need 384 per vector, at least one vector)",
            lt.len()
        )));
    }
    if let Some(i) = weights.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
        return Err(BakeError::Pca(format!(
            "weight {i} = {} is not finite and ≥ 0",
            weights[i]
        )));
    }
    if let Some(i) = lt.iter().position(|v| !v.is_finite()) {
        return Err(BakeError::Pca(format!(
            "vector {} element {} is not finite",
            i / LT_DIM,
            i % LT_DIM
        )));
    }
    let total_weight: f64 = weights.iter().sum();
    if !(total_weight > 0.0 && total_weight.is_finite()) {
        return Err(BakeError::Pca(format!("the weights sum to {total_weight}")));
    }

    // Mean: per-chunk partial sums added in chunk order.
    let partial_means: Vec<Vec<f64>> = lt
        .par_chunks(CHUNK * LT_DIM)
        .zip(weights.par_chunks(CHUNK))
        .map(|(t, w)| {
            let mut acc = vec![0.0f64; LT_DIM];
            for (v, &wv) in t.chunks_exact(LT_DIM).zip(w) {
                for (a, &x) in acc.iter_mut().zip(v) {
                    *a += wv * f64::from(x);
                }
            }
            acc
        })
        .collect();
    let mut mean = vec![0.0f64; LT_DIM];
    for p in &partial_means {
        for (m, x) in mean.iter_mut().zip(p) {
            *m += x;
        }
    }
    for m in &mut mean {
        *m /= total_weight;
    }

    // Covariance: Xᵀ X per chunk with rows √w (T − μ).
    let partial_cov: Vec<DMatrix<f64>> = lt
        .par_chunks(CHUNK * LT_DIM)
        .zip(weights.par_chunks(CHUNK))
        .map(|(t, w)| {
            let rows = w.len();
            let x = DMatrix::<f64>::from_fn(rows, LT_DIM, |i, j| {
                w[i].sqrt() * (f64::from(t[i * LT_DIM + j]) - mean[j])
            });
            x.tr_mul(&x)
        })
        .collect();
    let mut cov = DMatrix::<f64>::zeros(LT_DIM, LT_DIM);
    for p in &partial_cov {
        cov += p;
    }
    cov /= total_weight;
    // Exact symmetry (the products are symmetric up to rounding).
    let sym = (&cov + cov.transpose()) * 0.5;

    let eigen = SymmetricEigen::new(sym);
    let mut order: Vec<usize> = (0..LT_DIM).collect();
    order.sort_by(|&a, &b| {
        eigen.eigenvalues[b]
            .total_cmp(&eigen.eigenvalues[a])
            .then(a.cmp(&b))
    });
    let mut eigenvalues = Vec::with_capacity(LT_DIM);
    let mut components = Vec::with_capacity(LT_DIM * LT_DIM);
    for &i in &order {
        eigenvalues.push(eigen.eigenvalues[i]);
        let column = eigen.eigenvectors.column(i);
        let mut pivot = 0;
        for j in 1..LT_DIM {
            if column[j].abs() > column[pivot].abs() {
                pivot = j;
            }
        }
        let sign = if column[pivot] < 0.0 { -1.0 } else { 1.0 };
        components.extend(column.iter().map(|&x| sign * x));
    }
    Ok(WeightedPca {
        mean,
        eigenvalues,
        components,
        total_weight,
        count: n,
    })
}

impl WeightedPca {
    /// Σ of the (non-negative) eigenvalues: the weighted variance about the mean.
    pub fn total_variance(&self) -> f64 {
        self.eigenvalues.iter().map(|l| l.max(0.0)).sum()
    }

    /// Share of the variance the first `rank` components keep (1 when there is none).
    pub fn energy_kept(&self, rank: usize) -> f64 {
        let total = self.total_variance();
        if total <= 0.0 {
            return 1.0;
        }
        let kept: f64 = self.eigenvalues.iter().take(rank).map(|l| l.max(0.0)).sum();
        (kept / total).min(1.0)
    }

    /// Components whose eigenvalue exceeds [`RANK_TOLERANCE`] times the largest, capped
    /// at the number of vectors.
    pub fn numerical_rank(&self) -> usize {
        let largest = self.eigenvalues.first().copied().unwrap_or(0.0);
        if largest <= 0.0 || largest.is_nan() {
            return 0;
        }
        self.eigenvalues
            .iter()
            .filter(|&&l| l > RANK_TOLERANCE * largest)
            .count()
            .min(self.count)
    }

    /// The `f32` model of the first `rank` components (at least 1, at most 384).
    pub fn model(&self, rank: usize) -> PcaModel {
        let rank = rank.clamp(1, LT_DIM);
        PcaModel {
            mean: self.mean.iter().map(|&m| m as f32).collect(),
            basis: self.components[..rank * LT_DIM]
                .iter()
                .map(|&b| b as f32)
                .collect(),
        }
    }
}

/// Coefficients `c_vk = B_k · (T_v − μ)` (`n × K`, voxel-major) of `lt` (`n × 384`)
/// in `model`, computed in `f64` from the model's `f32` numbers.
pub fn project_coefficients(model: &PcaModel, lt: &[f32]) -> Vec<f32> {
    let rank = model.rank();
    let n = lt.len() / LT_DIM;
    if rank == 0 || n == 0 {
        return Vec::new();
    }
    let basis_t = DMatrix::<f64>::from_fn(LT_DIM, rank, |j, k| f64::from(model.component(k)[j]));
    let chunks: Vec<Vec<f32>> = lt
        .par_chunks(CHUNK * LT_DIM)
        .map(|t| {
            let rows = t.len() / LT_DIM;
            let x = DMatrix::<f64>::from_fn(rows, LT_DIM, |i, j| {
                f64::from(t[i * LT_DIM + j]) - f64::from(model.mean[j])
            });
            let c = x * &basis_t;
            let mut out = Vec::with_capacity(rows * rank);
            for i in 0..rows {
                for k in 0..rank {
                    out.push(c[(i, k)] as f32);
                }
            }
            out
        })
        .collect();
    chunks.concat()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn recovers_a_weighted_rank_two_structure() {
        let mut rng = Pcg64::seed_from_u64(5);
        let mut dirs = vec![[0.0f64; LT_DIM]; 2];
        for d in &mut dirs {
            for x in d.iter_mut() {
                *x = rng.random_range(-1.0..1.0);
            }
        }
        let n = 300;
        let mut lt = Vec::with_capacity(n * LT_DIM);
        let mut weights = Vec::with_capacity(n);
        for _ in 0..n {
            let a: f64 = rng.random_range(-2.0..2.0);
            let b: f64 = rng.random_range(-0.5..0.5);
            for (d0, d1) in dirs[0].iter().zip(&dirs[1]) {
                lt.push((1.0 + a * d0 + b * d1) as f32);
            }
            weights.push(rng.random_range(0.5..2.0));
        }
        let pca = fit_weighted_pca(&lt, &weights).unwrap();
        assert_eq!(pca.numerical_rank(), 2);
        assert!(pca.energy_kept(2) > 1.0 - 1e-9);
        assert!(pca.energy_kept(1) > 0.8 && pca.energy_kept(1) < 1.0);
        for w in pca.eigenvalues.windows(2) {
            assert!(w[0] >= w[1]);
        }
        // Rank-2 reconstruction is exact up to f32 rounding.
        let model = pca.model(2);
        let c = project_coefficients(&model, &lt);
        let mut out = vec![0.0f32; LT_DIM];
        for v in 0..n {
            model.reconstruct_into(&c[v * 2..v * 2 + 2], &mut out);
            for j in 0..LT_DIM {
                assert!((out[j] - lt[v * LT_DIM + j]).abs() < 1e-4, "{v} {j}");
            }
        }
        // Zero weights leave a vector out of the fit entirely.
        let mut w2 = weights.clone();
        w2[0] = 0.0;
        let mut lt2 = lt.clone();
        lt2[..LT_DIM].fill(1e3);
        let a = fit_weighted_pca(&lt2, &w2).unwrap();
        let b = fit_weighted_pca(&lt[LT_DIM..], &weights[1..]).unwrap();
        for (x, y) in a.mean.iter().zip(&b.mean) {
            assert!((x - y).abs() < 1e-9);
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert!(fit_weighted_pca(&[0.0; LT_DIM], &[0.0]).is_err());
        assert!(fit_weighted_pca(&[0.0; LT_DIM], &[f64::NAN]).is_err());
        assert!(fit_weighted_pca(&[0.0; 10], &[1.0]).is_err());
        let mut lt = vec![0.0f32; LT_DIM];
        lt[3] = f32::INFINITY;
        assert!(fit_weighted_pca(&lt, &[1.0]).is_err());
    }
}
