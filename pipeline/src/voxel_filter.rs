//! The box filter a network's field is baked through ([`VoxelFiltered`],
//! [`crate::NETWORK_VOXEL_FILTER`] sub-points per voxel edge): a trained network's
//! skin is a shell thinner than a voxel, which point samples at voxel centres alias
//! into stripes.

use glam::Vec3;
use nelf_format::conventions::LT_DIM;
use nelf_scene::adapter::{Adapted, Adapter};
use nelf_scene::field::{FieldError, FieldSource, ViewPolicy, check_batch, check_density_batch};

/// A field box-filtered over voxels: each query point stands for the cube of side
/// `voxel_m` around it, sampled on a fixed `n³` lattice of sub-points (cell centres).
/// σ is their mean — the optical depth a ray crossing the voxel meets, wherever a
/// shell thinner than the voxel lies inside it, which point samples at voxel centres
/// alias into stripes — and `T` their σ-weighted mean (the light the voxel's opacity
/// sends out), the plain mean where σ is 0 at every sub-point. `n = 1` is the inner
/// field at the voxel centres. Its light frame is the inner field's.
pub struct VoxelFiltered<'a> {
    inner: &'a dyn FieldSource,
    offsets: Vec<Vec3>,
    half_voxel_m: f32,
}

impl std::fmt::Debug for VoxelFiltered<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VoxelFiltered")
            .field("sub_points", &self.offsets.len())
            .field("voxel_m", &(2.0 * self.half_voxel_m))
            .finish_non_exhaustive()
    }
}

impl<'a> VoxelFiltered<'a> {
    /// `inner` filtered over voxels of side `voxel_m` with `n³` sub-points.
    pub fn new(inner: &'a dyn FieldSource, voxel_m: f32, n: usize) -> Result<Adapted<Self>, FieldError> {
        if !(voxel_m.is_finite() && voxel_m > 0.0) || n == 0 || n > 8 {
            return Err(FieldError::Settings(format!(
                "a voxel filter needs a positive voxel size and 1 to 8 sub-points per edge, got {voxel_m} m and {n}"
            )));
        }
        let cell = voxel_m / n as f32;
        let at = |i: usize| (i as f32 + 0.5) * cell - 0.5 * voxel_m;
        let offsets = (0..n * n * n)
            .map(|i| Vec3::new(at(i % n), at(i / n % n), at(i / (n * n))))
            .collect();
        Ok(Adapted(Self {
            inner,
            offsets,
            half_voxel_m: 0.5 * voxel_m,
        }))
    }

    fn sub_points(&self, points: &[Vec3]) -> Vec<Vec3> {
        points
            .iter()
            .flat_map(|p| self.offsets.iter().map(move |o| *p + *o))
            .collect()
    }
}

impl Adapter for VoxelFiltered<'_> {
    fn base(&self) -> &dyn FieldSource {
        self.inner
    }

    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        check_batch(points, density, lt)?;
        let k = self.offsets.len();
        let sub = self.sub_points(points);
        let mut sub_density = vec![0.0f32; sub.len()];
        let mut sub_lt = vec![0.0f32; sub.len() * LT_DIM];
        self.inner.evaluate(&sub, view, &mut sub_density, &mut sub_lt)?;
        for (i, (d, t)) in density.iter_mut().zip(lt.chunks_exact_mut(LT_DIM)).enumerate() {
            let sigmas = &sub_density[i * k..(i + 1) * k];
            let total: f32 = sigmas.iter().map(|s| s.max(0.0)).sum();
            *d = sigmas.iter().sum::<f32>() / k as f32;
            t.fill(0.0);
            for (j, s) in sigmas.iter().enumerate() {
                let w = if total > 0.0 {
                    s.max(0.0) / total
                } else {
                    1.0 / k as f32
                };
                let from = &sub_lt[(i * k + j) * LT_DIM..(i * k + j + 1) * LT_DIM];
                for (a, b) in t.iter_mut().zip(from) {
                    *a += w * b;
                }
            }
        }
        Ok(())
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        let (lo, hi) = self.inner.bounds();
        (
            lo - Vec3::splat(self.half_voxel_m),
            hi + Vec3::splat(self.half_voxel_m),
        )
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        check_density_batch(points, density)?;
        let k = self.offsets.len();
        let sub = self.sub_points(points);
        let mut sub_density = vec![0.0f32; sub.len()];
        self.inner.evaluate_density(&sub, &mut sub_density)?;
        for (d, s) in density.iter_mut().zip(sub_density.chunks_exact(k)) {
            *d = s.iter().sum::<f32>() / k as f32;
        }
        Ok(())
    }
}
