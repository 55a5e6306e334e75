//! `.nelf` writer: packs an [`Asset`] into the v1 layout of `SPEC.md` (header,
//! section table, 8-byte aligned sections, chunked zstd for density and
//! coefficients; version 1.2 with the optional view-dependent sections `VDEP` and
//! `VCOF` when the asset has a harmonic view-dependent part, 1.3 with `VREF` and `VRCO`
//! when it has a reflection part, 1.4 with `DNSF` when it has a fine density, 1.1
//! otherwise) and writes it atomically (temporary file in the same folder,
//! then rename). Output depends only on the asset and the options, so writing
//! the same asset twice gives byte-identical files.

use crate::io_error::IoResultExt;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

use crate::asset::{Asset, CoefficientEncoding, Coefficients, Reflection, has_negative_density};
use crate::error::{FormatError, Result};
use crate::spec::{
    BRICK_VOXELS, CHUNK_ENTRY_SIZE, FLAG_SIGNED_DENSITY, HEADER_CHECKSUM_OFFSET, HEADER_SIZE, Header,
    KIND_BRICKS, KIND_COEFFICIENTS, KIND_DENSITY, KIND_FINE_DENSITY, KIND_METADATA, KIND_PCA,
    KIND_QUANT_PARAMS, KIND_REFLECTION, KIND_REFLECTION_VALUES, KIND_VIEW, KIND_VIEW_COEFFICIENTS,
    MAX_CHUNK_RAW_BYTES, MAX_METADATA_BYTES, REFLECTION_BYTES_PER_BRICK, SECTION_ENTRY_SIZE, SectionCodec,
    SectionEntry, SectionKind, VERSION_MAJOR, VERSION_MINOR, VERSION_MINOR_REFLECTION, VERSION_MINOR_VIEW,
    VERSION_MINOR_WITHOUT_VIEW, ViewHeader, checksum, fine_density_bytes_per_brick, header_checksum,
    kind_name, shuffle,
};

/// Choices the writer makes; none of them changes what a reader gets back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteOptions {
    /// zstd compression level (1 = fastest … 19 = smallest; negative = faster still).
    pub zstd_level: i32,
    /// Bricks per independently compressed chunk of the density and coefficient
    /// sections (clamped so one chunk decodes to at most 4 MiB).
    pub chunk_bricks: u32,
    /// Byte-shuffle records (one voxel's coefficients, one `f16` density, …) before zstd.
    pub shuffle: bool,
}

impl Default for WriteOptions {
    /// zstd level 19, 32-brick chunks, shuffle on: chosen from
    /// `cargo bench -p nelf-format --bench codec` (SPEC.md, "Choosing the defaults").
    /// On the synthetic 225k-voxel asset at K = 16 with 8-bit coefficients, level 19
    /// makes files 21 % smaller than level 3 (decoding stays above 300 MB/s; encoding,
    /// ≈ 5 MB/s, is a bake-time cost); the shuffle saves 24 % at level 19; 32-brick
    /// chunks cost 3 % over 64 and halve the time to read one brick at random.
    fn default() -> Self {
        Self {
            zstd_level: 19,
            chunk_bricks: 32,
            shuffle: true,
        }
    }
}

/// What [`write_asset`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteReport {
    /// The file written.
    pub path: PathBuf,
    /// Its size in bytes.
    pub file_size: u64,
    /// Its section table.
    pub sections: Vec<SectionEntry>,
}

impl WriteReport {
    /// Decoded payload bytes over all sections.
    pub fn raw_payload_bytes(&self) -> u64 {
        self.sections.iter().map(|s| s.raw_length).sum()
    }
}

/// Writes `asset` to `path` atomically ([`crate::atomic`]): on any error nothing is
/// left under `path` (a previous file there is untouched).
pub fn write_asset(path: &Path, asset: &Asset, options: &WriteOptions) -> Result<WriteReport> {
    let (bytes, sections) = encode_asset(asset, options)?;
    crate::atomic::write_bytes_atomically(path, &bytes).with_path(path)?;
    Ok(WriteReport {
        path: path.to_path_buf(),
        file_size: bytes.len() as u64,
        sections,
    })
}

/// Encodes `asset` into the bytes of a `.nelf` file, returning them with the section table.
pub fn encode_asset(asset: &Asset, options: &WriteOptions) -> Result<(Vec<u8>, Vec<SectionEntry>)> {
    asset.validate()?;
    let rank = asset.rank();
    let encoding = asset.coefficients.encoding();
    let coef_brick_bytes = (BRICK_VOXELS * rank * encoding.bytes_per_value()) as u64;
    let view_header = asset.view.as_ref().map(|view| ViewHeader {
        lobes: view.lobe_count() as u32,
        rank: view.rank() as u32,
        encoding: view.coefficients.encoding(),
    });
    let view_brick_bytes = view_header.map_or(0, |h| h.bytes_per_brick());
    let fine_brick_bytes = asset
        .fine_density
        .as_ref()
        .map_or(0, |f| fine_density_bytes_per_brick(f.factor));
    let largest_brick = coef_brick_bytes
        .max(view_brick_bytes)
        .max(fine_brick_bytes)
        .max(REFLECTION_BYTES_PER_BRICK)
        .max(2 * BRICK_VOXELS as u64);
    let max_chunk_bricks = (MAX_CHUNK_RAW_BYTES / largest_brick).max(1);
    let chunk_bricks = u64::from(options.chunk_bricks).clamp(1, max_chunk_bricks) as u32;
    let mut zstd = Zstd::new(options.zstd_level)?;
    let shuffle_width = |w: u32| if options.shuffle { w } else { 0 };

    let mut payloads: Vec<Payload> = Vec::new();

    let brick_bytes: Vec<u8> = asset
        .bricks
        .iter()
        .flat_map(|c| c.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    // Brick coordinates are always stored raw: 6 bytes a brick, so a reader can bound
    // every count by the file size before decoding anything.
    payloads.push(Payload::raw(KIND_BRICKS, brick_bytes));

    let density_bytes: Vec<u8> = asset
        .density
        .iter()
        .flat_map(|v| v.to_bits().to_le_bytes())
        .collect();
    payloads.push(zstd.chunked(
        KIND_DENSITY,
        &density_bytes,
        2 * BRICK_VOXELS,
        chunk_bricks as usize,
        shuffle_width(2),
    )?);

    // The fine density (1.4): optional, so that an older reader skips it and renders
    // `DENS`, the coarse asset.
    if let Some(fine) = &asset.fine_density {
        let bytes: Vec<u8> = fine
            .values
            .iter()
            .flat_map(|v| v.to_bits().to_le_bytes())
            .collect();
        let mut dnsf = zstd.chunked(
            KIND_FINE_DENSITY,
            &bytes,
            fine_brick_bytes as usize,
            chunk_bricks as usize,
            shuffle_width(2),
        )?;
        dnsf.entry.required = false;
        payloads.push(dnsf);
    }

    let pca_bytes: Vec<u8> = asset
        .pca
        .mean
        .iter()
        .chain(&asset.pca.basis)
        .flat_map(|v| v.to_le_bytes())
        .collect();
    payloads.push(zstd.whole(KIND_PCA, &pca_bytes, shuffle_width(4))?);

    if asset.coefficients.encoding() == CoefficientEncoding::U8Affine {
        let params = quant_param_bytes(&asset.coefficients);
        payloads.push(zstd.whole(KIND_QUANT_PARAMS, &params, 0)?);
    }

    let coefficient_bytes = asset.coefficients.value_bytes();
    let record = (rank * encoding.bytes_per_value()) as u32;
    payloads.push(zstd.chunked(
        KIND_COEFFICIENTS,
        &coefficient_bytes,
        coef_brick_bytes as usize,
        chunk_bricks as usize,
        shuffle_width(record),
    )?);

    // The view-dependent part (1.2): optional sections, so that a 1.1 reader skips them
    // and renders the PCA part, which is the view-averaged asset.
    if let (Some(view), Some(view_header)) = (&asset.view, view_header) {
        let mut params = view_header.to_bytes().to_vec();
        params.extend(view.lobes.iter().chain(&view.basis).flat_map(|v| v.to_le_bytes()));
        params.extend(quant_param_bytes(&view.coefficients));
        let mut vdep = zstd.whole(KIND_VIEW, &params, shuffle_width(4))?;
        vdep.entry.required = false;
        payloads.push(vdep);
        let record = (view.coefficients.rank() * view_header.encoding.bytes_per_value()) as u32;
        let mut vcof = zstd.chunked(
            KIND_VIEW_COEFFICIENTS,
            &view.coefficients.value_bytes(),
            view_brick_bytes as usize,
            chunk_bricks as usize,
            shuffle_width(record),
        )?;
        vcof.entry.required = false;
        payloads.push(vcof);
    }

    // The reflection part (1.3): optional sections as well.
    if let Some(reflection) = &asset.reflection {
        let mut params = (reflection.eyes_m.len() as u32).to_le_bytes().to_vec();
        params.extend(reflection.exponent.to_le_bytes());
        params.extend(reflection.eyes_m.iter().flatten().flat_map(|v| v.to_le_bytes()));
        params.extend(quant_param_bytes(&reflection.coefficients));
        let mut vref = zstd.whole(KIND_REFLECTION, &params, 0)?;
        vref.entry.required = false;
        payloads.push(vref);
        let mut vrco = zstd.chunked(
            KIND_REFLECTION_VALUES,
            &reflection.coefficients.value_bytes(),
            REFLECTION_BYTES_PER_BRICK as usize,
            chunk_bricks as usize,
            shuffle_width(Reflection::VALUES_PER_VOXEL as u32),
        )?;
        vrco.entry.required = false;
        payloads.push(vrco);
    }

    let metadata = serde_json::to_vec(&asset.metadata)?;
    if metadata.len() as u64 > MAX_METADATA_BYTES {
        return Err(FormatError::CountTooLarge {
            what: "metadata bytes".into(),
            count: metadata.len() as u64,
            limit: MAX_METADATA_BYTES,
        });
    }
    let mut meta = zstd.whole(KIND_METADATA, &metadata, 0)?;
    meta.entry.required = false;
    payloads.push(meta);

    // Lay out: header, table, then each section at the next multiple of 8.
    let section_count = payloads.len();
    let mut offset = (HEADER_SIZE + section_count * SECTION_ENTRY_SIZE) as u64;
    for p in &mut payloads {
        offset = offset.next_multiple_of(8);
        p.entry.offset = offset;
        offset += p.entry.stored_length;
    }
    let file_size = offset;
    let header = Header {
        version_major: VERSION_MAJOR,
        version_minor: if asset.fine_density.is_some() {
            VERSION_MINOR
        } else if asset.reflection.is_some() {
            VERSION_MINOR_REFLECTION
        } else if asset.view.is_some() {
            VERSION_MINOR_VIEW
        } else {
            VERSION_MINOR_WITHOUT_VIEW
        },
        section_count: section_count as u32,
        flags: if has_negative_density(&asset.density)
            || asset
                .fine_density
                .as_ref()
                .is_some_and(|f| has_negative_density(&f.values))
        {
            FLAG_SIGNED_DENSITY
        } else {
            0
        },
        grid: asset.grid,
        brick_count: asset.bricks.len() as u32,
        chunk_bricks,
        world_from_light: asset.world_from_light,
        env_height: crate::conventions::ENV_H as u16,
        env_width: crate::conventions::ENV_W as u16,
        pca_rank: rank as u32,
        coefficient_encoding: encoding,
        file_size,
        fine_density_factor: asset.fine_density.as_ref().map_or(0, |f| f.factor),
    };
    let mut header_bytes = header.to_bytes();
    let table: Vec<u8> = payloads.iter().flat_map(|p| p.entry.to_bytes()).collect();
    let sum = header_checksum(&header_bytes, &table);
    header_bytes[HEADER_CHECKSUM_OFFSET..HEADER_SIZE].copy_from_slice(&sum.to_le_bytes());

    let mut out = Vec::with_capacity(file_size as usize);
    out.extend_from_slice(&header_bytes);
    out.extend_from_slice(&table);
    for p in &payloads {
        out.resize(p.entry.offset as usize, 0);
        out.extend_from_slice(&p.stored);
    }
    debug_assert_eq!(out.len() as u64, file_size);
    Ok((out, payloads.into_iter().map(|p| p.entry).collect()))
}

/// The 8-bit dequantisation parameters of `coefficients` as stored (`QPRM`, the end of
/// `VDEP`): `(scale, offset)` `f32` pairs per component; nothing for `f16`.
fn quant_param_bytes(coefficients: &Coefficients) -> Vec<u8> {
    match coefficients {
        Coefficients::U8Affine { scale, offset, .. } => scale
            .iter()
            .zip(offset)
            .flat_map(|(s, o)| s.to_le_bytes().into_iter().chain(o.to_le_bytes()))
            .collect(),
        Coefficients::F16 { .. } => Vec::new(),
    }
}

/// A section's stored bytes and its table entry (offset filled in at layout).
struct Payload {
    entry: SectionEntry,
    stored: Vec<u8>,
}

impl Payload {
    /// A section stored as is.
    fn raw(kind: SectionKind, raw: Vec<u8>) -> Self {
        Self {
            entry: SectionEntry {
                kind,
                required: true,
                codec: SectionCodec::Raw,
                shuffle: 0,
                offset: 0,
                stored_length: raw.len() as u64,
                raw_length: raw.len() as u64,
                checksum: checksum(&raw),
            },
            stored: raw,
        }
    }
}

/// A reusable zstd compressor that names the section in its errors.
struct Zstd {
    level: i32,
    compressor: zstd::bulk::Compressor<'static>,
}

impl Zstd {
    fn new(level: i32) -> Result<Self> {
        Ok(Self {
            level,
            compressor: Self::compressor(level)?,
        })
    }

    fn compressor(level: i32) -> Result<zstd::bulk::Compressor<'static>> {
        zstd::bulk::Compressor::new(level).map_err(|e| FormatError::Zstd {
            what: format!("compressor at level {level}"),
            message: e.to_string(),
        })
    }

    fn compress(&mut self, what: impl Fn() -> String, data: &[u8]) -> Result<Vec<u8>> {
        compress_with(&mut self.compressor, what, data)
    }

    /// A whole section: zstd of the shuffled bytes, or raw if that is not smaller.
    fn whole(&mut self, kind: SectionKind, raw: &[u8], shuffle_width: u32) -> Result<Payload> {
        let shuffled = shuffle(raw, shuffle_width as usize);
        let compressed = self.compress(|| format!("section {}", kind_name(kind)), &shuffled)?;
        let (codec, shuffle_width, stored) = if compressed.len() < raw.len() {
            (SectionCodec::Zstd, shuffle_width, compressed)
        } else {
            (SectionCodec::Raw, 0, raw.to_vec())
        };
        Ok(Payload {
            entry: SectionEntry {
                kind,
                required: true,
                codec,
                shuffle: shuffle_width,
                offset: 0,
                stored_length: stored.len() as u64,
                raw_length: raw.len() as u64,
                checksum: checksum(&stored),
            },
            stored,
        })
    }

    /// A chunked section: chunk table, then one zstd frame per `chunk_bricks` bricks.
    fn chunked(
        &mut self,
        kind: SectionKind,
        raw: &[u8],
        bytes_per_brick: usize,
        chunk_bricks: usize,
        shuffle_width: u32,
    ) -> Result<Payload> {
        let chunk_bytes = bytes_per_brick * chunk_bricks;
        // Chunks are independent frames: compressed on all cores, one compressor per
        // thread, laid out in order (the bytes do not depend on the thread count).
        let level = self.level;
        let frames: Vec<Vec<u8>> = raw
            .par_chunks(chunk_bytes.max(1))
            .enumerate()
            .map_init(
                || Self::compressor(level),
                |compressor, (i, chunk)| {
                    let compressor = compressor.as_mut().map_err(|e| FormatError::Zstd {
                        what: format!("compressor at level {level}"),
                        message: e.to_string(),
                    })?;
                    let shuffled = shuffle(chunk, shuffle_width as usize);
                    compress_with(
                        compressor,
                        || format!("section {} chunk {i}", kind_name(kind)),
                        &shuffled,
                    )
                },
            )
            .collect::<Result<_>>()?;
        let mut table = Vec::with_capacity(frames.len() * CHUNK_ENTRY_SIZE);
        let mut data = Vec::new();
        let mut offset = (frames.len() * CHUNK_ENTRY_SIZE) as u64;
        for stored in &frames {
            table.extend_from_slice(&offset.to_le_bytes());
            table.extend_from_slice(&(stored.len() as u64).to_le_bytes());
            table.extend_from_slice(&checksum(stored).to_le_bytes());
            offset += stored.len() as u64;
            data.extend_from_slice(stored);
        }
        table.extend_from_slice(&data);
        Ok(Payload {
            entry: SectionEntry {
                kind,
                required: true,
                codec: SectionCodec::ChunkedZstd,
                shuffle: shuffle_width,
                offset: 0,
                stored_length: table.len() as u64,
                raw_length: raw.len() as u64,
                checksum: checksum(&table),
            },
            stored: table,
        })
    }
}

/// Compresses `data` with `compressor`, naming `what` in the error.
fn compress_with(
    compressor: &mut zstd::bulk::Compressor<'static>,
    what: impl Fn() -> String,
    data: &[u8],
) -> Result<Vec<u8>> {
    compressor.compress(data).map_err(|e| FormatError::Zstd {
        what: what(),
        message: e.to_string(),
    })
}
