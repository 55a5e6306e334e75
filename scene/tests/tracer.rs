//! Properties of the light-transport path tracer and the image renderers:
//! white furnace, linearity, lighting rotation, agreement of the two independent
//! estimators, interreflection convergence, determinism.
#![allow(clippy::unwrap_used)]

use glam::{DMat3, DVec3, Vec3};
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LT_DIM, LatLong, PinholeCamera, lt_index, rotation_y, shade,
    texel_center_direction,
};
use nelf_scene::mesh::Mesh;
use nelf_scene::render::{
    DirectSettings, RenderError, RenderedImage, render_direct_image, render_lt_buffer, render_lt_image,
    render_lt_images,
};
use nelf_scene::shapes::{boxed, merge, quad, rotated, uv_sphere};
use nelf_scene::tracer::{LtTracer, Specular, TraceSettings};

const ALBEDO: [f32; 3] = [0.8, 0.5, 0.2];

/// A sphere resting on a square floor: occlusion and interreflection.
fn sphere_on_plane() -> Mesh {
    merge(&[
        uv_sphere(Vec3::ZERO, 0.5, 24, 48, [0.7, 0.5, 0.3]),
        quad(
            Vec3::new(-1.5, -0.5, 1.5),
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -3.0),
            4,
            [0.6; 3],
        ),
    ])
}

fn camera(size: u32) -> PinholeCamera {
    PinholeCamera::look_at(
        DVec3::new(0.4, 1.0, 2.4),
        DVec3::new(0.0, -0.15, 0.0),
        DVec3::Y,
        size,
        size,
        0.75,
    )
}

/// A smooth, coloured, non-uniform 8 × 16 map: a sky gradient and a broad warm lobe.
fn sky_map() -> LatLong {
    let sun = DVec3::new(0.5, 0.7, 0.5).normalize();
    let texels: Vec<[f32; 3]> = (0..ENV_TEXELS)
        .map(|k| {
            let d = texel_center_direction(k / ENV_W, k % ENV_W, ENV_H, ENV_W);
            let lobe = d.dot(sun).max(0.0).powi(3) as f32;
            let up = (0.5 + 0.5 * d.y) as f32;
            [
                0.2 + 0.3 * up + 1.2 * lobe,
                0.25 + 0.3 * up + 0.9 * lobe,
                0.35 + 0.4 * up + 0.5 * lobe,
            ]
        })
        .collect();
    LatLong::new(ENV_W, ENV_H, texels).unwrap()
}

fn random_map(seed: u32) -> LatLong {
    let mut state = seed.wrapping_mul(2_654_435_761).max(1);
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    };
    LatLong::new(
        ENV_W,
        ENV_H,
        (0..ENV_TEXELS).map(|_| [next(), next(), next()]).collect(),
    )
    .unwrap()
}

/// Alpha-weighted PSNR of `test` against `reference`, peak = reference maximum in the mask.
fn masked_psnr(reference: &RenderedImage, test: &RenderedImage) -> f64 {
    let (mut se, mut weight, mut peak) = (0.0f64, 0.0f64, 0.0f64);
    for ((r, t), &a) in reference.rgb.iter().zip(&test.rgb).zip(&reference.alpha) {
        if a <= 0.0 {
            continue;
        }
        for c in 0..3 {
            se += f64::from(a) * f64::from(r[c] - t[c]).powi(2);
            peak = peak.max(f64::from(r[c]));
        }
        weight += 3.0 * f64::from(a);
    }
    assert!(weight > 0.0, "empty mask");
    10.0 * (peak * peak / (se / weight)).log10()
}

#[test]
fn white_furnace_convex_sphere() {
    let sphere = uv_sphere(Vec3::new(0.1, -0.2, 0.05), 0.4, 48, 96, ALBEDO);
    let tilted = DMat3::from_rotation_x(0.3) * DMat3::from_rotation_y(1.1);
    for world_from_light in [DMat3::IDENTITY, tilted] {
        let settings = TraceSettings {
            world_from_light,
            ..TraceSettings::default()
        };
        let tracer = LtTracer::new(&sphere, settings).unwrap();
        let unit = LatLong::constant(ENV_W, ENV_H, [1.0; 3]);
        for (i, triangle) in [5u32, 700, 2100, 4000, 6500, 9000].into_iter().enumerate() {
            let sp = tracer.surface_point(triangle, 0.3, 0.25);
            let n = sp.shading_normal;
            let side = n.cross(Vec3::Y).normalize_or(Vec3::X);
            for omega_o in [n, (n + 0.8 * side).normalize(), (n - 2.0 * side).normalize()] {
                let mut rng = tracer.rng(i as u64);
                let lt = tracer.light_transport(&sp, omega_o, &mut rng);
                let radiance = shade(&lt, &unit);
                for c in 0..3 {
                    let sum: f32 = (0..ENV_TEXELS).map(|k| lt[c * ENV_TEXELS + k]).sum();
                    assert!((sum - radiance[c]).abs() < 1e-5);
                    let rel = (radiance[c] - ALBEDO[c]) / ALBEDO[c];
                    assert!(
                        rel.abs() < 0.005,
                        "triangle {triangle}, channel {c}: {} vs {}",
                        radiance[c],
                        ALBEDO[c]
                    );
                }
                // Light only from texels above the surface.
                for k in 0..ENV_TEXELS {
                    let d = world_from_light * texel_center_direction(k / ENV_W, k % ENV_W, ENV_H, ENV_W);
                    if d.as_vec3().dot(n) < -0.5 {
                        assert_eq!(lt[lt_index(0, k / ENV_W, k % ENV_W)], 0.0);
                    }
                }
            }
        }
    }
}

#[test]
fn white_furnace_image() {
    let sphere = uv_sphere(Vec3::ZERO, 0.5, 32, 64, ALBEDO);
    let settings = TraceSettings {
        indirect_samples: 4,
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&sphere, settings).unwrap();
    let cam = PinholeCamera::look_at(DVec3::new(0.0, 0.3, 2.0), DVec3::ZERO, DVec3::Y, 16, 16, 0.7);
    let image = render_lt_image(&tracer, &cam, &LatLong::constant(ENV_W, ENV_H, [1.0; 3]), None).unwrap();
    let mut covered = 0;
    for (rgb, &a) in image.rgb.iter().zip(&image.alpha) {
        if a > 0.0 {
            covered += 1;
            for c in 0..3 {
                assert!((rgb[c] - ALBEDO[c]).abs() < 0.01 * ALBEDO[c], "{rgb:?}");
            }
        } else {
            assert_eq!(*rgb, [0.0; 3]);
        }
    }
    assert!(covered > 60, "{covered}");
    // The silhouette is antialiased: some pixels are partly covered.
    assert!(image.alpha.iter().any(|&a| a > 0.0 && a < 1.0));
}

#[test]
fn lighting_is_linear() {
    let settings = TraceSettings {
        texel_samples: 4,
        indirect_samples: 9,
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&sphere_on_plane(), settings).unwrap();
    let cam = camera(20);
    let (l1, l2) = (random_map(1), random_map(2));
    let mut sum = l1.clone();
    for (s, t) in sum.texels_mut().iter_mut().zip(l2.texels()) {
        for c in 0..3 {
            s[c] += t[c];
        }
    }
    let images = render_lt_images(&tracer, &cam, &[l1, l2, sum], None).unwrap();
    let mut checked = 0;
    for i in 0..images[0].rgb.len() {
        for c in 0..3 {
            let lhs = images[2].rgb[i][c];
            let rhs = images[0].rgb[i][c] + images[1].rgb[i][c];
            assert!(
                (lhs - rhs).abs() <= 1e-5 * rhs.abs().max(1e-3),
                "pixel {i}: {lhs} vs {rhs}"
            );
            checked += usize::from(rhs > 0.0);
        }
    }
    assert!(checked > 300);
    // The single-map entry point gives the same pixels as the batch.
    let single = render_lt_image(&tracer, &cam, &random_map(2), None).unwrap();
    assert_eq!(single, images[1]);
}

#[test]
fn rotating_scene_and_light_frame_changes_nothing() {
    // Rotating mesh, camera and light frame together by R (about +y, 3/16 of a turn)
    // is the same scene. Direct lighting is sampled in the light frame, so with no
    // bounces the image agrees to float rounding (the BVH and ray origins differ by
    // f32 rounding, which can flip an occasional grazing shadow ray); indirect
    // directions are drawn in a tangent frame that does not rotate with the scene,
    // so with bounces it agrees to noise. Rotating mesh and camera but shifting the
    // map's columns instead is the same scene too, sampled by other random
    // directions: it agrees to noise.
    let steps = 3;
    let alpha = steps as f64 * std::f64::consts::TAU / ENV_W as f64;
    let r = rotation_y(alpha);
    let mesh = sphere_on_plane();
    let base = TraceSettings {
        bounces: 0,
        ..TraceSettings::default()
    };
    let light = sky_map();
    let cam = camera(24);
    let rotated_mesh = rotated(&mesh, r.as_mat3());
    let rotated_cam = PinholeCamera::look_at(
        r * DVec3::new(0.4, 1.0, 2.4),
        r * DVec3::new(0.0, -0.15, 0.0),
        DVec3::Y,
        24,
        24,
        0.75,
    );

    let original = render_lt_image(&LtTracer::new(&mesh, base).unwrap(), &cam, &light, None).unwrap();
    let frame_rotated = render_lt_image(
        &LtTracer::new(
            &rotated_mesh,
            TraceSettings {
                world_from_light: r,
                ..base
            },
        )
        .unwrap(),
        &rotated_cam,
        &light,
        None,
    )
    .unwrap();
    let psnr = masked_psnr(&original, &frame_rotated);
    println!("frame rotation: {psnr:.2} dB");
    assert!(psnr > 60.0, "frame rotation: {psnr} dB");
    let close = original
        .rgb
        .iter()
        .zip(&frame_rotated.rgb)
        .filter(|(a, b)| (0..3).all(|c| (a[c] - b[c]).abs() <= 1e-4 * a[c].max(1.0)))
        .count();
    assert!(
        close as f64 >= 0.97 * original.rgb.len() as f64,
        "{close} of {}",
        original.rgb.len()
    );

    // Column shift: world radiance from ω is L(R⁻¹ω), i.e. column j shows column j + steps.
    let shifted = LatLong::new(
        ENV_W,
        ENV_H,
        (0..ENV_TEXELS)
            .map(|k| light.get(k / ENV_W, (k % ENV_W + steps) % ENV_W))
            .collect(),
    )
    .unwrap();
    let base = TraceSettings {
        bounces: 1,
        ..TraceSettings::default()
    };
    let original = render_lt_image(&LtTracer::new(&mesh, base).unwrap(), &cam, &light, None).unwrap();
    let column_shifted = render_lt_image(
        &LtTracer::new(&rotated_mesh, base).unwrap(),
        &rotated_cam,
        &shifted,
        None,
    )
    .unwrap();
    let psnr = masked_psnr(&original, &column_shifted);
    println!("column shift: {psnr:.2} dB");
    assert!(psnr > 40.0, "column shift: {psnr} dB");
    // …and a wrong shift direction is clearly worse.
    let wrong = LatLong::new(
        ENV_W,
        ENV_H,
        (0..ENV_TEXELS)
            .map(|k| light.get(k / ENV_W, (k % ENV_W + ENV_W - steps) % ENV_W))
            .collect(),
    )
    .unwrap();
    let wrong_image = render_lt_image(
        &LtTracer::new(&rotated_mesh, base).unwrap(),
        &rotated_cam,
        &wrong,
        None,
    )
    .unwrap();
    assert!(masked_psnr(&original, &wrong_image) < psnr - 10.0);
}

#[test]
fn estimators_agree_at_default_samples() {
    let tracer = LtTracer::new(&sphere_on_plane(), TraceSettings::default()).unwrap();
    let cam = camera(32);
    let light = sky_map();
    let lt = render_lt_image(&tracer, &cam, &light, None).unwrap();
    let direct = render_direct_image(&tracer, &cam, &light, &DirectSettings::default(), None).unwrap();
    let psnr = masked_psnr(&direct, &lt);
    println!("T·L vs direct path tracing: {psnr:.2} dB");
    assert!(psnr >= 40.0, "{psnr} dB");
}

#[test]
fn estimators_agree_with_specular_lobe() {
    let settings = TraceSettings {
        specular: Some(Specular {
            weight: 0.3,
            exponent: 8.0,
        }),
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&sphere_on_plane(), settings).unwrap();
    let cam = camera(24);
    let light = sky_map();
    let lt = render_lt_image(&tracer, &cam, &light, None).unwrap();
    let direct = render_direct_image(&tracer, &cam, &light, &DirectSettings::default(), None).unwrap();
    let psnr = masked_psnr(&direct, &lt);
    println!("with a glossy lobe: {psnr:.2} dB");
    assert!(psnr >= 38.0, "{psnr} dB");
    // The lobe makes the image view-dependent: a diffuse render differs clearly.
    let diffuse = render_lt_image(
        &LtTracer::new(&sphere_on_plane(), TraceSettings::default()).unwrap(),
        &cam,
        &light,
        None,
    )
    .unwrap();
    assert!(masked_psnr(&direct, &diffuse) < psnr - 6.0);
}

#[test]
fn interreflection_converges_in_white_furnace() {
    // Two facing unit plates of albedo 1 under a uniform unit sky: with unlimited
    // bounces every surface has radiance exactly 1; each bounce adds light and the
    // deficit shrinks geometrically.
    let plates = merge(&[
        quad(Vec3::new(-0.5, 0.0, 0.5), Vec3::X, Vec3::NEG_Z, 1, [1.0; 3]),
        quad(Vec3::new(-0.5, 0.3, -0.5), Vec3::X, Vec3::Z, 1, [1.0; 3]),
    ]);
    let mut totals = Vec::new();
    for bounces in [0u32, 1, 2, 3, 4, 8] {
        let settings = TraceSettings {
            bounces,
            texel_samples: 16,
            indirect_samples: 1024,
            bounce_texel_samples: 2,
            ..TraceSettings::default()
        };
        let tracer = LtTracer::new(&plates, settings).unwrap();
        // Centre of the lower plate, facing up.
        let hit = tracer.intersect(Vec3::new(0.01, 0.2, 0.02), Vec3::NEG_Y).unwrap();
        let sp = tracer.surface_at_hit(&hit, Vec3::NEG_Y);
        assert!(sp.shading_normal.abs_diff_eq(Vec3::Y, 1e-6));
        let mut rng = tracer.rng(11);
        let lt = tracer.light_transport(&sp, Vec3::Y, &mut rng);
        totals.push(lt[..ENV_TEXELS].iter().sum::<f32>());
    }
    println!("radiance by bounces 0,1,2,3,4,8: {totals:?}");
    for w in totals.windows(2) {
        assert!(w[1] > w[0], "{totals:?}");
    }
    let deficits: Vec<f32> = totals.iter().map(|t| 1.0 - t).collect();
    for i in 0..4 {
        let ratio = deficits[i + 1] / deficits[i];
        assert!(
            ratio > 0.1 && ratio < 0.9,
            "deficit ratio {ratio} at {i}: {totals:?}"
        );
    }
    assert!(
        totals[0] < 0.6,
        "the facing plate blocks much of the sky: {totals:?}"
    );
    assert!((totals[5] - 1.0).abs() < 0.02, "{totals:?}");
}

#[test]
fn buffer_relights_like_direct_shading_and_runs_thread_independent() {
    let settings = TraceSettings {
        texel_samples: 4,
        indirect_samples: 4,
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&sphere_on_plane(), settings).unwrap();
    let cam = camera(16);
    let light = random_map(5);
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let serial = one_thread.install(|| render_lt_image(&tracer, &cam, &light, None).unwrap());
    let parallel = render_lt_image(&tracer, &cam, &light, None).unwrap();
    assert_eq!(serial, parallel);
    let buffer = render_lt_buffer(&tracer, &cam, usize::MAX, None).unwrap();
    assert_eq!(buffer.alpha, parallel.alpha);
    assert_eq!(buffer.bytes(), buffer.pixels.len() * 384 * 4);
    let relit = buffer.shade(&light).unwrap();
    for (a, b) in relit.rgb.iter().zip(&parallel.rgb) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= 1e-6 * b[c].max(1.0));
        }
    }
    assert!(buffer.lt_at(8, 8).is_some());
    assert!(matches!(
        render_lt_buffer(&tracer, &cam, 1000, None),
        Err(RenderError::TooLarge { .. })
    ));
    assert!(matches!(
        render_lt_image(&tracer, &cam, &LatLong::constant(32, 16, [1.0; 3]), None),
        Err(RenderError::LightSize { .. })
    ));
}

#[test]
fn back_faces_are_two_sided_and_settings_validate() {
    // A single quad facing away from the camera is seen from behind, lit from that side.
    let plate = quad(
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::Y * 2.0,
        Vec3::X * 2.0,
        1,
        ALBEDO,
    );
    let tracer = LtTracer::new(&plate, TraceSettings::default()).unwrap();
    let hit = tracer.intersect(Vec3::new(0.1, 0.1, 1.0), Vec3::NEG_Z).unwrap();
    let sp = tracer.surface_at_hit(&hit, Vec3::NEG_Z);
    assert!(sp.geometric_normal.abs_diff_eq(Vec3::Z, 1e-6));
    let lt = tracer.light_transport(&sp, Vec3::Z, &mut tracer.rng(0));
    let radiance = shade(&lt, &LatLong::constant(ENV_W, ENV_H, [1.0; 3]));
    assert!((radiance[0] - ALBEDO[0]).abs() < 0.005);
    // Only texels in front (+z) of the plate contribute.
    for (k, &t) in lt[..ENV_TEXELS].iter().enumerate() {
        let d = texel_center_direction(k / ENV_W, k % ENV_W, ENV_H, ENV_W);
        if d.z < -0.3 {
            assert_eq!(t, 0.0);
        }
    }
    let bad = [
        TraceSettings {
            texel_samples: 0,
            ..TraceSettings::default()
        },
        TraceSettings {
            world_from_light: DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)),
            ..TraceSettings::default()
        },
        TraceSettings {
            specular: Some(Specular {
                weight: 1.5,
                exponent: 1.0,
            }),
            ..TraceSettings::default()
        },
    ];
    for s in bad {
        assert!(LtTracer::new(&plate, s).is_err());
    }
    let open_box = boxed(Vec3::ZERO, Vec3::ONE, 1, true, true, ALBEDO);
    assert!(LtTracer::new(&open_box, TraceSettings::default()).is_ok());
}

/// Surface points of `sphere_on_plane` seen along a few rays: the sphere's top and
/// sides, near its contact with the floor, the floor in its shadow and in the open.
fn sample_surface_points(tracer: &LtTracer) -> Vec<nelf_scene::tracer::SurfacePoint> {
    [
        (Vec3::new(0.0, 2.0, 0.1), Vec3::NEG_Y),
        (Vec3::new(2.0, 0.2, 0.3), Vec3::NEG_X),
        (Vec3::new(0.3, -0.2, 2.0), Vec3::NEG_Z),
        (Vec3::new(0.55, 1.0, 0.0), Vec3::NEG_Y),
        (Vec3::new(-1.2, 1.0, 0.9), Vec3::NEG_Y),
    ]
    .into_iter()
    .map(|(origin, dir)| {
        let hit = tracer.intersect(origin, dir).unwrap();
        tracer.surface_at_hit(&hit, dir)
    })
    .collect()
}

/// Outgoing directions for the multi-direction estimator: a spread over the sphere
/// (about half below any surface point's horizon), a repeat, and a tilt.
fn outgoing_directions() -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    let mut dirs: Vec<Vec3> = (0..14)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / 14.0;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect();
    dirs.push(dirs[3]);
    dirs.push(Vec3::new(0.2, 0.9, 0.4).normalize());
    dirs
}

/// `light_transport_directions` against one `light_transport` call per direction
/// from the same generator state: equal bit for bit (`==` on every float).
fn assert_directions_match_single(tracer: &LtTracer, dirs: &[Vec3]) -> Vec<Vec<f32>> {
    let mut all = Vec::new();
    for (stream, sp) in sample_surface_points(tracer).iter().enumerate() {
        let mut joint = vec![f32::NAN; dirs.len() * LT_DIM];
        let mut rng = tracer.rng(stream as u64);
        tracer.light_transport_directions(sp, dirs, &mut rng, &mut joint);
        for (d, dir) in dirs.iter().enumerate() {
            let single = tracer.light_transport(sp, *dir, &mut tracer.rng(stream as u64));
            assert!(
                joint[d * LT_DIM..(d + 1) * LT_DIM] == single[..],
                "point {stream}, direction {d}: the joint estimate differs"
            );
        }
        assert!(joint.iter().any(|&v| v > 0.0), "point {stream} is lit");
        all.push(joint);
    }
    all
}

#[test]
fn light_transport_directions_equal_single_direction_estimates() {
    let settings = TraceSettings {
        texel_samples: 4,
        indirect_samples: 16,
        specular: Some(Specular {
            weight: 0.3,
            exponent: 8.0,
        }),
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&sphere_on_plane(), settings).unwrap();
    let dirs = outgoing_directions();
    for (i, joint) in assert_directions_match_single(&tracer, &dirs).iter().enumerate() {
        let vector = |d: usize| &joint[d * LT_DIM..(d + 1) * LT_DIM];
        // The lobe makes directions above the horizon differ; the repeat is a copy.
        let distinct = (0..dirs.len())
            .filter(|&d| (0..d).all(|e| vector(e) != vector(d)))
            .count();
        assert!(distinct >= 4, "point {i}: {distinct} distinct vectors");
        assert_eq!(vector(3), vector(14));
    }
    // Directions below the shading horizon all give the diffuse part alone.
    let sp = sample_surface_points(&tracer)[0];
    let below: Vec<Vec3> = dirs
        .iter()
        .copied()
        .filter(|d| d.dot(sp.shading_normal) <= 0.0)
        .collect();
    assert!(below.len() >= 4);
    let mut joint = vec![0.0f32; below.len() * LT_DIM];
    tracer.light_transport_directions(&sp, &below, &mut tracer.rng(9), &mut joint);
    for v in joint.chunks_exact(LT_DIM) {
        assert_eq!(v, &joint[..LT_DIM]);
    }
    // No directions: nothing written, nothing to do.
    tracer.light_transport_directions(&sp, &[], &mut tracer.rng(9), &mut []);
}

#[test]
fn light_transport_directions_without_a_lobe_are_one_vector() {
    let settings = TraceSettings {
        texel_samples: 4,
        indirect_samples: 16,
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&sphere_on_plane(), settings).unwrap();
    let dirs = outgoing_directions();
    for joint in assert_directions_match_single(&tracer, &dirs) {
        for v in joint.chunks_exact(LT_DIM) {
            assert_eq!(v, &joint[..LT_DIM]);
        }
    }
    // A zero-weight lobe is no lobe.
    let tracer = LtTracer::new(
        &sphere_on_plane(),
        TraceSettings {
            specular: Some(Specular {
                weight: 0.0,
                exponent: 8.0,
            }),
            ..settings
        },
    )
    .unwrap();
    for joint in assert_directions_match_single(&tracer, &dirs) {
        for v in joint.chunks_exact(LT_DIM) {
            assert_eq!(v, &joint[..LT_DIM]);
        }
    }
}

/// A black, purely glossy scene: an indirect path's weight is the lobe alone, zero
/// for some outgoing directions and not others, so the single-direction estimates'
/// random streams part; the joint estimator notices and still matches them.
#[test]
fn light_transport_directions_match_where_streams_part() {
    let mesh = merge(&[
        uv_sphere(Vec3::ZERO, 0.5, 24, 48, [0.0; 3]),
        quad(
            Vec3::new(-1.5, -0.5, 1.5),
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -3.0),
            4,
            [0.0, 0.4, 0.0],
        ),
    ]);
    let settings = TraceSettings {
        texel_samples: 4,
        indirect_samples: 16,
        specular: Some(Specular {
            weight: 1.0,
            exponent: 30.0,
        }),
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&mesh, settings).unwrap();
    assert_directions_match_single(&tracer, &outgoing_directions());
}
