//! Round trips of `.nelf` files: lossless sections bit-exact, quantized coefficients
//! within their stated bound, deterministic bytes, random access equal to whole
//! reads, atomic writes, versioning and optional sections.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::io::Cursor;

use common::{FileParts, chunked_payload, small_asset};
use nelf_format::conventions::{ENV_H, ENV_W, LT_DIM, LatLong, shade};
use nelf_format::io_error::FileIoError;
use nelf_format::spec::{
    BRICK_VOXELS, FLAG_SIGNED_DENSITY, KIND_COEFFICIENTS, KIND_METADATA, SectionCodec, SectionEntry,
    VERSION_MAJOR, checksum,
};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{
    AssetReader, CoefficientEncoding, Coefficients, FormatError, WriteOptions, encode_asset, read_asset,
    read_asset_bytes, write_asset,
};

const OPTION_SETS: [WriteOptions; 4] = [
    WriteOptions {
        zstd_level: 3,
        chunk_bricks: 64,
        shuffle: true,
    },
    WriteOptions {
        zstd_level: 1,
        chunk_bricks: 1,
        shuffle: false,
    },
    WriteOptions {
        zstd_level: 9,
        chunk_bricks: 3,
        shuffle: true,
    },
    WriteOptions {
        zstd_level: -1,
        chunk_bricks: 1000,
        shuffle: false,
    },
];

#[test]
fn round_trip_is_exact_for_every_encoding_and_option() {
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let asset = small_asset(encoding, 6, 1);
        for options in OPTION_SETS {
            let (bytes, sections) = encode_asset(&asset, &options).unwrap();
            let back = read_asset_bytes(&bytes).unwrap();
            // Equal field by field: bricks, f16 density bits, PCA f32 bits, codes, metadata.
            assert!(back == asset, "{encoding:?} {options:?}");
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&back.pca.basis), bits(&asset.pca.basis));
            assert_eq!(bits(&back.pca.mean), bits(&asset.pca.mean));
            assert_eq!(
                back.density.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                asset.density.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
            );
            assert_eq!(
                sections.len(),
                if encoding == CoefficientEncoding::U8Affine {
                    6
                } else {
                    5
                }
            );
        }
    }
}

#[test]
fn quantized_coefficients_within_stated_bound() {
    let field = SyntheticField::new(3000, 4);
    let pca = field.fit_pca(8, 1000);
    let exact = field.project(&pca);
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let q = Coefficients::quantize(&exact, 8, encoding).unwrap();
        let asset = field.asset_with(pca.clone(), q).unwrap();
        let back = read_asset_bytes(&encode_asset(&asset, &WriteOptions::default()).unwrap().0).unwrap();
        let mut c = vec![0.0f32; 8];
        for v in 0..back.voxel_count() {
            back.coefficients_f32(v, &mut c);
            for k in 0..8 {
                let want = exact[v * 8 + k];
                let bound = match back.coefficients.abs_error_bound(k) {
                    Some(b) => b,
                    None => want.abs() * 2f32.powi(-11) + 2f32.powi(-25),
                };
                assert!(
                    (c[k] - want).abs() <= bound,
                    "{encoding:?} voxel {v} k {k}: {} vs {want}",
                    c[k]
                );
            }
        }
    }
}

#[test]
fn reconstruction_follows_the_spec_formula() {
    // T = mean + Σ c_k B_k, radiance = Σ T[c][k] L[k][c]; the PCA of the synthetic
    // field reproduces its transport to within a few percent of the radiance.
    let field = SyntheticField::new(3000, 2);
    let asset = field.asset(16, CoefficientEncoding::F16).unwrap();
    let light = LatLong::new(
        ENV_W,
        ENV_H,
        (0..ENV_H * ENV_W)
            .map(|k| [1.0 + (k % 5) as f32, 2.0, 0.5])
            .collect(),
    )
    .unwrap();
    let mut exact = vec![0.0f32; LT_DIM];
    let mut c = vec![0.0f32; 16];
    for v in (0..asset.voxel_count()).step_by(97) {
        let t = asset.reconstruct_lt(v);
        asset.coefficients_f32(v, &mut c);
        for (j, &tj) in t.iter().enumerate() {
            let mut want = asset.pca.mean[j];
            for (k, ck) in c.iter().enumerate() {
                want += ck * asset.pca.basis[k * LT_DIM + j];
            }
            assert_eq!(tj, want);
        }
        field.lt(v, &mut exact);
        let (got, want) = (shade(&t, &light), shade(&exact, &light));
        for ch in 0..3 {
            assert!(
                (got[ch] - want[ch]).abs() < 0.05 * want[ch].abs() + 0.01,
                "voxel {v}: {got:?} vs {want:?}"
            );
        }
    }
    // Voxel positions follow bbox_min + (8·brick + i + 0.5)·voxel_size.
    let v = 3 * BRICK_VOXELS + 1 + 8 * 2 + 64 * 5;
    let b = asset.bricks[3];
    let p = asset.voxel_position_m(v);
    let g = asset.grid;
    let want = [1usize, 2, 5]
        .iter()
        .enumerate()
        .map(|(a, &i)| g.bbox_min_m[a] + (8.0 * f64::from(b[a]) + i as f64 + 0.5) * g.voxel_size_m)
        .collect::<Vec<_>>();
    assert_eq!(p.to_array().to_vec(), want);
}

#[test]
fn writing_twice_gives_identical_bytes() {
    let dir = tempfile::tempdir().unwrap();
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let asset = small_asset(encoding, 5, 9);
        let (a, b) = (dir.path().join("a.nelf"), dir.path().join("b.nelf"));
        write_asset(&a, &asset, &WriteOptions::default()).unwrap();
        write_asset(&b, &asset.clone(), &WriteOptions::default()).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        // And the generator itself is deterministic.
        assert!(small_asset(encoding, 5, 9) == asset);
        // Chunks are compressed on all cores: one thread writes the same bytes.
        let options = WriteOptions {
            chunk_bricks: 1,
            ..WriteOptions::default()
        };
        let many = encode_asset(&asset, &options).unwrap().0;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let one = pool.install(|| encode_asset(&asset, &options).unwrap().0);
        assert_eq!(many, one);
    }
}

#[test]
fn random_access_matches_whole_read() {
    let asset = small_asset(CoefficientEncoding::U8Affine, 7, 3);
    let options = WriteOptions {
        chunk_bricks: 3,
        ..WriteOptions::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.nelf");
    let report = write_asset(&path, &asset, &options).unwrap();
    assert_eq!(report.file_size, std::fs::metadata(&path).unwrap().len());
    let mut reader = AssetReader::open(&path).unwrap();
    assert_eq!(reader.bricks(), asset.bricks.as_slice());
    assert_eq!(reader.header().chunk_bricks, 3);
    assert_eq!(reader.sections(), report.sections.as_slice());
    let order: Vec<usize> = (0..asset.bricks.len()).rev().chain([2, 0, 5, 1]).collect();
    for i in order {
        let brick = reader.read_brick(i).unwrap();
        assert_eq!(brick.coord, asset.bricks[i]);
        for local in 0..BRICK_VOXELS {
            let v = i * BRICK_VOXELS + local;
            assert_eq!(brick.density[local], asset.density_at(v));
            let mut c = vec![0.0; 7];
            asset.coefficients_f32(v, &mut c);
            assert_eq!(&brick.coefficients[local * 7..(local + 1) * 7], c.as_slice());
        }
    }
    assert!(matches!(
        reader.read_brick(asset.bricks.len()),
        Err(FormatError::BrickOutOfRange { .. })
    ));
    reader.verify().unwrap();
    assert!(read_asset(&path).unwrap() == asset);
    assert!(asset.find_brick(asset.bricks[4]) == Some(4));
    assert!(asset.find_brick([999, 0, 0]).is_none());
}

#[test]
fn write_is_atomic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("asset.nelf");
    let good = small_asset(CoefficientEncoding::F16, 4, 5);
    write_asset(&path, &good, &WriteOptions::default()).unwrap();
    let before = std::fs::read(&path).unwrap();
    // An invalid asset fails before anything is written; the old file is untouched.
    let mut bad = good.clone();
    bad.density.pop();
    assert!(matches!(
        write_asset(&path, &bad, &WriteOptions::default()),
        Err(FormatError::InvalidAsset(_))
    ));
    assert_eq!(std::fs::read(&path).unwrap(), before);
    // A missing folder is an I/O error naming the path; nothing is created.
    let missing = dir.path().join("no/such/dir/asset.nelf");
    match write_asset(&missing, &good, &WriteOptions::default()) {
        Err(FormatError::Io(FileIoError { path, .. })) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
    // No temporary files are left behind.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["asset.nelf".to_string()]);
}

#[test]
fn invalid_assets_are_refused_by_the_writer() {
    let good = small_asset(CoefficientEncoding::U8Affine, 4, 6);
    let mut cases = Vec::new();
    let mut a = good.clone();
    a.bricks.swap(0, 1);
    cases.push(("unsorted bricks", a));
    let mut a = good.clone();
    a.bricks[0] = [60_000, 0, 0];
    cases.push(("brick outside grid", a));
    let mut a = good.clone();
    a.pca.basis[3] = f32::NAN;
    cases.push(("NaN basis", a));
    let mut a = good.clone();
    a.pca.basis.truncate(3 * LT_DIM);
    cases.push(("rank mismatch", a));
    let mut a = good.clone();
    a.world_from_light = glam::DMat3::from_diagonal(glam::DVec3::new(1.0, 1.0, -1.0));
    cases.push(("reflection", a));
    let mut a = good.clone();
    a.metadata = serde_json::json!([1, 2]);
    cases.push(("metadata array", a));
    let mut a = good.clone();
    a.density[5] = half::f16::INFINITY;
    cases.push(("infinite density", a));
    let mut a = good.clone();
    a.grid.voxel_size_m = 0.0;
    cases.push(("zero voxel size", a));
    for (name, asset) in cases {
        assert!(encode_asset(&asset, &WriteOptions::default()).is_err(), "{name}");
    }
}

#[test]
fn empty_asset_round_trips() {
    let mut asset = small_asset(CoefficientEncoding::U8Affine, 3, 8);
    asset.bricks.clear();
    asset.density.clear();
    if let Coefficients::U8Affine { codes, .. } = &mut asset.coefficients {
        codes.clear();
    }
    let (bytes, _) = encode_asset(&asset, &WriteOptions::default()).unwrap();
    assert!(read_asset_bytes(&bytes).unwrap() == asset);
    let mut reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
    assert!(matches!(
        reader.read_brick(0),
        Err(FormatError::BrickOutOfRange { .. })
    ));
}

#[test]
fn versioning_and_optional_sections() {
    let asset = small_asset(CoefficientEncoding::F16, 4, 2);
    let (bytes, _) = encode_asset(&asset, &WriteOptions::default()).unwrap();

    // A newer minor version reads; a different major does not.
    let mut newer = bytes.clone();
    newer[10..12].copy_from_slice(&7u16.to_le_bytes());
    common::resign(&mut newer);
    assert!(read_asset_bytes(&newer).unwrap() == asset);
    let mut major = bytes.clone();
    major[8..10].copy_from_slice(&(VERSION_MAJOR + 1).to_le_bytes());
    common::resign(&mut major);
    assert!(matches!(
        read_asset_bytes(&major),
        Err(FormatError::UnsupportedVersion { major: 2, .. })
    ));

    // An unknown optional section is skipped; an unknown required one is refused.
    let extra = |required: bool| {
        let mut parts = FileParts::parse(&bytes);
        let data = b"future data".to_vec();
        parts.sections.push((
            SectionEntry {
                kind: *b"XTRA",
                required,
                codec: SectionCodec::Unknown(77),
                shuffle: 0,
                offset: 0,
                stored_length: data.len() as u64,
                raw_length: 1 << 40,
                checksum: checksum(&data),
            },
            data,
        ));
        parts.build()
    };
    let with_optional = extra(false);
    assert!(read_asset_bytes(&with_optional).unwrap() == asset);
    let reader = AssetReader::new(Cursor::new(&with_optional)).unwrap();
    assert_eq!(reader.sections().last().unwrap().name(), "XTRA");
    assert!(matches!(
        read_asset_bytes(&extra(true)),
        Err(FormatError::UnknownRequiredSection { section }) if section == "XTRA"
    ));

    // Metadata is optional: without it the asset reads with an empty object.
    let mut parts = FileParts::parse(&bytes);
    parts.sections.retain(|(e, _)| e.kind != KIND_METADATA);
    let back = read_asset_bytes(&parts.build()).unwrap();
    assert_eq!(back.metadata, serde_json::json!({}));
}

#[test]
fn foreign_writer_layouts_are_read() {
    // A reader must accept any valid layout: sections in another table and file order,
    // and a chunked section written by another encoder with other shuffle choices.
    let asset = small_asset(CoefficientEncoding::U8Affine, 4, 12);
    let (bytes, _) = encode_asset(&asset, &WriteOptions::default()).unwrap();
    let mut parts = FileParts::parse(&bytes);
    parts.sections.reverse();
    assert!(read_asset_bytes(&parts.build()).unwrap() == asset);
    // Re-encode COEF with shuffle off by hand: still the same asset.
    let raw = asset.coefficients.to_f32();
    assert_eq!(raw.len(), asset.voxel_count() * 4);
    let Coefficients::U8Affine { codes, .. } = &asset.coefficients else {
        unreachable!()
    };
    let chunk_bricks = u32::from_le_bytes(bytes[108..112].try_into().unwrap()) as usize;
    let payload = chunked_payload(codes, BRICK_VOXELS * 4, chunk_bricks, 0);
    parts.replace(
        KIND_COEFFICIENTS,
        SectionCodec::ChunkedZstd,
        0,
        payload,
        codes.len() as u64,
    );
    assert!(read_asset_bytes(&parts.build()).unwrap() == asset);
}

#[test]
fn signed_density_sets_its_flag_and_round_trips() {
    let plain = small_asset(CoefficientEncoding::U8Affine, 4, 2);
    let (bytes, _) = encode_asset(&plain, &WriteOptions::default()).unwrap();
    let flags = |b: &[u8]| u64::from_le_bytes(b[24..32].try_into().unwrap());
    assert_eq!(
        flags(&bytes),
        0,
        "no negative value, no flag: 1.0 readers still read it"
    );

    let mut signed = plain.clone();
    signed.density[5] = half::f16::from_f32(-250.0);
    signed.density[700] = half::f16::from_f32(-0.5);
    let (bytes, _) = encode_asset(&signed, &WriteOptions::default()).unwrap();
    assert_eq!(flags(&bytes), FLAG_SIGNED_DENSITY);
    assert!(read_asset_bytes(&bytes).unwrap() == signed);
    let mut reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
    assert_eq!(reader.read_brick(1).unwrap().density[700 - BRICK_VOXELS], -0.5);

    // The flag allows negative values; it does not require them.
    let (mut plain_bytes, _) = encode_asset(&plain, &WriteOptions::default()).unwrap();
    plain_bytes[24..32].copy_from_slice(&FLAG_SIGNED_DENSITY.to_le_bytes());
    common::resign(&mut plain_bytes);
    assert!(read_asset_bytes(&plain_bytes).unwrap() == plain);

    // Negative values without the flag are refused, naming the voxel.
    let mut unflagged = bytes.clone();
    unflagged[24..32].copy_from_slice(&0u64.to_le_bytes());
    common::resign(&mut unflagged);
    let err = read_asset_bytes(&unflagged).unwrap_err();
    assert!(err.to_string().contains("voxel 5"), "{err}");

    // The encoder keeps the sign and clamps magnitudes to binary16's range.
    let encoded = nelf_format::encode_density(&[-1e9, -3.0, 0.0, 7.5, 1e9]).unwrap();
    let back: Vec<f32> = encoded.iter().map(|d| d.to_f32()).collect();
    assert_eq!(back, [-65504.0, -3.0, 0.0, 7.5, 65504.0]);
    assert!(nelf_format::encode_density(&[f32::NAN]).is_err());
}
