//! Fields of density and light transport over 3D space, and the exact one made from
//! a mesh.
//!
//! [`FieldSource`] is what the baker consumes: at any batch of points a volume
//! density `σ` (1/m) and a light-transport vector `T` (384 floats, channel-major,
//! solid angle folded in, `docs/CONVENTIONS.md`) for an outgoing direction given by a
//! [`ViewPolicy`]. The NeLF network implements it in another crate; [`MeshField`]
//! implements it exactly from a mesh, so a volume renderer and the baker have ground
//! truth to consume:
//!
//! * signed distance `d(x)`: distance to the closest surface point (BVH
//!   branch-and-bound), negative inside, the side decided by the generalised winding
//!   number (`w ≥ ½` is inside; Jacobson et al. 2013, evaluated fast as in Barill et
//!   al. 2018), which stays correct for meshes open at the neck where ray parity
//!   fails;
//! * density, a sharp, finite profile of `d` ([`DensityProfile`]): `σ(d) =
//!   σ_max · clamp(½ − d/w, 0, 1)`, i.e. `σ_max` deeper than `w/2` inside, a linear
//!   ramp across the shell `|d| < w/2`, and exactly 0 beyond `w/2` outside;
//! * light transport, `T(x) = T(p, n_p, ρ_p, ω_o)` at the closest surface point `p`
//!   with that point's interpolated normal and albedo ([`LtTracer`]), the normal
//!   turned toward `x` when `x` is outside behind `p`'s triangle (the back of an
//!   open sheet, as the two-sided tracer shades it). Each point's
//!   random stream is seeded from `p` (its coordinates' bits and triangle), so the
//!   field is a deterministic function of the closest point: constant along the
//!   normal, independent of batching and threads.

use glam::{DMat3, Vec3};
use indicatif::ProgressBar;
use nelf_format::conventions::LT_DIM;
use rayon::prelude::*;

use crate::bvh::ClosestPoint;
use crate::mesh::Mesh;
use crate::tracer::{LtTracer, MAX_AVERAGED_DIRECTIONS, SurfacePoint, TraceError, TraceSettings, mix64};

/// Errors evaluating a field.
#[derive(Debug, thiserror::Error)]
pub enum FieldError {
    /// Output buffers do not match the number of points.
    #[error(
        "{points} points need {points} densities and {lt_needed} light-transport floats, got {density} and {lt}"
    )]
    LengthMismatch {
        /// Points given.
        points: usize,
        /// Density slots given.
        density: usize,
        /// Light-transport floats given.
        lt: usize,
        /// Light-transport floats needed (`points × 384`).
        lt_needed: usize,
    },
    /// A query point is NaN or infinite.
    #[error("query point {index} is not finite")]
    NotFinite {
        /// Index of the point.
        index: usize,
    },
    /// The view policy cannot be used.
    #[error("invalid view policy: {0}")]
    View(String),
    /// The ground-truth tracer could not be set up.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// A settings value is out of range.
    #[error("invalid field settings: {0}")]
    Settings(String),
    /// Any other failure of a field implementation (e.g. a network backend).
    #[error("field backend: {0}")]
    Backend(String),
}

/// Which outgoing direction `ω_o` (unit, from the point toward the viewer) the light
/// transport is evaluated for.
#[derive(Debug, Clone, PartialEq)]
pub enum ViewPolicy {
    /// One fixed direction for every point (normalised when used).
    Direction(Vec3),
    /// Toward a viewer at this position: `ω_o = normalize(eye − x)` at query point `x`.
    TowardPoint(Vec3),
    /// The mean of `T` over these directions (at most [`MAX_AVERAGED_DIRECTIONS`]).
    AverageDirections(Vec<Vec3>),
    /// The mean of `T` over the directions toward these positions (e.g. the
    /// capture's camera centres; at most [`MAX_AVERAGED_DIRECTIONS`]).
    AverageTowardPoints(Vec<Vec3>),
}

impl ViewPolicy {
    /// Checks that the policy names at least one usable direction.
    pub fn validate(&self) -> Result<(), FieldError> {
        let list = match self {
            Self::Direction(d) => {
                return if d.is_finite() && d.length_squared() > 0.0 {
                    Ok(())
                } else {
                    Err(FieldError::View(format!("direction {d} is zero or not finite")))
                };
            }
            Self::TowardPoint(p) => {
                return if p.is_finite() {
                    Ok(())
                } else {
                    Err(FieldError::View(format!("eye {p} is not finite")))
                };
            }
            Self::AverageDirections(list) | Self::AverageTowardPoints(list) => list,
        };
        if list.is_empty() || list.len() > MAX_AVERAGED_DIRECTIONS {
            return Err(FieldError::View(format!(
                "an average needs 1 to {MAX_AVERAGED_DIRECTIONS} entries, got {}",
                list.len()
            )));
        }
        if let Some(bad) = list.iter().find(|v| !v.is_finite()) {
            return Err(FieldError::View(format!("entry {bad} is not finite")));
        }
        if matches!(self, Self::AverageDirections(_)) && list.iter().any(|v| v.length_squared() == 0.0) {
            return Err(FieldError::View("a direction is zero".into()));
        }
        Ok(())
    }

    /// The unit outgoing directions at query point `x`, written into `out`; returns
    /// how many. `fallback` is used where a direction is undefined (eye at `x`).
    pub fn directions_at(&self, x: Vec3, fallback: Vec3, out: &mut [Vec3; MAX_AVERAGED_DIRECTIONS]) -> usize {
        let toward = |eye: Vec3| (eye - x).normalize_or(fallback);
        match self {
            Self::Direction(d) => {
                out[0] = d.normalize_or(fallback);
                1
            }
            Self::TowardPoint(eye) => {
                out[0] = toward(*eye);
                1
            }
            Self::AverageDirections(list) => {
                let n = list.len().min(MAX_AVERAGED_DIRECTIONS);
                for (o, d) in out.iter_mut().zip(&list[..n]) {
                    *o = d.normalize_or(fallback);
                }
                n
            }
            Self::AverageTowardPoints(list) => {
                let n = list.len().min(MAX_AVERAGED_DIRECTIONS);
                for (o, eye) in out.iter_mut().zip(&list[..n]) {
                    *o = toward(*eye);
                }
                n
            }
        }
    }
}

/// A source of density and light transport at any 3D point: the ground-truth mesh
/// field here, the NeLF network elsewhere. Implementations must be deterministic
/// for a given point (independent of batch composition and threads).
pub trait FieldSource: Sync {
    /// Fills `density[i]` (σ, 1/m) and `lt[i·384 .. (i+1)·384]` (channel-major `T`,
    /// in the source's light frame) for every `points[i]` (metres, world frame).
    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError>;

    /// Light transport toward several outgoing directions at once (view-dependent
    /// bakes): `lt[(i·D + d)·384 ..][..384]` is point `i`'s `T` for the fixed unit world
    /// direction `directions[d]` (from the point toward the viewer), `D =
    /// directions.len()`; `density[i]` as [`Self::evaluate`]. The default calls
    /// [`Self::evaluate`] once per direction with [`ViewPolicy::Direction`]; sources
    /// that share work across directions (the ground-truth tracer traces each point's
    /// visibility once) override it, with the same results up to their own noise rules.
    fn evaluate_directions(
        &self,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        evaluate_directions_one_by_one(points, directions, density, lt, |p, view, d, t| {
            self.evaluate(p, view, d, t)
        })
    }

    /// Axis-aligned box `(min, max)` outside which the density is zero.
    fn bounds(&self) -> (Vec3, Vec3);

    /// Rotation from the light frame of the vectors to the world. Default identity.
    fn world_from_light(&self) -> DMat3 {
        DMat3::IDENTITY
    }

    /// Density only. The default evaluates everything in chunks and discards the
    /// light transport; sources that can do better override it.
    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        const CHUNK: usize = 1024;
        check_density_batch(points, density)?;
        let mut lt = vec![0.0f32; CHUNK.min(points.len()) * LT_DIM];
        let view = ViewPolicy::Direction(Vec3::Y);
        for (p, d) in points.chunks(CHUNK).zip(density.chunks_mut(CHUNK)) {
            self.evaluate(p, &view, d, &mut lt[..p.len() * LT_DIM])?;
        }
        Ok(())
    }
}

/// [`FieldSource::evaluate_directions`] as its default does it: checks the batch
/// ([`check_directions_batch`]), then calls `evaluate` once per direction with
/// [`ViewPolicy::Direction`] and scatters each direction's `T` into its place,
/// `lt[(i·D + d)·384 ..][..384]` (shared with the `Adapter` trait's default).
pub fn evaluate_directions_one_by_one(
    points: &[Vec3],
    directions: &[Vec3],
    density: &mut [f32],
    lt: &mut [f32],
    mut evaluate: impl FnMut(&[Vec3], &ViewPolicy, &mut [f32], &mut [f32]) -> Result<(), FieldError>,
) -> Result<(), FieldError> {
    check_directions_batch(points, directions, density, lt)?;
    let count = directions.len();
    let mut one = vec![0.0f32; points.len() * LT_DIM];
    for (d, dir) in directions.iter().enumerate() {
        evaluate(points, &ViewPolicy::Direction(*dir), density, &mut one)?;
        for (i, t) in one.chunks_exact(LT_DIM).enumerate() {
            let at = (i * count + d) * LT_DIM;
            lt[at..at + LT_DIM].copy_from_slice(t);
        }
    }
    Ok(())
}

fn length_error(points: usize, density: usize, lt: usize) -> FieldError {
    FieldError::LengthMismatch {
        points,
        density,
        lt,
        lt_needed: points * LT_DIM,
    }
}

/// Checks a density-only batch's buffer size and point finiteness (for
/// [`FieldSource::evaluate_density`] implementers).
pub fn check_density_batch(points: &[Vec3], density: &[f32]) -> Result<(), FieldError> {
    if density.len() != points.len() {
        return Err(length_error(points.len(), density.len(), points.len() * LT_DIM));
    }
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(FieldError::NotFinite { index });
    }
    Ok(())
}

/// Checks a batch for [`FieldSource::evaluate_directions`]: at least one direction,
/// each finite and non-zero (as [`ViewPolicy::Direction`] requires), buffer sizes
/// (`points.len()` densities, `points.len() × directions.len() × 384` floats) and
/// point finiteness.
pub fn check_directions_batch(
    points: &[Vec3],
    directions: &[Vec3],
    density: &[f32],
    lt: &[f32],
) -> Result<(), FieldError> {
    if directions.is_empty() {
        return Err(FieldError::View("no outgoing directions".into()));
    }
    let lt_needed = points.len() * directions.len() * LT_DIM;
    if density.len() != points.len() || lt.len() != lt_needed {
        return Err(FieldError::LengthMismatch {
            points: points.len(),
            density: density.len(),
            lt: lt.len(),
            lt_needed,
        });
    }
    for d in directions {
        ViewPolicy::Direction(*d).validate()?;
    }
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(FieldError::NotFinite { index });
    }
    Ok(())
}

/// Checks a batch's buffer sizes and point finiteness (for [`FieldSource`] implementers).
pub fn check_batch(points: &[Vec3], density: &[f32], lt: &[f32]) -> Result<(), FieldError> {
    if density.len() != points.len() || lt.len() != points.len() * LT_DIM {
        return Err(length_error(points.len(), density.len(), lt.len()));
    }
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(FieldError::NotFinite { index });
    }
    Ok(())
}

/// The density profile of a signed distance: `σ(d) = σ_max · clamp(½ − d/w, 0, 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DensityProfile {
    /// Density deep inside, `σ_max`, in 1/m.
    pub sigma_max_per_m: f32,
    /// Width `w` of the ramp, metres, centred on the surface.
    pub shell_width_m: f32,
}

impl Default for DensityProfile {
    /// A 1 mm shell with optical depth 50 across it (`σ_max = 10⁵ /m`): a ray
    /// reaches optical depth 1 about 0.14 mm into the shell, so a volume render puts
    /// the surface within about 0.4 mm of the mesh and is opaque to `e⁻⁵⁰`.
    fn default() -> Self {
        Self::with_shell_width(0.001)
    }
}

impl DensityProfile {
    /// A shell of width `shell_width_m` with optical depth 50 across it
    /// (`σ_max = 100 / w`). Bakers sampling the field on a grid should use a shell
    /// at least two voxels wide.
    pub fn with_shell_width(shell_width_m: f32) -> Self {
        Self {
            sigma_max_per_m: 100.0 / shell_width_m,
            shell_width_m,
        }
    }

    /// Density at signed distance `d_m` (negative inside), 1/m.
    pub fn density(&self, d_m: f32) -> f32 {
        self.sigma_max_per_m * (0.5 - d_m / self.shell_width_m).clamp(0.0, 1.0)
    }

    /// Distance outside the surface beyond which the density is 0, `w/2`.
    pub fn support_m(&self) -> f32 {
        0.5 * self.shell_width_m
    }

    fn validate(self) -> Result<(), FieldError> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        if ok(self.sigma_max_per_m) && ok(self.shell_width_m) {
            Ok(())
        } else {
            Err(FieldError::Settings(format!(
                "density profile {self:?} needs positive finite values"
            )))
        }
    }
}

/// The exact ground-truth field of a mesh (see the module documentation).
#[derive(Debug, Clone)]
pub struct MeshField {
    tracer: LtTracer,
    profile: DensityProfile,
}

impl MeshField {
    /// Builds the tracer for `mesh` and the field around it.
    pub fn new(mesh: &Mesh, trace: TraceSettings, profile: DensityProfile) -> Result<Self, FieldError> {
        Self::from_tracer(LtTracer::new(mesh, trace)?, profile)
    }

    /// The field of an existing tracer.
    pub fn from_tracer(tracer: LtTracer, profile: DensityProfile) -> Result<Self, FieldError> {
        profile.validate()?;
        Ok(Self { tracer, profile })
    }

    /// The tracer computing the light transport.
    pub fn tracer(&self) -> &LtTracer {
        &self.tracer
    }

    /// The density profile.
    pub fn profile(&self) -> &DensityProfile {
        &self.profile
    }

    /// Signed distance to the mesh (negative inside) and the closest surface point.
    pub fn signed_distance(&self, x: Vec3) -> Option<(f32, ClosestPoint)> {
        let bvh = self.tracer.bvh();
        let cp = bvh.closest_point(x, f32::INFINITY)?;
        let sign = if bvh.winding_number(x) >= 0.5 { -1.0 } else { 1.0 };
        Some((sign * cp.distance, cp))
    }

    /// Density at `x`, 1/m.
    pub fn density(&self, x: Vec3) -> f32 {
        let bvh = self.tracer.bvh();
        // Beyond the support outside the surface the density is exactly 0: no sign needed
        // unless a surface is within reach.
        match bvh.closest_point(x, self.profile.support_m()) {
            Some(cp) => {
                let sign = if bvh.winding_number(x) >= 0.5 { -1.0 } else { 1.0 };
                self.profile.density(sign * cp.distance)
            }
            None if bvh.winding_number(x) >= 0.5 => self.profile.sigma_max_per_m,
            None => 0.0,
        }
    }

    /// The closest surface point to `x`, with its outward normals and albedo.
    pub fn surface_point(&self, x: Vec3) -> Option<(SurfacePoint, ClosestPoint)> {
        let cp = self.tracer.bvh().closest_point(x, f32::INFINITY)?;
        Some((self.surface_at(&cp), cp))
    }

    /// The surface at a closest point found by the caller, outward normals.
    pub fn surface_at(&self, cp: &ClosestPoint) -> SurfacePoint {
        SurfacePoint {
            position: cp.point,
            ..self.tracer.surface_point(cp.triangle, cp.b1, cp.b2)
        }
    }

    /// The closest surface point to `x` as seen from `x`: like [`Self::surface_point`],
    /// but with both normals turned toward `x` when `x` lies outside the mesh
    /// (winding number below ½) behind the closest triangle. That is the side a
    /// camera at `x` would see, as the two-sided path tracer shades it
    /// ([`LtTracer::surface_at_hit`]): the back of a one-sided sheet (a collar, a
    /// flap of cloth), a flipped triangle, the inside of a torn shell. Points inside
    /// a closed surface keep its outward normals.
    pub fn surface_point_seen_from(&self, x: Vec3) -> Option<(SurfacePoint, ClosestPoint)> {
        let (sp, cp) = self.surface_point(x)?;
        let behind = (x - cp.point).dot(sp.geometric_normal) < 0.0;
        if behind && self.tracer.bvh().winding_number(x) < 0.5 {
            Some((sp.turned(), cp))
        } else {
            Some((sp, cp))
        }
    }

    /// Adds the light transport at `x` under `view` to `out` (384 floats, zeroed by the caller).
    fn light_transport_into(&self, x: Vec3, view: &ViewPolicy, out: &mut [f32]) {
        if let Some((sp, cp)) = self.surface_point_seen_from(x) {
            self.light_transport_at(x, &sp, &cp, view, out);
        }
    }

    /// Adds to `out` (384 floats, zeroed by the caller) the light transport at query
    /// point `x` under `view`, shading the surface point `sp` (the closest point `cp`,
    /// with the normals the caller chose): the field's definition for any caller
    /// that decides the side itself. The random stream is seeded from `cp`.
    pub fn light_transport_at(
        &self,
        x: Vec3,
        sp: &SurfacePoint,
        cp: &ClosestPoint,
        view: &ViewPolicy,
        out: &mut [f32],
    ) {
        let mut omegas = [Vec3::ZERO; MAX_AVERAGED_DIRECTIONS];
        let count = view.directions_at(x, sp.shading_normal, &mut omegas);
        let mut rng = self.tracer.rng(Self::stream(cp));
        self.tracer
            .light_transport_averaged(sp, &omegas[..count], &mut rng, out);
    }

    /// Writes to `out` (`directions.len() × 384` floats) the light transport of the
    /// surface point `sp` (closest point `cp`, normals chosen by the caller) toward
    /// each fixed world direction, normalised as [`ViewPolicy::Direction`] is: in one
    /// pass ([`LtTracer::light_transport_directions`]), and `out[d]` equal to what
    /// [`Self::light_transport_at`] adds with `ViewPolicy::Direction(directions[d])`.
    pub fn light_transport_directions_at(
        &self,
        sp: &SurfacePoint,
        cp: &ClosestPoint,
        directions: &[Vec3],
        out: &mut [f32],
    ) {
        let omegas: Vec<Vec3> = directions
            .iter()
            .map(|d| d.normalize_or(sp.shading_normal))
            .collect();
        let mut rng = self.tracer.rng(Self::stream(cp));
        self.tracer.light_transport_directions(sp, &omegas, &mut rng, out);
    }

    /// The random stream of the light transport at closest point `cp`: from its
    /// coordinates' bits and triangle.
    fn stream(cp: &ClosestPoint) -> u64 {
        let bits = |v: f32| u64::from(v.to_bits());
        mix64(bits(cp.point.x) | bits(cp.point.y) << 32)
            ^ mix64(bits(cp.point.z) | u64::from(cp.triangle) << 32)
    }

    /// [`FieldSource::evaluate`] with an optional progress bar (length set to the
    /// number of points, ticked per chunk of 64).
    pub fn evaluate_with_progress(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
        progress: Option<&ProgressBar>,
    ) -> Result<(), FieldError> {
        evaluate_in_parallel(points, view, density, lt, progress, |x, out| {
            self.light_transport_into(x, view, out);
            self.density(x)
        })
    }
}

/// The batch loop every mesh-based [`FieldSource`] shares: checks the buffers and
/// the view policy, then on all cores, in fixed chunks of 64 points, zeroes each
/// point's 384 floats and calls `point(x, out)`, which adds the light transport
/// into `out` and returns the density. Ticks `progress` (its length set to the
/// number of points) per chunk.
pub fn evaluate_in_parallel(
    points: &[Vec3],
    view: &ViewPolicy,
    density: &mut [f32],
    lt: &mut [f32],
    progress: Option<&ProgressBar>,
    point: impl Fn(Vec3, &mut [f32]) -> f32 + Sync,
) -> Result<(), FieldError> {
    const CHUNK: usize = 64;
    check_batch(points, density, lt)?;
    view.validate()?;
    if let Some(pb) = progress {
        pb.set_length(points.len() as u64);
    }
    points
        .par_chunks(CHUNK)
        .zip(density.par_chunks_mut(CHUNK))
        .zip(lt.par_chunks_mut(CHUNK * LT_DIM))
        .for_each(|((p, d), t)| {
            for ((x, sigma), out) in p.iter().zip(d.iter_mut()).zip(t.chunks_mut(LT_DIM)) {
                out.fill(0.0);
                *sigma = point(*x, out);
            }
            if let Some(pb) = progress {
                pb.inc(p.len() as u64);
            }
        });
    Ok(())
}

/// [`evaluate_in_parallel`] for [`FieldSource::evaluate_directions`]: checks the
/// batch ([`check_directions_batch`]), then on all cores, in fixed chunks of 64
/// points, calls `point(x, out)` with each point's `directions.len() × 384` floats
/// (to be written, not added: they hold the previous contents), which returns the
/// density.
pub fn evaluate_directions_in_parallel(
    points: &[Vec3],
    directions: &[Vec3],
    density: &mut [f32],
    lt: &mut [f32],
    point: impl Fn(Vec3, &mut [f32]) -> f32 + Sync,
) -> Result<(), FieldError> {
    const CHUNK: usize = 64;
    check_directions_batch(points, directions, density, lt)?;
    let per_point = directions.len() * LT_DIM;
    points
        .par_chunks(CHUNK)
        .zip(density.par_chunks_mut(CHUNK))
        .zip(lt.par_chunks_mut(CHUNK * per_point))
        .for_each(|((p, d), t)| {
            for ((x, sigma), out) in p.iter().zip(d.iter_mut()).zip(t.chunks_mut(per_point)) {
                *sigma = point(*x, out);
            }
        });
    Ok(())
}

impl FieldSource for MeshField {
    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.evaluate_with_progress(points, view, density, lt, None)
    }

    /// The mesh's bounds grown by the density's support outside the surface.
    fn bounds(&self) -> (Vec3, Vec3) {
        let (lo, hi) = self.tracer.mesh().bounds();
        let margin = Vec3::splat(self.profile.support_m());
        (lo - margin, hi + margin)
    }

    fn world_from_light(&self) -> DMat3 {
        self.tracer.settings().world_from_light
    }

    /// One pass per point for all directions
    /// ([`MeshField::light_transport_directions_at`]): the same results as the
    /// default's per-direction [`Self::evaluate`] calls, bit for bit.
    fn evaluate_directions(
        &self,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        evaluate_directions_in_parallel(points, directions, density, lt, |x, out| {
            match self.surface_point_seen_from(x) {
                Some((sp, cp)) => self.light_transport_directions_at(&sp, &cp, directions, out),
                None => out.fill(0.0),
            }
            self.density(x)
        })
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        check_density_batch(points, density)?;
        points
            .par_iter()
            .zip(density.par_iter_mut())
            .for_each(|(x, d)| *d = self.density(*x));
        Ok(())
    }
}
