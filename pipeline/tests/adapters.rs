//! The adapters between a field and the baker (`nelf_scene::adapter`): the
//! network bake's box filter, the signed log density over it, and parts of one field
//! swapped for another's, on small analytic fields and a sphere's ground truth.
//! Moved from `scene/tests/field.rs` with the adapters.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use glam::Vec3;
use nelf_format::conventions::{ENV_H, ENV_TEXELS, ENV_W, LT_DIM, shade};
use nelf_scene::field::{DensityProfile, FieldError, FieldSource, MeshField, ViewPolicy};
use nelf_scene::mesh::Mesh;
use nelf_scene::shapes::uv_sphere;
use nelf_scene::tracer::TraceSettings;

const RADIUS: f32 = 0.5;

fn sphere() -> Mesh {
    uv_sphere(Vec3::ZERO, RADIUS, 48, 96, [0.7, 0.5, 0.3])
}

fn fast_settings() -> TraceSettings {
    TraceSettings {
        texel_samples: 4,
        indirect_samples: 16,
        ..TraceSettings::default()
    }
}

/// A slab 1 mm thick at x ∈ [0.2, 1.2) mm with σ = 5000 /m and `T` = 1 everywhere in it,
/// `T` = 7 outside (where σ = 0).
struct ThinSlab;

impl FieldSource for ThinSlab {
    fn evaluate(
        &self,
        points: &[Vec3],
        _view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        for ((p, d), t) in points
            .iter()
            .zip(density.iter_mut())
            .zip(lt.chunks_exact_mut(LT_DIM))
        {
            let inside = (0.0002..0.0012).contains(&p.x);
            *d = if inside { 5000.0 } else { 0.0 };
            t.fill(if inside { 1.0 } else { 7.0 });
        }
        Ok(())
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        (Vec3::splat(-1.0), Vec3::splat(1.0))
    }
}

/// Box-filtering over voxels keeps the optical depth of a shell thinner than a voxel
/// (which a point sample at the voxel centre misses or overstates), and takes `T`
/// from where the density is.
#[test]
fn voxel_filter_keeps_a_thin_shells_optical_depth() {
    use nelf_pipeline::VoxelFiltered;
    let voxel = 0.004f32;
    // A voxel centred at x = 1.5 mm covers [−0.5, 3.5) mm: a quarter of it is slab.
    let centre = [Vec3::new(0.0015, 0.0, 0.0)];
    let point = |f: &dyn FieldSource| {
        let (mut d, mut t) = ([0.0f32], vec![0.0f32; LT_DIM]);
        f.evaluate(&centre, &ViewPolicy::Direction(Vec3::Z), &mut d, &mut t)
            .unwrap();
        (d[0], t[0])
    };
    // The point sample misses the slab entirely.
    assert_eq!(point(&ThinSlab), (0.0, 7.0));
    for n in [4usize, 8] {
        let filtered = VoxelFiltered::new(&ThinSlab, voxel, n).unwrap();
        let (sigma, t) = point(&filtered);
        // Sub-points at cell centres: exactly n/4 of n columns lie in the slab.
        assert!(
            (sigma * voxel - 5000.0 * 0.001).abs() < 1e-3,
            "n = {n}: σΔ = {}",
            sigma * voxel
        );
        assert!((t - 1.0).abs() < 1e-6, "n = {n}: T = {t}");
        let mut density = [0.0f32];
        filtered.evaluate_density(&centre, &mut density).unwrap();
        assert_eq!(density[0], sigma);
    }
    // Where there is no density at all, T is the plain mean; n = 1 is the point sample.
    let one = VoxelFiltered::new(&ThinSlab, voxel, 1).unwrap();
    assert_eq!(point(&one), (0.0, 7.0));
    assert!(VoxelFiltered::new(&ThinSlab, 0.0, 2).is_err());
    assert!(VoxelFiltered::new(&ThinSlab, voxel, 0).is_err());
}

/// The split field takes σ (everywhere, and for the density-only path) and the
/// bounds from one source, `T` from the other, whichever the view policy or batch.
#[test]
fn density_and_transport_takes_each_from_its_source() {
    use nelf_pipeline::DensityAndTransport;
    let sphere_field = MeshField::new(&sphere(), fast_settings(), DensityProfile::default()).unwrap();
    let split = DensityAndTransport::new(&sphere_field, &ThinSlab);
    let points = [Vec3::ZERO, Vec3::new(0.0007, 0.0, 0.0), Vec3::new(0.9, 0.0, 0.0)];
    let mut expected = [0.0f32; 3];
    sphere_field.evaluate_density(&points, &mut expected).unwrap();
    assert!(expected[0] > 0.0 && expected[2] == 0.0, "{expected:?}");
    let (mut density, mut lt) = ([0.0f32; 3], vec![0.0f32; 3 * LT_DIM]);
    split
        .evaluate(&points, &ViewPolicy::Direction(Vec3::Z), &mut density, &mut lt)
        .unwrap();
    assert_eq!(density, expected);
    // The slab's transport: 1 inside it (the second point), 7 elsewhere.
    for (t, want) in lt.chunks_exact(LT_DIM).zip([7.0f32, 1.0, 7.0]) {
        assert!(t.iter().all(|v| *v == want), "T {} against {want}", t[0]);
    }
    let mut many = vec![0.0f32; 3 * 2 * LT_DIM];
    density.fill(-1.0);
    split
        .evaluate_directions(&points, &[Vec3::Z, Vec3::X], &mut density, &mut many)
        .unwrap();
    assert_eq!(density, expected);
    assert_eq!(many[2 * LT_DIM], 1.0);
    density.fill(-1.0);
    split.evaluate_density(&points, &mut density).unwrap();
    assert_eq!(density, expected);
    assert_eq!(split.bounds(), sphere_field.bounds());
}

/// `T` = (texel index + 1) · (channel + 1) everywhere, σ = 1; channel 2 is zero at
/// points with x < 0 (a channel the lighting cannot light).
struct TexelRamp;

impl FieldSource for TexelRamp {
    fn evaluate(
        &self,
        points: &[Vec3],
        _view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        for ((p, d), t) in points
            .iter()
            .zip(density.iter_mut())
            .zip(lt.chunks_exact_mut(LT_DIM))
        {
            *d = 1.0;
            for (i, v) in t.iter_mut().enumerate() {
                let (c, k) = (i / ENV_TEXELS, i % ENV_TEXELS);
                *v = if c == 2 && p.x < 0.0 {
                    0.0
                } else {
                    (k + 1) as f32 * (c + 1) as f32
                };
            }
        }
        Ok(())
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        (Vec3::splat(-2.0), Vec3::splat(2.0))
    }
}

/// The shape-swapped field keeps the colour source's density and its shading under
/// the given lighting, with the shape source's transport up to one factor per
/// channel; a channel the shape source leaves dark keeps the colour source's `T`.
#[test]
fn transport_shape_from_keeps_the_colour_under_the_lighting() {
    use nelf_format::conventions::{LatLong, project_envmap};
    use nelf_pipeline::TransportShapeFrom;
    let texels: Vec<[f32; 3]> = (0..ENV_TEXELS)
        .map(|k| [0.1 + (k % 7) as f32 * 0.05, 0.2, 0.05 + (k % 3) as f32 * 0.1])
        .collect();
    let lighting = LatLong::new(ENV_W, ENV_H, texels).unwrap();
    let swapped = TransportShapeFrom::new(&TexelRamp, &ThinSlab, &lighting).unwrap();
    let points = [Vec3::new(0.0007, 0.0, 0.0), Vec3::new(-0.5, 0.0, 0.0)];
    let (mut density, mut lt) = ([0.0f32; 2], vec![0.0f32; 2 * LT_DIM]);
    swapped
        .evaluate(&points, &ViewPolicy::Direction(Vec3::Z), &mut density, &mut lt)
        .unwrap();
    assert_eq!(density, [5000.0, 0.0]);
    let light = project_envmap(&lighting, ThinSlab.world_from_light()).unwrap();
    for (i, (t, slab_t)) in lt.chunks_exact(LT_DIM).zip([1.0f32, 7.0]).enumerate() {
        let want = shade(&vec![slab_t; LT_DIM], &light);
        let got = shade(t, &light);
        for c in 0..3 {
            assert!(
                (got[c] - want[c]).abs() < 1e-4 * want[c],
                "point {i} channel {c}: {got:?} against {want:?}"
            );
        }
        // The ramp's shape: T ∝ texel index + 1 in channels 0 and 1 at both points,
        // and in channel 2 where the ramp lights it.
        for c in 0..3 {
            let row = &t[c * ENV_TEXELS..(c + 1) * ENV_TEXELS];
            if c == 2 && i == 1 {
                assert!(
                    row.iter().all(|v| *v == slab_t),
                    "the dark channel keeps the colour's T"
                );
            } else {
                for (k, v) in row.iter().enumerate() {
                    assert!(
                        (v / row[0] - (k + 1) as f32).abs() < 1e-3,
                        "point {i} channel {c} texel {k}"
                    );
                }
            }
        }
    }
    let mut only = [0.0f32; 2];
    swapped.evaluate_density(&points, &mut only).unwrap();
    assert_eq!(only, density);
}

/// The clamped cosine about a sphere's true normal: the same in every channel,
/// largest toward the normal, zero below the horizon, and integrating to π over
/// the sphere of directions (the cosine's integral; midpoint rule on 8 × 16 texels).
#[test]
fn true_normals_lambert_is_the_clamped_cosine_about_the_normal() {
    use nelf_format::conventions::{texel_center_direction, texel_solid_angle};
    use nelf_pipeline::TrueNormalsLambert;
    let sphere_field = MeshField::new(&sphere(), fast_settings(), DensityProfile::default()).unwrap();
    let lambert = TrueNormalsLambert::new(&sphere_field);
    for normal in [Vec3::X, Vec3::Y, Vec3::new(0.0, -0.6, 0.8)] {
        // Just outside the surface and just inside it: the same outward normal.
        let points = [normal * (RADIUS + 0.01), normal * (RADIUS - 0.01)];
        let (mut density, mut lt) = ([1.0f32; 2], vec![0.0f32; 2 * LT_DIM]);
        lambert
            .evaluate(&points, &ViewPolicy::Direction(Vec3::Z), &mut density, &mut lt)
            .unwrap();
        assert_eq!(density, [0.0, 0.0]);
        for t in lt.chunks_exact(LT_DIM) {
            let (red, rest) = t.split_at(ENV_TEXELS);
            assert_eq!(&rest[..ENV_TEXELS], red);
            assert_eq!(&rest[ENV_TEXELS..], red);
            let total: f32 = red.iter().sum();
            assert!(
                (total - std::f32::consts::PI).abs() < 0.05 * std::f32::consts::PI,
                "∫ = {total}"
            );
            for (k, v) in red.iter().enumerate() {
                let dir = texel_center_direction(k / ENV_W, k % ENV_W, ENV_H, ENV_W).as_vec3();
                let cos = dir.dot(normal);
                assert!(
                    if cos <= 0.0 { *v == 0.0 } else { *v > 0.0 },
                    "texel {k}: cos {cos}, T {v}"
                );
            }
            // Per steradian, the brightest texel is the one the normal points into.
            let per_sr = |k: usize| red[k] / texel_solid_angle(k / ENV_W, ENV_H, ENV_W) as f32;
            let top = (0..ENV_TEXELS)
                .max_by(|a, b| per_sr(*a).total_cmp(&per_sr(*b)))
                .unwrap();
            let dir = texel_center_direction(top / ENV_W, top % ENV_W, ENV_H, ENV_W).as_vec3();
            assert!(
                dir.dot(normal) > 0.9,
                "brightest texel {top} points {dir:?}, normal {normal:?}"
            );
        }
    }
}

/// A trained network's skin across the plane `x = surface`: σ grows by `e` every
/// `1/k` metres into `+x` and equals `k·ln 2` on the plane, where a ray coming from
/// `−x` reaches optical depth ln 2 (`τ(x) = σ(x)/k`).
struct ExponentialSkin {
    surface_m: f32,
    k_per_m: f32,
}

impl ExponentialSkin {
    fn sigma(&self, x: f32) -> f32 {
        (self.k_per_m * std::f32::consts::LN_2 * (self.k_per_m * (x - self.surface_m)).exp()).min(1e9)
    }
}

impl FieldSource for ExponentialSkin {
    fn evaluate(
        &self,
        points: &[Vec3],
        _view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        for ((p, d), t) in points
            .iter()
            .zip(density.iter_mut())
            .zip(lt.chunks_exact_mut(LT_DIM))
        {
            *d = self.sigma(p.x);
            t.fill(p.x);
        }
        Ok(())
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        (Vec3::splat(-1.0), Vec3::splat(1.0))
    }
}

/// Where a ray along `+x` through the lattice values `grid` (at `x = (i − 8)·Δ`),
/// interpolated linearly and clipped at 0 as the renderer does, reaches optical
/// depth ln 2.
fn half_transmittance_x(grid: &[f32], voxel: f32) -> f32 {
    let steps = 200;
    let mut tau = 0.0f64;
    for i in 0..grid.len() - 1 {
        for s in 0..steps {
            let f = (s as f32 + 0.5) / steps as f32;
            let sigma = ((1.0 - f) * grid[i] + f * grid[i + 1]).max(0.0);
            tau += f64::from(sigma * voxel / steps as f32);
            if tau >= std::f64::consts::LN_2 {
                return (i as f32 + f - 8.0) * voxel;
            }
        }
    }
    f32::INFINITY
}

/// A signed log density puts a steep skin's surface where the field has it, to a
/// small fraction of a voxel, wherever the surface lies between voxel centres; the
/// density itself, sampled on the same lattice (point samples or the bake's box
/// filter), renders swollen by a third to half a voxel.
#[test]
fn a_signed_log_density_keeps_a_steep_skin_in_place() {
    use nelf_scene::signed_density::SignedLogDensity;
    let voxel = 0.004f32;
    let k = 1000.0f32; // σ × e every millimetre
    let (mut raw_errors, mut signed_errors) = (Vec::new(), Vec::new());
    let (mut filtered_errors, mut filtered_signed_errors) = (Vec::new(), Vec::new());
    for o in 0..10 {
        let skin = ExponentialSkin {
            surface_m: voxel * (0.05 + 0.1 * o as f32),
            k_per_m: k,
        };
        let signed = SignedLogDensity::with_skin(&skin, 1.0 / k, 0.25 * voxel, voxel).unwrap();
        let points: Vec<Vec3> = (0..17)
            .map(|i| Vec3::new((i as f32 - 8.0) * voxel, 0.0, 0.0))
            .collect();
        let mut raw = vec![0.0f32; points.len()];
        let mut encoded = vec![0.0f32; points.len()];
        let mut lt = vec![0.0f32; points.len() * LT_DIM];
        skin.evaluate(&points, &ViewPolicy::Direction(Vec3::X), &mut raw, &mut lt)
            .unwrap();
        signed
            .evaluate(&points, &ViewPolicy::Direction(Vec3::X), &mut encoded, &mut lt)
            .unwrap();
        // Light transport passes through unchanged.
        assert_eq!(lt[LT_DIM], points[1].x);
        let mut density_only = vec![0.0f32; points.len()];
        signed.evaluate_density(&points, &mut density_only).unwrap();
        assert_eq!(density_only, encoded);
        raw_errors.push((half_transmittance_x(&raw, voxel) - skin.surface_m) / voxel);
        signed_errors.push((half_transmittance_x(&encoded, voxel) - skin.surface_m) / voxel);
        // The bake's box filter (2³ sub-points) first, as for a network.
        let filtered = nelf_pipeline::VoxelFiltered::new(&skin, voxel, 2).unwrap();
        filtered.evaluate_density(&points, &mut raw).unwrap();
        filtered_errors.push((half_transmittance_x(&raw, voxel) - skin.surface_m) / voxel);
        let signed = SignedLogDensity::with_skin(&filtered, 1.0 / k, 0.25 * voxel, voxel).unwrap();
        signed.evaluate_density(&points, &mut encoded).unwrap();
        filtered_signed_errors.push((half_transmittance_x(&encoded, voxel) - skin.surface_m) / voxel);
    }
    for (o, e) in signed_errors.iter().enumerate() {
        assert!(e.abs() < 0.02, "offset {o}: signed surface off by {e} voxels");
    }
    let raw_mean = raw_errors.iter().sum::<f32>() / raw_errors.len() as f32;
    let filtered_mean = filtered_errors.iter().sum::<f32>() / filtered_errors.len() as f32;
    // Over the box filter the mean of σ across a voxel's sub-points (at ±Δ/4) is
    // σ·cosh(kΔ/4) of its centre's: the surface moves out by ln(cosh(kΔ/4))/k,
    // 0.11 voxels here, a third of what σ itself loses, the same at every offset.
    let filter_shift = (k * voxel / 4.0).cosh().ln() / (k * voxel);
    for (o, e) in filtered_signed_errors.iter().enumerate() {
        assert!(
            (e + filter_shift).abs() < 0.02,
            "offset {o}: filtered signed surface off by {e} voxels"
        );
    }
    assert!(raw_mean < -0.25, "raw σ swells the surface by {raw_mean} voxels");
    assert!(
        filtered_mean < -0.25,
        "box-filtered σ swells the surface by {filtered_mean} voxels"
    );

    // Empty space is the negative cap; the encoding grows with σ; bad settings fail.
    let skin = ExponentialSkin {
        surface_m: 0.0,
        k_per_m: k,
    };
    let signed = SignedLogDensity::new(&skin, 693.0, k, 0.001, voxel).unwrap();
    assert!(signed.encode(0.0) < 0.0 && signed.encode(0.0) == signed.encode(f32::NAN));
    assert!(signed.encode(0.0) <= signed.encode(1.0));
    assert!(signed.encode(1.0) < signed.encode(693.0) && signed.encode(693.0) < signed.encode(1e5));
    assert!(signed.encode(693.0) > 0.0 && signed.encode(1e12) == -signed.encode(0.0));
    // The same profile of a distance (another surface stored alike, e.g. a visual
    // hull): zero at the lead outside, σ_iso's value at the surface, capped both ways.
    assert!(signed.encode_distance(0.001).abs() < 1e-3 * signed.encode(0.0).abs());
    assert!((signed.encode_distance(0.0) - signed.encode(693.0)).abs() < 1e-3 * signed.encode(693.0));
    assert_eq!(signed.encode_distance(f32::INFINITY), signed.encode(0.0));
    assert_eq!(signed.encode_distance(-1.0), -signed.encode(0.0));
    assert!(SignedLogDensity::new(&skin, 0.0, k, 0.001, voxel).is_err());
    assert!(SignedLogDensity::new(&skin, 693.0, f32::NAN, 0.001, voxel).is_err());
}
