//! Parts of one field swapped for another's (`nelf eval network --split`, to tell
//! where a learned field's error lies): [`DensityAndTransport`] (the density of one,
//! the transport of the other), [`TransportShapeFrom`] (one field's colour under a
//! lighting, the other's change of it with the lighting) and [`TrueNormalsLambert`]
//! (the clamped cosine about a mesh's true normals, a shape for the latter).

use glam::{DMat3, Vec3};
use nelf_format::conventions::{LT_DIM, LatLong};
use nelf_scene::adapter::{Adapted, Adapter};
use nelf_scene::field::{FieldError, FieldSource, MeshField, ViewPolicy, check_batch, check_density_batch};
use rayon::prelude::*;

/// A field with the density of one source and the light transport of another, at
/// the same points: the ablation that tells a learned field's geometry error from its
/// shading error (`nelf eval network --split`: the ground truth's density with the
/// network's transport, and the reverse). Bounds are the density source's (the
/// density is zero outside them); the light frame is the transport source's.
pub struct DensityAndTransport<'a> {
    density: &'a dyn FieldSource,
    transport: &'a dyn FieldSource,
}

impl std::fmt::Debug for DensityAndTransport<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DensityAndTransport").finish_non_exhaustive()
    }
}

impl<'a> DensityAndTransport<'a> {
    /// σ from `density`, `T` from `transport`.
    pub fn new(density: &'a dyn FieldSource, transport: &'a dyn FieldSource) -> Adapted<Self> {
        Adapted(Self { density, transport })
    }
}

impl Adapter for DensityAndTransport<'_> {
    fn base(&self) -> &dyn FieldSource {
        self.density
    }

    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.transport.evaluate(points, view, density, lt)?;
        self.density.evaluate_density(points, density)
    }

    fn evaluate_directions(
        &self,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.transport
            .evaluate_directions(points, directions, density, lt)?;
        self.density.evaluate_density(points, density)
    }

    fn world_from_light(&self) -> DMat3 {
        self.transport.world_from_light()
    }
}

/// A field with the density of `colour` and, at each point, the light transport of
/// `shape` scaled per channel so that under `lighting` it shades to what `colour`'s
/// transport shades to: `T_c = T^shape_c · (T^colour_c·L)/(T^shape_c·L)`. With a
/// learned field as `colour` and the ground truth as `shape`, it keeps what the
/// network reproduces of the source photos and replaces only how that colour changes
/// with the lighting (`nelf eval network --split`). Where `shape` shades a channel to
/// almost nothing under `lighting`, `colour`'s own transport is kept. Bounds are
/// `colour`'s, the light frame `shape`'s.
pub struct TransportShapeFrom<'a> {
    shape: &'a dyn FieldSource,
    colour: &'a dyn FieldSource,
    shape_light: LatLong,
    colour_light: LatLong,
}

impl std::fmt::Debug for TransportShapeFrom<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TransportShapeFrom").finish_non_exhaustive()
    }
}

impl<'a> TransportShapeFrom<'a> {
    /// `shape`'s transport at `colour`'s brightness under `lighting` (an environment
    /// map in the world frame), `colour`'s density.
    pub fn new(
        shape: &'a dyn FieldSource,
        colour: &'a dyn FieldSource,
        lighting: &LatLong,
    ) -> Result<Adapted<Self>, FieldError> {
        let project = |source: &dyn FieldSource| {
            nelf_format::conventions::project_envmap(lighting, source.world_from_light())
                .map_err(|e| FieldError::Settings(format!("the lighting: {e}")))
        };
        Ok(Adapted(Self {
            shape_light: project(shape)?,
            colour_light: project(colour)?,
            shape,
            colour,
        }))
    }

    fn rescale(&self, lt: &mut [f32], colour_lt: &[f32]) {
        use nelf_format::conventions::{ENV_TEXELS, shade};
        for (t, own) in lt.chunks_exact_mut(LT_DIM).zip(colour_lt.chunks_exact(LT_DIM)) {
            let want = shade(own, &self.colour_light);
            let have = shade(t, &self.shape_light);
            for c in 0..3 {
                let channel = c * ENV_TEXELS..(c + 1) * ENV_TEXELS;
                if have[c] > 1e-6 {
                    let scale = want[c] / have[c];
                    t[channel].iter_mut().for_each(|v| *v *= scale);
                } else {
                    t[channel.clone()].copy_from_slice(&own[channel]);
                }
            }
        }
    }
}

impl Adapter for TransportShapeFrom<'_> {
    fn base(&self) -> &dyn FieldSource {
        self.colour
    }

    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        let mut colour_lt = vec![0.0f32; lt.len()];
        self.colour.evaluate(points, view, density, &mut colour_lt)?;
        let mut unused = vec![0.0f32; points.len()];
        self.shape.evaluate(points, view, &mut unused, lt)?;
        self.rescale(lt, &colour_lt);
        Ok(())
    }

    fn world_from_light(&self) -> DMat3 {
        self.shape.world_from_light()
    }
}

/// The light transport of an unshadowed Lambertian surface with the normals of a
/// mesh: at each point, `T_c(ω_k) = max(0, n·ω_k)·Ω_k` for every channel, `n` the
/// closest surface point's shading normal (as seen from the point). No density
/// (σ = 0): a shape for [`TransportShapeFrom`], the shading prior of
/// `nelf_field::prior` with the true normals in place of the network's. Bounds and
/// light frame are the mesh's.
pub struct TrueNormalsLambert<'a> {
    mesh: &'a MeshField,
    /// `(ω_k in the world frame, Ω_k)` of the 128 texels.
    texels: Vec<(Vec3, f32)>,
}

impl std::fmt::Debug for TrueNormalsLambert<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrueNormalsLambert").finish_non_exhaustive()
    }
}

impl<'a> TrueNormalsLambert<'a> {
    /// The clamped cosine about `mesh`'s normals, in `mesh`'s light frame.
    pub fn new(mesh: &'a MeshField) -> Adapted<Self> {
        use nelf_format::conventions::{ENV_H, ENV_W, texel_center_direction, texel_solid_angle};
        let world_from_light = mesh.world_from_light();
        let texels = (0..ENV_H * ENV_W)
            .map(|k| {
                let (row, col) = (k / ENV_W, k % ENV_W);
                let dir = world_from_light * texel_center_direction(row, col, ENV_H, ENV_W);
                (dir.as_vec3(), texel_solid_angle(row, ENV_H, ENV_W) as f32)
            })
            .collect();
        Adapted(Self { mesh, texels })
    }
}

impl Adapter for TrueNormalsLambert<'_> {
    fn base(&self) -> &dyn FieldSource {
        self.mesh
    }

    fn evaluate(
        &self,
        points: &[Vec3],
        _view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        check_batch(points, density, lt)?;
        density.fill(0.0);
        points
            .par_iter()
            .zip(lt.par_chunks_exact_mut(LT_DIM))
            .for_each(|(x, t)| {
                let n = self
                    .mesh
                    .surface_point_seen_from(*x)
                    .map_or(Vec3::ZERO, |(sp, _)| sp.shading_normal);
                let texels = self.texels.len();
                for (k, (dir, solid_angle)) in self.texels.iter().enumerate() {
                    let value = n.dot(*dir).max(0.0) * solid_angle;
                    for c in 0..3 {
                        t[c * texels + k] = value;
                    }
                }
            });
        Ok(())
    }

    /// No density anywhere (not the mesh's).
    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        check_density_batch(points, density)?;
        density.fill(0.0);
        Ok(())
    }
}
