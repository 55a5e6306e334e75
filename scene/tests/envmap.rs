//! Environment maps: the shared HDRIs, `.hdr`/`.exr` round trips, projection to
//! the 8 × 16 basis, previews, and the procedural generator.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::path::{Path, PathBuf};

use nelf_format::conventions::{ENV_H, ENV_W, LatLong, texel_of_direction};
use nelf_scene::envgen::{EmitterShape, EnvFamily, EnvGenParams, procedural_env, procedural_envmap};
use nelf_scene::envmap::{envmap_to_basis, load_envmap, luminance, save_envmap_preview};
use nelf_scene::error::SceneError;

const SHARED_MAPS: [&str; 8] = [
    "city",
    "courtyard",
    "forest",
    "interior",
    "night",
    "studio",
    "sunrise",
    "sunset",
];

fn shared_map(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../data/envmaps/{name}.exr"))
}

fn relative_power_error(a: &LatLong, b: &LatLong) -> f64 {
    let (pa, pb) = (a.integral(), b.integral());
    (0..3).map(|c| (pa[c] - pb[c]).abs() / pa[c]).fold(0.0, f64::max)
}

/// Power `Σ Ω L` (luminance) of the rows above and below the horizon.
fn hemisphere_powers(map: &LatLong) -> (f64, f64) {
    let h = map.height();
    let mut upper = 0.0;
    let mut lower = 0.0;
    for row in 0..h {
        let omega = nelf_format::conventions::texel_solid_angle(row, h, map.width());
        let sum: f64 = (0..map.width())
            .map(|c| f64::from(luminance(map.get(row, c))))
            .sum();
        if row < h / 2 {
            upper += omega * sum;
        } else {
            lower += omega * sum;
        }
    }
    (upper, lower)
}

#[test]
fn shared_hdris_load_and_project_conserving_power() {
    for name in SHARED_MAPS {
        let map = load_envmap(shared_map(name)).unwrap();
        assert_eq!((map.width(), map.height()), (1024, 512), "{name}");
        assert!(
            map.texels().iter().flatten().all(|v| v.is_finite() && *v >= 0.0),
            "{name}"
        );
        assert!(
            map.integral().iter().all(|p| *p > 0.1),
            "{name}: {:?}",
            map.integral()
        );
        // Stored upright: more light from above the horizon than from below.
        let (upper, lower) = hemisphere_powers(&map);
        assert!(upper > lower, "{name}: upper {upper} vs lower {lower}");
        for degrees in [0.0f32, 33.3] {
            let basis = envmap_to_basis(&map, degrees);
            assert_eq!((basis.width(), basis.height()), (ENV_W, ENV_H));
            let error = relative_power_error(&map, &basis);
            assert!(error < 1e-3, "{name} turned {degrees}°: power error {error}");
        }
    }
}

#[test]
fn hdr_files_load_and_bad_values_are_clamped() {
    let dir = tempfile::tempdir().unwrap();
    // Radiance .hdr written with the image crate: RGBE keeps ~1 % precision.
    let (w, h) = (8u32, 4u32);
    let pixels: Vec<image::Rgb<f32>> = (0..w * h)
        .map(|i| image::Rgb([0.5 + i as f32, 2.0, 0.25 * (i % 3) as f32]))
        .collect();
    let path = dir.path().join("tiny.hdr");
    let file = std::fs::File::create(&path).unwrap();
    image::codecs::hdr::HdrEncoder::new(file)
        .encode(&pixels, w as usize, h as usize)
        .unwrap();
    let map = load_envmap(&path).unwrap();
    assert_eq!((map.width(), map.height()), (8, 4));
    for (got, want) in map.texels().iter().zip(&pixels) {
        for c in 0..3 {
            assert!(
                (got[c] - want.0[c]).abs() <= 0.01 * want.0[c] + 1e-6,
                "{got:?} vs {want:?}"
            );
        }
    }

    // EXR with negatives, NaN and infinity: all become 0.
    let exr_path = dir.path().join("bad.exr");
    exr::prelude::write_rgb_file(&exr_path, 4, 2, |x, y| match (x, y) {
        (0, 0) => (-1.0f32, f32::NAN, f32::INFINITY),
        (1, 0) => (1.5, -0.001, 3.0),
        _ => (0.25, 0.5, 0.75),
    })
    .unwrap();
    let map = load_envmap(&exr_path).unwrap();
    assert_eq!((map.width(), map.height()), (4, 2));
    assert_eq!(map.get(0, 0), [0.0, 0.0, 0.0]);
    assert_eq!(map.get(0, 1), [1.5, 0.0, 3.0]);
    assert_eq!(map.get(1, 3), [0.25, 0.5, 0.75]);
}

#[test]
fn envmap_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let err = load_envmap(dir.path().join("nothing.exr")).unwrap_err();
    assert!(err.to_string().contains("nothing.exr"), "{err}");
    let png = dir.path().join("map.png");
    assert!(matches!(
        load_envmap(&png),
        Err(SceneError::UnsupportedExtension { .. })
    ));
    let garbage = dir.path().join("garbage.hdr");
    std::fs::write(&garbage, b"not an image").unwrap();
    let err = load_envmap(&garbage).unwrap_err();
    assert!(err.to_string().contains("garbage.hdr"), "{err}");
}

#[test]
fn previews_are_written() {
    let dir = tempfile::tempdir().unwrap();
    let basis = envmap_to_basis(&procedural_envmap(1, &EnvGenParams::default()), 0.0);
    let path = dir.path().join("basis.png");
    save_envmap_preview(&path, &basis, 0.0).unwrap();
    let image = image::open(&path).unwrap();
    assert_eq!((image.width(), image.height()), (256, 128), "8×16 enlarged ×16");
    let big = LatLong::constant(300, 150, [0.5; 3]);
    save_envmap_preview(&path, &big, 0.0).unwrap();
    assert_eq!(image::open(&path).unwrap().width(), 300);
    assert!(save_envmap_preview(dir.path().join("no/such/dir.png"), &big, 0.0).is_err());
}

#[test]
fn procedural_maps_are_deterministic_varied_and_sane() {
    let params = EnvGenParams::default();
    let mut families = std::collections::HashSet::new();
    let mut previous: Option<LatLong> = None;
    for seed in 0..24u64 {
        let env = procedural_env(seed, &params);
        assert_eq!(env, procedural_env(seed, &params), "seed {seed} is deterministic");
        let map = &env.map;
        assert_eq!((map.width(), map.height()), (128, 64));
        assert!(map.texels().iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
        let power = map.integral();
        assert!(
            power.iter().all(|p| (0.5..100.0).contains(p)),
            "seed {seed}: power {power:?}"
        );
        if let Some(prev) = &previous {
            assert_ne!(prev, map, "seed {seed} differs from the one before");
        }
        previous = Some(map.clone());
        families.insert(format!("{:?}", env.family));
        let basis = envmap_to_basis(map, 0.0);
        assert!(relative_power_error(map, &basis) < 1e-5);
    }
    assert_eq!(families.len(), 3, "{families:?}");
}

#[test]
fn outdoor_suns_are_above_the_horizon_and_brightest() {
    let params = EnvGenParams {
        family: Some(EnvFamily::Outdoor),
        ..EnvGenParams::default()
    };
    for seed in 0..20u64 {
        let env = procedural_env(seed, &params);
        assert_eq!(env.family, EnvFamily::Outdoor);
        let sun = env.sun_direction.expect("outdoor maps have a sun");
        assert!(sun.y > 5f64.to_radians().sin() - 1e-9, "seed {seed}: sun {sun:?}");
        let EmitterShape::Disc { half_angle_rad, .. } = env.emitters[0].shape else {
            panic!("the sun is a disc")
        };
        let diameter = 2.0 * half_angle_rad.to_degrees();
        assert!((0.5..=15.0).contains(&diameter), "{diameter}°");
        let map = &env.map;
        let (row, col) = texel_of_direction(sun, map.height(), map.width());
        let sun_texel = luminance(map.get(row, col));
        let brightest = map.texels().iter().map(|t| luminance(*t)).fold(0.0, f32::max);
        // A large sun covers several texels fully; they differ only by the sky behind.
        assert!(
            sun_texel >= 0.99 * brightest,
            "seed {seed}: sun texel {sun_texel}, brightest {brightest}"
        );
    }
}

#[test]
fn families_place_their_lights() {
    for seed in 0..10u64 {
        let studio = procedural_env(
            seed,
            &EnvGenParams {
                family: Some(EnvFamily::Studio),
                ..EnvGenParams::default()
            },
        );
        assert_eq!(studio.emitters.len(), 3);
        assert!(
            studio.emitters[0].shape.centre().z > 0.3,
            "key light in front (+z)"
        );
        assert!(studio.emitters[2].shape.centre().z < 0.0, "rim light behind");
        let indoor = procedural_env(
            seed,
            &EnvGenParams {
                width: 64,
                height: 32,
                family: Some(EnvFamily::Indoor),
            },
        );
        assert!((1..=4).contains(&indoor.emitters.len()));
        assert_eq!((indoor.map.width(), indoor.map.height()), (64, 32));
        assert!(indoor.sun_direction.is_none());
    }
}
