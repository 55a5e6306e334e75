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
//! must equal what the header's counts require (for `VCOF`, the counts of `VDEP`), be at
//! most 4 MiB per chunk (1 MiB for metadata, 593 236 bytes for `VDEP`), and be at most
//! 32768 × its stored length (zstd's largest expansion). Brick coordinates are stored
//! raw, so every count is bounded by the file size.
//! Whole-asset decoding grows its arrays chunk by chunk, so a damaged or lying file
//! costs at most one chunk beyond what its intact chunks decode to.

use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use half::f16;

use crate::asset::{
    Asset, BrickData, CoefficientEncoding, Coefficients, FineDensity, PcaModel, Reflection, ViewDependence,
    json_type_name, validate_bricks, validate_density, validate_density_values, validate_quant_params,
};
use crate::conventions::LT_DIM;
use crate::error::{FormatError, Result};
use crate::io_error::IoResultExt;
use crate::spec::{
    BRICK_VOXELS, CHUNK_ENTRY_SIZE, HEADER_CHECKSUM_OFFSET, HEADER_SIZE, Header, KIND_BRICKS,
    KIND_COEFFICIENTS, KIND_DENSITY, KIND_FINE_DENSITY, KIND_METADATA, KIND_PCA, KIND_QUANT_PARAMS,
    KIND_REFLECTION, KIND_REFLECTION_VALUES, KIND_VIEW, KIND_VIEW_COEFFICIENTS, REFLECTION_BYTES_PER_BRICK,
    SECTION_ENTRY_SIZE, SectionCodec, SectionEntry, SectionKind, checksum, header_checksum, kind_name,
    u64_at, unshuffle,
};

mod sections;

use sections::{
    DENSITY_BYTES_PER_BRICK, check_plausible, checksums_differ, decompress, f16s, f32s, io_error, pairs,
    reflection_params, validate_chunked_entry, validate_table, view_bytes_per_brick, view_params,
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

/// What a chunked section holds (the index of its [`ChunkedSection`] in
/// `AssetReader::chunked`, which is the order a full read visits them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Chunked {
    /// `DENS`: `f16` densities.
    Density = 0,
    /// `COEF`: the PCA coefficients.
    Coefficients = 1,
    /// `VCOF`: the view-dependent coefficients (format 1.2, optional).
    View = 2,
    /// `VRCO`: the reflection part's values (format 1.3, optional).
    Reflection = 3,
    /// `DNSF`: the fine density (format 1.4, optional).
    FineDensity = 4,
}

impl Chunked {
    const ALL: [Self; 5] = [
        Self::Density,
        Self::Coefficients,
        Self::View,
        Self::Reflection,
        Self::FineDensity,
    ];
}

/// A chunked section's entry and its parsed chunk table.
#[derive(Debug, Clone)]
struct ChunkedSection {
    /// What it holds.
    what: Chunked,
    entry: SectionEntry,
    /// The chunk table's bytes (the start of the section), kept for the section checksum.
    table_bytes: Vec<u8>,
    chunks: Vec<Chunk>,
    bytes_per_brick: u64,
}

/// The most recently decoded chunk of every chunked section, so that reading bricks in
/// order decodes each chunk once.
#[derive(Debug, Clone)]
struct CachedChunk {
    index: usize,
    /// Decoded bytes, one per entry of `AssetReader::chunked`.
    raw: Vec<Vec<u8>>,
}

/// Random access to a `.nelf` file: validated header, section table, bricks, PCA
/// model, view-dependent parameters and metadata in memory; density and coefficients
/// decoded one chunk at a time.
#[derive(Debug)]
pub struct AssetReader<R> {
    source: R,
    path: Option<PathBuf>,
    header: Header,
    sections: Vec<SectionEntry>,
    bricks: Vec<[u16; 3]>,
    pca: PcaModel,
    /// The coefficients' rank, encoding and 8-bit parameters, without voxels.
    coefficients: Coefficients,
    /// The view-dependent part (`VDEP`) without voxels, if the file has one.
    view: Option<ViewDependence>,
    /// The reflection part (`VREF`) without voxels, if the file has one.
    reflection: Option<Reflection>,
    metadata: serde_json::Value,
    /// `DENS`, `COEF`, then `VCOF` or `VRCO` when there is a view-dependent part, then
    /// `DNSF` when there is a fine density (see [`Chunked`]).
    chunked: Vec<ChunkedSection>,
    cache: Option<CachedChunk>,
}

impl AssetReader<BufReader<File>> {
    /// Opens the file at `path` and validates its header, table and small sections.
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).with_path(path)?;
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

        let rank = header.pca_rank as usize;
        let coefficients = match (header.coefficient_encoding, find(KIND_QUANT_PARAMS)) {
            (CoefficientEncoding::U8Affine, Some(entry)) => {
                let (scale, offset) = pairs(&f32s(&reader.whole_section(&entry)?));
                validate_quant_params(&scale, &offset, "QPRM")?;
                Coefficients::U8Affine {
                    rank,
                    scale,
                    offset,
                    codes: Vec::new(),
                }
            }
            (CoefficientEncoding::U8Affine, None) => return Err(missing(KIND_QUANT_PARAMS)),
            (CoefficientEncoding::F16, Some(_)) => {
                return Err(FormatError::InvalidHeader {
                    field: "coefficient_encoding",
                    reason: "f16 coefficients need no QPRM section, but one is present".into(),
                });
            }
            (CoefficientEncoding::F16, None) => Coefficients::F16 {
                rank,
                values: Vec::new(),
            },
        };

        // The view-dependent part: VDEP gives the size of VCOF's bricks, so VCOF's entry
        // is checked only now (validate_table made sure both or neither are present).
        let view = match (find(KIND_VIEW), find(KIND_VIEW_COEFFICIENTS)) {
            (Some(params), Some(values)) => {
                let (view_header, view) = view_params(&reader.whole_section(&params)?)?;
                validate_chunked_entry(&header, &values, view_header.bytes_per_brick())?;
                Some(view)
            }
            _ => None,
        };
        let reflection = match (find(KIND_REFLECTION), find(KIND_REFLECTION_VALUES)) {
            (Some(params), Some(_)) => Some(reflection_params(&reader.whole_section(&params)?)?),
            _ => None,
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

        let mut chunked = Vec::with_capacity(Chunked::ALL.len());
        for which in Chunked::ALL {
            let (kind, bytes_per_brick) = match which {
                Chunked::Density => (KIND_DENSITY, DENSITY_BYTES_PER_BRICK),
                Chunked::Coefficients => (KIND_COEFFICIENTS, header.coefficient_bytes_per_brick()),
                Chunked::View => match &view {
                    Some(v) => (KIND_VIEW_COEFFICIENTS, view_bytes_per_brick(v)),
                    None => continue,
                },
                Chunked::Reflection => match &reflection {
                    Some(_) => (KIND_REFLECTION_VALUES, REFLECTION_BYTES_PER_BRICK),
                    None => continue,
                },
                Chunked::FineDensity => match header.fine_density_factor {
                    0 => continue,
                    _ => (KIND_FINE_DENSITY, header.fine_density_bytes_per_brick()),
                },
            };
            let entry = find(kind).ok_or_else(|| missing(kind))?;
            chunked.push(reader.chunk_table(&header, which, entry, bytes_per_brick)?);
        }

        Ok(Self {
            source,
            path,
            header,
            sections,
            bricks,
            pca,
            coefficients,
            view,
            reflection,
            metadata,
            chunked,
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

    /// The view-dependent part's parameters (format 1.2, section `VDEP`): its lobes, view
    /// basis and coefficient encoding, or `None` for a file without one. Its
    /// `coefficients` hold no voxel, only the rank `J·K_v`, the encoding and (8-bit) the
    /// dequantisation parameters; [`Self::read_brick`] gives each brick's coefficients
    /// dequantized, and [`ViewDependence::add_to`] adds a voxel's view-dependent transport.
    pub fn view_params(&self) -> Option<&ViewDependence> {
        self.view.as_ref()
    }

    /// The reflection part's parameters (format 1.3, section `VREF`): exponent, eyes and
    /// the values' dequantisation, or `None` for a file without one; its `coefficients`
    /// hold no voxel ([`Self::read_brick`] gives each brick's values).
    pub fn reflection_params(&self) -> Option<&Reflection> {
        self.reflection.as_ref()
    }

    /// Reads brick `index`: its coordinates, densities (1/m), dequantized coefficients
    /// and view-dependent coefficients or reflection values. Decodes (and checksums) only the chunk holding
    /// it in each chunked section; the last chunk decoded is kept, so reading bricks in
    /// order decodes each chunk once.
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
                raw: (0..self.chunked.len())
                    .map(|which| self.decode_chunk(which, chunk))
                    .collect::<Result<_>>()?,
            },
        };
        let slots: Vec<Chunked> = self.chunked.iter().map(|c| c.what).collect();
        let cached = self.cache.insert(cached);
        let within = index - chunk * chunk_bricks;
        let brick = |which: Chunked| {
            let slot = slots.iter().position(|&w| w == which).unwrap_or(0);
            let n = self.chunked[slot].bytes_per_brick as usize;
            &cached.raw[slot][within * n..(within + 1) * n]
        };
        let first_voxel = index * BRICK_VOXELS;
        let density: Vec<f16> = f16s(brick(Chunked::Density));
        validate_density(&density, first_voxel, self.header.signed_density())?;
        let coefficients =
            self.coefficients
                .dequantize_stored(brick(Chunked::Coefficients), first_voxel, "COEF")?;
        let view_coefficients = match &self.view {
            Some(view) => view
                .coefficients
                .dequantize_stored(brick(Chunked::View), first_voxel, "VCOF")?,
            None => Vec::new(),
        };
        let reflection = match &self.reflection {
            Some(part) => {
                part.coefficients
                    .dequantize_stored(brick(Chunked::Reflection), first_voxel, "VRCO")?
            }
            None => Vec::new(),
        };
        let fine_density = if slots.contains(&Chunked::FineDensity) {
            let values = f16s(brick(Chunked::FineDensity));
            validate_density_values(
                &values,
                index * values.len(),
                self.header.signed_density(),
                "DNSF",
            )?;
            values.iter().map(|d| d.to_f32()).collect()
        } else {
            Vec::new()
        };
        Ok(BrickData {
            coord: self.bricks[index],
            density: density.iter().map(|d| d.to_f32()).collect(),
            coefficients,
            view_coefficients,
            reflection,
            fine_density,
        })
    }

    /// Index in `self.chunked` of the section holding `which`, if the file has it.
    fn slot(&self, which: Chunked) -> Option<usize> {
        self.chunked.iter().position(|c| c.what == which)
    }

    /// Checks every byte: all section checksums (unknown optional sections too), every
    /// chunk's checksum and decoding, and every value's range. Memory: one chunk.
    pub fn verify(&mut self) -> Result<()> {
        for which in 0..self.chunked.len() {
            self.visit_chunks(which, &mut |_| ())?;
        }
        self.verify_other_sections()
    }

    /// Decodes the whole asset, checking every checksum and value.
    pub fn read_all(mut self) -> Result<Asset> {
        let mut density: Vec<f16> = Vec::new();
        self.visit_chunks(Chunked::Density as usize, &mut |raw| density.extend(f16s(raw)))?;
        let mut coefficients = self.coefficients.clone();
        self.visit_chunks(Chunked::Coefficients as usize, &mut |raw| {
            coefficients.extend_from_stored(raw);
        })?;
        let mut view = self.view.clone();
        if let (Some(view), Some(slot)) = (&mut view, self.slot(Chunked::View)) {
            self.visit_chunks(slot, &mut |raw| {
                view.coefficients.extend_from_stored(raw);
            })?;
        }
        let mut reflection = self.reflection.clone();
        if let (Some(part), Some(slot)) = (&mut reflection, self.slot(Chunked::Reflection)) {
            self.visit_chunks(slot, &mut |raw| {
                part.coefficients.extend_from_stored(raw);
            })?;
        }
        let mut fine_density = None;
        if let Some(slot) = self.slot(Chunked::FineDensity) {
            let mut values: Vec<f16> = Vec::new();
            self.visit_chunks(slot, &mut |raw| values.extend(f16s(raw)))?;
            fine_density = Some(FineDensity {
                factor: self.header.fine_density_factor,
                values,
            });
        }
        self.verify_other_sections()?;
        let asset = Asset {
            grid: self.header.grid,
            world_from_light: self.header.world_from_light,
            bricks: self.bricks,
            density,
            pca: self.pca,
            coefficients,
            view,
            reflection,
            fine_density,
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
            .filter(|s| !self.chunked.iter().any(|c| c.entry.kind == s.kind))
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

    /// Decodes every chunk of chunked section `which` (an index into `self.chunked`) in
    /// order, validates its values, hands the decoded bytes to `f`, and checks the
    /// section checksum over the chunk table and all chunks.
    fn visit_chunks(&mut self, which: usize, f: &mut dyn FnMut(&[u8])) -> Result<()> {
        let section = &self.chunked[which];
        let entry = section.entry;
        let mut hasher = xxhash_rust::xxh3::Xxh3Default::new();
        hasher.update(&section.table_bytes);
        let chunk_count = section.chunks.len();
        for i in 0..chunk_count {
            let (stored, raw) = self.read_and_decode_chunk(which, i)?;
            hasher.update(&stored);
            drop(stored);
            let first_voxel = i * self.header.chunk_bricks as usize * BRICK_VOXELS;
            match self.chunked[which].what {
                Chunked::Density => {
                    validate_density(&f16s(&raw), first_voxel, self.header.signed_density())?;
                }
                Chunked::Coefficients => self.coefficients.check_stored(&raw, first_voxel, "COEF")?,
                Chunked::View => {
                    if let Some(view) = &self.view {
                        view.coefficients.check_stored(&raw, first_voxel, "VCOF")?;
                    }
                }
                Chunked::Reflection => {
                    if let Some(part) = &self.reflection {
                        part.coefficients.check_stored(&raw, first_voxel, "VRCO")?;
                    }
                }
                Chunked::FineDensity => {
                    let per_brick = self.header.fine_density_bytes_per_brick() as usize / 2;
                    validate_density_values(
                        &f16s(&raw),
                        first_voxel / BRICK_VOXELS * per_brick,
                        self.header.signed_density(),
                        "DNSF",
                    )?;
                }
            }
            f(&raw);
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

    fn decode_chunk(&mut self, which: usize, index: usize) -> Result<Vec<u8>> {
        Ok(self.read_and_decode_chunk(which, index)?.1)
    }

    /// Reads chunk `index` of chunked section `which`: its stored bytes, checked against
    /// its checksum, and their decoding.
    fn read_and_decode_chunk(&mut self, which: usize, index: usize) -> Result<(Vec<u8>, Vec<u8>)> {
        let section = &self.chunked[which];
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
        what: Chunked,
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
            what,
            entry,
            table_bytes,
            chunks,
            bytes_per_brick,
        })
    }
}
