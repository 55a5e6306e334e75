//! The ground-truth light-transport path tracer: for a surface point `x` with
//! normal `n` seen from direction `ω_o`, the 384-number vector `T` (`docs/CONVENTIONS.md`,
//! "Solid angles") such that the radiance leaving `x` under a
//! distant environment map with per-texel mean radiance `L_k` is
//! `radiance_c = Σ_k T[c][k] · L_k[c]`.
//!
//! `T = T_dir + T_ind`, with `Ω_k` texel `k` of the light frame (world directions
//! `world_from_light · d`):
//!
//! * direct: `T_dir[c][k] = ∫_{Ω_k} f_c(ω_i, ω_o) V(x, ω_i) max(0, n·ω_i) dω_i`,
//!   estimated per texel with `texel_samples` jittered-stratified samples uniform in
//!   `(cos θ, φ)` (uniform in solid angle, pdf `1/Ω_k`): `Ω_k/N Σ f V cos`;
//! * indirect: `T_ind[c][k] = ∫ f_c (1 − V) T(hit, −ω_i)[c][k] cos dω_i`, estimated
//!   with `indirect_samples` cosine-weighted, jittered-stratified directions (the
//!   weight is `π f`, which is `ρ` for a diffuse surface); the vector at the hit uses
//!   `bounce_texel_samples` per texel and continues with one cosine-weighted
//!   direction per further bounce, up to `bounces` interreflections.
//!
//! The BRDF is Lambertian, `ρ/π` with `ρ` from [`Mesh::albedo_at`], optionally mixed
//! with a colourless, energy-conserving modified-Phong lobe (Lafortune & Willems
//! 1994): `f = (1 − k_s) ρ/π + k_s (s + 2)/(2π) max(0, r·ω_i)^s`, `r` the mirror
//! direction of `ω_o` about the shading normal. Its directional albedo is at most
//! `(1 − k_s) ρ + k_s ≤ 1`, so energy is never created. The lobe is off by default
//! ([`TraceSettings::default`] is Lambertian); [`Specular::MILD_SHEEN`] gives a mild
//! sheen like the NeLF paper's renders.
//!
//! Geometry conventions, decided here once:
//!
//! * **Normals.** Shading uses interpolated, area-weighted vertex normals (computed
//!   once); visibility uses the true triangles. Directions below the *geometric*
//!   tangent plane (`n_g·ω_i ≤ 0`) count as blocked by the surface itself (no ray is
//!   cast), in both the light-transport and the direct estimators.
//! * **Self-intersection.** Rays leave from `x + ε n_g`, with `ε` =
//!   `ray_epsilon_rel` × the mesh's bounding-box diagonal.
//! * **Two-sided hits.** A ray that hits a triangle from behind (inside an open mesh,
//!   e.g. up a cut neck) sees that side: both normals are flipped to face the ray.
//! * **`ω_o` below the surface.** When `n_s·ω_o ≤ 0` (silhouettes with interpolated
//!   normals, or a field query viewed from behind), the specular lobe is zero and
//!   only the diffuse part remains; the diffuse part does not depend on `ω_o`.
//!
//! Every estimate is deterministic: each vector draws from its own generator seeded
//! from `TraceSettings::seed` and a caller-supplied stream number (pixel, point), so
//! rayon's scheduling never changes a result.

use glam::{DMat3, Mat3, Vec3};
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LT_DIM, col_phi_bounds, direction, is_rotation, row_theta_bounds,
    texel_center_direction, texel_solid_angle,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use crate::bvh::{Bvh, Hit};
use crate::mesh::{Mesh, MeshError};

/// The random generator every estimate draws from.
pub type TraceRng = Pcg64Mcg;

/// Errors setting up the tracer.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The mesh failed validation.
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshError),
    /// A setting is out of range.
    #[error("invalid trace settings: {0}")]
    Settings(String),
}

/// A colourless glossy lobe (energy-conserving modified Phong) added to the diffuse BRDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Specular {
    /// Share of reflected energy in the lobe, `k_s ∈ [0, 1]`; the diffuse part is
    /// scaled by `1 − k_s`.
    pub weight: f32,
    /// Phong exponent `s ≥ 0`: larger is sharper.
    pub exponent: f32,
}

impl Specular {
    /// A mild sheen like the NeLF paper's renders: 4 % of the energy in a broad lobe.
    pub const MILD_SHEEN: Self = Self {
        weight: 0.04,
        exponent: 20.0,
    };
}

/// How light transport is estimated. Defaults are [`TraceSettings::default`]'s.
///
/// Cost, noise and agreement with the direct path tracer
/// ([`crate::render::render_direct_image`]) at the defaults are measured by
/// `cargo run --release -p nelf-scene --example trace_bench`
/// (`docs/measurements/settings.md`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceSettings {
    /// Interreflections after the direct term (0 = direct lighting only). Default 2.
    pub bounces: u32,
    /// Stratified samples per texel for the direct term at the first surface point.
    /// Default 16 (a 4 × 4 grid in `(cos θ, φ)`; 2,048 directions per vector, about
    /// half of them above the surface and traced).
    pub texel_samples: u32,
    /// Cosine-weighted, stratified indirect directions at the first surface point.
    /// Default 128 (an 8 × 16 grid).
    pub indirect_samples: u32,
    /// Samples per texel for the direct term at every later surface point. Default 1
    /// (128 directions per bounce).
    pub bounce_texel_samples: u32,
    /// Optional glossy lobe; `None` (default) is purely Lambertian.
    pub specular: Option<Specular>,
    /// Rotation taking light-frame texel directions to the world. Default identity.
    pub world_from_light: DMat3,
    /// Base seed; every vector derives its own stream from it. Default 0.
    pub seed: u64,
    /// Ray origin offset along the geometric normal, relative to the mesh's
    /// bounding-box diagonal. Default 1e-4.
    pub ray_epsilon_rel: f32,
    /// Image renders: colour is averaged over `pixel_grid²` regularly spaced sub-pixel
    /// points. Default 1 (the pixel centre).
    pub pixel_grid: u32,
    /// Image renders: coverage (alpha) is the hit fraction of `coverage_grid²`
    /// regularly spaced sub-pixel rays. Default 4.
    pub coverage_grid: u32,
}

impl Default for TraceSettings {
    fn default() -> Self {
        Self {
            bounces: 2,
            texel_samples: 16,
            indirect_samples: 128,
            bounce_texel_samples: 1,
            specular: None,
            world_from_light: DMat3::IDENTITY,
            seed: 0,
            ray_epsilon_rel: 1e-4,
            pixel_grid: 1,
            coverage_grid: 4,
        }
    }
}

impl TraceSettings {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), TraceError> {
        let bad = |msg: String| Err(TraceError::Settings(msg));
        if self.texel_samples == 0 {
            return bad("texel_samples must be at least 1".into());
        }
        if self.bounces > 0 && self.bounce_texel_samples == 0 {
            return bad("bounce_texel_samples must be at least 1 when bounces > 0".into());
        }
        if !(1..=64).contains(&self.pixel_grid) || !(1..=64).contains(&self.coverage_grid) {
            return bad(format!(
                "pixel_grid = {} and coverage_grid = {} must be in 1..=64",
                self.pixel_grid, self.coverage_grid
            ));
        }
        if !(self.ray_epsilon_rel.is_finite() && self.ray_epsilon_rel > 0.0) {
            return bad(format!(
                "ray_epsilon_rel = {} must be positive",
                self.ray_epsilon_rel
            ));
        }
        if !is_rotation(self.world_from_light, 1e-6) {
            return bad(format!(
                "world_from_light {:?} is not a rotation",
                self.world_from_light.to_cols_array()
            ));
        }
        if let Some(s) = self.specular
            && !((0.0..=1.0).contains(&s.weight) && s.exponent.is_finite() && s.exponent >= 0.0)
        {
            return bad(format!("specular {s:?}: weight must be in [0, 1], exponent ≥ 0"));
        }
        Ok(())
    }
}

/// A shading point: position, normals and albedo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Position, metres.
    pub position: Vec3,
    /// Unit normal of the true triangle (visibility, ray offsets).
    pub geometric_normal: Vec3,
    /// Unit interpolated normal (shading), on the same side as `geometric_normal`.
    pub shading_normal: Vec3,
    /// Diffuse albedo, linear RGB.
    pub albedo: [f32; 3],
}

impl SurfacePoint {
    /// The same point seen from the other side: both normals reversed (two-sided
    /// shading of the back of a triangle).
    #[must_use]
    pub fn turned(self) -> Self {
        Self {
            geometric_normal: -self.geometric_normal,
            shading_normal: -self.shading_normal,
            ..self
        }
    }
}

/// Bounds of one light-frame texel in `(cos θ, φ)` and its solid angle.
#[derive(Debug, Clone, Copy)]
struct TexelPatch {
    cos_top: f64,
    cos_bottom: f64,
    phi0: f64,
    phi1: f64,
    solid_angle: f32,
    /// World direction of the texel centre.
    centre: Vec3,
    /// Sine of the texel's angular radius around `centre` (slightly enlarged): a
    /// normal with `n·centre < −sin_radius` has the whole texel below its horizon.
    sin_radius: f32,
}

/// The BRDF at one vertex, for one or several (averaged) outgoing directions.
#[derive(Debug, Clone, Copy)]
struct Lobe<'a> {
    /// `(1 − k_s) ρ / π` per channel.
    diffuse: [f32; 3],
    /// `k_s (s + 2) / (2π) / M` for `M` averaged outgoing directions.
    spec_scale: f32,
    exponent: f32,
    /// Mirror directions of the outgoing directions above the shading horizon.
    reflections: &'a [Vec3],
}

impl Lobe<'_> {
    /// The colourless specular part `f_s(ω_i)` (0 without a lobe).
    #[inline]
    fn specular(&self, omega_i: Vec3) -> f32 {
        if self.spec_scale == 0.0 {
            return 0.0;
        }
        let sum: f32 = self
            .reflections
            .iter()
            .map(|r| r.dot(omega_i).max(0.0).powf(self.exponent))
            .sum();
        self.spec_scale * sum
    }
}

/// [`LtTracer::accumulate_joint`] met an indirect path traced for some of its
/// vectors and skipped for others.
#[derive(Debug, Clone, Copy)]
struct StreamsParted;

/// Most outgoing directions averaged in one call (reflections kept on the stack).
pub const MAX_AVERAGED_DIRECTIONS: usize = 64;

/// The light-transport path tracer over one mesh.
#[derive(Debug, Clone)]
pub struct LtTracer {
    mesh: Mesh,
    bvh: Bvh,
    vertex_normals: Vec<Vec3>,
    settings: TraceSettings,
    epsilon: f32,
    world_from_light: Mat3,
    texels: Vec<TexelPatch>,
}

impl LtTracer {
    /// Validates the mesh and settings, builds the BVH and vertex normals.
    pub fn new(mesh: &Mesh, settings: TraceSettings) -> Result<Self, TraceError> {
        mesh.validate()?;
        settings.validate()?;
        let bvh = Bvh::new(&mesh.positions, &mesh.triangles);
        // Area-weighted vertex normals: the unnormalised face normal has length 2·area.
        let mut vertex_normals = vec![Vec3::ZERO; mesh.positions.len()];
        for tri in &mesh.triangles {
            let [a, b, c] = tri.map(|i| mesh.positions[i as usize]);
            let n = (b - a).cross(c - a);
            for &i in tri {
                vertex_normals[i as usize] += n;
            }
        }
        for n in &mut vertex_normals {
            *n = n.normalize_or_zero();
        }
        let (lo, hi) = mesh.bounds();
        let diagonal = (hi - lo).length().max(f32::MIN_POSITIVE);
        let texels = (0..ENV_TEXELS)
            .map(|k| {
                let (row, col) = (k / ENV_W, k % ENV_W);
                let (t0, t1) = row_theta_bounds(row, ENV_H);
                let (phi0, phi1) = col_phi_bounds(col, ENV_W);
                let centre = texel_center_direction(row, col, ENV_H, ENV_W);
                // Angular radius: the farthest boundary point from the centre, found on a
                // fine sampling of the four edges, plus a margin.
                let steps = 32;
                let mut cos_radius = 1.0f64;
                for i in 0..=steps {
                    let f = f64::from(i) / f64::from(steps);
                    for (theta, phi) in [
                        (t0, phi0 + f * (phi1 - phi0)),
                        (t1, phi0 + f * (phi1 - phi0)),
                        (t0 + f * (t1 - t0), phi0),
                        (t0 + f * (t1 - t0), phi1),
                    ] {
                        cos_radius = cos_radius.min(centre.dot(direction(theta, phi)));
                    }
                }
                let radius = cos_radius.clamp(-1.0, 1.0).acos() + 0.01;
                TexelPatch {
                    cos_top: t0.cos(),
                    cos_bottom: t1.cos(),
                    phi0,
                    phi1,
                    solid_angle: texel_solid_angle(row, ENV_H, ENV_W) as f32,
                    centre: (settings.world_from_light * centre).as_vec3(),
                    sin_radius: radius.min(std::f64::consts::FRAC_PI_2).sin() as f32,
                }
            })
            .collect();
        Ok(Self {
            mesh: mesh.clone(),
            bvh,
            vertex_normals,
            settings,
            epsilon: settings.ray_epsilon_rel * diagonal,
            world_from_light: settings.world_from_light.as_mat3(),
            texels,
        })
    }

    /// The settings in use.
    pub fn settings(&self) -> &TraceSettings {
        &self.settings
    }

    /// The mesh traced.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The mesh's BVH.
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Ray origin offset along the geometric normal, metres.
    pub fn ray_epsilon(&self) -> f32 {
        self.epsilon
    }

    /// A generator for stream `stream` (a pixel, a point) of this tracer's seed.
    pub fn rng(&self, stream: u64) -> TraceRng {
        stream_rng(self.settings.seed, stream)
    }

    /// Closest hit of a ray from `origin` along `dir` (any length), `t ≥ 0`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<Hit> {
        self.bvh.closest_hit(origin, dir, 0.0, f32::INFINITY)
    }

    /// The surface at barycentrics `(b1, b2)` of `triangle`, normals outward (as wound).
    pub fn surface_point(&self, triangle: u32, b1: f32, b2: f32) -> SurfacePoint {
        let t = triangle as usize;
        let [a, b, c] = self.mesh.corners(t);
        let position = (1.0 - b1 - b2) * a + b1 * b + b2 * c;
        let geometric_normal = self.mesh.face_normal(t);
        let [na, nb, nc] = self.mesh.triangles[t].map(|i| self.vertex_normals[i as usize]);
        let interpolated = ((1.0 - b1 - b2) * na + b1 * nb + b2 * nc).normalize_or_zero();
        let shading_normal = if interpolated.dot(geometric_normal) > 0.0 {
            interpolated
        } else {
            geometric_normal
        };
        SurfacePoint {
            position,
            geometric_normal,
            shading_normal,
            albedo: self.mesh.albedo_at(t, b1, b2),
        }
    }

    /// The surface seen by a ray with direction `ray_dir` at `hit`: two-sided, so the
    /// normals are flipped when the ray arrives from behind the triangle.
    pub fn surface_at_hit(&self, hit: &Hit, ray_dir: Vec3) -> SurfacePoint {
        let sp = self.surface_point(hit.triangle, hit.b1, hit.b2);
        if sp.geometric_normal.dot(ray_dir) > 0.0 {
            sp.turned()
        } else {
            sp
        }
    }

    /// The light-transport vector `T` (channel-major, `T[c·128 + k]`) at `sp` seen
    /// from unit direction `omega_o` (pointing away from the surface, to the viewer).
    pub fn light_transport(&self, sp: &SurfacePoint, omega_o: Vec3, rng: &mut TraceRng) -> [f32; LT_DIM] {
        let mut out = [0.0f32; LT_DIM];
        self.light_transport_averaged(sp, &[omega_o], rng, &mut out);
        out
    }

    /// Adds to `out` (length [`LT_DIM`]) the mean of `T` over the unit outgoing
    /// directions `omegas` (at most [`MAX_AVERAGED_DIRECTIONS`]; further ones are
    /// ignored). `T` is linear in the BRDF, so the mean is one estimate with the mean
    /// BRDF, at the cost of one vector. An empty list means "any direction" and gives
    /// the diffuse part only.
    pub fn light_transport_averaged(
        &self,
        sp: &SurfacePoint,
        omegas: &[Vec3],
        rng: &mut TraceRng,
        out: &mut [f32],
    ) {
        assert_eq!(
            out.len(),
            LT_DIM,
            "light-transport output must hold {LT_DIM} floats"
        );
        let omegas = &omegas[..omegas.len().min(MAX_AVERAGED_DIRECTIONS)];
        let mut reflections = [Vec3::ZERO; MAX_AVERAGED_DIRECTIONS];
        let lobe = self.lobe(sp, omegas, &mut reflections);
        let Ok(out) = <&mut [f32; LT_DIM]>::try_from(out) else {
            return;
        };
        self.accumulate(
            sp,
            &lobe,
            self.settings.texel_samples,
            self.settings.indirect_samples,
            self.settings.bounces,
            [1.0; 3],
            rng,
            out,
        );
    }

    /// The light-transport vectors `T` at `sp` for each unit outgoing direction in
    /// `omegas`, written (not added) to `out[d·384 .. (d+1)·384]` (`out.len()` must be
    /// `omegas.len() × 384`), in one pass.
    ///
    /// Only the BRDF depends on `ω_o`: the direct samples, visibility rays and
    /// indirect paths are drawn and traced once and each direction's lobe is
    /// evaluated on them, with the same random draws in the same order as
    /// [`Self::light_transport`] makes. So `out[d]` equals `light_transport(sp,
    /// omegas[d], rng)` from the same generator state (bit for bit: the same
    /// operations in the same order). Directions with the same lobe (every direction
    /// without a specular lobe, every direction below the shading horizon) are
    /// computed once and copied.
    ///
    /// The one case where the single-direction estimates' random streams part is an
    /// indirect path that is traced for some directions and skipped for others (its
    /// weight is zero for some directions only: a black diffuse part, a zero-valued
    /// lobe); it is detected and the distinct lobes are then traced one by one, each
    /// from the generator's starting state. `rng` ends as after one of the
    /// single-direction estimates.
    pub fn light_transport_directions(
        &self,
        sp: &SurfacePoint,
        omegas: &[Vec3],
        rng: &mut TraceRng,
        out: &mut [f32],
    ) {
        assert_eq!(
            out.len(),
            omegas.len() * LT_DIM,
            "light transport toward {} directions needs {} floats",
            omegas.len(),
            omegas.len() * LT_DIM
        );
        out.fill(0.0);
        if omegas.is_empty() {
            return;
        }
        let mut reflections = vec![Vec3::ZERO; omegas.len()];
        // The distinct lobes, told apart by their mirror direction (or its absence),
        // and each direction's index among them.
        let mut distinct: Vec<(Option<[u32; 3]>, Lobe<'_>)> = Vec::new();
        let mut lobe_of = Vec::with_capacity(omegas.len());
        for (w, scratch) in omegas.iter().zip(reflections.chunks_exact_mut(1)) {
            let lobe = self.lobe(sp, std::slice::from_ref(w), scratch);
            let key = lobe.reflections.first().map(|r| r.to_array().map(f32::to_bits));
            let index = distinct.iter().position(|(k, _)| *k == key).unwrap_or_else(|| {
                distinct.push((key, lobe));
                distinct.len() - 1
            });
            lobe_of.push(index);
        }
        let lobes: Vec<Lobe<'_>> = distinct.into_iter().map(|(_, lobe)| lobe).collect();
        let mut vectors = vec![0.0f32; lobes.len() * LT_DIM];
        let settings = &self.settings;
        let one_by_one = |rng: &mut TraceRng, vectors: &mut [f32]| {
            let start = rng.clone();
            for (lobe, vector) in lobes.iter().zip(vectors.chunks_exact_mut(LT_DIM)) {
                *rng = start.clone();
                let Ok(vector) = <&mut [f32; LT_DIM]>::try_from(vector) else {
                    continue;
                };
                self.accumulate(
                    sp,
                    lobe,
                    settings.texel_samples,
                    settings.indirect_samples,
                    settings.bounces,
                    [1.0; 3],
                    rng,
                    vector,
                );
            }
        };
        if lobes.len() == 1 {
            one_by_one(rng, &mut vectors);
        } else {
            let start = rng.clone();
            let weights = vec![[1.0f32; 3]; lobes.len()];
            let joint = self.accumulate_joint(
                sp,
                &lobes,
                settings.texel_samples,
                settings.indirect_samples,
                settings.bounces,
                &weights,
                rng,
                &mut vectors,
            );
            if joint.is_err() {
                *rng = start;
                vectors.fill(0.0);
                one_by_one(rng, &mut vectors);
            }
        }
        for (o, &i) in out.chunks_exact_mut(LT_DIM).zip(&lobe_of) {
            o.copy_from_slice(&vectors[i * LT_DIM..(i + 1) * LT_DIM]);
        }
    }

    /// The BRDF at `sp` averaged over `omegas`; `reflections` is scratch space.
    fn lobe<'a>(&self, sp: &SurfacePoint, omegas: &[Vec3], reflections: &'a mut [Vec3]) -> Lobe<'a> {
        let n = sp.shading_normal;
        let (k_s, exponent) = self
            .settings
            .specular
            .map_or((0.0, 0.0), |s| (s.weight, s.exponent));
        let diffuse = sp.albedo.map(|a| (1.0 - k_s) * a * std::f32::consts::FRAC_1_PI);
        let mut count = 0;
        if k_s > 0.0 {
            for &w in omegas {
                let cos_o = n.dot(w);
                if cos_o > 0.0 && count < reflections.len() {
                    reflections[count] = (2.0 * cos_o * n - w).normalize_or_zero();
                    count += 1;
                }
            }
        }
        let spec_scale = if k_s > 0.0 && !omegas.is_empty() {
            k_s * (exponent + 2.0) / (2.0 * std::f32::consts::PI) / omegas.len() as f32
        } else {
            0.0
        };
        Lobe {
            diffuse,
            spec_scale,
            exponent,
            reflections: &reflections[..count],
        }
    }

    /// `out += weight ⊙ T(sp)` with the given sample counts and remaining bounces:
    /// [`Self::accumulate_joint`] for one vector (whose stream has no other to part from).
    #[allow(clippy::too_many_arguments)]
    fn accumulate(
        &self,
        sp: &SurfacePoint,
        lobe: &Lobe<'_>,
        texel_samples: u32,
        indirect_samples: u32,
        bounces_left: u32,
        weight: [f32; 3],
        rng: &mut TraceRng,
        out: &mut [f32; LT_DIM],
    ) {
        let one = self.accumulate_joint(
            sp,
            std::slice::from_ref(lobe),
            texel_samples,
            indirect_samples,
            bounces_left,
            &[weight],
            rng,
            out,
        );
        debug_assert!(one.is_ok(), "a single vector's stream cannot part");
    }

    /// [`Self::accumulate`] for several vectors at once that differ only in their
    /// BRDF: `out[u·384 ..] += weights[u] ⊙ T_u(sp)`, where `T_u` uses `lobes[u]`, or
    /// `lobes[0]` for every `u` when there is one lobe (a later vertex, whose lobe
    /// does not depend on the first `ω_o`). Draws exactly what `accumulate` draws for
    /// each `u`, and computes each `out[u]` with the same operations in the same
    /// order; fails, with `out` partly written, where `accumulate` would trace an
    /// indirect path for some `u` and skip it for others (their streams part).
    #[allow(clippy::too_many_arguments)]
    fn accumulate_joint(
        &self,
        sp: &SurfacePoint,
        lobes: &[Lobe<'_>],
        texel_samples: u32,
        indirect_samples: u32,
        bounces_left: u32,
        weights: &[[f32; 3]],
        rng: &mut TraceRng,
        out: &mut [f32],
    ) -> Result<(), StreamsParted> {
        debug_assert!(lobes.len() == 1 || lobes.len() == weights.len());
        debug_assert_eq!(out.len(), weights.len() * LT_DIM);
        let shared = lobes.len() == 1;
        let lobe_index = |u: usize| if shared { 0 } else { u };
        let origin = sp.position + self.epsilon * sp.geometric_normal;
        let (n_s, n_g) = (sp.shading_normal, sp.geometric_normal);
        let (rows, cols) = strata(texel_samples);
        let inv_count = 1.0 / texel_samples as f32;
        let mut spec_sums = vec![0.0f32; lobes.len()];
        for (k, patch) in self.texels.iter().enumerate() {
            if n_s.dot(patch.centre) < -patch.sin_radius {
                continue;
            }
            let mut diffuse_sum = 0.0f32;
            spec_sums.fill(0.0);
            for a in 0..rows {
                for b in 0..cols {
                    let (xi_u, xi_phi): (f64, f64) = (rng.random(), rng.random());
                    let u = patch.cos_top
                        + (patch.cos_bottom - patch.cos_top) * (f64::from(a) + xi_u) / f64::from(rows);
                    let phi =
                        patch.phi0 + (patch.phi1 - patch.phi0) * (f64::from(b) + xi_phi) / f64::from(cols);
                    let omega = self.world_from_light * direction(u.clamp(-1.0, 1.0).acos(), phi).as_vec3();
                    let cos_s = n_s.dot(omega);
                    if cos_s <= 0.0 || n_g.dot(omega) <= 0.0 {
                        continue;
                    }
                    if self.bvh.any_hit(origin, omega, 0.0, f32::INFINITY) {
                        continue;
                    }
                    diffuse_sum += cos_s;
                    for (sum, lobe) in spec_sums.iter_mut().zip(lobes) {
                        *sum += lobe.specular(omega) * cos_s;
                    }
                }
            }
            if diffuse_sum == 0.0 {
                continue;
            }
            let scale = patch.solid_angle * inv_count;
            for (u, (weight, vector)) in weights.iter().zip(out.chunks_exact_mut(LT_DIM)).enumerate() {
                let (lobe, spec_sum) = (&lobes[lobe_index(u)], spec_sums[lobe_index(u)]);
                for c in 0..3 {
                    vector[c * ENV_TEXELS + k] +=
                        weight[c] * scale * (lobe.diffuse[c] * diffuse_sum + spec_sum);
                }
            }
        }
        if bounces_left == 0 || indirect_samples == 0 {
            return Ok(());
        }
        let (rows, cols) = strata(indirect_samples);
        let frame = Frame::new(n_s);
        let inv_count = 1.0 / indirect_samples as f32;
        let mut f_pis = vec![0.0f32; lobes.len()];
        let mut next_weights = vec![[0.0f32; 3]; weights.len()];
        for a in 0..rows {
            for b in 0..cols {
                let xi1 = (a as f32 + rng.random::<f32>()) / rows as f32;
                let xi2 = (b as f32 + rng.random::<f32>()) / cols as f32;
                let omega = frame.to_world(cosine_hemisphere(xi1, xi2));
                if n_g.dot(omega) <= 0.0 {
                    continue;
                }
                let Some(hit) = self.bvh.closest_hit(origin, omega, 0.0, f32::INFINITY) else {
                    continue;
                };
                for (f_pi, lobe) in f_pis.iter_mut().zip(lobes) {
                    *f_pi = std::f32::consts::PI * lobe.specular(omega);
                }
                let mut traced = 0;
                for (u, (next, weight)) in next_weights.iter_mut().zip(weights).enumerate() {
                    let (lobe, f_pi) = (&lobes[lobe_index(u)], f_pis[lobe_index(u)]);
                    *next = std::array::from_fn(|c| {
                        weight[c] * inv_count * (std::f32::consts::PI * lobe.diffuse[c] + f_pi)
                    });
                    if !next.iter().all(|&w| w <= 0.0) {
                        traced += 1;
                    }
                }
                if traced == 0 {
                    continue;
                }
                if traced < weights.len() {
                    return Err(StreamsParted);
                }
                let next = self.surface_at_hit(&hit, omega);
                let mut reflections = [Vec3::ZERO; 1];
                let next_lobe = self.lobe(&next, &[-omega], &mut reflections);
                self.accumulate_joint(
                    &next,
                    std::slice::from_ref(&next_lobe),
                    self.settings.bounce_texel_samples,
                    1,
                    bounces_left - 1,
                    &next_weights,
                    rng,
                    out,
                )?;
            }
        }
        Ok(())
    }

    /// One path-traced radiance estimate at `sp` seen from `omega_o` under `light`
    /// (an environment map of any resolution in the light frame, piecewise constant,
    /// looked up by [`nelf_format::conventions::LatLong::lookup`]): cosine-weighted
    /// directions, no texel stratification, up to `bounces` interreflections. The
    /// independent cross-check of [`Self::light_transport`].
    pub fn path_radiance(
        &self,
        sp: &SurfacePoint,
        omega_o: Vec3,
        light: &nelf_format::conventions::LatLong,
        rng: &mut TraceRng,
    ) -> [f32; 3] {
        let light_from_world = self.settings.world_from_light.transpose();
        let mut radiance = [0.0f32; 3];
        let mut throughput = [1.0f32; 3];
        let mut vertex = *sp;
        let mut outgoing = omega_o;
        for depth in 0..=self.settings.bounces {
            let mut reflections = [Vec3::ZERO; 1];
            let lobe = self.lobe(&vertex, &[outgoing], &mut reflections);
            let frame = Frame::new(vertex.shading_normal);
            let omega = frame.to_world(cosine_hemisphere(rng.random(), rng.random()));
            if vertex.geometric_normal.dot(omega) <= 0.0 {
                break;
            }
            let f_pi = std::f32::consts::PI * lobe.specular(omega);
            for (t, d) in throughput.iter_mut().zip(lobe.diffuse) {
                *t *= std::f32::consts::PI * d + f_pi;
            }
            let origin = vertex.position + self.epsilon * vertex.geometric_normal;
            match self.bvh.closest_hit(origin, omega, 0.0, f32::INFINITY) {
                None => {
                    let l = light.lookup(light_from_world * omega.as_dvec3());
                    for ((r, t), l) in radiance.iter_mut().zip(throughput).zip(l) {
                        *r += t * l;
                    }
                    break;
                }
                Some(hit) => {
                    if depth == self.settings.bounces {
                        break;
                    }
                    vertex = self.surface_at_hit(&hit, omega);
                    outgoing = -omega;
                }
            }
        }
        radiance
    }
}

/// A generator for `stream` of base seed `seed` (splitmix64-style mixing, so nearby
/// streams are unrelated).
pub fn stream_rng(seed: u64, stream: u64) -> TraceRng {
    TraceRng::seed_from_u64(mix64(seed ^ mix64(stream.wrapping_add(0x9e37_79b9_7f4a_7c15))))
}

/// The splitmix64 finaliser.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Splits `n` samples into a `rows × cols` grid with `rows ≤ cols` as square as `n`
/// allows (`rows` is the largest divisor of `n` not above `√n`).
fn strata(n: u32) -> (u32, u32) {
    if n == 0 {
        return (0, 0);
    }
    let mut rows = (f64::from(n).sqrt().floor() as u32).max(1);
    while n % rows != 0 {
        rows -= 1;
    }
    (rows, n / rows)
}

/// Cosine-weighted direction on the +z hemisphere from two uniforms (Malley's method).
#[inline]
fn cosine_hemisphere(xi1: f32, xi2: f32) -> Vec3 {
    let r = xi1.sqrt();
    let (s, c) = (std::f32::consts::TAU * xi2).sin_cos();
    Vec3::new(r * c, r * s, (1.0 - xi1).max(0.0).sqrt())
}

/// An orthonormal frame around a unit normal (Duff et al. 2017).
#[derive(Debug, Clone, Copy)]
struct Frame {
    tangent: Vec3,
    bitangent: Vec3,
    normal: Vec3,
}

impl Frame {
    fn new(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Self {
            tangent: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            bitangent: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            normal: n,
        }
    }

    #[inline]
    fn to_world(self, v: Vec3) -> Vec3 {
        v.x * self.tangent + v.y * self.bitangent + v.z * self.normal
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strata_are_square_as_possible() {
        assert_eq!(strata(16), (4, 4));
        assert_eq!(strata(64), (8, 8));
        assert_eq!(strata(8), (2, 4));
        assert_eq!(strata(7), (1, 7));
        assert_eq!(strata(1), (1, 1));
    }

    #[test]
    fn frame_is_orthonormal() {
        for n in [
            Vec3::Z,
            Vec3::NEG_Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.2).normalize(),
        ] {
            let f = Frame::new(n);
            for (a, b) in [
                (f.tangent, f.bitangent),
                (f.tangent, f.normal),
                (f.bitangent, f.normal),
            ] {
                assert!(a.dot(b).abs() < 1e-6);
            }
            assert!((f.tangent.length() - 1.0).abs() < 1e-6);
            assert!((f.bitangent.length() - 1.0).abs() < 1e-6);
            assert!(f.to_world(Vec3::Z).abs_diff_eq(n, 1e-6));
        }
    }

    /// The joint estimate runs through where every direction traces the same paths
    /// and reports the parting streams of a black, purely glossy scene (where
    /// `light_transport_directions` falls back to one lobe at a time).
    #[test]
    fn joint_estimate_reports_parting_streams() {
        let scene = |albedo: [f32; 3], weight: f32| {
            let mesh = crate::shapes::merge(&[
                crate::shapes::uv_sphere(Vec3::ZERO, 0.5, 12, 24, albedo),
                crate::shapes::quad(
                    Vec3::new(-1.5, -0.5, 1.5),
                    Vec3::new(3.0, 0.0, 0.0),
                    Vec3::new(0.0, 0.0, -3.0),
                    2,
                    albedo,
                ),
            ]);
            let settings = TraceSettings {
                texel_samples: 1,
                indirect_samples: 64,
                specular: Some(Specular {
                    weight,
                    exponent: 30.0,
                }),
                ..TraceSettings::default()
            };
            LtTracer::new(&mesh, settings).unwrap()
        };
        let joint = |tracer: &LtTracer| {
            let hit = tracer.intersect(Vec3::new(0.7, 2.0, 0.1), Vec3::NEG_Y).unwrap();
            let sp = tracer.surface_at_hit(&hit, Vec3::NEG_Y);
            let omegas = [Vec3::Y, Vec3::new(0.6, 0.8, 0.0), Vec3::new(-0.6, 0.0, 0.8)];
            let mut reflections = [Vec3::ZERO; 3];
            let lobes: Vec<Lobe<'_>> = omegas
                .iter()
                .zip(reflections.chunks_exact_mut(1))
                .map(|(w, r)| tracer.lobe(&sp, std::slice::from_ref(w), r))
                .collect();
            let mut out = vec![0.0f32; 3 * LT_DIM];
            let s = tracer.settings;
            tracer.accumulate_joint(
                &sp,
                &lobes,
                s.texel_samples,
                s.indirect_samples,
                s.bounces,
                &[[1.0; 3]; 3],
                &mut tracer.rng(0),
                &mut out,
            )
        };
        assert!(joint(&scene([0.5; 3], 0.3)).is_ok());
        assert!(joint(&scene([0.0; 3], 1.0)).is_err());
    }

    #[test]
    fn phong_lobe_conserves_energy() {
        // Directional albedo of the lobe alone (k_s = 1) is ≤ 1 and close to 1 at normal incidence.
        let n = Vec3::Y;
        let sp = SurfacePoint {
            position: Vec3::ZERO,
            geometric_normal: n,
            shading_normal: n,
            albedo: [0.0; 3],
        };
        let mesh = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Z],
            triangles: vec![[0, 2, 1]],
            albedo: crate::mesh::Albedo::Uniform([0.0; 3]),
        };
        let settings = TraceSettings {
            specular: Some(Specular {
                weight: 1.0,
                exponent: 20.0,
            }),
            ..TraceSettings::default()
        };
        let tracer = LtTracer::new(&mesh, settings).unwrap();
        for tilt in [0.0f32, 0.6, 1.2] {
            let w_o = Vec3::new(tilt.sin(), tilt.cos(), 0.0);
            let mut refl = [Vec3::ZERO; 1];
            let lobe = tracer.lobe(&sp, &[w_o], &mut refl);
            let mut rng = stream_rng(1, 2);
            let m = 200_000;
            let mut sum = 0.0f64;
            for _ in 0..m {
                let w = Frame::new(n).to_world(cosine_hemisphere(rng.random(), rng.random()));
                sum += f64::from(std::f32::consts::PI * lobe.specular(w));
            }
            let albedo = sum / f64::from(m);
            assert!(albedo <= 1.01, "tilt {tilt}: {albedo}");
            if tilt == 0.0 {
                assert!((albedo - 1.0).abs() < 0.02, "{albedo}");
            }
        }
    }
}
