//! Round trip through `vdb-rs` 0.6, an OpenVDB reader written independently of ours:
//! it reads our files (both compressions), and the grid names and types, the header, the
//! voxel counts, the transforms and every active value of the float grids (`density`,
//! `pca_NN`) equal what the asset holds. The colour grid is checked by its descriptor
//! only here: vdb-rs 0.6 reads a root's background and tiles as 4 bytes whatever the
//! value type, so it reads every `vec3s` grid as empty (OpenVDB's own files too); its
//! values are compared through OpenVDB 10 itself in `openvdb10.rs`.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::Cursor;

use nelf_export::{Compression, VdbOptions, encode_vdb};
use vdb_rs::{Map, MetadataValue, VdbLevel, VdbReader};

fn read_float_grid(reader: &mut VdbReader<Cursor<Vec<u8>>>, name: &str) -> (BTreeMap<[i32; 3], f32>, Map) {
    let grid = reader.read_grid::<f32>(name).unwrap();
    let mut values = BTreeMap::new();
    for (p, v, level) in grid.iter() {
        assert!(
            level == VdbLevel::Voxel,
            "{name}: only voxels are active, no tiles"
        );
        let ijk = [p.x as i32, p.y as i32, p.z as i32];
        assert!(values.insert(ijk, v).is_none(), "{name}: {ijk:?} twice");
    }
    (values, grid.transform)
}

fn check(options: &VdbOptions) {
    let asset = common::asset();
    let lighting = common::lighting();
    let (bytes, report) = encode_vdb(&asset, &lighting, options).unwrap();
    assert_eq!(report.file_size, bytes.len() as u64);
    let rank = options.rank.unwrap_or(asset.rank());
    let expected = common::expected(&asset, &lighting, rank, options.scale);
    let mut reader = VdbReader::new(Cursor::new(bytes)).unwrap();

    let header = &reader.header;
    assert_eq!(
        (
            header.file_version,
            header.library_version_major,
            header.library_version_minor
        ),
        (224, 10, 0)
    );
    assert!(header.has_grid_offsets);
    assert_eq!(header.grid_count as usize, 2 + rank);
    assert_eq!(
        header.meta_data.0.get("nelf_pca_rank"),
        Some(&MetadataValue::I32(rank as i32))
    );

    let mut names: Vec<String> = vec!["density".into(), options.color_name.clone()];
    names.extend((0..rank).map(|k| format!("pca_{k:02}")));
    assert_eq!(
        reader.available_grids().into_iter().collect::<BTreeSet<_>>(),
        names.iter().cloned().collect::<BTreeSet<_>>()
    );
    let voxels = asset.voxel_count() as i64;
    for name in &names {
        let d = &reader.grid_descriptors[name];
        let tree = if name == &options.color_name {
            "Tree_vec3s_5_4_3"
        } else {
            "Tree_float_5_4_3"
        };
        assert_eq!(d.grid_type, tree);
        assert_eq!(d.voxel_count().unwrap(), voxels);
        assert_eq!(d.meta_data.0["name"], MetadataValue::String(name.clone()));
        let first = common::index_of(&asset, 0);
        let lo = d.aabb_min().unwrap();
        assert!(lo.x <= first[0] && lo.y <= first[1] && lo.z <= first[2]);
        assert_eq!(
            d.meta_data.0["file_compression"],
            MetadataValue::String(
                match options.compression {
                    Compression::None => "active values",
                    Compression::Zip => "zip + active values",
                }
                .into()
            )
        );
    }
    assert_eq!(
        reader.grid_descriptors["density"].meta_data.0["nelf_unit"],
        MetadataValue::String(options.density_unit())
    );

    let (density, transform) = read_float_grid(&mut reader, "density");
    assert_eq!(density.len(), asset.voxel_count());
    assert!(density == expected.density, "density values differ");
    let s = options.scale;
    let voxel = asset.grid.voxel_size_m;
    let Map::ScaleTranslateMap {
        translation,
        scale_values,
        voxel_size,
        scale_values_inverse,
        ..
    } = transform
    else {
        panic!("expected a (uniform) scale-translate map, got {transform:?}");
    };
    for a in 0..3 {
        assert_eq!(translation[a], s * (asset.grid.bbox_min_m[a] + 0.5 * voxel));
        assert_eq!(scale_values[a], s * voxel);
        assert_eq!(voxel_size[a], s * voxel);
        assert_eq!(scale_values_inverse[a], 1.0 / (s * voxel));
    }
    // Index coordinate → world is the asset's voxel centre (scaled).
    for v in [0, 777, asset.voxel_count() - 1] {
        let ijk = common::index_of(&asset, v);
        let centre = asset.voxel_position_m(v);
        for a in 0..3 {
            let world = translation[a] + voxel_size[a] * f64::from(ijk[a]);
            assert!((world - s * centre[a]).abs() < 1e-9 * s, "voxel {v} axis {a}");
        }
    }

    for (k, want) in expected.pca.iter().enumerate() {
        let (values, _) = read_float_grid(&mut reader, &format!("pca_{k:02}"));
        assert_eq!(values.len(), asset.voxel_count());
        assert!(&values == want, "pca_{k:02} values differ");
    }
}

#[test]
fn vdb_rs_reads_every_float_value_zipped() {
    check(&VdbOptions::default());
}

#[test]
fn vdb_rs_reads_every_float_value_uncompressed() {
    check(&VdbOptions {
        compression: Compression::None,
        ..VdbOptions::default()
    });
}

#[test]
fn vdb_rs_reads_every_float_value_zipped_scaled_and_cut() {
    check(&VdbOptions {
        scale: 100.0,
        rank: Some(3),
        color_name: "Cd".into(),
        compression: Compression::Zip,
        pca_grids: nelf_export::vdb::PcaGrids::Float,
    });
}

#[test]
fn output_is_deterministic_and_zip_is_smaller() {
    let asset = common::asset();
    let lighting = common::lighting();
    let raw = VdbOptions {
        compression: Compression::None,
        ..VdbOptions::default()
    };
    let plain = encode_vdb(&asset, &lighting, &raw).unwrap().0;
    assert_eq!(plain, encode_vdb(&asset, &lighting, &raw).unwrap().0);
    let zipped = encode_vdb(&asset, &lighting, &VdbOptions::default()).unwrap().0;
    assert_eq!(
        zipped,
        encode_vdb(&asset, &lighting, &VdbOptions::default()).unwrap().0
    );
    assert!(zipped.len() < plain.len(), "{} vs {}", zipped.len(), plain.len());
}

#[test]
fn write_vdb_writes_the_encoded_bytes_atomically() {
    let asset = common::asset();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("head.vdb");
    let report = nelf_export::write_vdb(&path, &asset, &common::white(), &VdbOptions::default()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes.len() as u64, report.file_size);
    assert_eq!(
        bytes,
        encode_vdb(&asset, &common::white(), &VdbOptions::default())
            .unwrap()
            .0
    );
    // Nothing else is left in the folder (no temporary file).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    // A folder that does not exist: an error naming the path, nothing written.
    let missing = dir.path().join("no/such/dir/head.vdb");
    let err = nelf_export::write_vdb(&missing, &asset, &common::white(), &VdbOptions::default()).unwrap_err();
    assert!(err.to_string().contains("no/such/dir"), "{err}");
}
