//! Format 1.2: the optional view-dependent part (`VDEP`, `VCOF`). Round trips of
//! view-dependent assets (both encodings, several lobe counts and ranks, zero bricks)
//! bit for bit; files without a view part unchanged (version 1.1, the bytes the 1.1
//! writer wrote); the view sections optional, so that a reader that does not know them
//! reads the view-averaged asset; random access to view coefficients; `nelf inspect`
//! (which reports the reflection part of format 1.3 the same way).
//! Damaged view sections are in `common::damage` (shared with the C reader's tests).
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::io::Cursor;

use common::{FileParts, small_asset};
use nelf_format::conventions::{LT_DIM, VIEW_HARMONICS};
use nelf_format::spec::{
    BRICK_VOXELS, KIND_COEFFICIENTS, KIND_METADATA, KIND_VIEW, KIND_VIEW_COEFFICIENTS, SectionCodec,
    VERSION_MINOR, VERSION_MINOR_VIEW, VERSION_MINOR_WITHOUT_VIEW,
};
use nelf_format::synthetic::{SyntheticField, synthetic_reflection, synthetic_view};
use nelf_format::{
    Asset, AssetReader, CoefficientEncoding, Coefficients, FormatError, WriteOptions, encode_asset,
    read_asset_bytes, write_asset,
};
use xxhash_rust::xxh3::xxh3_64;

const ENCODINGS: [CoefficientEncoding; 2] = [CoefficientEncoding::U8Affine, CoefficientEncoding::F16];

/// `asset` with a synthetic view-dependent part.
fn with_view(mut asset: Asset, lobes: usize, rank: usize, encoding: CoefficientEncoding) -> Asset {
    asset.view = Some(synthetic_view(&asset, lobes, rank, encoding, 17).unwrap());
    asset
}

/// `asset` without any brick (its view part, if any, too).
fn without_bricks(mut asset: Asset) -> Asset {
    asset.bricks.clear();
    asset.density.clear();
    let clear = |c: &mut Coefficients| match c {
        Coefficients::U8Affine { codes, .. } => codes.clear(),
        Coefficients::F16 { values, .. } => values.clear(),
    };
    clear(&mut asset.coefficients);
    if let Some(view) = &mut asset.view {
        clear(&mut view.coefficients);
    }
    asset
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn version_minor(bytes: &[u8]) -> u16 {
    u16::from_le_bytes([bytes[10], bytes[11]])
}

#[test]
fn view_dependent_assets_round_trip_bit_for_bit() {
    let options = [
        WriteOptions::default(),
        WriteOptions {
            zstd_level: 1,
            chunk_bricks: 3,
            shuffle: false,
        },
    ];
    let mut cases = 0;
    for pca_encoding in ENCODINGS {
        let base = small_asset(pca_encoding, 4, 3);
        for view_encoding in ENCODINGS {
            for (lobes, rank) in [
                (1, 1),
                (1, 5),
                (3, 2),
                (3, 16),
                (VIEW_HARMONICS, 1),
                (VIEW_HARMONICS, 4),
            ] {
                let asset = with_view(base.clone(), lobes, rank, view_encoding);
                for (o, options) in options.iter().enumerate() {
                    let what = format!("{pca_encoding:?}/{view_encoding:?} J {lobes} K_v {rank} options {o}");
                    let (bytes, sections) = encode_asset(&asset, options).unwrap();
                    assert_eq!(version_minor(&bytes), VERSION_MINOR_VIEW, "{what}");
                    assert_eq!(VERSION_MINOR_VIEW, 2);
                    assert_eq!(VERSION_MINOR, 4, "the newest minor is the fine density's (1.4)");
                    let back = read_asset_bytes(&bytes).unwrap();
                    assert!(back == asset, "{what}");
                    let (a, b) = (asset.view.as_ref().unwrap(), back.view.as_ref().unwrap());
                    assert_eq!(bits(&a.lobes), bits(&b.lobes), "{what}");
                    assert_eq!(bits(&a.basis), bits(&b.basis), "{what}");
                    assert_eq!(
                        bits(&a.coefficients.to_f32()),
                        bits(&b.coefficients.to_f32()),
                        "{what}"
                    );
                    // VDEP and VCOF follow COEF, precede META, and are optional.
                    let kinds: Vec<[u8; 4]> = sections.iter().map(|s| s.kind).collect();
                    let at = |k| kinds.iter().position(|&x| x == k).unwrap();
                    assert_eq!(at(KIND_VIEW), at(KIND_COEFFICIENTS) + 1, "{what}");
                    assert_eq!(at(KIND_VIEW_COEFFICIENTS), at(KIND_VIEW) + 1, "{what}");
                    assert_eq!(at(KIND_METADATA), at(KIND_VIEW_COEFFICIENTS) + 1, "{what}");
                    for s in &sections {
                        let optional = [KIND_VIEW, KIND_VIEW_COEFFICIENTS, KIND_METADATA].contains(&s.kind);
                        assert_eq!(s.required, !optional, "{what}: {}", s.name());
                    }
                    let vcof = &sections[at(KIND_VIEW_COEFFICIENTS)];
                    assert_eq!(vcof.codec, SectionCodec::ChunkedZstd);
                    let record = lobes * rank * view_encoding.bytes_per_value();
                    let width = if options.shuffle { record as u32 } else { 0 };
                    assert_eq!(vcof.shuffle, width, "{what}");
                    cases += 1;
                }
            }
            // Zero bricks.
            let empty = without_bricks(with_view(base.clone(), 2, 3, view_encoding));
            let bytes = encode_asset(&empty, &WriteOptions::default()).unwrap().0;
            assert!(read_asset_bytes(&bytes).unwrap() == empty);
            let mut reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
            assert_eq!(reader.view_params().unwrap().lobe_count(), 2);
            assert!(matches!(
                reader.read_brick(0),
                Err(FormatError::BrickOutOfRange { .. })
            ));
            reader.verify().unwrap();
        }
    }
    assert_eq!(cases, 2 * 2 * 6 * 2);
}

#[test]
fn largest_view_part_round_trips_with_smaller_chunks() {
    // J·K_v = 384 f16 coefficients: 384 KiB a brick, so 32-brick chunks would decode to
    // 12 MiB; the writer clamps chunks to 10 bricks (4 MiB) for every chunked section.
    let base = SyntheticField::new(12 * BRICK_VOXELS, 4)
        .asset(2, CoefficientEncoding::U8Affine)
        .unwrap();
    let asset = with_view(base, 8, 48, CoefficientEncoding::F16);
    let bytes = encode_asset(&asset, &WriteOptions::default()).unwrap().0;
    let chunk_bricks = u32::from_le_bytes(bytes[108..112].try_into().unwrap());
    assert_eq!(chunk_bricks, 10);
    assert!(read_asset_bytes(&bytes).unwrap() == asset);
}

#[test]
fn files_without_a_view_part_are_unchanged() {
    // The bytes the 1.1 writer (before the view part existed) wrote for these assets.
    let pins = [
        (
            CoefficientEncoding::U8Affine,
            4,
            21,
            32,
            24_347,
            0xe950_dc41_9bc7_aa8a_u64,
        ),
        (
            CoefficientEncoding::U8Affine,
            4,
            21,
            3,
            26_555,
            0x5a05_4f32_42a0_4f47,
        ),
        (CoefficientEncoding::F16, 6, 5, 32, 48_097, 0x7d96_41e4_5d26_07d9),
        (CoefficientEncoding::F16, 6, 5, 3, 50_921, 0x9999_d346_0af0_654f),
    ];
    for (encoding, rank, seed, chunk_bricks, length, hash) in pins {
        let asset = SyntheticField::new(3000, seed).asset(rank, encoding).unwrap();
        let options = WriteOptions {
            chunk_bricks,
            ..WriteOptions::default()
        };
        let bytes = encode_asset(&asset, &options).unwrap().0;
        assert_eq!(version_minor(&bytes), VERSION_MINOR_WITHOUT_VIEW);
        assert_eq!(
            (bytes.len(), xxh3_64(&bytes)),
            (length, hash),
            "{encoding:?} rank {rank} chunks {chunk_bricks}"
        );

        // With a view part, the file is the same one plus VDEP and VCOF (version 1.2):
        // taking them out again gives the 1.1 file byte for byte.
        let viewed = with_view(asset, 2, 3, CoefficientEncoding::U8Affine);
        let mut parts = FileParts::parse(&encode_asset(&viewed, &options).unwrap().0);
        parts
            .sections
            .retain(|(e, _)| e.kind != KIND_VIEW && e.kind != KIND_VIEW_COEFFICIENTS);
        parts.header[10..12].copy_from_slice(&VERSION_MINOR_WITHOUT_VIEW.to_le_bytes());
        assert_eq!(parts.build(), bytes);
    }
}

#[test]
fn readers_that_do_not_know_the_view_part_read_the_view_averaged_asset() {
    for view_encoding in ENCODINGS {
        let plain = small_asset(CoefficientEncoding::U8Affine, 3, 6);
        let asset = with_view(plain.clone(), 3, 2, view_encoding);
        let bytes = encode_asset(&asset, &WriteOptions::default()).unwrap().0;
        let reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
        let optional: Vec<String> = reader
            .sections()
            .iter()
            .filter(|s| !s.required)
            .map(nelf_format::spec::SectionEntry::name)
            .collect();
        assert_eq!(optional, ["VDEP", "VCOF", "META"]);
        // A 1.1 reader knows neither kind: to it they are unknown optional sections,
        // skipped (checksums still verified). Renamed to kinds this reader does not know
        // either, the file reads as the asset without its view part.
        let mut parts = FileParts::parse(&bytes);
        for (entry, _) in &mut parts.sections {
            match &entry.kind {
                b"VDEP" => entry.kind = *b"VDE?",
                b"VCOF" => entry.kind = *b"VCO?",
                _ => {}
            }
        }
        let renamed = parts.build();
        let back = read_asset_bytes(&renamed).unwrap();
        assert!(back.view.is_none());
        assert!(back == plain);
        // Still checked: a damaged skipped section is refused by a full read.
        let mut damaged = renamed.clone();
        let vcof = FileParts::parse(&renamed)
            .sections
            .iter()
            .find(|(e, _)| &e.kind == b"VCO?")
            .unwrap()
            .0;
        damaged[vcof.offset as usize + 30] ^= 4;
        assert!(matches!(
            read_asset_bytes(&damaged),
            Err(FormatError::ChecksumMismatch { what, .. }) if what.contains("VCO?")
        ));
    }
}

#[test]
fn random_access_gives_view_coefficients_and_parameters() {
    for view_encoding in ENCODINGS {
        let asset = with_view(small_asset(CoefficientEncoding::F16, 5, 8), 3, 4, view_encoding);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("view.nelf");
        let options = WriteOptions {
            chunk_bricks: 3,
            ..WriteOptions::default()
        };
        write_asset(&path, &asset, &options).unwrap();
        let mut reader = AssetReader::open(&path).unwrap();
        let view = asset.view.as_ref().unwrap();
        let params = reader.view_params().unwrap().clone();
        assert_eq!(bits(&params.lobes), bits(&view.lobes));
        assert_eq!(bits(&params.basis), bits(&view.basis));
        assert_eq!((params.lobe_count(), params.rank()), (3, 4));
        assert_eq!(params.coefficients.encoding(), view_encoding);
        assert_eq!(params.coefficients.rank(), 12);
        assert!(params.coefficients.is_empty());
        let omega = [0.2, -0.7, 0.4];
        let order: Vec<usize> = (0..asset.bricks.len()).rev().chain([1, 0, 4]).collect();
        let mut d = vec![0.0f32; 12];
        for i in order {
            let brick = reader.read_brick(i).unwrap();
            assert_eq!(brick.view_coefficients.len(), BRICK_VOXELS * 12);
            for local in (0..BRICK_VOXELS).step_by(7) {
                let v = i * BRICK_VOXELS + local;
                view.coefficients.voxel_f32(v, &mut d);
                let got = &brick.view_coefficients[local * 12..(local + 1) * 12];
                assert_eq!(bits(got), bits(&d), "brick {i} voxel {local}");
                // The reader's parameters and the brick's coefficients give the asset's T.
                let mut t = asset.reconstruct_lt(v);
                params.add_to(got, omega, &mut t);
                assert_eq!(bits(&t), bits(&asset.reconstruct_lt_toward(v, omega)));
            }
        }
        reader.verify().unwrap();
    }
    // Without a view part: no parameters, empty view coefficients.
    let asset = small_asset(CoefficientEncoding::U8Affine, 2, 9);
    let bytes = encode_asset(&asset, &WriteOptions::default()).unwrap().0;
    let mut reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
    assert!(reader.view_params().is_none());
    assert!(reader.read_brick(0).unwrap().view_coefficients.is_empty());
    assert_eq!(
        asset.reconstruct_lt_toward(5, [0.0, 0.0, 1.0]),
        asset.reconstruct_lt(5)
    );
}

#[test]
fn view_transport_follows_the_spec_formula() {
    // T(x, ω) = m + Σ_k c_k B_k + Σ_j Y_j(ω) Σ_i d_ji V_i, Y_j(ω) = Σ_l lobes[j·9 + l] y_l(ω).
    let asset = with_view(
        small_asset(CoefficientEncoding::F16, 3, 2),
        2,
        3,
        CoefficientEncoding::F16,
    );
    let view = asset.view.as_ref().unwrap();
    let omega = [1.0f32, 2.0, -2.0];
    let y = nelf_format::conventions::view_harmonics(omega);
    let unit = nelf_format::conventions::view_harmonics([1.0 / 3.0, 2.0 / 3.0, -2.0 / 3.0]);
    for (a, b) in y.iter().zip(unit) {
        assert!((a - b).abs() < 1e-6, "ω is normalised");
    }
    let mut d = vec![0.0f32; 6];
    for v in [0, 700, asset.voxel_count() - 1] {
        view.coefficients.voxel_f32(v, &mut d);
        let mut want = asset.reconstruct_lt(v);
        for j in 0..2 {
            let lobe: f32 = (0..VIEW_HARMONICS)
                .map(|l| view.lobes[j * VIEW_HARMONICS + l] * y[l])
                .sum();
            for i in 0..3 {
                for (e, w) in want.iter_mut().enumerate() {
                    *w += lobe * d[j * 3 + i] * view.basis[i * LT_DIM + e];
                }
            }
        }
        let got = asset.reconstruct_lt_toward(v, omega);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= 1e-6 * (1.0 + w.abs()), "voxel {v}: {g} vs {w}");
        }
    }
}

#[test]
fn invalid_view_parts_are_refused_by_the_writer() {
    let good = with_view(
        small_asset(CoefficientEncoding::U8Affine, 3, 4),
        2,
        3,
        CoefficientEncoding::U8Affine,
    );
    encode_asset(&good, &WriteOptions::default()).unwrap();
    let edit = |f: &dyn Fn(&mut nelf_format::ViewDependence)| {
        let mut a = good.clone();
        f(a.view.as_mut().unwrap());
        a
    };
    let cases = [
        ("NaN lobe", edit(&|v| v.lobes[3] = f32::NAN)),
        ("partial lobe", edit(&|v| v.lobes.truncate(VIEW_HARMONICS + 3))),
        ("no lobe", edit(&|v| v.lobes.clear())),
        ("infinite basis", edit(&|v| v.basis[10] = f32::INFINITY)),
        ("no basis", edit(&|v| v.basis.clear())),
        ("basis rank mismatch", edit(&|v| v.basis.truncate(2 * LT_DIM))),
        (
            "too many lobes",
            edit(&|v| v.lobes = vec![0.5; (VIEW_HARMONICS + 1) * VIEW_HARMONICS]),
        ),
        (
            "missing voxels",
            edit(&|v| {
                if let Coefficients::U8Affine { codes, .. } = &mut v.coefficients {
                    codes.truncate(codes.len() - 6);
                }
            }),
        ),
        (
            "negative scale",
            edit(&|v| {
                if let Coefficients::U8Affine { scale, .. } = &mut v.coefficients {
                    scale[1] = -1.0;
                }
            }),
        ),
    ];
    for (name, asset) in cases {
        let err = encode_asset(&asset, &WriteOptions::default()).unwrap_err();
        assert!(!matches!(err, FormatError::Io(_)), "{name}: {err}");
    }
    // J·K_v > 384.
    let mut big = good.clone();
    let view = big.view.as_mut().unwrap();
    view.lobes = vec![0.1; 2 * VIEW_HARMONICS];
    view.basis = vec![0.0; 193 * LT_DIM];
    assert!(encode_asset(&big, &WriteOptions::default()).is_err());
}

#[test]
fn inspect_reports_the_view_part() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("view.nelf");
    let asset = with_view(
        small_asset(CoefficientEncoding::U8Affine, 3, 1),
        3,
        2,
        CoefficientEncoding::F16,
    );
    let report = write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    let inspection = nelf_format::inspect::inspect(&path).unwrap();
    assert_eq!(inspection.version, "1.2");
    let view = inspection.view.as_ref().unwrap();
    assert_eq!(
        (
            view.lobes,
            view.rank,
            view.coefficients_per_voxel,
            view.encoding.as_str()
        ),
        (3, 2, 6, "f16")
    );
    let view_sections = report
        .sections
        .iter()
        .filter(|s| s.kind == KIND_VIEW || s.kind == KIND_VIEW_COEFFICIENTS);
    assert_eq!(
        view.stored_bytes,
        view_sections.clone().map(|s| s.stored_length).sum::<u64>()
    );
    assert_eq!(view.raw_bytes, view_sections.map(|s| s.raw_length).sum::<u64>());
    let text = inspection.to_text();
    assert!(
        text.contains("view dependence:   3 lobes × rank 2 = 6 coefficients per voxel, f16"),
        "{text}"
    );
    assert!(
        text.contains("  VDEP no ") && text.contains("  VCOF no "),
        "{text}"
    );
    let json = serde_json::to_value(&inspection).unwrap();
    assert_eq!(json["view"]["lobes"], 3);

    let plain = dir.path().join("plain.nelf");
    write_asset(
        &plain,
        &small_asset(CoefficientEncoding::F16, 2, 1),
        &WriteOptions::default(),
    )
    .unwrap();
    let inspection = nelf_format::inspect::inspect(&plain).unwrap();
    assert_eq!(inspection.version, "1.1");
    assert!(inspection.view.is_none());
    assert!(inspection.to_text().contains("view dependence:   none"));
}

#[test]
fn inspect_reports_the_reflection_part() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("reflection.nelf");
    let mut asset = small_asset(CoefficientEncoding::U8Affine, 3, 1);
    let part = synthetic_reflection(&asset, 20.0, 4).unwrap();
    let Coefficients::U8Affine { scale, offset, .. } = &part.coefficients else {
        panic!("reflection values are 8-bit")
    };
    let range = [offset[2], offset[2] + 255.0 * scale[2]];
    asset.reflection = Some(part.clone());
    let report = write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    let inspection = nelf_format::inspect::inspect(&path).unwrap();
    assert_eq!(inspection.version, "1.3");
    assert!(inspection.view.is_none());
    let r = inspection.reflection.as_ref().unwrap();
    assert_eq!(r.exponent, 20.0);
    assert_eq!(r.eyes_m, part.eyes_m);
    assert_eq!(r.scale_range, range);
    assert!(range[0] >= 0.0 && range[1] > range[0], "{range:?}");
    let sections = report
        .sections
        .iter()
        .filter(|s| s.kind == *b"VREF" || s.kind == *b"VRCO");
    assert_eq!(
        r.stored_bytes,
        sections.clone().map(|s| s.stored_length).sum::<u64>()
    );
    assert_eq!(r.raw_bytes, sections.map(|s| s.raw_length).sum::<u64>());
    let text = inspection.to_text();
    assert!(text.contains("view dependence:   none"), "{text}");
    assert!(
        text.contains(&format!(
            "reflection:        lobe exponent 20, 5 eyes, scale {} … {} (8-bit)",
            range[0], range[1]
        )),
        "{text}"
    );
    assert!(text.contains("reflection eyes:   ("), "{text}");
    assert!(
        text.contains("  VREF no ") && text.contains("  VRCO no "),
        "{text}"
    );
    let json = serde_json::to_value(&inspection).unwrap();
    assert_eq!(json["reflection"]["eyes_m"].as_array().unwrap().len(), 5);
    assert_eq!(json["reflection"]["exponent"], 20.0);

    // Without one: "none".
    let plain = dir.path().join("plain.nelf");
    write_asset(
        &plain,
        &small_asset(CoefficientEncoding::F16, 2, 1),
        &WriteOptions::default(),
    )
    .unwrap();
    let inspection = nelf_format::inspect::inspect(&plain).unwrap();
    assert!(inspection.reflection.is_none());
    assert!(inspection.to_text().contains("reflection:        none"));
}
