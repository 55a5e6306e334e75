//! Shared helpers for the `.nelf` integration tests: small synthetic assets, and
//! surgery on encoded files (re-laying out sections, re-signing the header) so that
//! tests can build hostile files that get past the checksums; [`damage`] generates
//! every damaged file the Rust and C reader tests share.
#![allow(dead_code, clippy::unwrap_used)]

pub mod damage;

use half::f16;
use nelf_format::spec::{
    CHUNK_ENTRY_SIZE, HEADER_CHECKSUM_OFFSET, HEADER_SIZE, SECTION_ENTRY_SIZE, SectionCodec, SectionEntry,
    SectionKind, checksum, header_checksum, shuffle,
};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{Asset, CoefficientEncoding, FineDensity};

/// A small synthetic asset (about 8 bricks) of rank `rank`.
pub fn small_asset(encoding: CoefficientEncoding, rank: usize, seed: u64) -> Asset {
    let field = SyntheticField::new(3000, seed);
    field.asset(rank, encoding).unwrap()
}

/// The fine density (format 1.4) of `asset` at factor `factor`: each fine voxel takes the
/// density of the voxel holding it times `1 + (i mod F + j mod F + k mod F) / 8`, so that
/// values vary inside a voxel; with `negatives`, every 37th fine voxel is negative (the
/// writer then sets the signed-density flag); every 41st is −0.
pub fn fine_density_of(asset: &Asset, factor: u32, negatives: bool) -> FineDensity {
    let f = factor as usize;
    let edge = 8 * f;
    let per_brick = edge * edge * edge;
    let values = (0..asset.bricks.len() * per_brick)
        .map(|g| {
            let (b, local) = (g / per_brick, g % per_brick);
            let (i, j, k) = (local % edge, local / edge % edge, local / (edge * edge));
            let coarse = b * 512 + i / f + 8 * (j / f + 8 * (k / f));
            let sub = (i % f + j % f + k % f) as f32 / 8.0;
            let sigma = asset.density[coarse].to_f32().abs() * (1.0 + sub);
            let sigma = match (g % 37, g % 41) {
                (0, _) if negatives => -sigma - 0.25,
                (_, 0) => -0.0,
                _ => sigma,
            };
            f16::from_f32(sigma)
        })
        .collect();
    FineDensity { factor, values }
}

/// `asset` with [`fine_density_of`] itself.
pub fn with_fine_density(mut asset: Asset, factor: u32, negatives: bool) -> Asset {
    asset.fine_density = Some(fine_density_of(&asset, factor, negatives));
    asset
}

/// An encoded file split into its header and sections.
#[derive(Debug, Clone)]
pub struct FileParts {
    pub header: [u8; HEADER_SIZE],
    pub sections: Vec<(SectionEntry, Vec<u8>)>,
}

impl FileParts {
    /// Splits a valid file.
    pub fn parse(bytes: &[u8]) -> Self {
        let mut header = [0u8; HEADER_SIZE];
        header.copy_from_slice(&bytes[..HEADER_SIZE]);
        let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
        let sections = (0..count)
            .map(|i| {
                let start = HEADER_SIZE + i * SECTION_ENTRY_SIZE;
                let entry =
                    SectionEntry::from_bytes(bytes[start..start + SECTION_ENTRY_SIZE].try_into().unwrap());
                let data =
                    bytes[entry.offset as usize..(entry.offset + entry.stored_length) as usize].to_vec();
                (entry, data)
            })
            .collect();
        Self { header, sections }
    }

    /// The section of kind `kind`.
    pub fn section_mut(&mut self, kind: SectionKind) -> &mut (SectionEntry, Vec<u8>) {
        self.sections.iter_mut().find(|(e, _)| e.kind == kind).unwrap()
    }

    /// Replaces a section's stored bytes (updating length and checksum; raw length given).
    pub fn replace(
        &mut self,
        kind: SectionKind,
        codec: SectionCodec,
        shuffle: u32,
        stored: Vec<u8>,
        raw_length: u64,
    ) {
        let (entry, data) = self.section_mut(kind);
        entry.codec = codec;
        entry.shuffle = shuffle;
        entry.stored_length = stored.len() as u64;
        entry.raw_length = raw_length;
        entry.checksum = checksum(&stored);
        *data = stored;
    }

    /// Lays the sections out again (8-byte aligned, in order), fixing offsets,
    /// `section_count`, `file_size` and the header checksum.
    pub fn build(&self) -> Vec<u8> {
        let mut header = self.header;
        let mut entries: Vec<SectionEntry> = self.sections.iter().map(|(e, _)| *e).collect();
        let mut offset = (HEADER_SIZE + entries.len() * SECTION_ENTRY_SIZE) as u64;
        for (e, (_, data)) in entries.iter_mut().zip(&self.sections) {
            offset = offset.next_multiple_of(8);
            e.offset = offset;
            e.stored_length = data.len() as u64;
            offset += e.stored_length;
        }
        header[16..20].copy_from_slice(&(entries.len() as u32).to_le_bytes());
        header[200..208].copy_from_slice(&offset.to_le_bytes());
        let table: Vec<u8> = entries.iter().flat_map(SectionEntry::to_bytes).collect();
        let sum = header_checksum(&header, &table);
        header[HEADER_CHECKSUM_OFFSET..].copy_from_slice(&sum.to_le_bytes());
        let mut out = header.to_vec();
        out.extend_from_slice(&table);
        for (e, (_, data)) in entries.iter().zip(&self.sections) {
            out.resize(e.offset as usize, 0);
            out.extend_from_slice(data);
        }
        out
    }
}

/// Recomputes the header checksum of `bytes` in place (after editing header or table).
pub fn resign(bytes: &mut [u8]) {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    let table_end = (HEADER_SIZE + count * SECTION_ENTRY_SIZE).min(bytes.len());
    let sum = header_checksum(&bytes[..HEADER_SIZE], &bytes[HEADER_SIZE..table_end]);
    bytes[HEADER_CHECKSUM_OFFSET..HEADER_SIZE].copy_from_slice(&sum.to_le_bytes());
}

/// Encodes `raw` as a chunked section (chunk table + zstd chunks), as the writer does.
pub fn chunked_payload(
    raw: &[u8],
    bytes_per_brick: usize,
    chunk_bricks: usize,
    shuffle_width: usize,
) -> Vec<u8> {
    let chunks: Vec<&[u8]> = raw.chunks(bytes_per_brick * chunk_bricks).collect();
    let compressed: Vec<Vec<u8>> = chunks
        .iter()
        .map(|c| zstd::bulk::compress(&shuffle(c, shuffle_width), 3).unwrap())
        .collect();
    let mut table = Vec::new();
    let mut offset = (chunks.len() * CHUNK_ENTRY_SIZE) as u64;
    for c in &compressed {
        table.extend_from_slice(&offset.to_le_bytes());
        table.extend_from_slice(&(c.len() as u64).to_le_bytes());
        table.extend_from_slice(&checksum(c).to_le_bytes());
        offset += c.len() as u64;
    }
    for c in &compressed {
        table.extend_from_slice(c);
    }
    table
}

/// Offsets of every boundary in a file: header end, table end, each section's start
/// and end, and each chunk's start inside chunked sections.
pub fn boundaries(bytes: &[u8]) -> Vec<usize> {
    let parts = FileParts::parse(bytes);
    let mut out = vec![0, 8, HEADER_SIZE];
    out.push(HEADER_SIZE + parts.sections.len() * SECTION_ENTRY_SIZE);
    for (e, data) in &parts.sections {
        out.push(e.offset as usize);
        out.push((e.offset + e.stored_length) as usize);
        if e.codec == SectionCodec::ChunkedZstd && data.len() >= CHUNK_ENTRY_SIZE {
            // The first chunk starts right after the table of `n` entries.
            let n = u64::from_le_bytes(data[..8].try_into().unwrap()) as usize / CHUNK_ENTRY_SIZE;
            for i in 0..n.min(data.len() / CHUNK_ENTRY_SIZE) {
                let at = i * CHUNK_ENTRY_SIZE;
                let off = u64::from_le_bytes(data[at..at + 8].try_into().unwrap()) as usize;
                out.push(e.offset as usize + off);
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out.retain(|&b| b <= bytes.len());
    out
}
