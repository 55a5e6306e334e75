//! Relighting: PCA projection of the lighting, rotation, linearity, errors.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::f64::consts::PI;

use common::{orbit_camera, random_map, synthetic};
use glam::{DMat3, DVec3};
use nelf_format::CoefficientEncoding;
use nelf_format::conventions::{ENV_H, ENV_W, LT_DIM, LatLong, project_envmap, rotation_y, shade};
use nelf_render::{
    MarchSettings, RenderError, project_light, project_light_texels, radiance_from_lt, render_asset,
    voxel_radiance,
};

fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    (0..3).all(|c| (a[c] - b[c]).abs() <= tol * (1.0 + b[c].abs()))
}

#[test]
fn projected_light_equals_shading_the_reconstructed_transport() {
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let asset = synthetic(4000, 8, encoding, 11);
        let env = random_map(40, 20, 2, 3.0);
        let tilted = DMat3::from_rotation_x(0.4) * rotation_y(1.1);
        for world_from_env in [DMat3::IDENTITY, rotation_y(0.7), tilted] {
            let light = project_light(&asset.pca, asset.world_from_light, &env, world_from_env).unwrap();
            let basis = project_envmap(&env, world_from_env.transpose() * asset.world_from_light).unwrap();
            for rank in [None, Some(8), Some(3), Some(1), Some(50)] {
                let used = rank.unwrap_or(8).min(8);
                let pca = asset.pca.truncated(used);
                let radiance = voxel_radiance(&asset, &light, rank);
                assert_eq!(radiance.len(), asset.voxel_count());
                let mut coefficients = vec![0.0f32; 8];
                let mut lt = vec![0.0f32; LT_DIM];
                for v in (0..asset.voxel_count()).step_by(13) {
                    asset.coefficients_f32(v, &mut coefficients);
                    pca.reconstruct_into(&coefficients[..used], &mut lt);
                    let want = shade(&lt, &basis);
                    assert!(
                        close(radiance[v], want, 2e-5),
                        "rank {rank:?} voxel {v}: {:?} vs {want:?}",
                        radiance[v]
                    );
                }
            }
        }
    }
}

#[test]
fn radiance_from_lt_is_the_per_voxel_dot_product() {
    let mut lt = vec![0.0f32; 2 * LT_DIM + 5];
    lt[3] = 2.0; // voxel 0, red, texel 3
    lt[LT_DIM + 128 + 17] = 0.5; // voxel 1, green, texel 17
    let light = random_map(ENV_W, ENV_H, 5, 1.0);
    let out = radiance_from_lt(&lt, &light);
    assert_eq!(out.len(), 2);
    assert_eq!(out[0], [2.0 * light.texels()[3][0], 0.0, 0.0]);
    assert_eq!(out[1], [0.0, 0.5 * light.texels()[17][1], 0.0]);
    // A map of another size is resampled into the basis first: a constant stays constant.
    let out = radiance_from_lt(&lt[..LT_DIM], &LatLong::constant(64, 32, [0.5; 3]));
    assert!((out[0][0] - 1.0).abs() < 1e-6);
}

#[test]
fn turning_the_light_by_one_column_shifts_the_projected_map() {
    // Turning the lighting by 2π/16 about +y makes light texel (row, col) see what texel
    // (row, col + 1) saw before: the projection equals that of the column-shifted map.
    let asset = synthetic(3000, 6, CoefficientEncoding::F16, 2);
    // Random texels, brighter on one side so that turning the lighting matters.
    let mut env = random_map(64, 32, 8, 1.0);
    for (i, t) in env.texels_mut().iter_mut().enumerate() {
        if i % 64 < 20 {
            *t = t.map(|v| 8.0 * v);
        }
    }
    let step = 2.0 * PI / ENV_W as f64;
    let unturned = project_envmap(&env, asset.world_from_light).unwrap();
    for shift in [1usize, 5] {
        let turned = project_light(
            &asset.pca,
            asset.world_from_light,
            &env,
            rotation_y(step * shift as f64),
        )
        .unwrap();
        let shifted: Vec<[f32; 3]> = (0..ENV_H * ENV_W)
            .map(|k| unturned.get(k / ENV_W, (k % ENV_W + shift) % ENV_W))
            .collect();
        let want = project_light_texels(&asset.pca, &LatLong::new(ENV_W, ENV_H, shifted).unwrap()).unwrap();
        assert!(close(turned.mean_rgb, want.mean_rgb, 1e-5));
        for (a, b) in turned.component_rgb.iter().zip(&want.component_rgb) {
            assert!(close(*a, *b, 1e-5), "{a:?} vs {b:?}");
        }
        // And it is not the unturned projection (the test can fail).
        let plain = project_light(&asset.pca, asset.world_from_light, &env, DMat3::IDENTITY).unwrap();
        assert!(!close(turned.mean_rgb, plain.mean_rgb, 1e-3));
    }
}

#[test]
fn rendering_is_linear_in_the_lighting() {
    let asset = synthetic(6000, 5, CoefficientEncoding::U8Affine, 4);
    let camera = orbit_camera(-30.0, 15.0, 0.5, 24, 20);
    let settings = MarchSettings::default();
    let (l1, l2) = (random_map(32, 16, 1, 1.0), random_map(32, 16, 2, 3.0));
    let sum = LatLong::new(
        32,
        16,
        l1.texels()
            .iter()
            .zip(l2.texels())
            .map(|(a, b)| [a[0] + b[0], a[1] + b[1], a[2] + b[2]])
            .collect(),
    )
    .unwrap();
    let turn = rotation_y(0.9);
    let render = |env: &LatLong| render_asset(&asset, &camera, env, turn, Some(4), &settings).unwrap();
    let (a, b, both) = (render(&l1), render(&l2), render(&sum));
    let peak = both.rgb.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(peak > 0.1);
    for ((x, y), z) in a.rgb.iter().zip(&b.rgb).zip(&both.rgb) {
        for c in 0..3 {
            assert!((x[c] + y[c] - z[c]).abs() < 1e-5 * peak, "{x:?} + {y:?} vs {z:?}");
        }
    }
    assert_eq!(a.alpha, both.alpha);
}

#[test]
fn bad_lighting_inputs_are_refused() {
    let asset = synthetic(2000, 3, CoefficientEncoding::F16, 1);
    let env = LatLong::constant(8, 4, [1.0; 3]);
    let mirror = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
    assert!(matches!(
        project_light(&asset.pca, asset.world_from_light, &env, mirror),
        Err(RenderError::NotARotation {
            what: "world_from_env",
            ..
        })
    ));
    assert!(matches!(
        project_light(&asset.pca, mirror, &env, DMat3::IDENTITY),
        Err(RenderError::NotARotation {
            what: "world_from_light",
            ..
        })
    ));
    let mut broken = asset.pca.clone();
    broken.mean.pop();
    let err = project_light(&broken, asset.world_from_light, &env, DMat3::IDENTITY).unwrap_err();
    assert!(err.to_string().contains("PCA mean"), "{err}");
    assert!(project_light_texels(&asset.pca, &env).is_err());
    // A hand-built asset that breaks the format is refused by render_asset, not rendered.
    let mut bad = asset.clone();
    bad.density.pop();
    let camera = orbit_camera(0.0, 0.0, 0.5, 4, 4);
    let err = render_asset(
        &bad,
        &camera,
        &env,
        DMat3::IDENTITY,
        None,
        &MarchSettings::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("density"), "{err}");
}
