//! `.nelf` reader: validates everything (SPEC.md, "Validation") and never panics or
//! allocates more than the file justifies.
//!
//! [`AssetReader`] opens a file (or any `Read + Seek` source), checks the header,
//! the section table and the small sections, and then reads single bricks on demand
//! by decoding only the chunk that holds them; [`read_asset`] and
//! [`read_asset_bytes`] decode the whole [`Asset`].
//!
//! Allocation bounds: the header and table are fixed-size; a section or chunk is read
//! only after its bounds are checked against the file size, and decompressed only
//! after its checksum matches, into a buffer of its declared decoded length, which
//! must equal what the header's counts require, be at most 4 MiB per chunk (1 MiB
//! for metadata), and be at most 32768 × its stored length (zstd's largest expansion).
//! Brick coordinates are stored raw, so every count is bounded by the file size.
//! Whole-asset decoding grows its arrays chunk by chunk, so a damaged or lying file
//! costs at most one chunk beyond what its intact chunks decode to.

use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use half::f16;

use crate::asset::{
    Asset, BrickData, CoefficientEncoding, Coefficients, PcaModel, json_type_name, validate_bricks,
    validate_density, validate_quant_params,
};
use crate::conventions::LT_DIM;
use crate::error::{FormatError, Result};
use crate::spec::{
    BRICK_VOXELS, CHUNK_ENTRY_SIZE, HEADER_CHECKSUM_OFFSET, HEADER_SIZE, Header, KIND_BRICKS,
    KIND_COEFFICIENTS, KIND_DENSITY, KIND_METADATA, KIND_PCA, KIND_QUANT_PARAMS, MAX_CHUNK_RAW_BYTES,
    MAX_METADATA_BYTES, MAX_ZSTD_EXPANSION, SECTION_ENTRY_SIZE, SectionCodec, SectionEntry, SectionKind,
    checksum, header_checksum, kind_name, u64_at, unshuffle,
};

/// Reads and fully validates the `.nelf` file at `path`.
pub fn read_asset(path: &Path) -> Result<Asset> {
    AssetReader::open(path)?.read_all()
}

/// Reads and fully validates a `.nelf` file held in memory.
pub fn read_asset_bytes(bytes: &[u8]) -> Result<Asset> {
    AssetReader::new(Cursor::new(bytes))?.read_all()
}

/// One chunk of a chunked section: where it is (absolute file offset) and its checksum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Chunk {
    offset: u64,
    stored_length: u64,
    checksum: u64,
}

/// A chunked section's entry and its parsed chunk table.
#[derive(Debug, Clone)]
struct ChunkedSection {
    entry: SectionEntry,
    /// The chunk table's bytes (the start of the section), kept for the section checksum.
    table_bytes: Vec<u8>,
    chunks: Vec<Chunk>,
    bytes_per_brick: u64,
}

/// The most recently decoded chunk, so that reading bricks in order decodes each chunk once.
#[derive(Debug, Clone)]
struct CachedChunk {
    index: usize,
    density: Vec<u8>,
    coefficients: Vec<u8>,
}

/// Random access to a `.nelf` file: validated header, section table, bricks, PCA
/// model and metadata in memory; density and coefficients decoded one chunk at a time.
#[derive(Debug)]
pub struct AssetReader<R> {
    source: R,
    path: Option<PathBuf>,
    header: Header,
    sections: Vec<SectionEntry>,
    bricks: Vec<[u16; 3]>,
    pca: PcaModel,
    quant_params: Option<(Vec<f32>, Vec<f32>)>,
    metadata: serde_json::Value,
    density: ChunkedSection,
    coefficients: ChunkedSection,
    cache: Option<CachedChunk>,
}

impl AssetReader<BufReader<File>> {
    /// Opens the file at `path` and validates its header, table and small sections.
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|source| FormatError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::with_path(BufReader::new(file), Some(path.to_path_buf()))
    }
}

impl<R: Read + Seek> AssetReader<R> {
    /// Validates the header, table and small sections of a `.nelf` stream.
    pub fn new(source: R) -> Result<Self> {
        Self::with_path(source, None)
    }

    fn with_path(mut source: R, path: Option<PathBuf>) -> Result<Self> {
        let io = |during: &str, source: std::io::Error| io_error(path.as_deref(), during, source);
        let file_size = source
            .seek(SeekFrom::End(0))
            .map_err(|e| io("seeking to the end", e))?;
        source
            .seek(SeekFrom::Start(0))
            .map_err(|e| io("seeking to the start", e))?;
        let head_len = file_size.min(HEADER_SIZE as u64) as usize;
        let mut head = vec![0u8; head_len];
        source
            .read_exact(&mut head)
            .map_err(|e| io("reading the header", e))?;
        let header = Header::from_bytes(&head, file_size)?;
        // from_bytes checked that the table fits inside the file.
        let table_len = header.section_count as usize * SECTION_ENTRY_SIZE;
        let mut table = vec![0u8; table_len];
        source
            .read_exact(&mut table)
            .map_err(|e| io("reading the section table", e))?;
        let stored = u64_at(&head, HEADER_CHECKSUM_OFFSET);
        let computed = header_checksum(&head, &table);
        if checksums_differ(stored, computed) {
            return Err(FormatError::ChecksumMismatch {
                what: "header and section table".into(),
                stored,
                computed,
            });
        }
        let sections: Vec<SectionEntry> = table
            .chunks_exact(SECTION_ENTRY_SIZE)
            .map(|b| {
                let mut entry = [0u8; SECTION_ENTRY_SIZE];
                entry.copy_from_slice(b);
                SectionEntry::from_bytes(&entry)
            })
            .collect();
        validate_table(&header, &sections)?;

        let mut reader = PartialReader {
            source: &mut source,
            path: path.as_deref(),
        };
        let find = |kind: SectionKind| sections.iter().find(|s| s.kind == kind).copied();
        let missing = |kind: SectionKind| FormatError::MissingSection {
            section: kind_name(kind),
        };

        let brick_entry = find(KIND_BRICKS).ok_or_else(|| missing(KIND_BRICKS))?;
        let brick_bytes = reader.whole_section(&brick_entry)?;
        let bricks: Vec<[u16; 3]> = brick_bytes
            .chunks_exact(6)
            .map(|b| {
                [
                    u16::from_le_bytes([b[0], b[1]]),
                    u16::from_le_bytes([b[2], b[3]]),
                    u16::from_le_bytes([b[4], b[5]]),
                ]
            })
            .collect();
        drop(brick_bytes);
        validate_bricks(&bricks, header.grid.grid_bricks)?;

        let pca_entry = find(KIND_PCA).ok_or_else(|| missing(KIND_PCA))?;
        let floats = f32s(&reader.whole_section(&pca_entry)?);
        let pca = PcaModel {
            mean: floats[..LT_DIM].to_vec(),
            basis: floats[LT_DIM..].to_vec(),
        };
        pca.validate()?;

        let quant_params = match (header.coefficient_encoding, find(KIND_QUANT_PARAMS)) {
            (CoefficientEncoding::U8Affine, Some(entry)) => {
                let floats = f32s(&reader.whole_section(&entry)?);
                let scale: Vec<f32> = floats.iter().step_by(2).copied().collect();
                let offset: Vec<f32> = floats.iter().skip(1).step_by(2).copied().collect();
                validate_quant_params(&scale, &offset)?;
                Some((scale, offset))
            }
            (CoefficientEncoding::U8Affine, None) => return Err(missing(KIND_QUANT_PARAMS)),
            (CoefficientEncoding::F16, Some(_)) => {
                return Err(FormatError::InvalidHeader {
                    field: "coefficient_encoding",
                    reason: "f16 coefficients need no QPRM section, but one is present".into(),
                });
            }
            (CoefficientEncoding::F16, None) => None,
        };

        let metadata = match find(KIND_METADATA) {
            Some(entry) => {
                let bytes = reader.whole_section(&entry)?;
                let value: serde_json::Value = serde_json::from_slice(&bytes)?;
                if !value.is_object() {
                    return Err(FormatError::MetadataNotObject {
                        found: json_type_name(&value),
                    });
                }
                value
            }
            None => serde_json::Value::Object(serde_json::Map::new()),
        };

        let density_entry = find(KIND_DENSITY).ok_or_else(|| missing(KIND_DENSITY))?;
        let density = reader.chunk_table(&header, density_entry, 2 * BRICK_VOXELS as u64)?;
        let coefficient_entry = find(KIND_COEFFICIENTS).ok_or_else(|| missing(KIND_COEFFICIENTS))?;
        let coefficients =
            reader.chunk_table(&header, coefficient_entry, header.coefficient_bytes_per_brick())?;

        Ok(Self {
            source,
            path,
            header,
            sections,
            bricks,
            pca,
            quant_params,
            metadata,
            density,
            coefficients,
            cache: None,
        })
    }

    /// The validated header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The section table, in file-table order (unknown optional sections included).
    pub fn sections(&self) -> &[SectionEntry] {
        &self.sections
    }

    /// Brick coordinates, in file order.
    pub fn bricks(&self) -> &[[u16; 3]] {
        &self.bricks
    }

    /// The PCA model.
    pub fn pca(&self) -> &PcaModel {
        &self.pca
    }

    /// The metadata object (empty if the file has none).
    pub fn metadata(&self) -> &serde_json::Value {
        &self.metadata
    }

    /// Reads brick `index`: its coordinates, densities (1/m) and dequantized
    /// coefficients. Decodes (and checksums) only the chunk holding it; the last
    /// chunk decoded is kept, so reading bricks in order decodes each chunk once.
    pub fn read_brick(&mut self, index: usize) -> Result<BrickData> {
        if index >= self.bricks.len() {
            return Err(FormatError::BrickOutOfRange {
                index,
                count: self.bricks.len(),
            });
        }
        let chunk_bricks = self.header.chunk_bricks as usize;
        let chunk = index / chunk_bricks;
        let cached = match self.cache.take() {
            Some(c) if c.index == chunk => c,
            _ => CachedChunk {
                index: chunk,
                density: self.decode_chunk(false, chunk)?,
                coefficients: self.decode_chunk(true, chunk)?,
            },
        };
        let cached = self.cache.insert(cached);
        let within = index - chunk * chunk_bricks;
        let d_bytes = 2 * BRICK_VOXELS;
        let density: Vec<f16> = f16s(&cached.density[within * d_bytes..(within + 1) * d_bytes]);
        validate_density(&density, index * BRICK_VOXELS, self.header.signed_density())?;
        let c_bytes = self.coefficients.bytes_per_brick as usize;
        let raw = &cached.coefficients[within * c_bytes..(within + 1) * c_bytes];
        let coefficients = dequantize(
            raw,
            &self.header,
            self.quant_params.as_ref(),
            index * BRICK_VOXELS,
        )?;
        Ok(BrickData {
            coord: self.bricks[index],
            density: density.iter().map(|d| d.to_f32()).collect(),
            coefficients,
        })
    }

    /// Checks every byte: all section checksums (unknown optional sections too), every
    /// chunk's checksum and decoding, and every value's range. Memory: one chunk.
    pub fn verify(&mut self) -> Result<()> {
        self.visit_chunks(false, &mut |_, _| Ok(()))?;
        self.visit_chunks(true, &mut |_, _| Ok(()))?;
        self.verify_other_sections()
    }

    /// Decodes the whole asset, checking every checksum and value.
    pub fn read_all(mut self) -> Result<Asset> {
        let mut density: Vec<f16> = Vec::new();
        self.visit_chunks(false, &mut |_, raw| {
            density.extend(f16s(raw));
            Ok(())
        })?;
        let mut codes: Vec<u8> = Vec::new();
        self.visit_chunks(true, &mut |_, raw| {
            codes.extend_from_slice(raw);
            Ok(())
        })?;
        self.verify_other_sections()?;
        let rank = self.header.pca_rank as usize;
        let coefficients = match self.quant_params.take() {
            Some((scale, offset)) => Coefficients::U8Affine {
                rank,
                scale,
                offset,
                codes,
            },
            None => Coefficients::F16 {
                rank,
                values: f16s(&codes),
            },
        };
        let asset = Asset {
            grid: self.header.grid,
            world_from_light: self.header.world_from_light,
            bricks: self.bricks,
            density,
            pca: self.pca,
            coefficients,
            view: None,
            metadata: self.metadata,
        };
        asset.validate()?;
        Ok(asset)
    }

    /// Streams the checksums of sections that are not chunked (the small ones were
    /// checked at open; this covers unknown optional sections).
    fn verify_other_sections(&mut self) -> Result<()> {
        let others: Vec<SectionEntry> = self
            .sections
            .iter()
            .filter(|s| s.kind != KIND_DENSITY && s.kind != KIND_COEFFICIENTS)
            .copied()
            .collect();
        let mut reader = PartialReader {
            source: &mut self.source,
            path: self.path.as_deref(),
        };
        for entry in others {
            reader.stream_checksum(&entry)?;
        }
        // Every byte not in the header, the table or a section must be zero.
        let mut spans: Vec<(u64, u64)> = self
            .sections
            .iter()
            .map(|s| (s.offset, s.offset + s.stored_length))
            .collect();
        spans.sort_unstable();
        let mut cursor = self.header.data_start();
        for (start, end) in spans
            .into_iter()
            .chain([(self.header.file_size, self.header.file_size)])
        {
            if start > cursor {
                reader.check_zero(cursor, start - cursor)?;
            }
            cursor = cursor.max(end);
        }
        Ok(())
    }

    /// Decodes every chunk of the density (`false`) or coefficient (`true`) section in
    /// order, validates its values, hands the decoded bytes to `f`, and checks the
    /// section checksum over the chunk table and all chunks.
    fn visit_chunks(
        &mut self,
        coefficients: bool,
        f: &mut dyn FnMut(usize, &[u8]) -> Result<()>,
    ) -> Result<()> {
        let section = if coefficients {
            &self.coefficients
        } else {
            &self.density
        };
        let entry = section.entry;
        let mut hasher = xxhash_rust::xxh3::Xxh3Default::new();
        hasher.update(&section.table_bytes);
        let chunk_count = section.chunks.len();
        for i in 0..chunk_count {
            let (stored, raw) = self.read_and_decode_chunk(coefficients, i)?;
            hasher.update(&stored);
            drop(stored);
            let first_voxel = i * self.header.chunk_bricks as usize * BRICK_VOXELS;
            if coefficients {
                if self.header.coefficient_encoding == CoefficientEncoding::F16 {
                    check_finite_f16(&f16s(&raw), self.header.pca_rank as usize, first_voxel)?;
                }
            } else {
                validate_density(&f16s(&raw), first_voxel, self.header.signed_density())?;
            }
            f(i, &raw)?;
        }
        let computed = hasher.digest();
        if checksums_differ(entry.checksum, computed) {
            return Err(FormatError::ChecksumMismatch {
                what: format!("section {}", entry.name()),
                stored: entry.checksum,
                computed,
            });
        }
        Ok(())
    }

    fn decode_chunk(&mut self, coefficients: bool, index: usize) -> Result<Vec<u8>> {
        Ok(self.read_and_decode_chunk(coefficients, index)?.1)
    }

    /// Reads chunk `index`'s stored bytes, checks its checksum, and decodes it.
    fn read_and_decode_chunk(&mut self, coefficients: bool, index: usize) -> Result<(Vec<u8>, Vec<u8>)> {
        let section = if coefficients {
            &self.coefficients
        } else {
            &self.density
        };
        let chunk = section.chunks[index];
        let entry = section.entry;
        let raw_length = self.header.bricks_in_chunk(index as u64) * section.bytes_per_brick;
        let what = format!("section {} chunk {index}", entry.name());
        let mut reader = PartialReader {
            source: &mut self.source,
            path: self.path.as_deref(),
        };
        let stored = reader.read_at(chunk.offset, chunk.stored_length, &what)?;
        let computed = checksum(&stored);
        if checksums_differ(chunk.checksum, computed) {
            return Err(FormatError::ChecksumMismatch {
                what,
                stored: chunk.checksum,
                computed,
            });
        }
        let raw = decompress(&stored, raw_length, &what)?;
        Ok((stored, unshuffle(&raw, entry.shuffle as usize)))
    }
}

/// Borrowed source plus path, for reading sections during and after open.
struct PartialReader<'a, R> {
    source: &'a mut R,
    path: Option<&'a Path>,
}

impl<R: Read + Seek> PartialReader<'_, R> {
    /// Reads `length` bytes at `offset` (bounds were validated against the file size).
    fn read_at(&mut self, offset: u64, length: u64, what: &str) -> Result<Vec<u8>> {
        let io = |source| io_error(self.path, &format!("reading {what}"), source);
        self.source.seek(SeekFrom::Start(offset)).map_err(io)?;
        let mut buf = vec![0u8; length as usize];
        self.source
            .read_exact(&mut buf)
            .map_err(|source| io_error(self.path, &format!("reading {what}"), source))?;
        Ok(buf)
    }

    /// Reads, checksums and decodes a whole (non-chunked) section.
    fn whole_section(&mut self, entry: &SectionEntry) -> Result<Vec<u8>> {
        let what = format!("section {}", entry.name());
        let stored = self.read_at(entry.offset, entry.stored_length, &what)?;
        let computed = checksum(&stored);
        if checksums_differ(entry.checksum, computed) {
            return Err(FormatError::ChecksumMismatch {
                what,
                stored: entry.checksum,
                computed,
            });
        }
        match entry.codec {
            SectionCodec::Raw => Ok(stored),
            SectionCodec::Zstd => {
                let raw = decompress(&stored, entry.raw_length, &what)?;
                Ok(unshuffle(&raw, entry.shuffle as usize))
            }
            SectionCodec::ChunkedZstd | SectionCodec::Unknown(_) => Err(FormatError::BadCodec {
                section: entry.name(),
                reason: format!("codec {} cannot hold this section", entry.codec.name()),
            }),
        }
    }

    /// Checks a section's checksum reading it in pieces of at most 1 MiB.
    fn stream_checksum(&mut self, entry: &SectionEntry) -> Result<()> {
        const PIECE: u64 = 1 << 20;
        let mut hasher = xxhash_rust::xxh3::Xxh3Default::new();
        let what = format!("section {}", entry.name());
        let mut done = 0u64;
        while done < entry.stored_length {
            let n = PIECE.min(entry.stored_length - done);
            hasher.update(&self.read_at(entry.offset + done, n, &what)?);
            done += n;
        }
        let computed = hasher.digest();
        if checksums_differ(entry.checksum, computed) {
            return Err(FormatError::ChecksumMismatch {
                what,
                stored: entry.checksum,
                computed,
            });
        }
        Ok(())
    }

    /// Checks that `length` bytes at `offset` are zero, reading at most 1 MiB at a time.
    fn check_zero(&mut self, offset: u64, length: u64) -> Result<()> {
        const PIECE: u64 = 1 << 20;
        let mut done = 0u64;
        while done < length {
            let n = PIECE.min(length - done);
            let bytes = self.read_at(offset + done, n, "padding")?;
            if let Some(i) = bytes.iter().position(|&b| b != 0) {
                return Err(FormatError::NonZeroPadding {
                    offset: offset + done + i as u64,
                });
            }
            done += n;
        }
        Ok(())
    }

    /// Reads and validates the chunk table at the start of a chunked section: one
    /// entry per chunk, chunks tiling the rest of the section in order, each chunk's
    /// declared decoded length plausible for its stored length.
    fn chunk_table(
        &mut self,
        header: &Header,
        entry: SectionEntry,
        bytes_per_brick: u64,
    ) -> Result<ChunkedSection> {
        let name = entry.name();
        let bad = |reason: String| FormatError::BadChunkTable {
            section: name.clone(),
            reason,
        };
        let chunk_count = header.chunk_count();
        let table_len = chunk_count * CHUNK_ENTRY_SIZE as u64;
        if table_len > entry.stored_length {
            return Err(FormatError::CountTooLarge {
                what: format!("chunks in section {name} (⌈brick_count / chunk_bricks⌉)"),
                count: chunk_count,
                limit: entry.stored_length / CHUNK_ENTRY_SIZE as u64,
            });
        }
        let table_bytes = self.read_at(entry.offset, table_len, &format!("section {name} chunk table"))?;
        let mut chunks = Vec::with_capacity(chunk_count as usize);
        let mut expected = table_len;
        for (i, e) in table_bytes.chunks_exact(CHUNK_ENTRY_SIZE).enumerate() {
            let (offset, stored_length, sum) = (u64_at(e, 0), u64_at(e, 8), u64_at(e, 16));
            if offset != expected {
                return Err(bad(format!("chunk {i} starts at {offset}, expected {expected}")));
            }
            expected = match offset.checked_add(stored_length) {
                Some(end) if end <= entry.stored_length => end,
                _ => {
                    return Err(bad(format!(
                        "chunk {i} ({stored_length} bytes at {offset}) runs past the section's {} bytes",
                        entry.stored_length
                    )));
                }
            };
            let raw = header.bricks_in_chunk(i as u64) * bytes_per_brick;
            check_plausible(raw, stored_length, || format!("section {name} chunk {i}"))?;
            chunks.push(Chunk {
                offset: entry.offset + offset,
                stored_length,
                checksum: sum,
            });
        }
        if expected != entry.stored_length {
            return Err(bad(format!(
                "chunks end at {expected} but the section is {} bytes",
                entry.stored_length
            )));
        }
        Ok(ChunkedSection {
            entry,
            table_bytes,
            chunks,
            bytes_per_brick,
        })
    }
}

/// Whether a stored checksum disagrees with the computed one. Builds for fuzzing
/// (`cargo fuzz` sets `--cfg fuzzing`) ignore checksums, so that mutated inputs reach
/// the decoders and value checks behind them instead of stopping at the first hash.
#[allow(unexpected_cfgs)]
fn checksums_differ(stored: u64, computed: u64) -> bool {
    !cfg!(fuzzing) && stored != computed
}

/// Maps an I/O error to [`FormatError::Io`] (with a path) or [`FormatError::Stream`].
fn io_error(path: Option<&Path>, during: &str, source: std::io::Error) -> FormatError {
    match path {
        Some(p) => FormatError::Io {
            path: p.to_path_buf(),
            source: std::io::Error::new(source.kind(), format!("{during}: {source}")),
        },
        None => FormatError::Stream {
            during: during.to_string(),
            source,
        },
    }
}

/// Rejects a declared decoded length that zstd cannot produce from `stored` bytes.
fn check_plausible(raw: u64, stored: u64, what: impl Fn() -> String) -> Result<()> {
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
fn decompress(stored: &[u8], raw_length: u64, what: &str) -> Result<Vec<u8>> {
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

/// Expected decoded length of a known section, or `None` for metadata (variable).
fn expected_raw_length(header: &Header, kind: SectionKind) -> Option<u64> {
    let bricks = u64::from(header.brick_count);
    let rank = u64::from(header.pca_rank);
    match kind {
        KIND_BRICKS => Some(6 * bricks),
        KIND_DENSITY => Some(2 * BRICK_VOXELS as u64 * bricks),
        KIND_PCA => Some(4 * LT_DIM as u64 * (rank + 1)),
        KIND_QUANT_PARAMS => Some(8 * rank),
        KIND_COEFFICIENTS => Some(header.coefficient_bytes_per_brick() * bricks),
        _ => None,
    }
}

fn is_known(kind: SectionKind) -> bool {
    [
        KIND_BRICKS,
        KIND_DENSITY,
        KIND_PCA,
        KIND_QUANT_PARAMS,
        KIND_COEFFICIENTS,
        KIND_METADATA,
    ]
    .contains(&kind)
}

/// Checks the section table: bounds, alignment, overlaps, duplicates, unknown
/// required kinds, codecs and shuffles, and declared lengths against the header.
fn validate_table(header: &Header, sections: &[SectionEntry]) -> Result<()> {
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
    for s in sections {
        if !is_known(s.kind) {
            if s.required {
                return Err(FormatError::UnknownRequiredSection { section: s.name() });
            }
            continue;
        }
        validate_known_entry(header, s)?;
    }
    for kind in [KIND_BRICKS, KIND_DENSITY, KIND_PCA, KIND_COEFFICIENTS] {
        if !sections.iter().any(|s| s.kind == kind) {
            return Err(FormatError::MissingSection {
                section: kind_name(kind),
            });
        }
    }
    Ok(())
}

fn validate_known_entry(header: &Header, s: &SectionEntry) -> Result<()> {
    let name = s.name();
    let bad = |reason: String| FormatError::BadCodec {
        section: name.clone(),
        reason,
    };
    let chunked = s.kind == KIND_DENSITY || s.kind == KIND_COEFFICIENTS;
    match (s.codec, chunked) {
        (SectionCodec::Raw, false) | (SectionCodec::ChunkedZstd, true) => {}
        (SectionCodec::Zstd, false) if s.kind != KIND_BRICKS => {}
        (codec, _) => {
            return Err(bad(format!(
                "codec {} is not allowed for this section",
                codec.name()
            )));
        }
    }
    match expected_raw_length(header, s.kind) {
        Some(expected) if expected != s.raw_length => {
            return Err(FormatError::SectionLength {
                section: name,
                expected,
                found: s.raw_length,
            });
        }
        Some(_) => {}
        None => {
            if s.raw_length > MAX_METADATA_BYTES {
                return Err(FormatError::CountTooLarge {
                    what: format!("section {name} decoded length"),
                    count: s.raw_length,
                    limit: MAX_METADATA_BYTES,
                });
            }
        }
    }
    let width = u64::from(s.shuffle);
    match s.codec {
        SectionCodec::Raw => {
            if s.shuffle != 0 {
                return Err(bad(format!("raw section with shuffle width {}", s.shuffle)));
            }
            if s.stored_length != s.raw_length {
                return Err(bad(format!(
                    "raw section stores {} bytes but declares {} decoded",
                    s.stored_length, s.raw_length
                )));
            }
        }
        SectionCodec::Zstd => {
            if width > 1 && s.raw_length % width != 0 {
                return Err(bad(format!(
                    "shuffle width {width} does not divide decoded length {}",
                    s.raw_length
                )));
            }
            check_plausible(s.raw_length, s.stored_length, || format!("section {name}"))?;
        }
        SectionCodec::ChunkedZstd => {
            let per_brick = if s.kind == KIND_DENSITY {
                2 * BRICK_VOXELS as u64
            } else {
                header.coefficient_bytes_per_brick()
            };
            if width > 1 && per_brick % width != 0 {
                return Err(bad(format!(
                    "shuffle width {width} does not divide the {per_brick} bytes of a brick"
                )));
            }
            if u64::from(header.chunk_bricks) * per_brick > MAX_CHUNK_RAW_BYTES {
                return Err(FormatError::CountTooLarge {
                    what: format!("section {name} chunk decoded bytes"),
                    count: u64::from(header.chunk_bricks) * per_brick,
                    limit: MAX_CHUNK_RAW_BYTES,
                });
            }
        }
        SectionCodec::Unknown(_) => {}
    }
    Ok(())
}

/// Little-endian `f32`s of `bytes` (length a multiple of 4).
fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// Little-endian binary16s of `bytes`.
fn f16s(bytes: &[u8]) -> Vec<f16> {
    bytes
        .chunks_exact(2)
        .map(|b| f16::from_bits(u16::from_le_bytes([b[0], b[1]])))
        .collect()
}

/// Dequantizes one brick's stored coefficients to `f32`, rejecting non-finite `f16`s.
fn dequantize(
    raw: &[u8],
    header: &Header,
    quant_params: Option<&(Vec<f32>, Vec<f32>)>,
    first_voxel: usize,
) -> Result<Vec<f32>> {
    let rank = header.pca_rank as usize;
    // `quant_params` is present exactly when the encoding is 8-bit (checked at open).
    if let Some((scale, offset)) = quant_params {
        return Ok(raw
            .iter()
            .enumerate()
            .map(|(i, &code)| offset[i % rank] + scale[i % rank] * f32::from(code))
            .collect());
    }
    let values = f16s(raw);
    check_finite_f16(&values, rank, first_voxel)?;
    Ok(values.iter().map(|v| v.to_f32()).collect())
}

/// Rejects NaN or infinite `f16` coefficients, naming the voxel and component.
fn check_finite_f16(values: &[f16], rank: usize, first_voxel: usize) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(FormatError::NonFinite {
            what: format!(
                "section COEF voxel {} component {}",
                first_voxel + i / rank.max(1),
                i % rank.max(1)
            ),
        }),
        None => Ok(()),
    }
}
