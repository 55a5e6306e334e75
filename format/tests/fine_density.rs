//! The fine density (format 1.4, `DNSF`, header `fine_density_factor`): round trip at
//! `F` = 2 and 4 (negative values with the signed-density flag), version, random access,
//! the writer's chunk limit, files without it written as before, and what a reader that
//! does not know it (1.0–1.3) reads: the coarse asset.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::io::Cursor;

use common::{FileParts, fine_density_of, resign, small_asset, with_fine_density};
use half::f16;
use nelf_format::spec::{
    FLAG_SIGNED_DENSITY, KIND_DENSITY, KIND_FINE_DENSITY, SectionCodec, VERSION_MINOR,
    VERSION_MINOR_REFLECTION, VERSION_MINOR_VIEW, VERSION_MINOR_WITHOUT_VIEW,
};
use nelf_format::synthetic::{synthetic_reflection, synthetic_view};
use nelf_format::{
    Asset, AssetReader, CoefficientEncoding, FineDensity, WriteOptions, encode_asset, read_asset_bytes,
    write_asset,
};

const ENCODINGS: [CoefficientEncoding; 2] = [CoefficientEncoding::U8Affine, CoefficientEncoding::F16];

fn version_minor(bytes: &[u8]) -> u16 {
    u16::from_le_bytes([bytes[10], bytes[11]])
}

fn factor_field(bytes: &[u8]) -> u32 {
    u32::from_le_bytes(bytes[196..200].try_into().unwrap())
}

fn flags(bytes: &[u8]) -> u64 {
    u64::from_le_bytes(bytes[24..32].try_into().unwrap())
}

fn chunk_bricks(bytes: &[u8]) -> u32 {
    u32::from_le_bytes(bytes[108..112].try_into().unwrap())
}

fn bits(values: &[f16]) -> Vec<u16> {
    values.iter().map(|v| v.to_bits()).collect()
}

/// `asset` without its fine density.
fn coarse(asset: &Asset) -> Asset {
    Asset {
        fine_density: None,
        ..asset.clone()
    }
}

#[test]
fn a_fine_density_round_trips_as_version_1_4_at_factors_2_and_4() {
    let options = [
        WriteOptions::default(),
        WriteOptions {
            zstd_level: 1,
            chunk_bricks: 3,
            shuffle: false,
        },
    ];
    let mut cases = 0;
    for encoding in ENCODINGS {
        let base = small_asset(encoding, 3, 5);
        for factor in [2, 4] {
            for negatives in [false, true] {
                let asset = with_fine_density(base.clone(), factor, negatives);
                let fine = asset.fine_density.as_ref().unwrap();
                let per_brick = 512 * factor.pow(3) as usize;
                assert_eq!(fine.voxels_per_brick(), per_brick);
                assert_eq!(fine.brick_edge(), 8 * factor as usize);
                assert_eq!(
                    fine.values.iter().any(|v| v.to_f32() < 0.0),
                    negatives,
                    "the case must hold negative values exactly when asked"
                );
                for (o, options) in options.iter().enumerate() {
                    let what = format!("{encoding:?} F {factor} negatives {negatives} options {o}");
                    let (bytes, sections) = encode_asset(&asset, options).unwrap();
                    assert_eq!(version_minor(&bytes), VERSION_MINOR, "{what}");
                    assert_eq!(VERSION_MINOR, 4);
                    assert_eq!(factor_field(&bytes), factor, "{what}");
                    // Only the fine values are negative: the flag follows them.
                    assert!(!nelf_format::has_negative_density(&asset.density));
                    assert_eq!(flags(&bytes) & FLAG_SIGNED_DENSITY != 0, negatives, "{what}");
                    // DNSF: chunked, optional, right after DENS, 1024·F³ bytes a brick.
                    let at = sections.iter().position(|s| s.kind == KIND_FINE_DENSITY).unwrap();
                    assert_eq!(sections[at - 1].kind, KIND_DENSITY, "{what}");
                    let entry = sections[at];
                    assert!(!entry.required, "{what}: DNSF must be optional");
                    assert_eq!(entry.codec, SectionCodec::ChunkedZstd, "{what}");
                    assert_eq!(entry.raw_length, (asset.bricks.len() * 2 * per_brick) as u64);
                    assert_eq!(entry.shuffle, if options.shuffle { 2 } else { 0 }, "{what}");

                    let back = read_asset_bytes(&bytes).unwrap();
                    assert!(back == asset, "{what}");
                    let back_fine = back.fine_density.as_ref().unwrap();
                    assert_eq!(back_fine.factor, factor, "{what}");
                    // Bit for bit: −0 stays −0.
                    assert_eq!(bits(&back_fine.values), bits(&fine.values), "{what}");
                    assert_eq!(
                        encode_asset(&back, options).unwrap().0,
                        bytes,
                        "{what}: re-encoding"
                    );

                    // Random access: every brick's fine values, in the brick's fine order.
                    let mut reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
                    assert_eq!(reader.header().fine_density_factor, factor);
                    for b in 0..asset.bricks.len() {
                        let brick = reader.read_brick(b).unwrap();
                        let want: Vec<u32> = fine.values[b * per_brick..(b + 1) * per_brick]
                            .iter()
                            .map(|v| v.to_f32().to_bits())
                            .collect();
                        let got: Vec<u32> = brick.fine_density.iter().map(|v| v.to_bits()).collect();
                        assert_eq!(got, want, "{what}: brick {b}");
                        let density: Vec<f32> = asset.density[b * 512..(b + 1) * 512]
                            .iter()
                            .map(|d| d.to_f32())
                            .collect();
                        assert_eq!(brick.density, density, "{what}: brick {b}");
                    }
                    reader.verify().unwrap();
                    cases += 1;
                }
            }
        }
    }
    assert_eq!(cases, 16);
}

#[test]
fn a_fine_density_goes_with_either_view_dependent_part() {
    let base = small_asset(CoefficientEncoding::U8Affine, 4, 8);
    let mut viewed = with_fine_density(base.clone(), 2, false);
    viewed.view = Some(synthetic_view(&viewed, 2, 3, CoefficientEncoding::F16, 4).unwrap());
    let mut reflecting = with_fine_density(base, 4, true);
    reflecting.reflection = Some(synthetic_reflection(&reflecting, 20.0, 6).unwrap());
    for asset in [viewed, reflecting] {
        let bytes = encode_asset(&asset, &WriteOptions::default()).unwrap().0;
        assert_eq!(version_minor(&bytes), VERSION_MINOR);
        let back = read_asset_bytes(&bytes).unwrap();
        assert!(back == asset);
        let mut reader = AssetReader::new(Cursor::new(&bytes)).unwrap();
        let last = asset.bricks.len() - 1;
        let brick = reader.read_brick(last).unwrap();
        let fine = asset.fine_density.as_ref().unwrap();
        let n = fine.voxels_per_brick();
        assert_eq!(brick.fine_density.len(), n);
        assert_eq!(
            brick.fine_density[n - 1],
            fine.values[(last + 1) * n - 1].to_f32()
        );
        assert!(!brick.view_coefficients.is_empty() || !brick.reflection.is_empty());
    }
}

#[test]
fn files_without_a_fine_density_are_written_as_before() {
    let plain = small_asset(CoefficientEncoding::F16, 3, 2);
    let mut viewed = plain.clone();
    viewed.view = Some(synthetic_view(&viewed, 2, 2, CoefficientEncoding::U8Affine, 1).unwrap());
    let mut reflecting = plain.clone();
    reflecting.reflection = Some(synthetic_reflection(&reflecting, 20.0, 2).unwrap());
    for (asset, minor) in [
        (plain, VERSION_MINOR_WITHOUT_VIEW),
        (viewed, VERSION_MINOR_VIEW),
        (reflecting, VERSION_MINOR_REFLECTION),
    ] {
        for factor in [2, 4] {
            let options = WriteOptions {
                chunk_bricks: 3,
                ..WriteOptions::default()
            };
            let bytes = encode_asset(&asset, &options).unwrap().0;
            assert_eq!(version_minor(&bytes), minor);
            assert_eq!(factor_field(&bytes), 0, "bytes 196..200 stay 0 without DNSF");
            let parts = FileParts::parse(&bytes);
            assert!(parts.sections.iter().all(|(e, _)| e.kind != KIND_FINE_DENSITY));
            // The same asset with a fine density (no negative value) is the same file plus
            // DNSF: taking it out again, with the factor and the minor version of before,
            // gives the file without it byte for byte.
            let fine = with_fine_density(asset.clone(), factor, false);
            let fine_bytes = encode_asset(&fine, &options).unwrap().0;
            assert_eq!(version_minor(&fine_bytes), VERSION_MINOR);
            let mut parts = FileParts::parse(&fine_bytes);
            parts.sections.retain(|(e, _)| e.kind != KIND_FINE_DENSITY);
            parts.header[196..200].copy_from_slice(&0u32.to_le_bytes());
            parts.header[10..12].copy_from_slice(&minor.to_le_bytes());
            assert_eq!(parts.build(), bytes, "minor {minor} F {factor}");
        }
    }
}

#[test]
fn readers_that_do_not_know_the_fine_density_read_the_coarse_asset() {
    for (factor, negatives) in [(2, false), (4, true)] {
        let asset = with_fine_density(
            small_asset(CoefficientEncoding::U8Affine, 3, 6),
            factor,
            negatives,
        );
        let bytes = encode_asset(&asset, &WriteOptions::default()).unwrap().0;
        // A 1.0–1.3 reader ignores header bytes 196..200 (reserved to it) and skips DNSF,
        // an unknown kind without the required bit (checksums still verified). Renamed to a
        // kind this reader does not know either, and with the factor it ignores set to 0,
        // the file reads as the coarse asset.
        let mut older = bytes.clone();
        older[196..200].fill(0);
        let count = u32::from_le_bytes(older[16..20].try_into().unwrap()) as usize;
        let entry = (0..count)
            .map(|i| 256 + 48 * i)
            .find(|&o| older[o..o + 4] == KIND_FINE_DENSITY)
            .unwrap();
        assert_eq!(older[entry + 4] & 1, 0, "DNSF must not carry the required bit");
        older[entry..entry + 4].copy_from_slice(b"DNSX");
        resign(&mut older);
        let back = read_asset_bytes(&older).unwrap();
        assert!(back.fine_density.is_none());
        assert!(back == coarse(&asset), "F {factor}");
        let mut reader = AssetReader::new(Cursor::new(&older)).unwrap();
        assert!(reader.read_brick(0).unwrap().fine_density.is_empty());
        reader.verify().unwrap();
        // The unknown section is still checksummed: a damaged byte in it is found.
        let (e, _) = FileParts::parse(&older)
            .sections
            .into_iter()
            .find(|(e, _)| e.kind == *b"DNSX")
            .unwrap();
        let mut damaged = older.clone();
        damaged[(e.offset + e.stored_length / 2) as usize] ^= 4;
        let err = read_asset_bytes(&damaged).unwrap_err();
        assert!(err.to_string().contains("DNSX"), "{err}");

        // Without the section and the factor, the coarse parts are exactly the asset's.
        let mut parts = FileParts::parse(&bytes);
        parts.sections.retain(|(e, _)| e.kind != KIND_FINE_DENSITY);
        parts.header[196..200].fill(0);
        let stripped = read_asset_bytes(&parts.build()).unwrap();
        assert!(stripped == coarse(&asset));
    }
}

#[test]
fn the_writer_keeps_fine_density_chunks_within_4_mib() {
    let base = small_asset(CoefficientEncoding::U8Affine, 2, 3);
    let options = WriteOptions {
        chunk_bricks: 5000,
        ..WriteOptions::default()
    };
    // 4 MiB / 1536 (a VRCO brick) = 2730 without; 4 MiB / (1024·F³) with a fine density.
    for (factor, most) in [(0, 2730), (2, 512), (4, 64)] {
        let asset = match factor {
            0 => base.clone(),
            f => with_fine_density(base.clone(), f, false),
        };
        let bytes = encode_asset(&asset, &options).unwrap().0;
        assert_eq!(chunk_bricks(&bytes), most, "F {factor}");
        assert!(read_asset_bytes(&bytes).unwrap() == asset);
        // One brick more per chunk is refused by the reader (header step).
        if factor != 0 {
            let mut b = bytes.clone();
            b[108..112].copy_from_slice(&(most + 1).to_le_bytes());
            resign(&mut b);
            let err = read_asset_bytes(&b).unwrap_err();
            assert!(err.to_string().contains("chunk_bricks"), "{err}");
        }
    }
}

#[test]
fn bad_fine_densities_are_refused_by_the_writer() {
    let base = small_asset(CoefficientEncoding::U8Affine, 2, 4);
    let good = fine_density_of(&base, 2, false);
    let write = |fine: FineDensity| {
        let asset = Asset {
            fine_density: Some(fine),
            ..base.clone()
        };
        encode_asset(&asset, &WriteOptions::default())
            .unwrap_err()
            .to_string()
    };
    for factor in [0, 1, 3, 8] {
        let err = write(FineDensity {
            factor,
            values: good.values.clone(),
        });
        assert!(err.contains("factor"), "F {factor}: {err}");
    }
    let mut short = good.clone();
    short.values.pop();
    assert!(write(short).contains("fine density values"));
    let mut nan = good.clone();
    nan.values[4097] = f16::NAN;
    let err = write(nan);
    assert!(err.contains("section DNSF voxel 4097"), "{err}");
}

#[test]
fn inspect_reports_the_fine_density() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fine.nelf");
    let asset = with_fine_density(small_asset(CoefficientEncoding::U8Affine, 3, 1), 4, false);
    let report = write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    let inspection = nelf_format::inspect::inspect(&path).unwrap();
    assert_eq!(inspection.version, "1.4");
    let fine = inspection.fine_density.as_ref().unwrap();
    let entry = report
        .sections
        .iter()
        .find(|s| s.kind == KIND_FINE_DENSITY)
        .unwrap();
    assert_eq!(
        (fine.factor, fine.brick_edge, fine.voxels_per_brick),
        (4, 32, 32_768)
    );
    assert_eq!(fine.voxel_count, asset.bricks.len() as u64 * 32_768);
    assert_eq!(fine.voxel_size_m, asset.grid.voxel_size_m / 4.0);
    assert_eq!(
        (fine.stored_bytes, fine.raw_bytes),
        (entry.stored_length, entry.raw_length)
    );
    assert_eq!(fine.raw_bytes, asset.bricks.len() as u64 * 65_536);
    let text = inspection.to_text();
    let want = format!(
        "fine density:      F = 4, 32³ fine voxels a brick ({} in all) of",
        fine.voxel_count
    );
    assert!(text.contains(&want), "{text}");
    assert!(
        text.contains(&format!(
            "{} bytes stored, {} decoded",
            entry.stored_length, entry.raw_length
        )),
        "{text}"
    );
    assert!(text.contains("  DNSF no "), "{text}");
    let json = serde_json::to_value(&inspection).unwrap();
    assert_eq!(json["fine_density"]["factor"], 4);
    assert_eq!(json["fine_density"]["raw_bytes"], entry.raw_length);

    let plain = dir.path().join("plain.nelf");
    write_asset(&plain, &coarse(&asset), &WriteOptions::default()).unwrap();
    let inspection = nelf_format::inspect::inspect(&plain).unwrap();
    assert_eq!(inspection.version, "1.1");
    assert!(inspection.fine_density.is_none());
    assert!(inspection.to_text().contains("fine density:      none"));
    let json = serde_json::to_value(&inspection).unwrap();
    assert!(json["fine_density"].is_null());
}
