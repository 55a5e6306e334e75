//! Damaged and hostile `.nelf` files: truncations at every boundary and at random
//! offsets, bit flips in every section, hand-made hostile headers and sections, and a
//! seeded mini-fuzzer. Every case must give a typed error naming the problem (never a
//! panic); the allocation bound is checked in `alloc.rs`.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};

use common::{FileParts, boundaries, chunked_payload, resign, small_asset};
use nelf_format::spec::{
    BRICK_VOXELS, HEADER_SIZE, KIND_BRICKS, KIND_COEFFICIENTS, KIND_DENSITY, KIND_METADATA, KIND_PCA,
    KIND_QUANT_PARAMS, SECTION_ENTRY_SIZE, SectionCodec, SectionEntry,
};
use nelf_format::{
    Asset, AssetReader, CoefficientEncoding, Coefficients, FormatError, WriteOptions, encode_asset,
    read_asset_bytes,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn options() -> WriteOptions {
    WriteOptions {
        chunk_bricks: 3,
        ..WriteOptions::default()
    }
}

fn encoded(encoding: CoefficientEncoding) -> (Asset, Vec<u8>) {
    let asset = small_asset(encoding, 4, 21);
    let bytes = encode_asset(&asset, &options()).unwrap().0;
    (asset, bytes)
}

/// Reads `bytes` both ways (whole, and random access of every brick plus verify),
/// failing the test on a panic. Returns the whole-read result; asserts that random
/// access fails too when the whole read fails.
fn read_both(bytes: &[u8], what: &str) -> Result<Asset, FormatError> {
    let whole = catch_unwind(AssertUnwindSafe(|| read_asset_bytes(bytes)))
        .unwrap_or_else(|_| panic!("read_asset_bytes panicked on {what}"));
    let random = catch_unwind(AssertUnwindSafe(|| -> Result<(), FormatError> {
        let mut reader = AssetReader::new(Cursor::new(bytes))?;
        for i in 0..reader.bricks().len() {
            reader.read_brick(i)?;
        }
        reader.verify()
    }))
    .unwrap_or_else(|_| panic!("AssetReader panicked on {what}"));
    assert_eq!(
        whole.is_ok(),
        random.is_ok(),
        "{what}: whole {whole:?} vs random access {random:?}"
    );
    whole
}

fn field(bytes: &mut [u8], offset: usize, value: &[u8]) {
    bytes[offset..offset + value.len()].copy_from_slice(value);
}

#[test]
fn truncation_at_every_boundary_and_random_offsets() {
    let mut rng = Pcg64::seed_from_u64(1);
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let (_, bytes) = encoded(encoding);
        let mut cuts: Vec<usize> = boundaries(&bytes)
            .into_iter()
            .flat_map(|b| [b.saturating_sub(1), b, b + 1])
            .filter(|&c| c < bytes.len())
            .collect();
        cuts.extend((0..200).map(|_| rng.random_range(0..bytes.len())));
        for cut in cuts {
            let err = read_both(&bytes[..cut], &format!("truncation at {cut}")).unwrap_err();
            assert!(
                matches!(err, FormatError::Truncated { .. }),
                "truncation at {cut} of {}: {err}",
                bytes.len()
            );
        }
    }
}

#[test]
fn bit_flips_in_every_section_are_detected_and_named() {
    let mut rng = Pcg64::seed_from_u64(2);
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let (_, bytes) = encoded(encoding);
        let parts = FileParts::parse(&bytes);
        for (entry, _) in &parts.sections {
            for _ in 0..40 {
                let at = entry.offset as usize + rng.random_range(0..entry.stored_length as usize);
                let mut damaged = bytes.clone();
                damaged[at] ^= 1 << rng.random_range(0..8);
                let err = read_both(&damaged, &format!("flip at {at} in {}", entry.name())).unwrap_err();
                assert!(
                    err.to_string().contains(&entry.name()),
                    "flip in {} at {at}: {err}",
                    entry.name()
                );
            }
        }
        // Header and table: caught by the header checksum (or earlier field checks).
        let table_end = HEADER_SIZE + parts.sections.len() * SECTION_ENTRY_SIZE;
        for at in 0..table_end {
            let mut damaged = bytes.clone();
            damaged[at] ^= 1 << (at % 8);
            read_both(&damaged, &format!("flip at {at} in header/table")).unwrap_err();
        }
        // Anywhere at all, padding included.
        for _ in 0..300 {
            let at = rng.random_range(0..bytes.len());
            let mut damaged = bytes.clone();
            damaged[at] ^= 1 << rng.random_range(0..8);
            read_both(&damaged, &format!("flip at {at}")).unwrap_err();
        }
    }
}

/// Applies `edit` to the header bytes of a fresh file, re-signs, and returns the error.
fn hostile_header(bytes: &[u8], edit: impl Fn(&mut Vec<u8>)) -> FormatError {
    let mut b = bytes.to_vec();
    edit(&mut b);
    resign(&mut b);
    read_both(&b, "hostile header").unwrap_err()
}

/// Offset of the table entry of section `kind`.
fn entry_offset(bytes: &[u8], kind: [u8; 4]) -> usize {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    (0..count)
        .map(|i| HEADER_SIZE + i * SECTION_ENTRY_SIZE)
        .find(|&o| bytes[o..o + 4] == kind)
        .unwrap()
}

#[test]
fn hostile_headers_give_named_errors() {
    let (_, bytes) = encoded(CoefficientEncoding::U8Affine);
    let nan = f64::NAN.to_le_bytes();
    let len = bytes.len() as u64;
    macro_rules! expect {
        ($edit:expr, $pat:pat) => {{
            let err = hostile_header(&bytes, $edit);
            assert!(matches!(err, $pat), "{}: got {err}", stringify!($edit));
        }};
    }
    expect!(|b| field(b, 0, b"NELF\0\0\0\0"), FormatError::BadMagic { .. });
    expect!(
        |b| field(b, 8, &2u16.to_le_bytes()),
        FormatError::UnsupportedVersion { major: 2, .. }
    );
    expect!(
        |b| field(b, 12, &512u32.to_le_bytes()),
        FormatError::InvalidHeader {
            field: "header_size",
            ..
        }
    );
    expect!(
        |b| field(b, 16, &100_000u32.to_le_bytes()),
        FormatError::TooManySections { .. }
    );
    // Bit 0 (signed density) is known; bit 1 is not.
    expect!(
        |b| field(b, 24, &3u64.to_le_bytes()),
        FormatError::UnsupportedFeature { flags: 2 }
    );
    expect!(|b| field(b, 32, &nan), FormatError::NonFinite { .. });
    expect!(|b| field(b, 80, &nan), FormatError::NonFinite { .. });
    expect!(
        |b| field(b, 80, &(-1.0f64).to_le_bytes()),
        FormatError::InvalidHeader { field: "grid", .. }
    );
    expect!(
        |b| field(b, 56, &5.0f64.to_le_bytes()),
        FormatError::InvalidHeader {
            field: "bbox_max",
            ..
        }
    );
    expect!(
        |b| field(b, 88, &0u32.to_le_bytes()),
        FormatError::InvalidHeader { field: "grid", .. }
    );
    expect!(
        |b| field(b, 88, &u32::MAX.to_le_bytes()),
        FormatError::InvalidHeader { field: "grid", .. }
    );
    expect!(
        |b| field(b, 100, &16u32.to_le_bytes()),
        FormatError::InvalidHeader {
            field: "brick_size",
            ..
        }
    );
    expect!(
        |b| field(b, 104, &u32::MAX.to_le_bytes()),
        FormatError::SectionLength { .. }
    );
    expect!(
        |b| field(b, 108, &0u32.to_le_bytes()),
        FormatError::InvalidHeader {
            field: "chunk_bricks",
            ..
        }
    );
    expect!(
        |b| field(b, 108, &u32::MAX.to_le_bytes()),
        FormatError::CountTooLarge { .. }
    );
    expect!(
        |b| field(b, 112, &f64::INFINITY.to_le_bytes()),
        FormatError::NonFinite { .. }
    );
    expect!(
        |b| field(b, 112, &(-1.0f64).to_le_bytes()),
        FormatError::InvalidHeader {
            field: "world_from_light",
            ..
        }
    );
    expect!(
        |b| field(b, 184, &16u16.to_le_bytes()),
        FormatError::InvalidHeader {
            field: "env_size",
            ..
        }
    );
    expect!(
        |b| field(b, 188, &0u32.to_le_bytes()),
        FormatError::BadRank { rank: 0, .. }
    );
    expect!(
        |b| field(b, 188, &385u32.to_le_bytes()),
        FormatError::BadRank { rank: 385, .. }
    );
    expect!(
        |b| field(b, 188, &5u32.to_le_bytes()),
        FormatError::SectionLength { .. }
    );
    expect!(
        |b| field(b, 192, &9u32.to_le_bytes()),
        FormatError::InvalidHeader {
            field: "coefficient_encoding",
            ..
        }
    );
    expect!(
        |b| field(b, 200, &(len + 8).to_le_bytes()),
        FormatError::Truncated { .. }
    );
    expect!(
        |b| field(b, 200, &(len - 8).to_le_bytes()),
        FormatError::FileSizeMismatch { .. }
    );

    // Section table entries.
    let brck = entry_offset(&bytes, KIND_BRICKS);
    let dens = entry_offset(&bytes, KIND_DENSITY);
    let pcab = entry_offset(&bytes, KIND_PCA);
    let coef = entry_offset(&bytes, KIND_COEFFICIENTS);
    let meta = entry_offset(&bytes, KIND_METADATA);
    expect!(
        |b| field(b, dens + 16, &(len.next_multiple_of(8) + 8).to_le_bytes()),
        FormatError::SectionOutOfBounds { .. }
    );
    expect!(
        |b| field(b, dens + 16, &8u64.to_le_bytes()),
        FormatError::SectionOutOfBounds { .. }
    );
    expect!(
        |b| field(b, dens + 16, &(u64::MAX - 7).to_le_bytes()),
        FormatError::SectionOutOfBounds { .. }
    );
    expect!(
        |b| field(b, dens + 24, &u64::MAX.to_le_bytes()),
        FormatError::SectionOutOfBounds { .. }
    );
    expect!(
        |b| {
            let brick_offset = b[brck + 16..brck + 24].to_vec();
            field(b, dens + 16, &brick_offset);
        },
        FormatError::SectionsOverlap { .. }
    );
    expect!(
        |b| {
            let o = u64::from_le_bytes(b[dens + 16..dens + 24].try_into().unwrap());
            field(b, dens + 16, &(o + 4).to_le_bytes());
        },
        FormatError::Misaligned { .. }
    );
    expect!(|b| field(b, pcab, b"BRCK"), FormatError::DuplicateSection { .. });
    expect!(
        |b| field(b, pcab, b"ZZZZ"),
        FormatError::UnknownRequiredSection { .. }
    );
    expect!(
        |b| field(b, coef + 32, &u64::MAX.to_le_bytes()),
        FormatError::SectionLength { .. }
    );
    expect!(
        |b| field(b, coef + 6, &1u16.to_le_bytes()),
        FormatError::BadCodec { .. }
    );
    expect!(
        |b| field(b, coef + 6, &9u16.to_le_bytes()),
        FormatError::BadCodec { .. }
    );
    expect!(
        |b| field(b, brck + 6, &1u16.to_le_bytes()),
        FormatError::BadCodec { .. }
    );
    expect!(
        |b| field(b, coef + 8, &3u32.to_le_bytes()),
        FormatError::BadCodec { .. }
    );
    expect!(
        |b| field(b, brck + 8, &6u32.to_le_bytes()),
        FormatError::BadCodec { .. }
    );
    expect!(
        |b| field(b, pcab + 32, &(1u64 << 40).to_le_bytes()),
        FormatError::SectionLength { .. }
    );
    expect!(
        |b| field(b, meta + 32, &(1u64 << 40).to_le_bytes()),
        FormatError::CountTooLarge { .. }
    );
    expect!(
        |b| field(b, brck + 40, &0u64.to_le_bytes()),
        FormatError::ChecksumMismatch { .. }
    );
}

#[test]
fn hostile_sections_give_named_errors() {
    let (asset, bytes) = encoded(CoefficientEncoding::U8Affine);
    let (f16_asset, f16_bytes) = encoded(CoefficientEncoding::F16);
    let chunk_bricks = 3;
    let check = |parts: FileParts, what: &str, want: &dyn Fn(&FormatError) -> bool| {
        let err = read_both(&parts.build(), what).unwrap_err();
        assert!(want(&err), "{what}: got {err}");
    };
    let raw_pca = |a: &Asset| -> Vec<u8> {
        a.pca
            .mean
            .iter()
            .chain(&a.pca.basis)
            .flat_map(|v| v.to_le_bytes())
            .collect()
    };

    // Missing required section.
    let mut p = FileParts::parse(&bytes);
    p.sections.retain(|(e, _)| e.kind != KIND_DENSITY);
    check(
        p,
        "missing DENS",
        &|e| matches!(e, FormatError::MissingSection { section } if section == "DENS"),
    );
    let mut p = FileParts::parse(&bytes);
    p.sections.retain(|(e, _)| e.kind != KIND_QUANT_PARAMS);
    check(
        p,
        "missing QPRM",
        &|e| matches!(e, FormatError::MissingSection { section } if section == "QPRM"),
    );

    // Unsorted bricks.
    let mut p = FileParts::parse(&bytes);
    let mut raw = p.section_mut(KIND_BRICKS).1.clone();
    raw[..12].rotate_left(6);
    let n = raw.len() as u64;
    p.replace(KIND_BRICKS, SectionCodec::Raw, 0, raw, n);
    check(p, "unsorted bricks", &|e| {
        matches!(e, FormatError::InvalidBricks(_))
    });

    // NaN in the PCA basis (stored raw).
    let mut p = FileParts::parse(&bytes);
    let mut raw = raw_pca(&asset);
    raw[4 * 400..4 * 401].copy_from_slice(&f32::NAN.to_le_bytes());
    let n = raw.len() as u64;
    p.replace(KIND_PCA, SectionCodec::Raw, 0, raw, n);
    check(
        p,
        "NaN basis",
        &|e| matches!(e, FormatError::NonFinite { what } if what.contains("PCA basis")),
    );

    // zstd garbage with a valid checksum, and zstd data of the wrong length.
    let mut p = FileParts::parse(&bytes);
    let n = raw_pca(&asset).len() as u64;
    p.replace(
        KIND_PCA,
        SectionCodec::Zstd,
        0,
        vec![0x28, 0xb5, 0x2f, 0xfd, 1, 2, 3, 4, 5],
        n,
    );
    check(
        p,
        "zstd garbage",
        &|e| matches!(e, FormatError::Zstd { what, .. } if what.contains("PCAB")),
    );
    let mut p = FileParts::parse(&bytes);
    let short = zstd::bulk::compress(&raw_pca(&asset)[..1000], 3).unwrap();
    p.replace(KIND_PCA, SectionCodec::Zstd, 0, short, n);
    check(p, "short zstd", &|e| matches!(e, FormatError::Zstd { .. }));
    let mut p = FileParts::parse(&bytes);
    let long = zstd::bulk::compress(&[raw_pca(&asset), vec![0; 64]].concat(), 3).unwrap();
    p.replace(KIND_PCA, SectionCodec::Zstd, 0, long, n);
    check(p, "long zstd", &|e| matches!(e, FormatError::Zstd { .. }));

    // Quantization parameters: NaN and negative scale.
    for (value, name) in [(f32::NAN, "NaN scale"), (-1.0, "negative scale")] {
        let mut p = FileParts::parse(&bytes);
        let mut raw = vec![0u8; 8 * 4];
        raw[..4].copy_from_slice(&value.to_le_bytes());
        p.replace(KIND_QUANT_PARAMS, SectionCodec::Raw, 0, raw, 32);
        check(p, name, &|e| {
            matches!(
                e,
                FormatError::NonFinite { .. } | FormatError::InvalidValue { .. }
            )
        });
    }

    // Densities: negative and NaN, in validly compressed chunks.
    for (bits, name) in [(0xBC00u16, "negative density"), (0x7E00, "NaN density")] {
        let mut p = FileParts::parse(&bytes);
        let mut raw: Vec<u8> = asset
            .density
            .iter()
            .flat_map(|d| d.to_bits().to_le_bytes())
            .collect();
        raw[2 * 700..2 * 701].copy_from_slice(&bits.to_le_bytes());
        let n = raw.len() as u64;
        p.replace(
            KIND_DENSITY,
            SectionCodec::ChunkedZstd,
            2,
            chunked_payload(&raw, 2 * BRICK_VOXELS, chunk_bricks, 2),
            n,
        );
        check(
            p,
            name,
            &|e| matches!(e, FormatError::NonFinite { what } | FormatError::InvalidValue { what, .. } if what.contains("voxel 700")),
        );
    }

    // NaN f16 coefficient.
    let mut p = FileParts::parse(&f16_bytes);
    let Coefficients::F16 { values, .. } = &f16_asset.coefficients else {
        unreachable!()
    };
    let mut raw: Vec<u8> = values.iter().flat_map(|v| v.to_bits().to_le_bytes()).collect();
    raw[2 * 4 * 600 + 2..2 * 4 * 600 + 4].copy_from_slice(&0x7C00u16.to_le_bytes());
    let n = raw.len() as u64;
    p.replace(
        KIND_COEFFICIENTS,
        SectionCodec::ChunkedZstd,
        8,
        chunked_payload(&raw, 8 * BRICK_VOXELS, chunk_bricks, 8),
        n,
    );
    check(
        p,
        "inf coefficient",
        &|e| matches!(e, FormatError::NonFinite { what } if what.contains("voxel 600 component 1")),
    );

    // A QPRM section in an f16 file.
    let mut p = FileParts::parse(&f16_bytes);
    let qprm = FileParts::parse(&bytes).section_mut(KIND_QUANT_PARAMS).clone();
    p.sections.push(qprm);
    check(p, "QPRM with f16", &|e| {
        matches!(
            e,
            FormatError::InvalidHeader {
                field: "coefficient_encoding",
                ..
            }
        )
    });

    // Chunk tables: a lying chunk length, a gap, and an implausibly small chunk.
    let coef = |p: &mut FileParts| p.section_mut(KIND_COEFFICIENTS).1.clone();
    let mut p = FileParts::parse(&bytes);
    let mut table = coef(&mut p);
    table[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
    let n = asset.coefficients.len() as u64;
    p.replace(KIND_COEFFICIENTS, SectionCodec::ChunkedZstd, 4, table, n);
    check(
        p,
        "chunk length",
        &|e| matches!(e, FormatError::BadChunkTable { section, .. } if section == "COEF"),
    );
    let mut p = FileParts::parse(&bytes);
    let mut table = coef(&mut p);
    let first = u64::from_le_bytes(table[..8].try_into().unwrap());
    table[..8].copy_from_slice(&(first + 1).to_le_bytes());
    p.replace(KIND_COEFFICIENTS, SectionCodec::ChunkedZstd, 4, table, n);
    check(p, "chunk gap", &|e| {
        matches!(e, FormatError::BadChunkTable { .. })
    });
    let mut p = FileParts::parse(&bytes);
    let chunks = asset.bricks.len().div_ceil(chunk_bricks);
    let mut table = Vec::new();
    // Empty chunks that claim to decode to whole bricks.
    for _ in 0..chunks {
        table.extend_from_slice(&((24 * chunks) as u64).to_le_bytes());
        table.extend_from_slice(&0u64.to_le_bytes());
        table.extend_from_slice(&nelf_format::spec::checksum(&[]).to_le_bytes());
    }
    p.replace(KIND_COEFFICIENTS, SectionCodec::ChunkedZstd, 4, table, n);
    check(p, "empty chunk", &|e| {
        matches!(e, FormatError::ImplausibleLength { .. })
    });

    // Metadata: not JSON, not an object.
    for (text, name) in [(&b"{not json"[..], "bad JSON"), (&b"[1, 2]"[..], "JSON array")] {
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_METADATA,
            SectionCodec::Raw,
            0,
            text.to_vec(),
            text.len() as u64,
        );
        check(p, name, &|e| {
            matches!(e, FormatError::Json(_) | FormatError::MetadataNotObject { .. })
        });
    }

    // Non-zero padding between sections.
    let mut b = bytes.clone();
    let p = FileParts::parse(&b);
    let mut gaps: Vec<(u64, u64)> = p
        .sections
        .iter()
        .map(|(e, _)| (e.offset, e.offset + e.stored_length))
        .collect();
    gaps.sort_unstable();
    let gap = gaps.windows(2).find(|w| w[1].0 > w[0].1).map(|w| w[0].1).unwrap();
    b[gap as usize] = 1;
    assert!(matches!(read_both(&b, "padding"), Err(FormatError::NonZeroPadding { offset }) if offset == gap));
}

#[test]
fn mini_fuzzer_never_panics() {
    let mut rng = Pcg64::seed_from_u64(0x5eed);
    let files: Vec<Vec<u8>> = [CoefficientEncoding::U8Affine, CoefficientEncoding::F16]
        .into_iter()
        .map(|e| encoded(e).1)
        .collect();
    let extremes: [u64; 8] = [
        0,
        1,
        7,
        255,
        0xFFFF,
        u64::from(u32::MAX),
        u64::MAX,
        f64::NAN.to_bits(),
    ];
    let mut accepted = 0;
    for iteration in 0..1500 {
        let mut b = files[iteration % 2].clone();
        let table_end = HEADER_SIZE + 6 * SECTION_ENTRY_SIZE;
        let mutations = rng.random_range(1..4);
        for _ in 0..mutations {
            match rng.random_range(0..5) {
                0 => {
                    let at = rng.random_range(0..b.len());
                    b[at] = rng.random();
                }
                1 => {
                    // An extreme value in an aligned header/table field.
                    let at = rng.random_range(0..table_end.min(b.len()) / 4) * 4;
                    let v = extremes[rng.random_range(0..extremes.len())].to_le_bytes();
                    let width = if rng.random_bool(0.5) { 4 } else { 8 };
                    let end = (at + width).min(b.len());
                    b[at..end].copy_from_slice(&v[..end - at]);
                }
                2 => {
                    let cut = rng.random_range(0..b.len());
                    b.truncate(cut);
                }
                3 => {
                    let at = rng.random_range(0..b.len());
                    b[at] ^= 1 << rng.random_range(0..8);
                }
                _ => {
                    // Insert or delete a run of bytes.
                    let at = rng.random_range(0..b.len());
                    if rng.random_bool(0.5) {
                        let run: Vec<u8> = (0..rng.random_range(1..64)).map(|_| rng.random()).collect();
                        b.splice(at..at, run);
                    } else {
                        let end = (at + rng.random_range(1..64)).min(b.len());
                        b.drain(at..end);
                    }
                }
            }
            if b.is_empty() {
                break;
            }
        }
        // Half the time, re-sign so the mutation reaches the field checks.
        if rng.random_bool(0.5) && b.len() >= HEADER_SIZE {
            resign(&mut b);
        }
        if let Ok(asset) = read_both(&b, &format!("fuzz iteration {iteration}")) {
            // Only harmless mutations survive; what they give must be a valid asset.
            asset.validate().unwrap();
            encode_asset(&asset, &WriteOptions::default()).unwrap();
            accepted += 1;
        }
    }
    eprintln!("mini-fuzzer: {accepted} of 1500 mutated files were accepted");
    assert!(accepted < 150, "{accepted} of 1500 mutations were accepted");
}

#[test]
fn section_entry_layout_is_stable() {
    // The 48-byte entry layout is part of the spec: check one entry byte by byte.
    let e = SectionEntry {
        kind: *b"DENS",
        required: true,
        codec: SectionCodec::ChunkedZstd,
        shuffle: 2,
        offset: 0x0102_0304_0506_0708,
        stored_length: 9,
        raw_length: 10,
        checksum: 11,
    };
    let b = e.to_bytes();
    assert_eq!(&b[0..4], b"DENS");
    assert_eq!(&b[4..8], &[1, 0, 2, 0]);
    assert_eq!(&b[8..12], &[2, 0, 0, 0]);
    assert_eq!(&b[16..24], &[8, 7, 6, 5, 4, 3, 2, 1]);
    assert_eq!(b[24], 9);
    assert_eq!(b[32], 10);
    assert_eq!(b[40], 11);
}
