//! Properties of the volumetric ground-truth field: signed distance and its sign on
//! closed and open meshes, the density profile, a volume render of it, light
//! transport from the nearest surface point, view policies, and the batch API.
#![allow(clippy::unwrap_used)]

use glam::Vec3;
use nelf_format::conventions::{ENV_H, ENV_TEXELS, ENV_W, LT_DIM, LatLong, shade};
use nelf_scene::field::{DensityProfile, FieldError, FieldSource, MeshField, ViewPolicy};
use nelf_scene::mesh::Mesh;
use nelf_scene::shapes::{merge, quad, uv_sphere};
use nelf_scene::tracer::{Specular, TraceSettings};

const RADIUS: f32 = 0.5;

fn sphere() -> Mesh {
    uv_sphere(Vec3::ZERO, RADIUS, 48, 96, [0.7, 0.5, 0.3])
}

/// Deterministic unit vectors spread over the sphere (a Fibonacci lattice).
fn directions(n: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

fn fast_settings() -> TraceSettings {
    TraceSettings {
        texel_samples: 4,
        indirect_samples: 16,
        ..TraceSettings::default()
    }
}

#[test]
fn signed_distance_of_a_sphere() {
    let field = MeshField::new(&sphere(), fast_settings(), DensityProfile::default()).unwrap();
    // Chord error of the tessellation: the mesh lies within r(1 − cos(π/48)) inside the sphere.
    let tessellation = RADIUS * (1.0 - (std::f32::consts::PI / 48.0).cos()) + 1e-5;
    for (i, dir) in directions(200).into_iter().enumerate() {
        let r = [0.0, 0.1, 0.3, 0.45, 0.49, 0.51, 0.55, 0.8, 2.0][i % 9];
        let (d, cp) = field.signed_distance(dir * r).unwrap();
        let want = r - RADIUS;
        assert!(d.signum() == want.signum(), "r = {r}: {d}");
        assert!((d - want).abs() <= tessellation + 1e-6, "r = {r}: {d} vs {want}");
        assert!((cp.point.length() - RADIUS).abs() <= tessellation);
    }
}

#[test]
fn sign_is_robust_for_open_meshes() {
    // Cut a cap out of the sphere (like a head open at the neck): ray parity would
    // misclassify many points, the winding number does not.
    let mut open = sphere();
    open.triangles.retain(|t| {
        let c = t.iter().map(|&i| open.positions[i as usize]).sum::<Vec3>() / 3.0;
        c.y > -0.4 * RADIUS
    });
    let field = MeshField::new(&open, fast_settings(), DensityProfile::default()).unwrap();
    for (i, dir) in directions(150).into_iter().enumerate() {
        let r = [0.2, 0.4, 0.7, 1.5][i % 4];
        let x = dir * r;
        let (d, _) = field.signed_distance(x).unwrap();
        if r < RADIUS && dir.y > -0.2 {
            assert!(d < 0.0, "inside point {x} classified outside: {d}");
        }
        if r > RADIUS && dir.y > -0.2 {
            assert!(d > 0.0, "outside point {x} classified inside: {d}");
        }
    }
}

#[test]
fn density_profile_values() {
    let profile = DensityProfile::with_shell_width(0.004);
    let s = profile.sigma_max_per_m;
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * b.abs().max(1.0);
    assert!(close(s, 25_000.0), "{s}");
    // Optical depth across the shell is 50.
    assert!(close(s * profile.shell_width_m, 100.0));
    assert_eq!(profile.density(-0.01), s);
    assert_eq!(profile.density(-0.0021), s);
    assert_eq!(profile.density(0.0), 0.5 * s);
    assert!(close(profile.density(0.001), 0.25 * s));
    assert!(close(profile.density(-0.001), 0.75 * s));
    assert_eq!(profile.density(0.0021), 0.0);
    assert_eq!(profile.density(0.5), 0.0);
    assert!(close(profile.support_m(), 0.002));
    // The field's density follows the profile of the (analytic) distance.
    let field = MeshField::new(&sphere(), fast_settings(), profile).unwrap();
    for (i, dir) in directions(60).into_iter().enumerate() {
        let r = RADIUS + [-0.3, -0.0015, -0.0005, 0.0005, 0.0015, 0.01][i % 6];
        let x = dir * r;
        let (d, _) = field.signed_distance(x).unwrap();
        assert_eq!(field.density(x), profile.density(d));
    }
    assert_eq!(field.density(Vec3::ZERO), s);
    assert_eq!(field.density(Vec3::splat(3.0)), 0.0);
    let (lo, hi) = field.bounds();
    assert!(lo.cmple(Vec3::splat(-RADIUS - 0.002 + 1e-6)).all());
    assert!(hi.cmpge(Vec3::splat(RADIUS + 0.002 - 1e-6)).all());
}

#[test]
fn volume_render_of_the_density_finds_the_surface() {
    // March rays at the sphere: opacity saturates and the expected termination depth
    // is within 0.4 mm of the mesh surface (default 1 mm shell).
    let mesh = sphere();
    let field = MeshField::new(&mesh, fast_settings(), DensityProfile::default()).unwrap();
    let tracer = field.tracer();
    for dir in directions(12) {
        let origin = dir * 1.0;
        let toward = -dir;
        let surface_t = tracer.intersect(origin, toward).unwrap().t;
        let (start, step) = (surface_t - 0.002, 2.0e-6f32);
        let (mut transmittance, mut expected_t) = (1.0f64, 0.0f64);
        for i in 0..2000 {
            let t = start + (i as f32 + 0.5) * step;
            let sigma = f64::from(field.density(origin + t * toward));
            let absorbed = transmittance * (1.0 - (-sigma * f64::from(step)).exp());
            expected_t += absorbed * f64::from(t);
            transmittance -= absorbed;
        }
        assert!(transmittance < 1e-6, "not opaque: {transmittance}");
        let offset = expected_t - f64::from(surface_t);
        assert!(offset.abs() < 4e-4, "termination {offset} m from the surface");
    }
}

#[test]
fn light_transport_comes_from_the_nearest_surface_point() {
    // A sphere on a floor (occlusion and interreflection): T at a point off the
    // surface matches T at its nearest surface point to within noise, and is far
    // from T at another surface point.
    let scene = merge(&[
        sphere(),
        quad(
            Vec3::new(-1.5, -0.5, 1.5),
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -3.0),
            4,
            [0.6; 3],
        ),
    ]);
    let field = MeshField::new(&scene, TraceSettings::default(), DensityProfile::default()).unwrap();
    let tracer = field.tracer();
    let n = Vec3::new(0.6, 0.3, 0.5).normalize();
    let surface = tracer.intersect(n * 2.0, -n).unwrap();
    let sp = tracer.surface_point(surface.triangle, surface.b1, surface.b2);
    let off = sp.position + 0.02 * sp.shading_normal;
    let (nearest, cp) = field.surface_point(off).unwrap();
    assert_eq!(cp.triangle, surface.triangle);
    assert!(nearest.position.distance(sp.position) < 1e-3);

    let view = ViewPolicy::Direction(n);
    let mut density = [0.0f32; 1];
    let mut lt_off = vec![0.0f32; LT_DIM];
    field.evaluate(&[off], &view, &mut density, &mut lt_off).unwrap();
    assert_eq!(density[0], 0.0);
    // Reference: mean and spread of T at the surface point over 16 seeds.
    let seeds = 16;
    let estimates = |at: &nelf_scene::tracer::SurfacePoint| -> Vec<Vec<f32>> {
        (0..seeds)
            .map(|s| tracer.light_transport(at, n, &mut tracer.rng(1000 + s)).to_vec())
            .collect()
    };
    let mean_of = |v: &[Vec<f32>]| -> Vec<f32> {
        (0..LT_DIM)
            .map(|i| v.iter().map(|e| e[i]).sum::<f32>() / v.len() as f32)
            .collect()
    };
    let distance = |x: &[f32], y: &[f32]| x.iter().zip(y).map(|(p, q)| (p - q).powi(2)).sum::<f32>().sqrt();
    let at_surface = estimates(&sp);
    let mean = mean_of(&at_surface);
    let noise = (at_surface.iter().map(|e| distance(e, &mean).powi(2)).sum::<f32>() / seeds as f32).sqrt();
    let off_distance = distance(&lt_off, &mean);
    assert!(off_distance < 2.0 * noise, "{off_distance} vs noise {noise}");
    let other = tracer.surface_point((surface.triangle + 3000) % 9024, 0.2, 0.2);
    let far = distance(&lt_off, &mean_of(&estimates(&other)));
    assert!(far > 5.0 * noise, "{far} vs noise {noise}");
    // Shaded under a uniform sky: within 4 standard deviations of the seeds' spread.
    let unit = LatLong::constant(ENV_W, ENV_H, [1.0; 3]);
    let radiance: Vec<[f32; 3]> = at_surface.iter().map(|e| shade(e, &unit)).collect();
    let x = shade(&lt_off, &unit);
    for c in 0..3 {
        let m = radiance.iter().map(|r| r[c]).sum::<f32>() / seeds as f32;
        let sd = (radiance.iter().map(|r| (r[c] - m).powi(2)).sum::<f32>() / (seeds - 1) as f32).sqrt();
        assert!(
            (x[c] - m).abs() <= 4.0 * sd + 1e-5,
            "channel {c}: {} vs {m} ± {sd}",
            x[c]
        );
    }
}

#[test]
fn batch_matches_single_points_and_threads() {
    let field = MeshField::new(&sphere(), fast_settings(), DensityProfile::with_shell_width(0.01)).unwrap();
    let points: Vec<Vec3> = directions(40)
        .into_iter()
        .enumerate()
        .map(|(i, d)| d * (RADIUS + [-0.1, -0.004, 0.0, 0.003, 0.05][i % 5]))
        .collect();
    let view = ViewPolicy::TowardPoint(Vec3::new(0.2, 0.3, 3.0));
    let mut density = vec![0.0f32; points.len()];
    let mut lt = vec![f32::NAN; points.len() * LT_DIM];
    field.evaluate(&points, &view, &mut density, &mut lt).unwrap();
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let (mut d1, mut l1) = (vec![0.0f32; points.len()], vec![0.0f32; points.len() * LT_DIM]);
    one_thread.install(|| field.evaluate(&points, &view, &mut d1, &mut l1).unwrap());
    assert_eq!(density, d1);
    assert_eq!(lt, l1);
    for (i, p) in points.iter().enumerate().step_by(7) {
        let mut d = [0.0f32; 1];
        let mut l = vec![0.0f32; LT_DIM];
        field
            .evaluate(std::slice::from_ref(p), &view, &mut d, &mut l)
            .unwrap();
        assert_eq!(d[0], density[i]);
        assert_eq!(l, lt[i * LT_DIM..(i + 1) * LT_DIM]);
    }
    let mut only_density = vec![0.0f32; points.len()];
    field.evaluate_density(&points, &mut only_density).unwrap();
    assert_eq!(only_density, density);
    assert!(density.contains(&0.0) && density.iter().any(|&d| d > 0.0));
    assert!(lt.iter().all(|v| v.is_finite()) && lt.iter().any(|&v| v > 0.0));
}

#[test]
fn view_policies_with_a_glossy_lobe() {
    let settings = TraceSettings {
        specular: Some(Specular {
            weight: 0.3,
            exponent: 10.0,
        }),
        ..fast_settings()
    };
    let field = MeshField::new(&sphere(), settings, DensityProfile::default()).unwrap();
    let x = Vec3::new(0.1, 0.2, 0.6);
    let eye = Vec3::new(0.5, 0.5, 2.0);
    let (d1, d2) = (
        Vec3::new(0.3, 0.2, 1.0).normalize(),
        Vec3::new(-0.6, 0.5, 0.5).normalize(),
    );
    let eval = |view: ViewPolicy| {
        let mut d = [0.0f32; 1];
        let mut l = vec![0.0f32; LT_DIM];
        field.evaluate(&[x], &view, &mut d, &mut l).unwrap();
        l
    };
    // Toward a point is the fixed direction to it.
    assert_eq!(
        eval(ViewPolicy::TowardPoint(eye)),
        eval(ViewPolicy::Direction(eye - x))
    );
    // The average over directions is the mean of the single-direction vectors (same
    // random stream, T linear in the BRDF).
    let (a, b) = (eval(ViewPolicy::Direction(d1)), eval(ViewPolicy::Direction(d2)));
    let mean = eval(ViewPolicy::AverageDirections(vec![d1, d2]));
    for i in 0..LT_DIM {
        let want = 0.5 * (a[i] + b[i]);
        assert!(
            (mean[i] - want).abs() <= 1e-5 * want.abs().max(1e-3),
            "{i}: {} vs {want}",
            mean[i]
        );
    }
    let toward_both = eval(ViewPolicy::AverageTowardPoints(vec![x + d1, x + 2.0 * d2]));
    for i in 0..LT_DIM {
        assert!((toward_both[i] - mean[i]).abs() <= 1e-5 * mean[i].abs().max(1e-3));
    }
    // The lobe is view-dependent: the two directions give clearly different vectors.
    let (sa, sb): (f32, f32) = (a[..ENV_TEXELS].iter().sum(), b[..ENV_TEXELS].iter().sum());
    assert!(
        a.iter()
            .zip(&b)
            .any(|(p, q)| (p - q).abs() > 0.05 * p.abs().max(q.abs())),
        "{sa} {sb}"
    );
}

#[test]
fn rejects_bad_batches_and_views() {
    let field = MeshField::new(&sphere(), fast_settings(), DensityProfile::default()).unwrap();
    let points = [Vec3::ZERO, Vec3::ONE];
    let view = ViewPolicy::Direction(Vec3::Z);
    let mut d = [0.0f32; 2];
    let mut short = vec![0.0f32; LT_DIM];
    assert!(matches!(
        field.evaluate(&points, &view, &mut d, &mut short),
        Err(FieldError::LengthMismatch { .. })
    ));
    let mut lt = vec![0.0f32; 2 * LT_DIM];
    assert!(matches!(
        field.evaluate(&[Vec3::ZERO, Vec3::NAN], &view, &mut d, &mut lt),
        Err(FieldError::NotFinite { index: 1 })
    ));
    for bad in [
        ViewPolicy::Direction(Vec3::ZERO),
        ViewPolicy::AverageDirections(vec![]),
        ViewPolicy::AverageTowardPoints(vec![Vec3::ZERO; 65]),
        ViewPolicy::TowardPoint(Vec3::INFINITY),
    ] {
        assert!(matches!(
            field.evaluate(&points, &bad, &mut d, &mut lt),
            Err(FieldError::View(_))
        ));
    }
    assert!(MeshField::new(&sphere(), fast_settings(), DensityProfile::with_shell_width(0.0)).is_err());
}

/// Query points around the sphere: inside, in the shell, outside, far outside.
fn points_around_sphere(n: usize) -> Vec<Vec3> {
    directions(n)
        .into_iter()
        .enumerate()
        .map(|(i, d)| d * (RADIUS + [-0.1, -0.004, 0.0, 0.003, 0.05, 2.0][i % 6]))
        .collect()
}

/// Per-direction `evaluate` with `ViewPolicy::Direction`, laid out as
/// `evaluate_directions` lays it out.
fn per_direction(field: &impl FieldSource, points: &[Vec3], dirs: &[Vec3]) -> (Vec<f32>, Vec<f32>) {
    let mut density = vec![0.0f32; points.len()];
    let mut lt = vec![0.0f32; points.len() * dirs.len() * LT_DIM];
    let mut one = vec![0.0f32; points.len() * LT_DIM];
    for (d, dir) in dirs.iter().enumerate() {
        field
            .evaluate(points, &ViewPolicy::Direction(*dir), &mut density, &mut one)
            .unwrap();
        for (i, t) in one.chunks_exact(LT_DIM).enumerate() {
            let at = (i * dirs.len() + d) * LT_DIM;
            lt[at..at + LT_DIM].copy_from_slice(t);
        }
    }
    (density, lt)
}

/// `evaluate_directions` (one trace per point for every direction) equals one
/// `evaluate` per direction bit for bit (compared with `==`, no tolerance), with
/// a glossy lobe; without one every direction gets the same vector.
#[test]
fn evaluate_directions_equals_per_direction_evaluate() {
    let glossy = TraceSettings {
        specular: Some(Specular::MILD_SHEEN),
        ..fast_settings()
    };
    // A sphere over a floor, so that the indirect paths hit something.
    let mesh = merge(&[
        sphere(),
        quad(
            Vec3::new(-2.0, -RADIUS - 0.02, 2.0),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -4.0),
            4,
            [0.6; 3],
        ),
    ]);
    let field = MeshField::new(&mesh, glossy, DensityProfile::with_shell_width(0.01)).unwrap();
    let points = points_around_sphere(36);
    // Not all unit: they are normalised as `ViewPolicy::Direction` normalises them.
    let mut dirs: Vec<Vec3> = directions(12);
    dirs.push(Vec3::new(0.0, 0.0, 3.0));
    let (want_density, want_lt) = per_direction(&field, &points, &dirs);
    let mut density = vec![f32::NAN; points.len()];
    let mut lt = vec![f32::NAN; points.len() * dirs.len() * LT_DIM];
    field
        .evaluate_directions(&points, &dirs, &mut density, &mut lt)
        .unwrap();
    assert_eq!(density, want_density);
    assert!(
        lt == want_lt,
        "evaluate_directions differs from per-direction evaluate"
    );
    // The lobe is there: at a lit surface point the directions differ.
    let at = |i: usize, d: usize| &lt[(i * dirs.len() + d) * LT_DIM..][..LT_DIM];
    assert!((0..dirs.len()).any(|d| at(2, d) != at(2, 0)));
    // Independent of the batch and the thread count.
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let tail = &points[7..];
    let (mut d1, mut l1) = (
        vec![0.0f32; tail.len()],
        vec![0.0f32; tail.len() * dirs.len() * LT_DIM],
    );
    one_thread.install(|| field.evaluate_directions(tail, &dirs, &mut d1, &mut l1).unwrap());
    assert_eq!(d1, density[7..]);
    assert!(l1 == lt[7 * dirs.len() * LT_DIM..]);

    // Without a lobe, T does not depend on the direction.
    let field = MeshField::new(&mesh, fast_settings(), DensityProfile::with_shell_width(0.01)).unwrap();
    let (_, want_lt) = per_direction(&field, &points, &dirs);
    field
        .evaluate_directions(&points, &dirs, &mut density, &mut lt)
        .unwrap();
    assert!(lt == want_lt);
    for per_point in lt.chunks_exact(dirs.len() * LT_DIM) {
        for v in per_point.chunks_exact(LT_DIM) {
            assert_eq!(v, &per_point[..LT_DIM]);
        }
    }
    assert!(lt.iter().any(|&v| v > 0.0));
}

#[test]
fn evaluate_directions_rejects_bad_batches() {
    let field = MeshField::new(&sphere(), fast_settings(), DensityProfile::default()).unwrap();
    let points = [Vec3::ZERO, Vec3::ONE];
    let dirs = [Vec3::Z, Vec3::X];
    let mut d = [0.0f32; 2];
    let mut lt = vec![0.0f32; 2 * 2 * LT_DIM];
    let mut short = vec![0.0f32; 2 * LT_DIM];
    assert!(matches!(
        field.evaluate_directions(&points, &dirs, &mut d, &mut short),
        Err(FieldError::LengthMismatch { lt_needed, .. }) if lt_needed == 4 * LT_DIM
    ));
    assert!(matches!(
        field.evaluate_directions(&[Vec3::ZERO, Vec3::NAN], &dirs, &mut d, &mut lt),
        Err(FieldError::NotFinite { index: 1 })
    ));
    for bad in [vec![], vec![Vec3::Z, Vec3::ZERO], vec![Vec3::NAN, Vec3::X]] {
        let mut lt = vec![0.0f32; 2 * bad.len() * LT_DIM];
        assert!(matches!(
            field.evaluate_directions(&points, &bad, &mut d, &mut lt),
            Err(FieldError::View(_))
        ));
    }
}

/// Times `evaluate_directions` with 16 directions against 1 (and against the
/// trait's per-direction default) on points around a procedural head with a mild
/// sheen, in CPU time of one thread (the machine is shared, wall time is noisy). A
/// measurement, not a test: `cargo test --release -p nelf-scene --test field --
/// --ignored --nocapture evaluate_directions_timing`.
#[test]
#[ignore = "timing by hand"]
fn evaluate_directions_timing() {
    use nelf_scene::head::{HeadParams, procedural_head};

    /// The trait's default, per-direction `evaluate`, for comparison.
    struct PerDirection<'a>(&'a MeshField);
    impl FieldSource for PerDirection<'_> {
        fn evaluate(
            &self,
            p: &[Vec3],
            v: &ViewPolicy,
            d: &mut [f32],
            l: &mut [f32],
        ) -> Result<(), FieldError> {
            self.0.evaluate(p, v, d, l)
        }
        fn bounds(&self) -> (Vec3, Vec3) {
            self.0.bounds()
        }
    }

    /// CPU time of the calling thread, seconds (Linux).
    fn thread_cpu_s() -> f64 {
        let text = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap();
        let ns: u64 = text.split_whitespace().next().unwrap().parse().unwrap();
        ns as f64 * 1e-9
    }

    let mesh = procedural_head(3, &HeadParams::default());
    let settings = TraceSettings {
        specular: Some(Specular::MILD_SHEEN),
        ..TraceSettings::default()
    };
    let field = MeshField::new(&mesh, settings, DensityProfile::with_shell_width(0.002)).unwrap();
    // Points 0–1 mm off the surface along the vertex normals of every n-th vertex.
    let normals = {
        let mut n = vec![Vec3::ZERO; mesh.positions.len()];
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            for &i in t {
                n[i as usize] += (b - a).cross(c - a);
            }
        }
        n
    };
    let count = 2000;
    let step = (mesh.positions.len() / count).max(1);
    let points: Vec<Vec3> = (0..count)
        .map(|i| {
            let v = (i * step) % mesh.positions.len();
            mesh.positions[v] + normals[v].normalize_or_zero() * 0.001 * (i % 3) as f32 / 2.0
        })
        .collect();
    let dirs = directions(16);
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let time = |source: &dyn FieldSource, points: &[Vec3], d: usize| {
        let mut density = vec![0.0f32; points.len()];
        let mut lt = vec![0.0f32; points.len() * d * LT_DIM];
        one_thread.install(|| {
            let start = thread_cpu_s();
            source
                .evaluate_directions(points, &dirs[..d], &mut density, &mut lt)
                .unwrap();
            (thread_cpu_s() - start) / points.len() as f64 * 1e3
        })
    };
    for round in 0..2 {
        let one = time(&field, &points, 1);
        let sixteen = time(&field, &points, 16);
        let default = time(&PerDirection(&field), &points[..count / 4], 16);
        println!(
            "round {round}, {count} points ({} for the default), one thread's CPU time per point: \
             D = 1 {one:.3} ms, D = 16 {sixteen:.3} ms ({:.2}×), per-direction default D = 16 {default:.3} ms ({:.2}×)",
            count / 4,
            sixteen / one,
            default / one
        );
    }
}
