//! An asset with a fine density (format 1.4): the `density` grid holds the fine σ (÷ the
//! scale) on its own transform, voxel edge `Δ/F`, each fine voxel at the index whose world
//! position is SPEC.md §6's fine-voxel centre; every other grid stays on the voxels,
//! exactly as without the fine density. Checked on the grids we build and, through
//! `vdb-rs` (an independent reader), on the encoded file. OpenVDB 10 itself reads it in
//! `openvdb10.rs`.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::io::Cursor;

use nelf_export::openvdb::{AnyGrid, Grid, MetaValue, leaf_offset};
use nelf_export::{VdbExportConfig, VdbExported, VdbOptions, build_vdb, encode_vdb};
use nelf_format::Asset;
use vdb_rs::{Map, VdbReader};

/// Every active value of a float grid by index coordinate.
fn values(grid: &Grid<f32>) -> BTreeMap<[i32; 3], f32> {
    let mut out = BTreeMap::new();
    for (origin, leaf) in grid.leaves() {
        for x in 0..8 {
            for y in 0..8 {
                for z in 0..8 {
                    let ijk = [origin[0] + x as i32, origin[1] + y as i32, origin[2] + z as i32];
                    assert!(out.insert(ijk, leaf[leaf_offset(x, y, z)]).is_none());
                }
            }
        }
    }
    out
}

fn float_grid<'a>(grids: &'a [AnyGrid], name: &str) -> &'a Grid<f32> {
    match grids.iter().find(|g| g.name() == name) {
        Some(AnyGrid::Float(g)) => g,
        _ => panic!("no float grid {name}"),
    }
}

/// Fine voxel `(i, j, k)` of brick `b`: its stored σ (1/m).
fn stored_fine(asset: &Asset, b: usize, [i, j, k]: [usize; 3]) -> f32 {
    let fine = asset.fine_density.as_ref().unwrap();
    let edge = fine.brick_edge();
    fine.values[b * fine.voxels_per_brick() + i + edge * (j + edge * k)].to_f32()
}

#[test]
fn density_grid_holds_the_fine_density_at_fine_voxel_centres() {
    for (factor, scale) in [(2u32, 1.0), (4, 100.0)] {
        let coarse = common::asset();
        let asset = common::with_fine_density(coarse.clone(), factor);
        let f = factor as usize;
        let options = VdbOptions {
            scale,
            ..VdbOptions::default()
        };
        let lighting = common::white();
        let (file, report) = build_vdb(&asset, &lighting, &options).unwrap();
        let density = float_grid(file.grids(), "density");

        // The fine density really differs from the coarse one upsampled (else this test
        // could not tell which the exporter wrote).
        let mut differ = 0;
        let mut total = 0;
        for b in 0..asset.bricks.len() {
            for (i, j, k) in [(0, 0, 0), (1, 0, 0), (0, 1, 1), (5, 7, 3)] {
                let v = b * 512 + i / f + 8 * (j / f) + 64 * (k / f);
                total += 1;
                differ += usize::from(stored_fine(&asset, b, [i, j, k]) != asset.density[v].to_f32());
            }
        }
        assert!(
            differ * 2 > total,
            "{differ} of {total} fine values differ from the coarse"
        );

        // Voxel size Δ/F, every fine voxel active, each the stored σ / scale.
        let t = density.transform();
        let fine_voxel = scale * asset.grid.voxel_size_m / f64::from(factor);
        assert!((t.voxel_size - fine_voxel).abs() <= 1e-15 * fine_voxel, "{t:?}");
        assert_eq!(
            report.grids[0].active_voxels,
            (asset.bricks.len() * 512 * f * f * f) as u64
        );
        assert_eq!(report.density_factor, Some(factor));
        let got = values(density);
        assert!(
            got == common::expected_fine_density(&asset, scale),
            "F = {factor}: density values differ"
        );

        // The value at SPEC's fine-voxel centre: the world point maps to an integer index
        // of the grid, which holds that fine voxel's σ / scale.
        let edge = 8 * f;
        for (b, brick) in asset.bricks.iter().enumerate() {
            for ijk in [
                [0, 0, 0],
                [edge - 1, 0, 0],
                [3, edge - 2, 1],
                [edge - 1; 3],
                [1, 2, edge - 3],
            ] {
                let centre = common::fine_voxel_centre(&asset, *brick, ijk, scale);
                let index: [f64; 3] = std::array::from_fn(|a| (centre[a] - t.translation[a]) / t.voxel_size);
                let rounded = index.map(f64::round);
                for a in 0..3 {
                    assert!((index[a] - rounded[a]).abs() < 1e-6, "{index:?}");
                }
                let world = t.index_to_world(rounded);
                for a in 0..3 {
                    assert!(
                        (world[a] - centre[a]).abs() <= 1e-12 * scale,
                        "{world:?} vs {centre:?}"
                    );
                }
                let want = (f64::from(stored_fine(&asset, b, ijk)) / scale) as f32;
                assert_eq!(
                    got[&rounded.map(|c| c as i32)],
                    want,
                    "brick {b} fine voxel {ijk:?}"
                );
            }
        }

        // Metadata says it is the fine density.
        let meta = density.file_metadata(options.compression);
        assert_eq!(meta["nelf_density_factor"], MetaValue::Int32(factor as i32));
        assert!(matches!(&meta["nelf_quantity"], MetaValue::String(q) if q.starts_with("fine")));
        assert_eq!(
            file.metadata()["nelf_density_factor"],
            MetaValue::Int32(factor as i32)
        );
        assert_eq!(
            file.metadata()["nelf_density_voxel_size_m"],
            MetaValue::Double(asset.grid.voxel_size_m / f64::from(factor))
        );

        // Every other grid is exactly the coarse asset's export.
        let (plain, plain_report) = build_vdb(&coarse, &lighting, &options).unwrap();
        assert_eq!(plain_report.density_factor, None);
        assert!(!plain.metadata().contains_key("nelf_density_factor"));
        let plain_density = float_grid(plain.grids(), "density");
        assert!(
            !plain_density
                .file_metadata(options.compression)
                .contains_key("nelf_density_factor")
        );
        assert_eq!(plain.grids().len(), file.grids().len());
        for (a, b) in plain.grids().iter().zip(file.grids()).skip(1) {
            match (a, b) {
                (AnyGrid::Float(a), AnyGrid::Float(b)) => {
                    assert_eq!(a.transform(), b.transform());
                    assert_eq!(values(a), values(b), "{}", a.name());
                }
                (AnyGrid::Vec3s(a), AnyGrid::Vec3s(b)) => {
                    assert_eq!(a.transform(), b.transform());
                    assert!(a.leaves().eq(b.leaves()), "{}", a.name());
                }
                _ => panic!("grid types differ"),
            }
        }
        assert_eq!(
            plain_density.transform().voxel_size,
            scale * asset.grid.voxel_size_m
        );
    }
}

/// The encoded file, read by vdb-rs: the density's own map (voxel size Δ/F, translation
/// at the first fine voxel's centre) and every fine value.
#[test]
fn vdb_rs_reads_the_fine_density_grid() {
    let asset = common::with_fine_density(common::asset(), 2);
    let options = VdbOptions::default();
    let (bytes, _) = encode_vdb(&asset, &common::lighting(), &options).unwrap();
    let mut reader = VdbReader::new(Cursor::new(bytes)).unwrap();
    let grid = reader.read_grid::<f32>("density").unwrap();
    let got: BTreeMap<[i32; 3], f32> = grid
        .iter()
        .map(|(p, v, _)| ([p.x as i32, p.y as i32, p.z as i32], v))
        .collect();
    assert!(got == common::expected_fine_density(&asset, 1.0));
    let Map::ScaleTranslateMap {
        translation,
        voxel_size,
        ..
    } = grid.transform
    else {
        panic!("expected a scale-translate map, got {:?}", grid.transform);
    };
    let fine_voxel = asset.grid.voxel_size_m / 2.0;
    for a in 0..3 {
        assert_eq!(voxel_size[a], fine_voxel);
        assert_eq!(translation[a], asset.grid.bbox_min_m[a] + 0.5 * fine_voxel);
    }
    let pca = reader.read_grid::<f32>("pca_00").unwrap();
    let Map::ScaleTranslateMap { voxel_size, .. } = pca.transform else {
        panic!("expected a scale-translate map");
    };
    assert_eq!(voxel_size[0], asset.grid.voxel_size_m);
}

/// What `nelf export vdb` prints: the voxel count is the voxels', and the fine density is
/// named with its factor.
#[test]
fn export_text_names_the_fine_density() {
    let asset = common::with_fine_density(common::asset(), 2);
    let (_, report) = build_vdb(&asset, &common::white(), &VdbOptions::default()).unwrap();
    let config = VdbExportConfig {
        asset: "head.nelf".into(),
        out: "head.vdb".into(),
        lighting: nelf_scene::shot::LightingArgs::default(),
        rank: None,
        scale: 1.0,
        color_name: "color".into(),
        compression: nelf_export::Compression::Zip,
        preset: None,
        pca_grids: nelf_export::vdb::PcaGrids::Float,
    };
    let text = VdbExported::File {
        report: report.clone(),
        asset_file_size: 1,
        write_seconds: 0.0,
        record_path: "head.vdb.export.json".into(),
    }
    .to_text(&config);
    assert!(
        text.contains(&format!("({} voxels,", asset.voxel_count())),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "2 times finer per axis ({} fine voxels",
            8 * asset.voxel_count()
        )),
        "{text}"
    );
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["density_factor"], 2);
}
