//! Ray marching: the discretised emission–absorption integral, early termination,
//! empty-space skipping and visibility weights.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use common::{Rng, all_bricks, geometry, orbit_camera, random_map, synthetic};
use glam::{DMat3, DVec3};
use nelf_format::CoefficientEncoding;
use nelf_format::conventions::PinholeCamera;
use nelf_render::{
    BrickGrid, MarchSettings, RenderError, asset_density, project_light, render_features, render_volume,
    render_volume_stats, render_volume_unskipped, visibility_weights, voxel_radiance,
};

const SLAB_VOXEL_M: f64 = 0.005;
/// Slab voxels along z: layers `SLAB_FIRST .. SLAB_FIRST + SLAB_LAYERS`.
const SLAB_FIRST: usize = 8;
const SLAB_LAYERS: usize = 10;

/// A 2 × 2 × 4-brick grid (16 × 16 × 32 voxels of 5 mm, all bricks present) holding a
/// slab of density `sigma` in voxel layers 8..18 along z, radiance `rgb` everywhere.
fn slab(sigma: f32, rgb: [f32; 3]) -> (BrickGrid, Vec<f32>, Vec<[f32; 3]>) {
    let grid = BrickGrid::new(
        geometry([-0.04, -0.04, 0.0], SLAB_VOXEL_M, [2, 2, 4]),
        all_bricks([2, 2, 4]),
    )
    .unwrap();
    let density = (0..grid.voxel_count())
        .map(|v| {
            let k = grid.bricks()[v / 512][2] as usize * 8 + (v % 512) / 64;
            if (SLAB_FIRST..SLAB_FIRST + SLAB_LAYERS).contains(&k) {
                sigma
            } else {
                0.0
            }
        })
        .collect();
    (grid.clone(), density, vec![rgb; grid.voxel_count()])
}

/// Layer (global z index) of voxel `v` of the slab grid.
fn layer(grid: &BrickGrid, v: usize) -> usize {
    grid.bricks()[v / 512][2] as usize * 8 + (v % 512) / 64
}

/// A 9 × 9 camera 1 m in front of the slab grid looking along +z, 2° field of view.
fn head_on_camera() -> PinholeCamera {
    PinholeCamera::look_at(
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::Y,
        9,
        9,
        2f64.to_radians(),
    )
}

/// The synthetic shell asset (6³ bricks with empty ones inside and in the corners)
/// under a random map: grid, density and per-voxel radiance.
fn shell_scene() -> (BrickGrid, Vec<f32>, Vec<[f32; 3]>) {
    let asset = synthetic(60_000, 6, CoefficientEncoding::U8Affine, 5);
    let grid = BrickGrid::from_asset(&asset).unwrap();
    let density = asset_density(&asset);
    let env = random_map(32, 16, 4, 2.0);
    let light = project_light(&asset.pca, asset.world_from_light, &env, DMat3::IDENTITY).unwrap();
    let radiance = voxel_radiance(&asset, &light, None);
    (grid, density, radiance)
}

#[test]
fn homogeneous_slab_gives_one_minus_exp_optical_depth() {
    // σ L = 40 1/m × 10 voxels × 5 mm = 2. With Δ = ½ voxel and the ray entering on a voxel
    // face, every sample interval lies inside one linear piece of the trilinear profile, so
    // the midpoint sum of σ is exact and rgb = c (1 − e^{−σL}) up to f32 rounding head-on.
    let c = [0.2f32, 0.5, 1.0];
    let (grid, density, radiance) = slab(40.0, c);
    let camera = head_on_camera();
    let image = render_volume(&grid, &density, &radiance, &camera, &MarchSettings::default()).unwrap();
    let optical_depth = 40.0 * SLAB_LAYERS as f64 * SLAB_VOXEL_M;
    let want = 1.0 - (-optical_depth).exp();
    assert!(
        (f64::from(image.alpha_at(4, 4)) - want).abs() < 2e-6,
        "{} vs {want}",
        image.alpha_at(4, 4)
    );
    for (got, c) in image.rgb_at(4, 4).into_iter().zip(c) {
        let (got, c) = (f64::from(got), f64::from(c));
        assert!((got - c * want).abs() < 2e-6 * c, "{got}");
    }
    // Off-axis rays cross the slab obliquely: path length L / cos θ, midpoint error small.
    for v in 0..9 {
        for u in 0..9 {
            let (_, d) = camera.pixel_ray(u, v);
            let want = 1.0 - (-optical_depth / d.z).exp();
            let got = f64::from(image.alpha_at(u, v));
            assert!((got - want).abs() < 1e-4, "pixel ({u}, {v}): {got} vs {want}");
            assert!((f64::from(image.rgb_at(u, v)[1]) - 0.5 * got).abs() < 1e-6);
        }
    }
}

#[test]
fn opaque_slab_terminates_early() {
    let c = [1.0f32, 0.25, 0.5];
    let (grid, density, radiance) = slab(400.0, c);
    let camera = head_on_camera();
    let settings = MarchSettings::default();
    let (image, stats) = render_volume_stats(&grid, &density, &radiance, &camera, &settings).unwrap();
    let alpha = image.alpha_at(4, 4);
    // Stopped right after T fell below 1e-3: each plateau sample multiplies T by e^{−1}.
    assert!(
        alpha > 1.0 - 1e-3 && alpha < 1.0 - 1e-3 * (-1.01f32).exp(),
        "alpha {alpha}"
    );
    for (got, c) in image.rgb_at(4, 4).into_iter().zip(c) {
        assert!((got - c * alpha).abs() < 1e-5);
    }
    // Without termination every ray takes all its 64 samples (the grid is 32 voxels deep).
    let no_stop = MarchSettings {
        min_transmittance: 0.0,
        ..settings
    };
    let (full, full_stats) = render_volume_stats(&grid, &density, &radiance, &camera, &no_stop).unwrap();
    assert!(full.alpha_at(4, 4) > 1.0 - 1e-6);
    assert!(stats.samples_evaluated * 2 < full_stats.samples_evaluated);
    assert_eq!(full_stats.samples_evaluated, 81 * 64);
}

#[test]
fn rays_missing_the_box_see_nothing_and_cameras_inside_work() {
    let (grid, density, radiance) = slab(40.0, [1.0; 3]);
    let away = PinholeCamera::look_at(
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::new(0.0, 0.0, -2.0),
        DVec3::Y,
        5,
        5,
        0.5,
    );
    let image = render_volume(&grid, &density, &radiance, &away, &MarchSettings::default()).unwrap();
    assert!(image.alpha.iter().all(|&a| a == 0.0) && image.rgb.iter().all(|c| *c == [0.0; 3]));
    // From inside the slab, looking back out of it: only the slab in front is seen.
    let inside = PinholeCamera::look_at(
        DVec3::new(0.0, 0.0, 0.065),
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::Y,
        5,
        5,
        0.01,
    );
    let image = render_volume(&grid, &density, &radiance, &inside, &MarchSettings::default()).unwrap();
    // From z = 65 mm (voxel coordinate 13) back to z = 0: a plateau from the last centre at
    // 8.5 to 13 (4.5 voxels) plus the ramp from 8.5 to 7.5 (½ voxel of σ): σ · 5 voxels.
    let want = 1.0 - (-40.0f64 * 5.0 * SLAB_VOXEL_M).exp();
    assert!(
        (f64::from(image.alpha_at(2, 2)) - want).abs() < 1e-5,
        "{} vs {want}",
        image.alpha_at(2, 2)
    );
}

#[test]
fn empty_space_skipping_changes_nothing() {
    let (grid, density, radiance) = shell_scene();
    let inside = PinholeCamera::look_at(
        DVec3::new(0.02, 0.03, -0.01),
        DVec3::new(0.5, -0.2, 1.0),
        DVec3::Y,
        40,
        32,
        1.5,
    );
    let cameras = [
        orbit_camera(0.0, 0.0, 0.6, 40, 32),
        orbit_camera(37.0, 21.0, 0.45, 40, 32),
        orbit_camera(-123.0, -64.0, 0.8, 33, 27),
        inside,
    ];
    for settings in [
        MarchSettings::default(),
        MarchSettings {
            step_voxels: 0.37,
            min_transmittance: 0.0,
            ..MarchSettings::default()
        },
        MarchSettings {
            step_voxels: 1.3,
            min_transmittance: 0.05,
            ..MarchSettings::default()
        },
    ] {
        for (n, camera) in cameras.iter().enumerate() {
            let (skipped, stats) =
                render_volume_stats(&grid, &density, &radiance, camera, &settings).unwrap();
            let reference = render_volume_unskipped(&grid, &density, &radiance, camera, &settings).unwrap();
            assert_eq!(skipped, reference, "camera {n}, {settings:?}");
            // The shell's 6³-brick grid has empty bricks inside and in the corners.
            assert!(
                stats.samples_skipped > stats.samples_evaluated / 10,
                "camera {n}: {stats:?}"
            );
            assert!(skipped.alpha.iter().any(|&a| a > 0.5));
        }
    }
}

#[test]
fn visibility_weights_are_the_gradient_of_image_brightness() {
    // Σ_pixels rgb = Σ_v weight_v · r_v for any per-voxel grey radiance r.
    let asset = synthetic(12_000, 4, CoefficientEncoding::F16, 8);
    let grid = BrickGrid::from_asset(&asset).unwrap();
    let density = asset_density(&asset);
    let camera = orbit_camera(20.0, 10.0, 0.5, 36, 28);
    let settings = MarchSettings::default();
    let mut weights = vec![0.0f32; grid.voxel_count()];
    visibility_weights(&grid, &density, &camera, &settings, &mut weights).unwrap();
    assert!(weights.iter().all(|&w| w >= 0.0));
    let mut rng = Rng::new(3);
    for _ in 0..3 {
        let grey: Vec<f32> = (0..grid.voxel_count()).map(|_| rng.next()).collect();
        let radiance: Vec<[f32; 3]> = grey.iter().map(|&g| [g, 2.0 * g, 1.0]).collect();
        let image = render_volume(&grid, &density, &radiance, &camera, &settings).unwrap();
        let image_sum: f64 = image.rgb.iter().map(|c| f64::from(c[0])).sum();
        let weighted: f64 = weights
            .iter()
            .zip(&grey)
            .map(|(&w, &g)| f64::from(w) * f64::from(g))
            .sum();
        assert!(
            (image_sum - weighted).abs() < 1e-4 * image_sum,
            "{image_sum} vs {weighted}"
        );
        // With radiance 1 everywhere the identity is Σ pixels = Σ weights.
        let ones: f64 = image.rgb.iter().map(|c| f64::from(c[2])).sum();
        let total: f64 = weights.iter().map(|&w| f64::from(w)).sum();
        assert!(
            (ones - total).abs() < 1e-4 * total && total > 10.0,
            "{ones} vs {total}"
        );
    }
    // Calling again accumulates.
    let mut twice = weights.clone();
    visibility_weights(&grid, &density, &camera, &settings, &mut twice).unwrap();
    for (a, b) in weights.iter().zip(&twice) {
        assert!((2.0 * a - b).abs() <= 1e-6 * b.abs());
    }
}

#[test]
fn voxels_behind_an_opaque_slab_get_no_weight() {
    let (grid, density, _) = slab(400.0, [1.0; 3]);
    let camera = head_on_camera();
    let mut weights = vec![0.0f32; grid.voxel_count()];
    visibility_weights(&grid, &density, &camera, &MarchSettings::default(), &mut weights).unwrap();
    let by_layer = |range: std::ops::Range<usize>| -> f32 {
        (0..grid.voxel_count())
            .filter(|&v| range.contains(&layer(&grid, v)))
            .map(|v| weights[v])
            .sum()
    };
    assert!(by_layer(SLAB_FIRST..SLAB_FIRST + 2) > 10.0);
    assert_eq!(by_layer(SLAB_FIRST + 6..32), 0.0);
    assert_eq!(by_layer(0..SLAB_FIRST - 1), 0.0);
}

#[test]
fn bad_inputs_are_refused() {
    let (grid, density, radiance) = slab(40.0, [1.0; 3]);
    let camera = head_on_camera();
    let ok = MarchSettings::default();
    let short = &density[1..];
    assert!(matches!(
        render_volume(&grid, short, &radiance, &camera, &ok),
        Err(RenderError::LengthMismatch { what: "density", .. })
    ));
    assert!(matches!(
        render_volume(&grid, &density, &radiance[1..], &camera, &ok),
        Err(RenderError::LengthMismatch { what: "radiance", .. })
    ));
    let mut weights = vec![0.0; 3];
    assert!(visibility_weights(&grid, &density, &camera, &ok, &mut weights).is_err());
    for bad in [
        MarchSettings {
            step_voxels: 0.0,
            ..ok
        },
        MarchSettings {
            step_voxels: f32::NAN,
            ..ok
        },
        MarchSettings {
            min_transmittance: 1.0,
            ..ok
        },
    ] {
        assert!(matches!(
            render_volume(&grid, &density, &radiance, &camera, &bad),
            Err(RenderError::BadSettings(_))
        ));
    }
    let mut broken = camera;
    broken.rotation = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
    let err = render_volume(&grid, &density, &radiance, &broken, &ok).unwrap_err();
    assert!(err.to_string().contains("not a rotation"), "{err}");
}

#[test]
fn supersampling_is_the_box_filtered_finer_image() {
    // n² rays through a regular sub-pixel grid are exactly the pixel centres of an
    // n-times finer camera (fx, fy, cx, cy scaled by n), averaged n × n.
    let (grid, density, radiance) = shell_scene();
    let camera = orbit_camera(37.0, 21.0, 0.45, 20, 16);
    let one = render_volume(&grid, &density, &radiance, &camera, &MarchSettings::default()).unwrap();
    let n = 3u32;
    let settings = MarchSettings {
        pixel_grid: n,
        ..MarchSettings::default()
    };
    let coarse = render_volume(&grid, &density, &radiance, &camera, &settings).unwrap();
    let fine_camera = PinholeCamera {
        width: camera.width * n,
        height: camera.height * n,
        fx: camera.fx * f64::from(n),
        fy: camera.fy * f64::from(n),
        cx: camera.cx * f64::from(n),
        cy: camera.cy * f64::from(n),
        ..camera
    };
    let fine = render_volume(
        &grid,
        &density,
        &radiance,
        &fine_camera,
        &MarchSettings::default(),
    )
    .unwrap();
    let mut max_diff = 0.0f32;
    for v in 0..camera.height {
        for u in 0..camera.width {
            let (mut rgb, mut alpha) = ([0.0f32; 3], 0.0f32);
            for j in 0..n {
                for i in 0..n {
                    let c = fine.rgb_at(u * n + i, v * n + j);
                    for ch in 0..3 {
                        rgb[ch] += c[ch] / (n * n) as f32;
                    }
                    alpha += fine.alpha_at(u * n + i, v * n + j) / (n * n) as f32;
                }
            }
            let got = coarse.rgb_at(u, v);
            for ch in 0..3 {
                max_diff = max_diff.max((got[ch] - rgb[ch]).abs());
            }
            max_diff = max_diff.max((coarse.alpha_at(u, v) - alpha).abs());
        }
    }
    assert!(
        max_diff < 1e-5,
        "supersampled vs box-filtered fine image: {max_diff}"
    );
    // Edges are antialiased: some pixel is partly covered where one ray per pixel
    // gives (nearly) all or nothing.
    let partial = |img: &nelf_render::Image| img.alpha.iter().filter(|&&a| a > 0.05 && a < 0.95).count();
    assert!(
        partial(&coarse) > partial(&one),
        "{} vs {}",
        partial(&coarse),
        partial(&one)
    );
    let too_many = MarchSettings {
        pixel_grid: 17,
        ..MarchSettings::default()
    };
    assert!(render_volume(&grid, &density, &radiance, &camera, &too_many).is_err());
}

#[test]
fn negative_density_clips_after_interpolation() {
    // A signed linear ramp along the view ray, σ = (a/Δ)·(u − u₀) at voxel centres u
    // (in voxels; negative before u₀), is reproduced exactly by trilinear
    // interpolation and clipped at 0 *after* it, so the ray's optical depth is the
    // integral of the ramp from u₀, wherever u₀ sits between voxel centres:
    // τ = a·((31.5 − u₀)²/2 + 0.375·(31.5 − u₀)) (the last term: the half voxel
    // beyond the last centre, where the missing neighbour counts as 0). Clipping
    // before interpolating would add a·(c − u₀)²/2-type errors at the first centre c.
    let (grid, _, radiance) = slab(0.0, [1.0, 1.0, 1.0]);
    let a = 0.01f64;
    let settings = MarchSettings {
        step_voxels: 0.05,
        min_transmittance: 0.0,
        ..MarchSettings::default()
    };
    for u0 in [8.5f64, 8.8, 9.3] {
        let stored: Vec<f64> = (0..grid.voxel_count())
            .map(|v| a / SLAB_VOXEL_M * (layer(&grid, v) as f64 + 0.5 - u0))
            .collect();
        let signed: Vec<f32> = stored.iter().map(|&d| d as f32).collect();
        let preclipped: Vec<f32> = stored.iter().map(|&d| d.max(0.0) as f32).collect();
        let render = |density: &[f32]| {
            render_volume(&grid, density, &radiance, &head_on_camera(), &settings)
                .unwrap()
                .alpha_at(4, 4)
        };
        let length = 31.5 - u0;
        let tau = a * (0.5 * length * length + 0.375 * length);
        let expected = (1.0 - (-tau).exp()) as f32;
        let got = render(&signed);
        assert!(
            (got - expected).abs() < 2e-5,
            "u0 {u0}: alpha {got} vs {expected}"
        );
        if u0.fract() != 0.5 {
            let wrong = render(&preclipped);
            assert!(
                (wrong - expected).abs() > 5e-5,
                "u0 {u0}: clipping first is visible"
            );
        }
    }
}

#[test]
fn feature_renders_are_renders_of_linear_radiance() {
    let (grid, density, radiance) = shell_scene();
    let camera = orbit_camera(-40.0, 15.0, 0.5, 24, 20);
    for pixel_grid in [1, 2] {
        let settings = MarchSettings {
            pixel_grid,
            ..MarchSettings::default()
        };
        let image = render_volume(&grid, &density, &radiance, &camera, &settings).unwrap();
        let white = vec![[1.0f32; 3]; grid.voxel_count()];
        let ones = render_volume(&grid, &density, &white, &camera, &settings).unwrap();
        // Features [1, r, g, b]: the first renders a constant radiance of 1 (missing
        // voxels count 0 in interpolation, as for any radiance), the others the image.
        let features: Vec<f32> = radiance.iter().flat_map(|c| [1.0, c[0], c[1], c[2]]).collect();
        let pixels = render_features(&grid, &density, &features, 4, &camera, &settings).unwrap();
        let scale = image.rgb.iter().flatten().fold(0.0f32, |m, &x| m.max(x.abs()));
        for (p, (rgb, one)) in pixels.chunks_exact(4).zip(image.rgb.iter().zip(&ones.rgb)) {
            assert!((p[0] - one[0]).abs() < 1e-5, "{} vs {}", p[0], one[0]);
            for ch in 0..3 {
                assert!(
                    (p[ch + 1] - rgb[ch]).abs() < 1e-5 * scale,
                    "{} vs {}",
                    p[ch + 1],
                    rgb[ch]
                );
            }
        }
    }
    assert!(render_features(&grid, &density, &[0.0; 3], 4, &camera, &MarchSettings::default()).is_err());
}

/// Variants of one asset that differ only in their shading parts (none, a view part,
/// reflection parts of two exponents), marched once by `render_asset_radiances`, give
/// each variant's own `render_asset` image bit for bit, with and without a fine
/// density, at one and at 2 × 2 rays per pixel; radiances of the wrong length are refused.
#[test]
fn variants_marched_once_are_their_own_renders() {
    use nelf_format::synthetic::{synthetic_reflection, synthetic_view};
    use nelf_render::{asset_radiance, render_asset, render_asset_radiances};
    let base = synthetic(6000, 4, CoefficientEncoding::U8Affine, 11);
    let mut fine = base.clone();
    let factor = 2u32;
    let per_brick = 512 * (factor as usize).pow(3);
    fine.fine_density = Some(nelf_format::FineDensity {
        factor,
        values: (0..base.bricks.len() * per_brick)
            .map(|i| half::f16::from_f32(40.0 * ((i % 7) as f32)))
            .collect(),
    });
    let env = random_map(16, 8, 5, 1.0);
    let camera = orbit_camera(25.0, 10.0, 0.6, 40, 32);
    for asset in [&base, &fine] {
        let mut variants = vec![asset.clone()];
        let mut viewed = asset.clone();
        viewed.view = Some(synthetic_view(asset, 3, 4, CoefficientEncoding::U8Affine, 2).unwrap());
        variants.push(viewed);
        for exponent in [10.0, 40.0] {
            let mut reflected = asset.clone();
            reflected.reflection = Some(synthetic_reflection(asset, exponent, 3).unwrap());
            variants.push(reflected);
        }
        for pixel_grid in [1, 2] {
            let settings = MarchSettings {
                pixel_grid,
                ..MarchSettings::default()
            };
            let radiances: Vec<Vec<[f32; 3]>> = variants
                .iter()
                .map(|v| asset_radiance(v, &camera, &env, DMat3::IDENTITY, None).unwrap())
                .collect();
            let images = render_asset_radiances(asset, &radiances, &camera, &settings).unwrap();
            assert_eq!(images.len(), variants.len());
            for (variant, image) in variants.iter().zip(&images) {
                let own = render_asset(variant, &camera, &env, DMat3::IDENTITY, None, &settings).unwrap();
                assert_eq!(own.rgb, image.rgb);
                assert_eq!(own.alpha, image.alpha);
                assert!(own.alpha.iter().any(|&a| a > 0.1), "the camera sees the asset");
            }
            // The variants' images differ: the shading parts are there.
            assert_ne!(images[0].rgb, images[2].rgb);
            // A lobe table built once gives the same radiance; one of another exponent
            // is not used.
            for (variant, radiance) in variants.iter().zip(&radiances) {
                for exponent in [10.0, 40.0] {
                    let lobe = nelf_render::ReflectionLobe::new(exponent, variant.world_from_light);
                    let with = nelf_render::asset_radiance_with(
                        variant,
                        &camera,
                        &env,
                        DMat3::IDENTITY,
                        None,
                        Some(&lobe),
                    )
                    .unwrap();
                    assert_eq!(&with, radiance);
                }
            }
        }
    }
    let short = vec![vec![[0.0f32; 3]; base.voxel_count() - 1]];
    assert!(matches!(
        render_asset_radiances(&base, &short, &camera, &MarchSettings::default()),
        Err(RenderError::LengthMismatch { .. })
    ));
}
