//! The baker's signed density ([`SignedLogDensity`]): a field's density re-encoded
//! as a signed affine function of `ln σ`, so that a grid of it, interpolated
//! trilinearly and clipped at 0 (SPEC's signed-density flag), puts the surface where
//! the field has it. An [`Adapter`]: light transport, bounds and light frame are the
//! inner field's.

use glam::Vec3;

use crate::adapter::{Adapted, Adapter};
use crate::field::{FieldError, FieldSource, ViewPolicy};

/// A field whose density is re-encoded as a *signed* affine function of `ln σ`, so
/// that a grid of it, interpolated trilinearly and clipped at 0 by the renderer
/// (SPEC's signed-density flag), puts the surface where the inner field has it.
///
/// Sampled on a grid, a steep density (a trained network's skin rises by orders of
/// magnitude within a millimetre) interpolates into a ramp that is already opaque
/// at its low end, one voxel outside the surface: a baked head renders swollen by
/// about a voxel, a bright halo round every silhouette. Near a surface `ln σ` is
/// close to affine in the signed distance `d` (σ ∝ `e^{−k·d}`), so
/// `d̂ = −ln(σ/σ_iso)/k` estimates the distance to the level `σ_iso`, and the stored
/// value is the ground-truth bake's signed shell profile (`nelf-bake`'s
/// `ShellProfile::Signed`) of `d̂`:
/// `s = clamp(g · (ℓ − d̂), −g·(ℓ + 2Δ), g·(ℓ + 2Δ))` with `g = 2 ln 2 / ℓ²`, so a
/// ray meets optical depth `ln 2` exactly at `σ = σ_iso`, as for a mesh. Where the
/// inner σ is 0 (pruned, empty) `s` is the negative cap. Light transport is the
/// inner field's. Over a box filter (`nelf_pipeline::VoxelFiltered`) the mean of an
/// exponential skin across a voxel's sub-points moves the level out by
/// `ln cosh(kΔ/2n)/k` (0.11 voxels for `n = 2`, `kΔ = 4`), against 0.3–0.45 voxels
/// for σ itself (`pipeline/tests/adapters.rs`).
///
/// Its constructors return it [`Adapted`] (a [`FieldSource`]), which dereferences to
/// it for [`Self::encode`] and [`Self::encode_distance`].
pub struct SignedLogDensity<'a> {
    inner: &'a dyn FieldSource,
    iso_per_m: f32,
    decay_per_m: f32,
    lead_m: f32,
    voxel_m: f32,
}

impl std::fmt::Debug for SignedLogDensity<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SignedLogDensity")
            .field("iso_per_m", &self.iso_per_m)
            .field("decay_per_m", &self.decay_per_m)
            .field("lead_m", &self.lead_m)
            .field("voxel_m", &self.voxel_m)
            .finish_non_exhaustive()
    }
}

impl<'a> SignedLogDensity<'a> {
    /// `inner` with its surface at density `iso_per_m` (1/m), across which σ falls
    /// by `e` every `1/decay_per_m` metres, encoded with lead `lead_m` on a grid of
    /// voxel `voxel_m`.
    pub fn new(
        inner: &'a dyn FieldSource,
        iso_per_m: f32,
        decay_per_m: f32,
        lead_m: f32,
        voxel_m: f32,
    ) -> Result<Adapted<Self>, FieldError> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        if !(ok(iso_per_m) && ok(decay_per_m) && ok(lead_m) && ok(voxel_m)) {
            return Err(FieldError::Settings(format!(
                "a signed log density needs positive settings, got σ_iso {iso_per_m}/m, decay {decay_per_m}/m, lead {lead_m} m, voxel {voxel_m} m"
            )));
        }
        Ok(Adapted(Self {
            inner,
            iso_per_m,
            decay_per_m,
            lead_m,
            voxel_m,
        }))
    }

    /// `inner` whose σ grows by `e` every `skin_m` metres across its surface, the
    /// surface at `σ_iso = ln 2 / skin_m`, where a ray through such a skin reaches
    /// optical depth ln 2 (`nelf bake --network-skin-mm`).
    pub fn with_skin(
        inner: &'a dyn FieldSource,
        skin_m: f32,
        lead_m: f32,
        voxel_m: f32,
    ) -> Result<Adapted<Self>, FieldError> {
        Self::new(
            inner,
            std::f32::consts::LN_2 / skin_m,
            1.0 / skin_m,
            lead_m,
            voxel_m,
        )
    }

    /// The stored signed value for an inner density `sigma` (1/m).
    pub fn encode(&self, sigma: f32) -> f32 {
        if sigma <= 0.0 || sigma.is_nan() {
            return self.encode_distance(f32::INFINITY);
        }
        self.encode_distance(-(sigma / self.iso_per_m).ln() / self.decay_per_m)
    }

    /// The stored signed value at `distance_m` outside a surface (negative: inside),
    /// the profile [`SignedLogDensity::encode`] gives its estimate `d̂`: another
    /// surface, such as the visual hull, stored the same way.
    pub fn encode_distance(&self, distance_m: f32) -> f32 {
        let slope = 2.0 * std::f32::consts::LN_2 / (self.lead_m * self.lead_m);
        let cap = slope * (self.lead_m + 2.0 * self.voxel_m);
        if distance_m.is_nan() {
            return -cap;
        }
        (slope * (self.lead_m - distance_m)).clamp(-cap, cap)
    }

    /// Replaces every inner density in `density` by its stored signed value
    /// ([`Self::encode`]).
    fn encode_all(&self, density: &mut [f32]) {
        for d in density.iter_mut() {
            *d = self.encode(*d);
        }
    }
}

impl Adapter for SignedLogDensity<'_> {
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
        self.inner.evaluate(points, view, density, lt)?;
        self.encode_all(density);
        Ok(())
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        self.inner.evaluate_density(points, density)?;
        self.encode_all(density);
        Ok(())
    }
}
