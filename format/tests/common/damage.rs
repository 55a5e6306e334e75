//! The damage generator: every damaged and hostile `.nelf` file the tests feed to a
//! reader, each with what the reader must answer. `damage.rs` checks the Rust reader
//! against these cases; `c_reader.rs` runs the same cases through the C reader
//! (`include/nelf.h`) and checks it fails with the same error.
//!
//! Cases: truncations at every boundary and at random offsets, bit flips in every
//! section and in the header and table, hand-made hostile headers and sections (the
//! view-dependent parts of format 1.2, `VDEP`/`VCOF`, and 1.3, `VREF`/`VRCO`, and the fine
//! density of 1.4, `DNSF` and the header's `fine_density_factor`, included), and a seeded
//! mini-fuzzer (truncations, bit flips, extreme header values, insertions
//! and deletions). Every generator is deterministic (fixed seeds).

use super::{FileParts, boundaries, chunked_payload, resign, small_asset, with_fine_density};
use nelf_format::conventions::{LT_DIM, VIEW_HARMONICS};
use nelf_format::spec::{
    BRICK_VOXELS, HEADER_SIZE, KIND_BRICKS, KIND_COEFFICIENTS, KIND_DENSITY, KIND_FINE_DENSITY,
    KIND_METADATA, KIND_PCA, KIND_QUANT_PARAMS, KIND_REFLECTION, KIND_REFLECTION_VALUES, KIND_VIEW,
    KIND_VIEW_COEFFICIENTS, REFLECTION_BYTES_PER_BRICK, SECTION_ENTRY_SIZE, SectionCodec,
};
use nelf_format::synthetic::{SyntheticField, synthetic_reflection, synthetic_view};
use nelf_format::{
    Asset, CoefficientEncoding, Coefficients, FormatError, ViewDependence, WriteOptions, encode_asset,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// What a reader must answer for a damaged file.
pub enum Expect {
    /// An error for which the predicate holds.
    Error(Box<dyn Fn(&FormatError) -> bool>),
    /// Any answer: a mutation may happen to leave the file valid (mini-fuzzer).
    Anything,
}

impl Expect {
    /// Any error at all.
    pub fn any_error() -> Self {
        Self::Error(Box::new(|_| true))
    }

    /// An error for which `f` holds.
    pub fn error(f: impl Fn(&FormatError) -> bool + 'static) -> Self {
        Self::Error(Box::new(f))
    }
}

/// One damaged file.
pub struct Damaged {
    /// What was done to it (for messages).
    pub what: String,
    /// Its bytes.
    pub bytes: Vec<u8>,
    /// What a reader must answer.
    pub expect: Expect,
}

impl Damaged {
    fn new(what: impl Into<String>, bytes: Vec<u8>, expect: Expect) -> Self {
        Self {
            what: what.into(),
            bytes,
            expect,
        }
    }
}

/// Bricks per chunk of the files the generators damage (several chunks per section).
pub const CHUNK_BRICKS: usize = 3;

/// Write options of the files the generators damage.
pub fn options() -> WriteOptions {
    WriteOptions {
        chunk_bricks: CHUNK_BRICKS as u32,
        ..WriteOptions::default()
    }
}

/// The intact asset and file every generator starts from (rank 4, about 8 bricks).
pub fn encoded(encoding: CoefficientEncoding) -> (Asset, Vec<u8>) {
    let asset = small_asset(encoding, 4, 21);
    let bytes = encode_asset(&asset, &options()).unwrap().0;
    (asset, bytes)
}

const ENCODINGS: [CoefficientEncoding; 2] = [CoefficientEncoding::U8Affine, CoefficientEncoding::F16];

/// The other encoding.
fn other(encoding: CoefficientEncoding) -> CoefficientEncoding {
    match encoding {
        CoefficientEncoding::U8Affine => CoefficientEncoding::F16,
        CoefficientEncoding::F16 => CoefficientEncoding::U8Affine,
    }
}

/// The intact view-dependent (format 1.2) asset and file: the PCA part in the other
/// encoding (so that both mixes are covered), a view part of 3 lobes × rank 2 whose
/// coefficients are stored with `encoding`.
pub fn encoded_view(encoding: CoefficientEncoding) -> (Asset, Vec<u8>) {
    let mut asset = small_asset(other(encoding), 4, 21);
    asset.view = Some(synthetic_view(&asset, 3, 2, encoding, 5).unwrap());
    let bytes = encode_asset(&asset, &options()).unwrap().0;
    (asset, bytes)
}

/// The intact reflection (format 1.3) asset and file: the PCA part with `encoding`
/// (rank 4, about 8 bricks), a reflection part of 5 eyes and lobe exponent 20.
pub fn encoded_reflection(encoding: CoefficientEncoding) -> (Asset, Vec<u8>) {
    let mut asset = small_asset(encoding, 4, 21);
    asset.reflection = Some(synthetic_reflection(&asset, 20.0, 5).unwrap());
    let bytes = encode_asset(&asset, &options()).unwrap().0;
    (asset, bytes)
}

/// The intact fine-density (format 1.4) asset and file: the PCA part with `encoding`
/// (rank 4, about 8 bricks) and a fine density at factor `factor` (2 or 4) without
/// negative values (some −0).
pub fn encoded_fine(encoding: CoefficientEncoding, factor: u32) -> (Asset, Vec<u8>) {
    let asset = with_fine_density(small_asset(encoding, 4, 21), factor, false);
    let bytes = encode_asset(&asset, &options()).unwrap().0;
    (asset, bytes)
}

/// Every intact file the generators damage, named: both encodings, without a
/// view-dependent part, with a harmonic one, with a reflection part and with a fine
/// density (factor 2).
fn intact_files() -> Vec<(String, Vec<u8>)> {
    ENCODINGS
        .into_iter()
        .flat_map(|e| {
            [
                (format!("{e:?}"), encoded(e).1),
                (format!("{e:?} view"), encoded_view(e).1),
                (format!("{e:?} reflection"), encoded_reflection(e).1),
                (format!("{e:?} fine density"), encoded_fine(e, 2).1),
            ]
        })
        .collect()
}

/// Truncations at (and next to) every boundary and at 200 random offsets, per encoding:
/// each must be reported as [`FormatError::Truncated`].
pub fn truncations() -> Vec<Damaged> {
    let mut rng = Pcg64::seed_from_u64(1);
    let mut out = Vec::new();
    for (name, bytes) in intact_files() {
        let mut cuts: Vec<usize> = boundaries(&bytes)
            .into_iter()
            .flat_map(|b| [b.saturating_sub(1), b, b + 1])
            .filter(|&c| c < bytes.len())
            .collect();
        cuts.extend((0..200).map(|_| rng.random_range(0..bytes.len())));
        for cut in cuts {
            out.push(Damaged::new(
                format!("{name} truncation at {cut} of {}", bytes.len()),
                bytes[..cut].to_vec(),
                Expect::error(|e| matches!(e, FormatError::Truncated { .. })),
            ));
        }
    }
    out
}

/// Single bit flips: 40 in every section (the error must name the section), every
/// bit position of the header and table (some bit per byte), and 300 anywhere; in the
/// view-dependent and reflection files, 40 in every section. (In the files without a
/// fine density, a flip in header bytes 196..200 makes `fine_density_factor` 2 or 4 or
/// invalid; in the fine-density file, invalid.)
pub fn bit_flips() -> Vec<Damaged> {
    let mut rng = Pcg64::seed_from_u64(2);
    let mut out = Vec::new();
    for (file, bytes) in intact_files() {
        let parts = FileParts::parse(&bytes);
        for (entry, _) in &parts.sections {
            for _ in 0..40 {
                let at = entry.offset as usize + rng.random_range(0..entry.stored_length as usize);
                let mut damaged = bytes.clone();
                damaged[at] ^= 1 << rng.random_range(0..8);
                let name = entry.name();
                out.push(Damaged::new(
                    format!("{file} flip at {at} in {name}"),
                    damaged,
                    Expect::error(move |e| e.to_string().contains(&name)),
                ));
            }
        }
        if file.contains("view") || file.contains("reflection") {
            continue;
        }
        let encoding = file;
        // Header and table: caught by the header checksum (or earlier field checks).
        let table_end = HEADER_SIZE + parts.sections.len() * SECTION_ENTRY_SIZE;
        for at in 0..table_end {
            let mut damaged = bytes.clone();
            damaged[at] ^= 1 << (at % 8);
            out.push(Damaged::new(
                format!("{encoding} flip at {at} in header/table"),
                damaged,
                Expect::any_error(),
            ));
        }
        // Anywhere at all, padding included.
        for _ in 0..300 {
            let at = rng.random_range(0..bytes.len());
            let mut damaged = bytes.clone();
            damaged[at] ^= 1 << rng.random_range(0..8);
            out.push(Damaged::new(
                format!("{encoding} flip at {at}"),
                damaged,
                Expect::any_error(),
            ));
        }
    }
    out
}

fn field(bytes: &mut [u8], offset: usize, value: &[u8]) {
    bytes[offset..offset + value.len()].copy_from_slice(value);
}

/// Offset of the table entry of section `kind`.
fn entry_offset(bytes: &[u8], kind: [u8; 4]) -> usize {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    (0..count)
        .map(|i| HEADER_SIZE + i * SECTION_ENTRY_SIZE)
        .find(|&o| bytes[o..o + 4] == kind)
        .unwrap()
}

/// Hand-made hostile header fields and section-table entries, re-signed so that they
/// reach the field checks, each with the error it must give.
pub fn hostile_headers() -> Vec<Damaged> {
    let (_, bytes) = encoded(CoefficientEncoding::U8Affine);
    let nan = f64::NAN.to_le_bytes();
    let len = bytes.len() as u64;
    let mut out = Vec::new();
    macro_rules! expect {
        ($edit:expr, $pat:pat) => {{
            let mut b = bytes.clone();
            let edit: &dyn Fn(&mut Vec<u8>) = &$edit;
            edit(&mut b);
            resign(&mut b);
            out.push(Damaged::new(
                format!("hostile header {}", stringify!($edit)),
                b,
                Expect::error(|e| matches!(e, $pat)),
            ));
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
    out
}

/// Hand-made hostile sections with valid checksums (missing sections, unsorted bricks,
/// NaNs, bad zstd, bad quantization parameters, bad densities and coefficients, bad
/// chunk tables, bad metadata, non-zero padding), each with the error it must give.
pub fn hostile_sections() -> Vec<Damaged> {
    let (asset, bytes) = encoded(CoefficientEncoding::U8Affine);
    let (f16_asset, f16_bytes) = encoded(CoefficientEncoding::F16);
    let mut out = Vec::new();
    let mut push = |parts: FileParts, what: &str, expect: Expect| {
        out.push(Damaged::new(what, parts.build(), expect));
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
    push(
        p,
        "missing DENS",
        Expect::error(|e| matches!(e, FormatError::MissingSection { section } if section == "DENS")),
    );
    let mut p = FileParts::parse(&bytes);
    p.sections.retain(|(e, _)| e.kind != KIND_QUANT_PARAMS);
    push(
        p,
        "missing QPRM",
        Expect::error(|e| matches!(e, FormatError::MissingSection { section } if section == "QPRM")),
    );

    // Unsorted bricks.
    let mut p = FileParts::parse(&bytes);
    let mut raw = p.section_mut(KIND_BRICKS).1.clone();
    raw[..12].rotate_left(6);
    let n = raw.len() as u64;
    p.replace(KIND_BRICKS, SectionCodec::Raw, 0, raw, n);
    push(
        p,
        "unsorted bricks",
        Expect::error(|e| matches!(e, FormatError::InvalidBricks(_))),
    );

    // NaN in the PCA basis (stored raw).
    let mut p = FileParts::parse(&bytes);
    let mut raw = raw_pca(&asset);
    raw[4 * 400..4 * 401].copy_from_slice(&f32::NAN.to_le_bytes());
    let n = raw.len() as u64;
    p.replace(KIND_PCA, SectionCodec::Raw, 0, raw, n);
    push(
        p,
        "NaN basis",
        Expect::error(|e| matches!(e, FormatError::NonFinite { what } if what.contains("PCA basis"))),
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
    push(
        p,
        "zstd garbage",
        Expect::error(|e| matches!(e, FormatError::Zstd { what, .. } if what.contains("PCAB"))),
    );
    let mut p = FileParts::parse(&bytes);
    let short = zstd::bulk::compress(&raw_pca(&asset)[..1000], 3).unwrap();
    p.replace(KIND_PCA, SectionCodec::Zstd, 0, short, n);
    push(
        p,
        "short zstd",
        Expect::error(|e| matches!(e, FormatError::Zstd { .. })),
    );
    let mut p = FileParts::parse(&bytes);
    let long = zstd::bulk::compress(&[raw_pca(&asset), vec![0; 64]].concat(), 3).unwrap();
    p.replace(KIND_PCA, SectionCodec::Zstd, 0, long, n);
    push(
        p,
        "long zstd",
        Expect::error(|e| matches!(e, FormatError::Zstd { .. })),
    );

    // Quantization parameters: NaN and negative scale.
    for (value, name) in [(f32::NAN, "NaN scale"), (-1.0, "negative scale")] {
        let mut p = FileParts::parse(&bytes);
        let mut raw = vec![0u8; 8 * 4];
        raw[..4].copy_from_slice(&value.to_le_bytes());
        p.replace(KIND_QUANT_PARAMS, SectionCodec::Raw, 0, raw, 32);
        push(
            p,
            name,
            Expect::error(|e| {
                matches!(
                    e,
                    FormatError::NonFinite { .. } | FormatError::InvalidValue { .. }
                )
            }),
        );
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
            chunked_payload(&raw, 2 * BRICK_VOXELS, CHUNK_BRICKS, 2),
            n,
        );
        push(
            p,
            name,
            Expect::error(
                |e| matches!(e, FormatError::NonFinite { what } | FormatError::InvalidValue { what, .. } if what.contains("voxel 700")),
            ),
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
        chunked_payload(&raw, 8 * BRICK_VOXELS, CHUNK_BRICKS, 8),
        n,
    );
    push(
        p,
        "inf coefficient",
        Expect::error(
            |e| matches!(e, FormatError::NonFinite { what } if what.contains("voxel 600 component 1")),
        ),
    );

    // A QPRM section in an f16 file.
    let mut p = FileParts::parse(&f16_bytes);
    let qprm = FileParts::parse(&bytes).section_mut(KIND_QUANT_PARAMS).clone();
    p.sections.push(qprm);
    push(
        p,
        "QPRM with f16",
        Expect::error(|e| {
            matches!(
                e,
                FormatError::InvalidHeader {
                    field: "coefficient_encoding",
                    ..
                }
            )
        }),
    );

    // Chunk tables: a lying chunk length, a gap, and an implausibly small chunk.
    let coef = |p: &mut FileParts| p.section_mut(KIND_COEFFICIENTS).1.clone();
    let mut p = FileParts::parse(&bytes);
    let mut table = coef(&mut p);
    table[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
    let n = asset.coefficients.len() as u64;
    p.replace(KIND_COEFFICIENTS, SectionCodec::ChunkedZstd, 4, table, n);
    push(
        p,
        "chunk length",
        Expect::error(|e| matches!(e, FormatError::BadChunkTable { section, .. } if section == "COEF")),
    );
    let mut p = FileParts::parse(&bytes);
    let mut table = coef(&mut p);
    let first = u64::from_le_bytes(table[..8].try_into().unwrap());
    table[..8].copy_from_slice(&(first + 1).to_le_bytes());
    p.replace(KIND_COEFFICIENTS, SectionCodec::ChunkedZstd, 4, table, n);
    push(
        p,
        "chunk gap",
        Expect::error(|e| matches!(e, FormatError::BadChunkTable { .. })),
    );
    let mut p = FileParts::parse(&bytes);
    let chunks = asset.bricks.len().div_ceil(CHUNK_BRICKS);
    let mut table = Vec::new();
    // Empty chunks that claim to decode to whole bricks.
    for _ in 0..chunks {
        table.extend_from_slice(&((24 * chunks) as u64).to_le_bytes());
        table.extend_from_slice(&0u64.to_le_bytes());
        table.extend_from_slice(&nelf_format::spec::checksum(&[]).to_le_bytes());
    }
    p.replace(KIND_COEFFICIENTS, SectionCodec::ChunkedZstd, 4, table, n);
    push(
        p,
        "empty chunk",
        Expect::error(|e| matches!(e, FormatError::ImplausibleLength { .. })),
    );

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
        push(
            p,
            name,
            Expect::error(|e| matches!(e, FormatError::Json(_) | FormatError::MetadataNotObject { .. })),
        );
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
    out.push(Damaged::new(
        "padding",
        b,
        Expect::error(move |e| matches!(e, FormatError::NonZeroPadding { offset } if *offset == gap)),
    ));
    out
}

/// Number of files [`mutations`] makes.
pub const MUTATIONS: usize = 1500;

/// The mini-fuzzer: 1500 files with one to three random mutations each (byte
/// overwrites, extreme values in header and table fields, truncations, bit flips,
/// insertions and deletions), half of them re-signed so that the mutation reaches the
/// field checks. A few mutations are harmless, so any answer is allowed.
pub fn mutations() -> Vec<Damaged> {
    let mut rng = Pcg64::seed_from_u64(0x5eed);
    let files: Vec<Vec<u8>> = intact_files().into_iter().map(|(_, bytes)| bytes).collect();
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
    let mut out = Vec::with_capacity(MUTATIONS);
    for iteration in 0..MUTATIONS {
        let mut b = files[iteration % files.len()].clone();
        let sections = u32::from_le_bytes(b[16..20].try_into().unwrap()) as usize;
        let table_end = HEADER_SIZE + sections * SECTION_ENTRY_SIZE;
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
        out.push(Damaged::new(
            format!("fuzz iteration {iteration}"),
            b,
            Expect::Anything,
        ));
    }
    out
}

/// One bit flipped in every byte of `VDEP` and of `VCOF` (chunk table and chunks) of a
/// one-brick view-dependent file, per encoding: each must be refused naming the section.
pub fn view_byte_flips() -> Vec<Damaged> {
    let mut out = Vec::new();
    for encoding in ENCODINGS {
        let field = SyntheticField::new(1, 3);
        let mut asset = field.asset(2, other(encoding)).unwrap();
        asset.view = Some(synthetic_view(&asset, 2, 1, encoding, 8).unwrap());
        let bytes = encode_asset(&asset, &options()).unwrap().0;
        let parts = FileParts::parse(&bytes);
        for (entry, _) in &parts.sections {
            if entry.kind != KIND_VIEW && entry.kind != KIND_VIEW_COEFFICIENTS {
                continue;
            }
            for i in 0..entry.stored_length as usize {
                let at = entry.offset as usize + i;
                let mut damaged = bytes.clone();
                damaged[at] ^= 1 << (i % 8);
                let name = entry.name();
                out.push(Damaged::new(
                    format!("{encoding:?} view flip at {at} in {name}"),
                    damaged,
                    Expect::error(move |e| e.to_string().contains(&name)),
                ));
            }
        }
    }
    out
}

/// The decoded bytes of a `VDEP` section: header (`J`, `K_v`, encoding, reserved) and
/// `f32` values.
fn vdep_bytes(lobes: u32, rank: u32, encoding: u32, values: &[f32]) -> Vec<u8> {
    let mut out: Vec<u8> = [lobes, rank, encoding, 0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    out.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    out
}

/// The `f32` values of `VDEP` for `view`: lobes, basis, then (8-bit) the parameters.
fn vdep_values(view: &ViewDependence) -> Vec<f32> {
    let mut values: Vec<f32> = view.lobes.iter().chain(&view.basis).copied().collect();
    if let Coefficients::U8Affine { scale, offset, .. } = &view.coefficients {
        values.extend(scale.iter().zip(offset).flat_map(|(s, o)| [*s, *o]));
    }
    values
}

/// Hand-made hostile view-dependent sections (format 1.2) with valid checksums: one of
/// the two sections without the other, `VDEP` sizes out of range or disagreeing with its
/// length, non-finite lobes, basis and parameters, a `VCOF` that disagrees with `VDEP`,
/// bad `VCOF` chunk tables and values, bad codecs, each with the error it must give.
pub fn hostile_view_sections() -> Vec<Damaged> {
    let mut out = Vec::new();
    let mut push = |parts: FileParts, what: &str, expect: Expect| {
        out.push(Damaged::new(
            format!("hostile view: {what}"),
            parts.build(),
            expect,
        ));
    };
    let invalid_view = |needle: &'static str| {
        Expect::error(move |e| matches!(e, FormatError::InvalidView(m) if m.contains(needle)))
    };
    for encoding in ENCODINGS {
        let (asset, bytes) = encoded_view(encoding);
        let view = asset.view.as_ref().unwrap();
        let code = encoding.to_u32();
        let values = vdep_values(view);
        let with_vdep = |raw: Vec<u8>| {
            let mut p = FileParts::parse(&bytes);
            let n = raw.len() as u64;
            p.replace(KIND_VIEW, SectionCodec::Raw, 0, raw, n);
            p
        };

        // One section without the other.
        for (gone, name) in [
            (KIND_VIEW, "VCOF without VDEP"),
            (KIND_VIEW_COEFFICIENTS, "VDEP without VCOF"),
        ] {
            let mut p = FileParts::parse(&bytes);
            p.sections.retain(|(e, _)| e.kind != gone);
            push(p, name, invalid_view("without section"));
        }

        // VDEP's sizes.
        for (lobes, rank, enc, name) in [
            (0, 2, code, "no lobe"),
            (VIEW_HARMONICS as u32 + 1, 1, code, "too many lobes"),
            (3, 0, code, "rank 0"),
            (3, 129, code, "over 384 coefficients per voxel"),
            (3, 2, 3, "unknown encoding"),
        ] {
            push(
                with_vdep(vdep_bytes(lobes, rank, enc, &values)),
                name,
                invalid_view("section VDEP"),
            );
        }
        let mut long = values.clone();
        long.push(0.5);
        push(
            with_vdep(vdep_bytes(3, 2, code, &long)),
            "VDEP too long",
            invalid_view("decoded bytes"),
        );
        push(
            with_vdep(vdep_bytes(3, 2, code, &values[..values.len() - 2])),
            "VDEP too short",
            invalid_view("decoded bytes"),
        );
        push(
            with_vdep(vec![3, 0, 0, 0, 2, 0, 0, 0]),
            "VDEP shorter than its header",
            invalid_view("header"),
        );
        // The reserved field is ignored.
        let mut reserved = vdep_bytes(3, 2, code, &values);
        reserved[12] = 0xAB;
        push(
            with_vdep(reserved),
            "reserved VDEP field (accepted)",
            Expect::Anything,
        );

        // Non-finite and negative values, named.
        let lobe_count = 3 * VIEW_HARMONICS;
        for (at, value, name, needle) in [
            (5, f32::NAN, "NaN lobe", "lobe 0 weight 5"),
            (
                lobe_count + LT_DIM + 7,
                f32::INFINITY,
                "infinite basis",
                "basis vector 1 element 7",
            ),
        ] {
            let mut v = values.clone();
            v[at] = value;
            push(
                with_vdep(vdep_bytes(3, 2, code, &v)),
                name,
                Expect::error(
                    move |e| matches!(e, FormatError::NonFinite { what } if what.contains("VDEP") && what.contains(needle)),
                ),
            );
        }
        if encoding == CoefficientEncoding::U8Affine {
            let params = lobe_count + 2 * LT_DIM;
            // (offset 2 + 255 · 2e36 overflows f32; values chosen to print alike in C and Rust.)
            for (at, value, name) in [
                (params + 2 * 4, f32::NAN, "NaN VDEP scale"),
                (params + 2 * 4, -0.5, "negative VDEP scale"),
                (params + 2 * 3, 2e36, "VDEP offset + 255 scale overflows"),
            ] {
                let mut v = values.clone();
                v[at] = value;
                v[params + 2 * 3 + 1] = 2.0;
                v[params + 2 * 4 + 1] = 2.0;
                push(
                    with_vdep(vdep_bytes(3, 2, code, &v)),
                    name,
                    Expect::error(|e| {
                        matches!(
                            e,
                            FormatError::NonFinite { what } | FormatError::InvalidValue { what, .. }
                                if what.contains("section VDEP component")
                        )
                    }),
                );
            }
        }

        // A VDEP whose size disagrees with VCOF's length (2 lobes instead of 3).
        let mut fewer = values[VIEW_HARMONICS..].to_vec();
        if encoding == CoefficientEncoding::U8Affine {
            fewer.truncate(fewer.len() - 4);
        }
        push(
            with_vdep(vdep_bytes(2, 2, code, &fewer)),
            "VDEP says 2 lobes, VCOF holds 3",
            Expect::error(|e| matches!(e, FormatError::SectionLength { section, .. } if section == "VCOF")),
        );

        // VCOF's entry and chunk table.
        let vcof = |p: &mut FileParts| p.section_mut(KIND_VIEW_COEFFICIENTS).clone();
        let mut p = FileParts::parse(&bytes);
        let (entry, table) = vcof(&mut p);
        let mut lying = table.clone();
        lying[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
        p.replace(
            KIND_VIEW_COEFFICIENTS,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            lying,
            entry.raw_length,
        );
        push(
            p,
            "VCOF chunk length",
            Expect::error(|e| matches!(e, FormatError::BadChunkTable { section, .. } if section == "VCOF")),
        );
        let mut p = FileParts::parse(&bytes);
        let chunks = asset.bricks.len().div_ceil(CHUNK_BRICKS);
        let mut empty = Vec::new();
        for _ in 0..chunks {
            empty.extend_from_slice(&((24 * chunks) as u64).to_le_bytes());
            empty.extend_from_slice(&0u64.to_le_bytes());
            empty.extend_from_slice(&nelf_format::spec::checksum(&[]).to_le_bytes());
        }
        p.replace(
            KIND_VIEW_COEFFICIENTS,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            empty,
            entry.raw_length,
        );
        push(
            p,
            "VCOF empty chunks",
            Expect::error(
                |e| matches!(e, FormatError::ImplausibleLength { what, .. } if what.contains("VCOF")),
            ),
        );
        for (field, value, name) in [
            (32, entry.raw_length + 512, "VCOF raw length"),
            (8, 5, "VCOF shuffle"),
        ] {
            let mut p = FileParts::parse(&bytes);
            let (e, _) = p.section_mut(KIND_VIEW_COEFFICIENTS);
            if field == 32 {
                e.raw_length = value;
            } else {
                e.shuffle = value as u32;
            }
            push(
                p,
                name,
                Expect::error(|e| {
                    matches!(
                        e,
                        FormatError::SectionLength { section, .. } | FormatError::BadCodec { section, .. }
                            if section == "VCOF"
                    )
                }),
            );
        }
        for (kind, codec, name) in [
            (KIND_VIEW_COEFFICIENTS, SectionCodec::Zstd, "VCOF codec 1"),
            (KIND_VIEW, SectionCodec::ChunkedZstd, "VDEP codec 2"),
        ] {
            let mut p = FileParts::parse(&bytes);
            p.section_mut(kind).0.codec = codec;
            push(
                p,
                name,
                Expect::error(
                    |e| matches!(e, FormatError::BadCodec { section, .. } if section.starts_with('V')),
                ),
            );
        }
        let mut p = FileParts::parse(&bytes);
        p.section_mut(KIND_VIEW).0.raw_length = 1 << 40;
        push(p, "VDEP huge", invalid_view("largest possible"));

        // A non-finite f16 view coefficient.
        if let Coefficients::F16 { values: stored, .. } = &view.coefficients {
            let mut raw: Vec<u8> = stored.iter().flat_map(|v| v.to_bits().to_le_bytes()).collect();
            let at = 2 * (6 * 600 + 1);
            raw[at..at + 2].copy_from_slice(&0x7E00u16.to_le_bytes());
            let mut p = FileParts::parse(&bytes);
            let n = raw.len() as u64;
            p.replace(
                KIND_VIEW_COEFFICIENTS,
                SectionCodec::ChunkedZstd,
                12,
                chunked_payload(&raw, 12 * BRICK_VOXELS, CHUNK_BRICKS, 12),
                n,
            );
            push(
                p,
                "NaN view coefficient",
                Expect::error(
                    |e| matches!(e, FormatError::NonFinite { what } if what.contains("VCOF voxel 600 component 1")),
                ),
            );
        }

        // VCOF chunks over 4 MiB: VDEP claims 384 f16 coefficients per voxel with 16-brick chunks.
        let mut p = FileParts::parse(&encode_asset(&asset, &options_with(16)).unwrap().0);
        let big = ViewDependence {
            lobes: vec![0.25; 8 * VIEW_HARMONICS],
            basis: vec![0.0; 48 * LT_DIM],
            coefficients: Coefficients::F16 {
                rank: 384,
                values: Vec::new(),
            },
        };
        let raw = vdep_bytes(8, 48, 2, &vdep_values(&big));
        let n = raw.len() as u64;
        p.replace(KIND_VIEW, SectionCodec::Raw, 0, raw, n);
        let (e, _) = p.section_mut(KIND_VIEW_COEFFICIENTS);
        e.raw_length = (asset.bricks.len() * BRICK_VOXELS * 384 * 2) as u64;
        e.shuffle = 0;
        push(
            p,
            "VCOF chunks over 4 MiB",
            Expect::error(
                |e| matches!(e, FormatError::CountTooLarge { what, .. } if what.contains("VCOF chunk")),
            ),
        );
    }
    out
}

/// One bit flipped in every byte of `VREF` and of `VRCO` (chunk table and chunk) of a
/// one-brick reflection file, per encoding of the PCA part: each must be refused naming
/// the section.
pub fn reflection_byte_flips() -> Vec<Damaged> {
    let mut out = Vec::new();
    for encoding in ENCODINGS {
        let field = SyntheticField::new(1, 3);
        let mut asset = field.asset(2, encoding).unwrap();
        asset.reflection = Some(synthetic_reflection(&asset, 12.0, 8).unwrap());
        let bytes = encode_asset(&asset, &options()).unwrap().0;
        let parts = FileParts::parse(&bytes);
        for (entry, _) in &parts.sections {
            if entry.kind != KIND_REFLECTION && entry.kind != KIND_REFLECTION_VALUES {
                continue;
            }
            for i in 0..entry.stored_length as usize {
                let at = entry.offset as usize + i;
                let mut damaged = bytes.clone();
                damaged[at] ^= 1 << (i % 8);
                let name = entry.name();
                out.push(Damaged::new(
                    format!("{encoding:?} reflection flip at {at} in {name}"),
                    damaged,
                    Expect::error(move |e| e.to_string().contains(&name)),
                ));
            }
        }
    }
    out
}

/// The decoded bytes of a `VREF` section: eye count, lobe exponent, eyes, then the
/// `(scale, offset)` pairs of `VRCO`'s three values.
fn vref_bytes(eye_count: u32, exponent: f32, eyes: &[[f32; 3]], pairs: &[[f32; 2]]) -> Vec<u8> {
    let mut out = eye_count.to_le_bytes().to_vec();
    out.extend(exponent.to_le_bytes());
    out.extend(eyes.iter().flatten().flat_map(|v| v.to_le_bytes()));
    out.extend(pairs.iter().flatten().flat_map(|v| v.to_le_bytes()));
    out
}

/// Hand-made hostile reflection sections (format 1.3) with valid checksums: one of `VREF`
/// and `VRCO` without the other, both view-dependent parts in one file, eye counts and
/// lengths that disagree, the lobe exponent out of range, non-finite eyes, bad 8-bit
/// parameters (a negative offset of the scale among them), bad zstd, a `VRCO` of the
/// wrong length, shuffle, codec or chunk table, chunks over 4 MiB; each with the error it
/// must give, which names the section. Exponents 1 and 200 and an offset of −0 are valid.
pub fn hostile_reflection_sections() -> Vec<Damaged> {
    let mut out = Vec::new();
    let mut push = |parts: FileParts, what: &str, expect: Expect| {
        out.push(Damaged::new(
            format!("hostile reflection: {what}"),
            parts.build(),
            expect,
        ));
    };
    let invalid_view = |needle: &'static str| {
        Expect::error(move |e| matches!(e, FormatError::InvalidView(m) if m.contains(needle)))
    };
    for encoding in ENCODINGS {
        let (asset, bytes) = encoded_reflection(encoding);
        let part = asset.reflection.as_ref().unwrap();
        let Coefficients::U8Affine {
            scale, offset, codes, ..
        } = &part.coefficients
        else {
            unreachable!("reflection values are 8-bit")
        };
        let pairs: Vec<[f32; 2]> = scale.iter().zip(offset).map(|(&s, &o)| [s, o]).collect();
        let (exponent, eyes) = (part.exponent, part.eyes_m.clone());
        let count = eyes.len() as u32;
        let with_vref = |raw: Vec<u8>| {
            let mut p = FileParts::parse(&bytes);
            let n = raw.len() as u64;
            p.replace(KIND_REFLECTION, SectionCodec::Raw, 0, raw, n);
            p
        };

        // One section without the other, and two view-dependent parts in one file.
        for (gone, name) in [
            (KIND_REFLECTION, "VRCO without VREF"),
            (KIND_REFLECTION_VALUES, "VREF without VRCO"),
        ] {
            let mut p = FileParts::parse(&bytes);
            p.sections.retain(|(e, _)| e.kind != gone);
            push(p, name, invalid_view("without section"));
        }
        let view = FileParts::parse(&encoded_view(encoding).1);
        for (kinds, name) in [
            (
                &[KIND_VIEW, KIND_VIEW_COEFFICIENTS][..],
                "VDEP and VCOF beside VREF and VRCO",
            ),
            (&[KIND_VIEW][..], "VDEP beside VREF and VRCO"),
        ] {
            let mut p = FileParts::parse(&bytes);
            let at = p.sections.len() - 1;
            for (i, kind) in kinds.iter().enumerate() {
                let section = view
                    .sections
                    .iter()
                    .find(|(e, _)| e.kind == *kind)
                    .unwrap()
                    .clone();
                p.sections.insert(at + i, section);
            }
            push(p, name, invalid_view("VDEP and VREF are both present"));
        }

        // Eye counts and lengths.
        for (n, name) in [
            (0, "no eye"),
            (17, "17 eyes"),
            (count - 1, "one eye fewer than stored"),
            (count + 1, "one eye more than stored"),
        ] {
            push(
                with_vref(vref_bytes(n, exponent, &eyes, &pairs)),
                name,
                invalid_view("eyes do not fit"),
            );
        }
        let mut long = vref_bytes(count, exponent, &eyes, &pairs);
        long.extend([0; 4]);
        push(
            with_vref(long),
            "VREF 4 bytes too long",
            invalid_view("decoded bytes"),
        );
        let seventeen = vec![[0.1, 0.2, 0.3]; 17];
        push(
            with_vref(vref_bytes(17, exponent, &seventeen, &pairs)),
            "VREF of 17 eyes",
            invalid_view("decoded bytes"),
        );
        push(
            with_vref(vref_bytes(count, exponent, &[], &[])),
            "VREF shorter than one eye",
            invalid_view("decoded bytes"),
        );
        let full = vref_bytes(count, exponent, &eyes, &pairs);
        push(
            with_vref(full[..full.len() - 12].to_vec()),
            "VREF cut by one eye's bytes",
            invalid_view("eyes do not fit"),
        );
        let mut p = FileParts::parse(&bytes);
        p.section_mut(KIND_REFLECTION).0.raw_length = 1 << 40;
        push(p, "VREF huge", invalid_view("decoded bytes"));
        let mut p = with_vref(full.clone());
        p.section_mut(KIND_REFLECTION).0.raw_length += 12;
        push(
            p,
            "VREF stored raw, declaring one eye more",
            Expect::error(|e| matches!(e, FormatError::BadCodec { section, .. } if section == "VREF")),
        );
        // zstd that decodes short, and zstd garbage.
        let n = full.len() as u64;
        for (stored, name) in [
            (
                zstd::bulk::compress(&full[..full.len() - 12], 3).unwrap(),
                "VREF zstd short",
            ),
            (vec![0x28, 0xb5, 0x2f, 0xfd, 1, 2, 3, 4, 5], "VREF zstd garbage"),
        ] {
            let mut p = FileParts::parse(&bytes);
            p.replace(KIND_REFLECTION, SectionCodec::Zstd, 0, stored, n);
            push(
                p,
                name,
                Expect::error(|e| matches!(e, FormatError::Zstd { what, .. } if what.contains("VREF"))),
            );
        }

        // The lobe exponent: 1..=200.
        for (value, name) in [
            (0.5, "exponent 0.5"),
            (0.0, "exponent 0"),
            (-20.0, "negative exponent"),
            (200.5, "exponent 200.5"),
            (f32::NAN, "NaN exponent"),
            (f32::INFINITY, "infinite exponent"),
        ] {
            push(
                with_vref(vref_bytes(count, value, &eyes, &pairs)),
                name,
                invalid_view("lobe exponent"),
            );
        }
        for value in [1.0, 200.0] {
            push(
                with_vref(vref_bytes(count, value, &eyes, &pairs)),
                &format!("exponent {value} (accepted)"),
                Expect::Anything,
            );
        }

        // Non-finite eyes, named.
        for (eye, axis, value) in [(2, 1, f32::NAN), (0, 2, f32::NEG_INFINITY)] {
            let mut e = eyes.clone();
            e[eye][axis] = value;
            let needle = format!("section VREF eye {eye}");
            push(
                with_vref(vref_bytes(count, exponent, &e, &pairs)),
                &format!("non-finite eye {eye}"),
                Expect::error(move |e| matches!(e, FormatError::NonFinite { what } if *what == needle)),
            );
        }

        // The 8-bit parameters: a negative offset of the scale (−0 is fine), then the rules
        // of QPRM (values chosen to print alike in C and Rust).
        let mut negative = pairs.clone();
        negative[2][1] = -0.5;
        push(
            with_vref(vref_bytes(count, exponent, &eyes, &negative)),
            "negative offset of the scale",
            invalid_view("offset -0.5 is negative"),
        );
        let mut zero = pairs.clone();
        zero[2][1] = -0.0;
        push(
            with_vref(vref_bytes(count, exponent, &eyes, &zero)),
            "offset -0 of the scale (accepted)",
            Expect::Anything,
        );
        for (k, pair, name) in [
            (0, [-0.5, 2.0], "negative VREF scale"),
            (1, [f32::NAN, 2.0], "NaN VREF scale"),
            (2, [2e36, 2.0], "VREF offset + 255 scale overflows"),
            (1, [0.25, f32::INFINITY], "infinite VREF offset"),
        ] {
            let mut p = pairs.clone();
            p[k] = pair;
            let needle = format!("section VREF component {k}");
            push(
                with_vref(vref_bytes(count, exponent, &eyes, &p)),
                name,
                Expect::error(move |e| {
                    matches!(
                        e,
                        FormatError::NonFinite { what } | FormatError::InvalidValue { what, .. }
                            if what.starts_with(&needle)
                    )
                }),
            );
        }

        // VRCO's entry and chunk table.
        for (shuffle, name) in [
            (None, "VRCO raw length one brick more"),
            (Some(5), "VRCO shuffle 5"),
            (Some(1024), "VRCO shuffle 1024"),
        ] {
            let mut p = FileParts::parse(&bytes);
            let (e, _) = p.section_mut(KIND_REFLECTION_VALUES);
            match shuffle {
                Some(width) => e.shuffle = width,
                None => e.raw_length += REFLECTION_BYTES_PER_BRICK,
            }
            push(
                p,
                name,
                Expect::error(|e| {
                    matches!(
                        e,
                        FormatError::SectionLength { section, .. } | FormatError::BadCodec { section, .. }
                            if section == "VRCO"
                    )
                }),
            );
        }
        for (kind, codec, name) in [
            (KIND_REFLECTION_VALUES, SectionCodec::Zstd, "VRCO codec 1"),
            (KIND_REFLECTION_VALUES, SectionCodec::Raw, "VRCO codec 0"),
            (KIND_REFLECTION, SectionCodec::ChunkedZstd, "VREF codec 2"),
            (KIND_REFLECTION, SectionCodec::Unknown(9), "VREF codec 9"),
        ] {
            let mut p = FileParts::parse(&bytes);
            p.section_mut(kind).0.codec = codec;
            let want = kind_text(kind);
            push(
                p,
                name,
                Expect::error(
                    move |e| matches!(e, FormatError::BadCodec { section, .. } if *section == want),
                ),
            );
        }
        let (entry, table) = FileParts::parse(&bytes)
            .section_mut(KIND_REFLECTION_VALUES)
            .clone();
        let mut lying = table.clone();
        lying[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_REFLECTION_VALUES,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            lying,
            entry.raw_length,
        );
        push(
            p,
            "VRCO chunk length",
            Expect::error(|e| matches!(e, FormatError::BadChunkTable { section, .. } if section == "VRCO")),
        );
        let chunks = asset.bricks.len().div_ceil(CHUNK_BRICKS);
        let mut empty = Vec::new();
        for _ in 0..chunks {
            empty.extend_from_slice(&((24 * chunks) as u64).to_le_bytes());
            empty.extend_from_slice(&0u64.to_le_bytes());
            empty.extend_from_slice(&nelf_format::spec::checksum(&[]).to_le_bytes());
        }
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_REFLECTION_VALUES,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            empty,
            entry.raw_length,
        );
        push(
            p,
            "VRCO empty chunks",
            Expect::error(
                |e| matches!(e, FormatError::ImplausibleLength { what, .. } if what.contains("VRCO")),
            ),
        );
        // A chunk of a damaged VRCO (valid checksum) that decodes to too few bytes.
        // Chunk 0 re-encoded one voxel short, the table's tiling and checksums kept valid.
        let brick_bytes = REFLECTION_BYTES_PER_BRICK as usize;
        let intact = chunked_payload(codes, brick_bytes, CHUNK_BRICKS, 3);
        let short = &codes[..CHUNK_BRICKS * brick_bytes - 3];
        let first = zstd::bulk::compress(&nelf_format::spec::shuffle(short, 3), 3).unwrap();
        let short_chunk = replace_chunk(&intact, 0, &first);
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_REFLECTION_VALUES,
            SectionCodec::ChunkedZstd,
            3,
            short_chunk,
            entry.raw_length,
        );
        push(
            p,
            "VRCO chunk 0 decodes short",
            Expect::error(|e| matches!(e, FormatError::Zstd { what, .. } if what == "section VRCO chunk 0")),
        );

        // VRCO chunks over 4 MiB: rank 1 (at most 1024 bytes a brick elsewhere) with 4096-brick
        // chunks passes the header's limit, but VRCO's 1536 bytes a brick do not.
        let mut small = small_asset(encoding, 1, 21);
        small.reflection = Some(synthetic_reflection(&small, 20.0, 5).unwrap());
        let mut p = FileParts::parse(&encode_asset(&small, &options()).unwrap().0);
        p.header[108..112].copy_from_slice(&4096u32.to_le_bytes());
        push(
            p,
            "VRCO chunks over 4 MiB",
            Expect::error(
                |e| matches!(e, FormatError::CountTooLarge { what, .. } if what.contains("VRCO chunk")),
            ),
        );
    }
    out
}

/// `kind` as the reader names it.
fn kind_text(kind: [u8; 4]) -> String {
    String::from_utf8_lossy(&kind).into_owned()
}

/// The chunked section `section` (chunk table and chunks) with chunk `index` replaced by
/// `stored`: the table's offsets, lengths and checksums follow.
fn replace_chunk(section: &[u8], index: usize, stored: &[u8]) -> Vec<u8> {
    let first = u64::from_le_bytes(section[..8].try_into().unwrap()) as usize;
    let count = first / 24;
    let mut chunks: Vec<Vec<u8>> = (0..count)
        .map(|i| {
            let e = &section[24 * i..24 * i + 24];
            let offset = u64::from_le_bytes(e[..8].try_into().unwrap()) as usize;
            let length = u64::from_le_bytes(e[8..16].try_into().unwrap()) as usize;
            section[offset..offset + length].to_vec()
        })
        .collect();
    chunks[index] = stored.to_vec();
    let mut table = Vec::new();
    let mut offset = first as u64;
    for c in &chunks {
        table.extend_from_slice(&offset.to_le_bytes());
        table.extend_from_slice(&(c.len() as u64).to_le_bytes());
        table.extend_from_slice(&nelf_format::spec::checksum(c).to_le_bytes());
        offset += c.len() as u64;
    }
    for c in &chunks {
        table.extend_from_slice(c);
    }
    table
}

/// One bit flipped in every byte of `DNSF` (chunk table and chunk) of a one-brick file
/// with a fine density at factor 2, per encoding of the PCA part, and at factor 4 for the
/// 8-bit one: each must be refused naming the section.
pub fn fine_density_byte_flips() -> Vec<Damaged> {
    let mut out = Vec::new();
    for (encoding, factor) in [
        (CoefficientEncoding::U8Affine, 2),
        (CoefficientEncoding::F16, 2),
        (CoefficientEncoding::U8Affine, 4),
    ] {
        let field = SyntheticField::new(1, 3);
        let asset = with_fine_density(field.asset(2, encoding).unwrap(), factor, false);
        let bytes = encode_asset(&asset, &options()).unwrap().0;
        let parts = FileParts::parse(&bytes);
        let (entry, _) = parts
            .sections
            .iter()
            .find(|(e, _)| e.kind == KIND_FINE_DENSITY)
            .unwrap();
        for i in 0..entry.stored_length as usize {
            let at = entry.offset as usize + i;
            let mut damaged = bytes.clone();
            damaged[at] ^= 1 << (i % 8);
            out.push(Damaged::new(
                format!("{encoding:?} fine density F {factor} flip at {at} in DNSF"),
                damaged,
                Expect::error(|e| e.to_string().contains("DNSF")),
            ));
        }
    }
    out
}

/// Hand-made hostile fine densities (format 1.4) with valid checksums: header factors
/// other than 0, 2 and 4, a factor without `DNSF` and `DNSF` without a factor, a factor
/// that disagrees with `DNSF`'s length, `DNSF` of the wrong length, codec or shuffle, twice,
/// non-finite values and a negative one without the signed-density flag (named by their
/// fine voxel), bad chunk tables and zstd, chunks over 4 MiB; each with the error it must
/// give. `DNSF` with the required bit, and a negative value with the flag, are valid.
pub fn hostile_fine_density_sections() -> Vec<Damaged> {
    let mut out = Vec::new();
    let mut push = |parts: FileParts, what: &str, expect: Expect| {
        out.push(Damaged::new(
            format!("hostile fine density: {what}"),
            parts.build(),
            expect,
        ));
    };
    let bad_factor = |needle: &'static str| {
        Expect::error(move |e| {
            matches!(
                e,
                FormatError::InvalidHeader { field: "fine_density_factor", reason } if reason.contains(needle)
            )
        })
    };
    let named = |pick: fn(&FormatError) -> Option<&str>| {
        Expect::error(move |e| pick(e).is_some_and(|section| section == "DNSF"))
    };
    for encoding in ENCODINGS {
        let (asset, bytes) = encoded_fine(encoding, 2);
        let fine = asset.fine_density.as_ref().unwrap();
        let per_brick = fine.voxels_per_brick();
        let with_factor = |bytes: &[u8], factor: u32| {
            let mut p = FileParts::parse(bytes);
            p.header[196..200].copy_from_slice(&factor.to_le_bytes());
            p
        };

        // The header's factor: 0, 2 or 4, and DNSF present exactly when it is not 0.
        for factor in [1, 3, 8, u32::MAX] {
            push(
                with_factor(&bytes, factor),
                &format!("factor {factor}"),
                bad_factor("must be 0 (none), 2 or 4"),
            );
        }
        push(
            with_factor(&bytes, 0),
            "DNSF without a factor",
            bad_factor("section DNSF is present"),
        );
        let mut p = FileParts::parse(&bytes);
        p.sections.retain(|(e, _)| e.kind != KIND_FINE_DENSITY);
        push(
            p,
            "factor 2 without DNSF",
            Expect::error(|e| matches!(e, FormatError::MissingSection { section } if section == "DNSF")),
        );
        push(
            with_factor(&encoded(encoding).1, 4),
            "factor 4 in a file without DNSF",
            Expect::error(|e| matches!(e, FormatError::MissingSection { section } if section == "DNSF")),
        );
        push(
            with_factor(&bytes, 4),
            "factor 4 for a DNSF of factor 2",
            named(|e| match e {
                FormatError::SectionLength { section, .. } => Some(section.as_str()),
                _ => None,
            }),
        );

        // DNSF's entry.
        let mut p = FileParts::parse(&bytes);
        p.section_mut(KIND_FINE_DENSITY).0.raw_length += 2 * per_brick as u64;
        push(
            p,
            "DNSF raw length one brick more",
            named(|e| match e {
                FormatError::SectionLength { section, .. } => Some(section.as_str()),
                _ => None,
            }),
        );
        for (codec, shuffle, name) in [
            (SectionCodec::Zstd, 2, "DNSF codec 1"),
            (SectionCodec::Raw, 2, "DNSF codec 0"),
            (SectionCodec::Unknown(9), 2, "DNSF codec 9"),
            (SectionCodec::ChunkedZstd, 3, "DNSF shuffle 3"),
            (SectionCodec::ChunkedZstd, 3 << 12, "DNSF shuffle 3 × 4096"),
        ] {
            let mut p = FileParts::parse(&bytes);
            let (e, _) = p.section_mut(KIND_FINE_DENSITY);
            e.codec = codec;
            e.shuffle = shuffle;
            push(
                p,
                name,
                named(|e| match e {
                    FormatError::BadCodec { section, .. } => Some(section.as_str()),
                    _ => None,
                }),
            );
        }
        let mut p = FileParts::parse(&bytes);
        let dnsf = p.section_mut(KIND_FINE_DENSITY).clone();
        p.sections.push(dnsf);
        push(
            p,
            "DNSF twice",
            named(|e| match e {
                FormatError::DuplicateSection { section } => Some(section.as_str()),
                _ => None,
            }),
        );
        // The required bit: a known kind is read whatever it says.
        let mut p = FileParts::parse(&bytes);
        p.section_mut(KIND_FINE_DENSITY).0.required = true;
        push(p, "DNSF marked required (accepted)", Expect::Anything);

        // Values, in validly compressed chunks: named by their fine voxel (brick 4, in
        // chunk 1).
        let at = 4 * per_brick + 123;
        let raw_with = |bits: u16| -> Vec<u8> {
            let mut raw: Vec<u8> = fine
                .values
                .iter()
                .flat_map(|v| v.to_bits().to_le_bytes())
                .collect();
            raw[2 * at..2 * at + 2].copy_from_slice(&bits.to_le_bytes());
            raw
        };
        let (entry, _) = FileParts::parse(&bytes).section_mut(KIND_FINE_DENSITY).clone();
        let with_values = |raw: &[u8]| {
            let mut p = FileParts::parse(&bytes);
            p.replace(
                KIND_FINE_DENSITY,
                SectionCodec::ChunkedZstd,
                2,
                chunked_payload(raw, 2 * per_brick, CHUNK_BRICKS, 2),
                entry.raw_length,
            );
            p
        };
        for (bits, name) in [(0x7E00u16, "NaN"), (0xFC00, "-inf")] {
            let needle = format!("section DNSF voxel {at}");
            push(
                with_values(&raw_with(bits)),
                &format!("{name} fine density"),
                Expect::error(move |e| matches!(e, FormatError::NonFinite { what } if *what == needle)),
            );
        }
        let needle = format!("section DNSF voxel {at}");
        push(
            with_values(&raw_with(0xB800)),
            "negative fine density without the signed-density flag",
            Expect::error(move |e| matches!(e, FormatError::InvalidValue { what, .. } if *what == needle)),
        );
        let mut p = with_values(&raw_with(0xB800));
        p.header[24] |= 1;
        push(
            p,
            "negative fine density with the signed-density flag (accepted)",
            Expect::Anything,
        );

        // Chunk tables and zstd.
        let mut lying = entry_data(&bytes, KIND_FINE_DENSITY);
        lying[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_FINE_DENSITY,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            lying,
            entry.raw_length,
        );
        push(
            p,
            "DNSF chunk length",
            named(|e| match e {
                FormatError::BadChunkTable { section, .. } => Some(section.as_str()),
                _ => None,
            }),
        );
        let chunks = asset.bricks.len().div_ceil(CHUNK_BRICKS);
        let mut empty = Vec::new();
        for _ in 0..chunks {
            empty.extend_from_slice(&((24 * chunks) as u64).to_le_bytes());
            empty.extend_from_slice(&0u64.to_le_bytes());
            empty.extend_from_slice(&nelf_format::spec::checksum(&[]).to_le_bytes());
        }
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_FINE_DENSITY,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            empty,
            entry.raw_length,
        );
        push(
            p,
            "DNSF empty chunks",
            Expect::error(
                |e| matches!(e, FormatError::ImplausibleLength { what, .. } if what.contains("DNSF")),
            ),
        );
        let mut p = FileParts::parse(&bytes);
        p.replace(
            KIND_FINE_DENSITY,
            SectionCodec::ChunkedZstd,
            entry.shuffle,
            vec![0; 40],
            entry.raw_length,
        );
        push(
            p,
            "DNSF shorter than its chunk table",
            Expect::error(
                |e| matches!(e, FormatError::CountTooLarge { what, .. } if what.contains("chunks in section DNSF")),
            ),
        );
        let raw: Vec<u8> = fine
            .values
            .iter()
            .flat_map(|v| v.to_bits().to_le_bytes())
            .collect();
        let intact = chunked_payload(&raw, 2 * per_brick, CHUNK_BRICKS, 2);
        for (chunk, stored, name, needle) in [
            (
                0,
                zstd::bulk::compress(
                    &nelf_format::spec::shuffle(&raw[..CHUNK_BRICKS * 2 * per_brick - 2], 2),
                    3,
                )
                .unwrap(),
                "DNSF chunk 0 decodes short",
                "section DNSF chunk 0",
            ),
            (
                1,
                vec![0x28, 0xb5, 0x2f, 0xfd, 1, 2, 3, 4, 5],
                "DNSF chunk 1 zstd garbage",
                "section DNSF chunk 1",
            ),
        ] {
            let mut p = FileParts::parse(&bytes);
            p.replace(
                KIND_FINE_DENSITY,
                SectionCodec::ChunkedZstd,
                2,
                replace_chunk(&intact, chunk, &stored),
                entry.raw_length,
            );
            push(
                p,
                name,
                Expect::error(move |e| matches!(e, FormatError::Zstd { what, .. } if what == needle)),
            );
        }

        // Chunks over 4 MiB: 513 bricks a chunk at factor 2 (8 KiB a brick), 65 at factor 4
        // (64 KiB), which the other sections would allow.
        for (factor, most) in [(2, 512u32), (4, 64)] {
            let (_, fine_bytes) = encoded_fine(encoding, factor);
            for (chunk_bricks, expect) in [(most + 1, true), (most, false)] {
                let mut p = FileParts::parse(&fine_bytes);
                p.header[108..112].copy_from_slice(&chunk_bricks.to_le_bytes());
                let what = format!("F {factor} with {chunk_bricks} bricks a chunk");
                if expect {
                    push(
                        p,
                        &what,
                        Expect::error(
                            |e| matches!(e, FormatError::CountTooLarge { what, .. } if what.starts_with("chunk_bricks")),
                        ),
                    );
                } else {
                    // Within the limit: the header passes; the chunk table (written for 3
                    // bricks a chunk) does not.
                    push(
                        p,
                        &what,
                        Expect::error(|e| {
                            matches!(
                                e,
                                FormatError::BadChunkTable { .. } | FormatError::ImplausibleLength { .. }
                            )
                        }),
                    );
                }
            }
        }
    }
    out
}

/// The stored bytes of section `kind` of `bytes`.
fn entry_data(bytes: &[u8], kind: [u8; 4]) -> Vec<u8> {
    FileParts::parse(bytes).section_mut(kind).1.clone()
}

/// [`options`] with `chunk_bricks` bricks per chunk.
fn options_with(chunk_bricks: u32) -> WriteOptions {
    WriteOptions {
        chunk_bricks,
        ..options()
    }
}

/// Every case of every generator.
pub fn all() -> Vec<Damaged> {
    let mut out = truncations();
    out.extend(bit_flips());
    out.extend(hostile_headers());
    out.extend(hostile_sections());
    out.extend(view_byte_flips());
    out.extend(hostile_view_sections());
    out.extend(reflection_byte_flips());
    out.extend(hostile_reflection_sections());
    out.extend(fine_density_byte_flips());
    out.extend(hostile_fine_density_sections());
    out.extend(mutations());
    out
}
