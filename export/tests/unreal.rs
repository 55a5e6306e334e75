//! The Unreal preset: files of at most 8 scalar channels (density + PCA coefficients),
//! read back by vdb-rs with every value equal to the one-file export's grids; the
//! channel map, the Custom-node HLSL and the projected-lighting texture agree with
//! them and with `nelf-render`'s projection.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::io::Cursor;

use nelf_export::VdbOptions;
use nelf_export::unreal::{SVT_CHANNELS, relight_hlsl, relight_hlsl_fine_density, write_unreal};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{CoefficientEncoding, Coefficients};
use vdb_rs::VdbReader;

#[test]
fn unreal_preset_splits_channels_and_keeps_every_value() {
    // Rank 12: density + 12 coefficients = 13 channels = two SVT files (8 + 5).
    let field = SyntheticField::new(6_000, 3);
    let pca = field.fit_pca(12, 300);
    let coefficients =
        Coefficients::quantize(&field.project(&pca), 12, CoefficientEncoding::U8Affine).unwrap();
    let asset = field.asset_with(pca, coefficients).unwrap();
    let lighting = common::lighting();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("head.vdb");
    let report = write_unreal(&out, &asset, &lighting, &VdbOptions::default()).unwrap();
    assert_eq!(report.rank, 12);
    assert_eq!(report.files.len(), 2);
    assert_eq!(report.files[0].channels.len(), SVT_CHANNELS);
    assert_eq!(report.files[1].channels.len(), 5);
    assert_eq!(report.files[0].channels[0].grid, "density");
    assert_eq!(
        (
            report.files[0].channels[0].attributes.as_str(),
            report.files[0].channels[0].channel.as_str()
        ),
        ("A", "r")
    );
    assert_eq!(report.files[1].channels[4].grid, "pca_11");
    assert_eq!(
        (
            report.files[1].channels[4].attributes.as_str(),
            report.files[1].channels[4].channel.as_str()
        ),
        ("B", "r")
    );

    // Every value of every channel equals the asset's.
    let expected = common::expected(&asset, &lighting, 12, 1.0);
    for file in &report.files {
        let bytes = std::fs::read(dir.path().join(&file.file)).unwrap();
        let mut reader = VdbReader::new(Cursor::new(bytes)).unwrap();
        for ch in &file.channels {
            let grid = reader.read_grid::<f32>(&ch.grid).unwrap();
            let values: BTreeMap<[i32; 3], f32> = grid
                .iter()
                .map(|(p, v, _)| ([p.x as i32, p.y as i32, p.z as i32], v))
                .collect();
            let want = if ch.grid == "density" {
                &expected.density
            } else {
                &expected.pca[ch.grid[4..].parse::<usize>().unwrap()]
            };
            assert_eq!(&values, want, "{}", ch.grid);
            let lo = want.values().copied().fold(f32::INFINITY, f32::min);
            let hi = want.values().copied().fold(f32::NEG_INFINITY, f32::max);
            assert_eq!(ch.range, [lo, hi], "{} range", ch.grid);
        }
    }

    // The HLSL reads pca_k from the channel the map names, weighted by texel k + 1.
    let hlsl = std::fs::read_to_string(dir.path().join(&report.hlsl_file)).unwrap();
    assert_eq!(hlsl, relight_hlsl(2, 12));
    assert!(hlsl.contains(
        "float3 NelfRelight(float4 A0, float4 B0, float4 A1, float4 B1, Texture2D ProjectedLight)"
    ));
    for (n, file) in report.files.iter().enumerate() {
        for ch in file.channels.iter().filter(|c| c.grid != "density") {
            let k: usize = ch.grid[4..].parse().unwrap();
            let line = format!(
                "{}{n}.{} * ProjectedLight.Load(int3({}, 0, 0)).rgb; // {}",
                ch.attributes,
                ch.channel,
                k + 1,
                ch.grid
            );
            assert!(hlsl.contains(&line), "missing: {line}");
        }
    }

    // The projected-lighting texture: P_mean then P_k, as nelf-render projects them.
    // (Read raw: the env-map loader would zero the negative components.)
    let texture = image::open(dir.path().join(&report.projected_light_file))
        .unwrap()
        .into_rgb32f();
    let light = lighting.project(&asset).unwrap();
    assert_eq!(texture.dimensions(), (13, 1));
    let want: Vec<f32> = std::iter::once(light.mean_rgb)
        .chain(light.component_rgb)
        .flatten()
        .collect();
    assert_eq!(texture.as_raw(), &want);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("head.unreal.json")).unwrap()).unwrap();
    assert_eq!(manifest["files"].as_array().unwrap().len(), 2);
}

/// With a fine density the density is an SVT of its own (its own resolution): every fine
/// value at voxel size Δ/F, while the coefficient files hold only `pca_NN`, eight each,
/// `pca_k` in channel k, as the HLSL reads them. Without one the manifest names no
/// density file.
#[test]
fn unreal_preset_gives_a_fine_density_its_own_svt() {
    let asset = common::with_fine_density(common::asset(), 2);
    let lighting = common::lighting();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("head.vdb");
    let report = write_unreal(&out, &asset, &lighting, &VdbOptions::default()).unwrap();
    assert_eq!(report.rank, 5);
    assert_eq!(report.density_factor, Some(2));
    assert_eq!(report.files.len(), 1);
    let names: Vec<&str> = report.files[0].channels.iter().map(|c| c.grid.as_str()).collect();
    assert_eq!(names, ["pca_00", "pca_01", "pca_02", "pca_03", "pca_04"]);
    let first = &report.files[0].channels[0];
    assert_eq!((first.attributes.as_str(), first.channel.as_str()), ("A", "r"));
    let density = report.density_file.as_ref().unwrap();
    assert_eq!(density.file, "head_density.vdb");
    assert_eq!(density.channels.len(), 1);
    assert_eq!(
        (
            density.channels[0].grid.as_str(),
            density.channels[0].attributes.as_str(),
            density.channels[0].channel.as_str()
        ),
        ("density", "A", "r")
    );

    let fine = common::expected_fine_density(&asset, 1.0);
    let bytes = std::fs::read(dir.path().join(&density.file)).unwrap();
    let mut reader = VdbReader::new(Cursor::new(bytes)).unwrap();
    assert_eq!(reader.available_grids(), ["density"]);
    let grid = reader.read_grid::<f32>("density").unwrap();
    let values: BTreeMap<[i32; 3], f32> = grid
        .iter()
        .map(|(p, v, _)| ([p.x as i32, p.y as i32, p.z as i32], v))
        .collect();
    assert!(values == fine, "fine density values differ");
    let lo = fine.values().copied().fold(f32::INFINITY, f32::min);
    let hi = fine.values().copied().fold(f32::NEG_INFINITY, f32::max);
    assert_eq!(density.channels[0].range, [lo, hi]);
    let vdb_rs::Map::ScaleTranslateMap { voxel_size, .. } = grid.transform else {
        panic!("expected a scale-translate map");
    };
    assert_eq!(voxel_size[0], asset.grid.voxel_size_m / 2.0);

    let expected = common::expected(&asset, &lighting, 5, 1.0);
    let bytes = std::fs::read(dir.path().join(&report.files[0].file)).unwrap();
    let mut reader = VdbReader::new(Cursor::new(bytes)).unwrap();
    for (k, ch) in report.files[0].channels.iter().enumerate() {
        let grid = reader.read_grid::<f32>(&ch.grid).unwrap();
        let values: BTreeMap<[i32; 3], f32> = grid
            .iter()
            .map(|(p, v, _)| ([p.x as i32, p.y as i32, p.z as i32], v))
            .collect();
        assert!(values == expected.pca[k], "{}", ch.grid);
    }

    let hlsl = std::fs::read_to_string(dir.path().join(&report.hlsl_file)).unwrap();
    assert_eq!(hlsl, relight_hlsl_fine_density(1, 5, "head_density.vdb"));
    assert!(hlsl.contains("float3 NelfRelight(float4 A0, float4 B0, Texture2D ProjectedLight)"));
    assert!(hlsl.contains("A0.r * ProjectedLight.Load(int3(1, 0, 0)).rgb; // pca_00"));
    assert!(hlsl.contains("B0.r * ProjectedLight.Load(int3(5, 0, 0)).rgb; // pca_04"));
    assert!(hlsl.contains("head_density.vdb"));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("head.unreal.json")).unwrap()).unwrap();
    assert_eq!(manifest["density_file"]["file"], "head_density.vdb");
    assert_eq!(manifest["density_factor"], 2);

    // The same asset without its fine density: density in A0.r, no density file.
    let coarse_dir = tempfile::tempdir().unwrap();
    let mut coarse = asset.clone();
    coarse.fine_density = None;
    let report = write_unreal(
        &coarse_dir.path().join("head.vdb"),
        &coarse,
        &lighting,
        &VdbOptions::default(),
    )
    .unwrap();
    assert_eq!(report.files[0].channels[0].grid, "density");
    assert!(report.density_file.is_none());
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(coarse_dir.path().join("head.unreal.json")).unwrap())
            .unwrap();
    assert!(manifest.get("density_file").is_none() && manifest.get("density_factor").is_none());
    assert!(!coarse_dir.path().join("head_density.vdb").exists());
}
