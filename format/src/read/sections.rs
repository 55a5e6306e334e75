//! The checks and decoders of the reader's sections, kept apart from the reading
//! itself ([`super`]): the section table's validation (SPEC.md, "Validation"),
//! checksums, bounded zstd decompression, and the decoding of the small parameter
//! sections (`VDEP`, `RFLP`) and of raw little-endian arrays. Nothing here reads a
//! file; every function takes bytes or parsed headers and returns a value or a
//! [`FormatError`] naming what is wrong.

use std::path::Path;

use half::f16;

use crate::asset::{
    CoefficientEncoding, Coefficients, MAX_REFLECTION_EYES, Reflection, ViewDependence, validate_quant_params,
};
use crate::conventions::{LT_DIM, VIEW_HARMONICS};
use crate::error::{FormatError, Result};
use crate::io_error::FileIoError;
use crate::spec::{
    BRICK_VOXELS, Header, KIND_BRICKS, KIND_COEFFICIENTS, KIND_DENSITY, KIND_FINE_DENSITY, KIND_PCA,
    KIND_QUANT_PARAMS, KIND_REFLECTION, KIND_REFLECTION_VALUES, KIND_VIEW, KIND_VIEW_COEFFICIENTS,
    MAX_CHUNK_RAW_BYTES, MAX_METADATA_BYTES, MAX_VIEW_PARAMS_BYTES, MAX_ZSTD_EXPANSION,
    REFLECTION_BYTES_PER_BRICK, SectionCodec, SectionEntry, SectionKind, VIEW_HEADER_SIZE, ViewHeader,
    is_known_kind, kind_name, reflection_params_bytes,
};

/// Whether a stored checksum disagrees with the computed one. Builds for fuzzing
/// (`cargo fuzz` sets `--cfg fuzzing`) ignore checksums, so that mutated inputs reach
/// the decoders and value checks behind them instead of stopping at the first hash.
#[allow(unexpected_cfgs)]
pub(super) fn checksums_differ(stored: u64, computed: u64) -> bool {
    !cfg!(fuzzing) && stored != computed
}

/// Maps an I/O error to [`FormatError::Io`] (with a path) or [`FormatError::Stream`].
pub(super) fn io_error(path: Option<&Path>, during: &str, source: std::io::Error) -> FormatError {
    match path {
        Some(p) => FormatError::Io(FileIoError::new(
            p.to_path_buf(),
            std::io::Error::new(source.kind(), format!("{during}: {source}")),
        )),
        None => FormatError::Stream {
            during: during.to_string(),
            source,
        },
    }
}

/// Rejects a declared decoded length that zstd cannot produce from `stored` bytes.
pub(super) fn check_plausible(raw: u64, stored: u64, what: impl Fn() -> String) -> Result<()> {
    if raw > stored.saturating_mul(MAX_ZSTD_EXPANSION) {
        return Err(FormatError::ImplausibleLength {
            what: what(),
            raw,
            stored,
        });
    }
    Ok(())
}

/// Decompresses zstd data into exactly `raw_length` bytes (never more are allocated).
pub(super) fn decompress(stored: &[u8], raw_length: u64, what: &str) -> Result<Vec<u8>> {
    let zstd_error = |message: String| FormatError::Zstd {
        what: what.to_string(),
        message,
    };
    let mut out = Vec::with_capacity(raw_length as usize);
    let mut decompressor = zstd::bulk::Decompressor::new().map_err(|e| zstd_error(e.to_string()))?;
    let n = decompressor
        .decompress_to_buffer(stored, &mut out)
        .map_err(|e| zstd_error(e.to_string()))?;
    if n as u64 != raw_length {
        return Err(zstd_error(format!("decoded {n} bytes, expected {raw_length}")));
    }
    Ok(out)
}

/// Decoded bytes of one brick of `DENS` (512 `f16`s).
pub(super) const DENSITY_BYTES_PER_BRICK: u64 = 2 * BRICK_VOXELS as u64;

/// Decoded bytes of one brick of `VCOF` for `view` (`512 · J·K_v · w`).
pub(super) fn view_bytes_per_brick(view: &ViewDependence) -> u64 {
    (BRICK_VOXELS * view.coefficients.rank() * view.coefficients.encoding().bytes_per_value()) as u64
}

/// Decodes `VDEP` (format 1.2): its [`ViewHeader`], then the lobes, the view basis and,
/// for 8-bit coefficients, the dequantisation parameters, all checked; the returned part
/// holds no voxel.
pub(super) fn view_params(bytes: &[u8]) -> Result<(ViewHeader, ViewDependence)> {
    let header = ViewHeader::from_section(bytes)?;
    let floats = f32s(&bytes[VIEW_HEADER_SIZE..]);
    let (lobes, rest) = floats.split_at(header.lobes as usize * VIEW_HARMONICS);
    let (basis, params) = rest.split_at(header.rank as usize * LT_DIM);
    let rank = header.coefficients_per_voxel() as usize;
    let coefficients = match header.encoding {
        CoefficientEncoding::U8Affine => {
            let (scale, offset) = pairs(params);
            Coefficients::U8Affine {
                rank,
                scale,
                offset,
                codes: Vec::new(),
            }
        }
        CoefficientEncoding::F16 => Coefficients::F16 {
            rank,
            values: Vec::new(),
        },
    };
    let view = ViewDependence {
        lobes: lobes.to_vec(),
        basis: basis.to_vec(),
        coefficients,
    };
    // Lobes, then basis, finite; then the 8-bit parameters (as QPRM's).
    view.validate(0)?;
    Ok((header, view))
}

/// Decodes `VREF` (format 1.3): eye count, exponent, eyes and the 8-bit parameters of
/// `VRCO`, all checked; the returned part holds no voxel.
pub(super) fn reflection_params(bytes: &[u8]) -> Result<Reflection> {
    let bad = |reason: String| FormatError::InvalidView(format!("section VREF: {reason}"));
    if bytes.len() < 8 {
        return Err(bad(format!("{} bytes, fewer than its 8-byte start", bytes.len())));
    }
    let eyes = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as usize;
    if !(1..=MAX_REFLECTION_EYES).contains(&eyes) || reflection_params_bytes(eyes) != bytes.len() as u64 {
        return Err(bad(format!(
            "{eyes} eyes do not fit its {} bytes (32 + 12 per eye, 1..={MAX_REFLECTION_EYES} eyes)",
            bytes.len()
        )));
    }
    let floats = f32s(&bytes[4..]);
    let eyes_m = floats[1..=3 * eyes]
        .chunks_exact(3)
        .map(|e| [e[0], e[1], e[2]])
        .collect();
    let (scale, offset) = pairs(&floats[1 + 3 * eyes..]);
    validate_quant_params(&scale, &offset, "VREF")?;
    let part = Reflection {
        exponent: floats[0],
        eyes_m,
        coefficients: Coefficients::U8Affine {
            rank: Reflection::VALUES_PER_VOXEL,
            scale,
            offset,
            codes: Vec::new(),
        },
    };
    part.validate(0)?;
    Ok(part)
}

/// Checks the section table: bounds, alignment, overlaps, duplicates, unknown
/// required kinds, codecs and shuffles, and declared lengths against the header.
pub(super) fn validate_table(header: &Header, sections: &[SectionEntry]) -> Result<()> {
    let data_start = header.data_start();
    for (i, s) in sections.iter().enumerate() {
        let name = s.name();
        if s.offset % 8 != 0 {
            return Err(FormatError::Misaligned {
                section: name,
                offset: s.offset,
            });
        }
        let end = s.offset.checked_add(s.stored_length);
        if s.offset < data_start || end.is_none_or(|e| e > header.file_size) {
            return Err(FormatError::SectionOutOfBounds {
                section: name,
                offset: s.offset,
                length: s.stored_length,
                data_start,
                file_size: header.file_size,
            });
        }
        if sections[..i].iter().any(|o| o.kind == s.kind) {
            return Err(FormatError::DuplicateSection { section: name });
        }
    }
    let mut by_offset: Vec<&SectionEntry> = sections.iter().collect();
    by_offset.sort_by_key(|s| (s.offset, s.stored_length));
    for pair in by_offset.windows(2) {
        if pair[0].offset + pair[0].stored_length > pair[1].offset {
            return Err(FormatError::SectionsOverlap {
                first: pair[0].name(),
                second: pair[1].name(),
            });
        }
    }
    let has = |kind: SectionKind| sections.iter().any(|s| s.kind == kind);
    // The fine density (1.4) is there exactly when the header declares its factor.
    match (header.fine_density_factor, has(KIND_FINE_DENSITY)) {
        (0, true) => {
            return Err(FormatError::InvalidHeader {
                field: "fine_density_factor",
                reason: "0, but section DNSF is present".into(),
            });
        }
        (f, false) if f != 0 => {
            return Err(FormatError::MissingSection {
                section: "DNSF".into(),
            });
        }
        _ => {}
    }
    for s in sections {
        if !is_known_kind(s.kind) {
            if s.required {
                return Err(FormatError::UnknownRequiredSection { section: s.name() });
            }
            continue;
        }
        validate_known_entry(header, s)?;
    }
    for kind in [KIND_BRICKS, KIND_DENSITY, KIND_PCA, KIND_COEFFICIENTS] {
        if !has(kind) {
            return Err(FormatError::MissingSection {
                section: kind_name(kind),
            });
        }
    }
    // The view-dependent part is optional, but whole: its parameters and coefficients;
    // and a file holds at most one (harmonic or reflection).
    if has(KIND_VIEW) && has(KIND_REFLECTION) {
        return Err(FormatError::InvalidView(
            "sections VDEP and VREF are both present: a file holds at most one view-dependent part".into(),
        ));
    }
    for (present, absent) in [
        (KIND_VIEW, KIND_VIEW_COEFFICIENTS),
        (KIND_VIEW_COEFFICIENTS, KIND_VIEW),
        (KIND_REFLECTION, KIND_REFLECTION_VALUES),
        (KIND_REFLECTION_VALUES, KIND_REFLECTION),
    ] {
        if has(present) && !has(absent) {
            return Err(FormatError::InvalidView(format!(
                "section {} is present without section {}",
                kind_name(present),
                kind_name(absent)
            )));
        }
    }
    Ok(())
}

/// Checks a known section's entry against the header: its codec, its declared decoded
/// length, and the rules of its codec. `VCOF`'s length, shuffle and chunk size depend on
/// `VDEP`, so they are checked once that is read ([`validate_chunked_entry`]).
pub(super) fn validate_known_entry(header: &Header, s: &SectionEntry) -> Result<()> {
    let chunked = [
        KIND_DENSITY,
        KIND_FINE_DENSITY,
        KIND_COEFFICIENTS,
        KIND_VIEW_COEFFICIENTS,
        KIND_REFLECTION_VALUES,
    ]
    .contains(&s.kind);
    match (s.codec, chunked) {
        (SectionCodec::Raw, false) | (SectionCodec::ChunkedZstd, true) => {}
        (SectionCodec::Zstd, false) if s.kind != KIND_BRICKS => {}
        (codec, _) => {
            return Err(FormatError::BadCodec {
                section: s.name(),
                reason: format!("codec {} is not allowed for this section", codec.name()),
            });
        }
    }
    let bricks = u64::from(header.brick_count);
    let rank = u64::from(header.pca_rank);
    let expected = match s.kind {
        KIND_DENSITY => return validate_chunked_entry(header, s, DENSITY_BYTES_PER_BRICK),
        // validate_table checked the factor is not 0 when DNSF is present.
        KIND_FINE_DENSITY => return validate_chunked_entry(header, s, header.fine_density_bytes_per_brick()),
        KIND_COEFFICIENTS => return validate_chunked_entry(header, s, header.coefficient_bytes_per_brick()),
        KIND_VIEW_COEFFICIENTS => return Ok(()),
        KIND_REFLECTION_VALUES => return validate_chunked_entry(header, s, REFLECTION_BYTES_PER_BRICK),
        KIND_REFLECTION => {
            let fits = (1..=MAX_REFLECTION_EYES).any(|e| reflection_params_bytes(e) == s.raw_length);
            if !fits {
                return Err(FormatError::InvalidView(format!(
                    "section VREF declares {} decoded bytes, which is not 32 + 12 × (1..={MAX_REFLECTION_EYES} eyes)",
                    s.raw_length
                )));
            }
            s.raw_length
        }
        KIND_BRICKS => 6 * bricks,
        KIND_PCA => 4 * LT_DIM as u64 * (rank + 1),
        KIND_QUANT_PARAMS => 8 * rank,
        KIND_VIEW => {
            if s.raw_length > MAX_VIEW_PARAMS_BYTES {
                return Err(FormatError::InvalidView(format!(
                    "section VDEP declares {} decoded bytes, more than the largest possible {MAX_VIEW_PARAMS_BYTES}",
                    s.raw_length
                )));
            }
            s.raw_length
        }
        _ => {
            if s.raw_length > MAX_METADATA_BYTES {
                return Err(FormatError::CountTooLarge {
                    what: format!("section {} decoded length", s.name()),
                    count: s.raw_length,
                    limit: MAX_METADATA_BYTES,
                });
            }
            s.raw_length
        }
    };
    if expected != s.raw_length {
        return Err(FormatError::SectionLength {
            section: s.name(),
            expected,
            found: s.raw_length,
        });
    }
    let bad = |reason: String| FormatError::BadCodec {
        section: s.name(),
        reason,
    };
    let width = u64::from(s.shuffle);
    if s.codec == SectionCodec::Raw {
        if s.shuffle != 0 {
            return Err(bad(format!("raw section with shuffle width {}", s.shuffle)));
        }
        if s.stored_length != s.raw_length {
            return Err(bad(format!(
                "raw section stores {} bytes but declares {} decoded",
                s.stored_length, s.raw_length
            )));
        }
    } else {
        if width > 1 && s.raw_length % width != 0 {
            return Err(bad(format!(
                "shuffle width {width} does not divide decoded length {}",
                s.raw_length
            )));
        }
        check_plausible(s.raw_length, s.stored_length, || format!("section {}", s.name()))?;
    }
    Ok(())
}

/// Checks a chunked section's entry (`DENS`, `DNSF`, `COEF`, `VCOF`, `VRCO`) whose bricks decode to
/// `bytes_per_brick` bytes: its decoded length (`brick_count × bytes_per_brick`), its
/// shuffle width (dividing a brick) and the decoded size of a chunk (≤ 4 MiB).
pub(super) fn validate_chunked_entry(header: &Header, s: &SectionEntry, bytes_per_brick: u64) -> Result<()> {
    let expected = u64::from(header.brick_count) * bytes_per_brick;
    if expected != s.raw_length {
        return Err(FormatError::SectionLength {
            section: s.name(),
            expected,
            found: s.raw_length,
        });
    }
    let width = u64::from(s.shuffle);
    if width > 1 && bytes_per_brick % width != 0 {
        return Err(FormatError::BadCodec {
            section: s.name(),
            reason: format!("shuffle width {width} does not divide the {bytes_per_brick} bytes of a brick"),
        });
    }
    let chunk = u64::from(header.chunk_bricks) * bytes_per_brick;
    if chunk > MAX_CHUNK_RAW_BYTES {
        return Err(FormatError::CountTooLarge {
            what: format!("section {} chunk decoded bytes", s.name()),
            count: chunk,
            limit: MAX_CHUNK_RAW_BYTES,
        });
    }
    Ok(())
}

/// Little-endian `f32`s of `bytes` (length a multiple of 4).
pub(super) fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// Little-endian binary16s of `bytes`.
pub(super) fn f16s(bytes: &[u8]) -> Vec<f16> {
    bytes
        .chunks_exact(2)
        .map(|b| f16::from_bits(u16::from_le_bytes([b[0], b[1]])))
        .collect()
}

/// Splits interleaved `(scale, offset)` pairs (`QPRM`, the end of `VDEP`).
pub(super) fn pairs(floats: &[f32]) -> (Vec<f32>, Vec<f32>) {
    (
        floats.iter().step_by(2).copied().collect(),
        floats.iter().skip(1).step_by(2).copied().collect(),
    )
}
