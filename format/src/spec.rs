//! Byte layout of `.nelf` v1 (see `format/SPEC.md`): the fixed 256-byte header,
//! the 48-byte section-table entries, section kinds and codecs, the limits a reader
//! enforces, and the byte shuffle filter. Little-endian everywhere.
//!
//! This module only packs and unpacks fixed-size records and checks the header's
//! own fields; `read`/`write` move whole sections.

use glam::DMat3;

use crate::asset::CoefficientEncoding;
use crate::conventions::{ENV_H, ENV_W, LT_DIM, VIEW_HARMONICS, is_rotation};
use crate::error::{FormatError, Result};
use crate::grid::GridGeometry;
pub use crate::grid::{BRICK_SIZE, BRICK_VOXELS, FINE_DENSITY_FACTORS, MAX_GRID_BRICKS};

/// File magic: `\x89 N E L F \r \n \x1a` (a high byte and line endings catch text-mode damage).
pub const MAGIC: [u8; 8] = [0x89, b'N', b'E', b'L', b'F', 0x0D, 0x0A, 0x1A];
/// Major version this crate reads and writes; a reader rejects any other.
pub const VERSION_MAJOR: u16 = 1;
/// Newest minor version this crate writes: 4 for an asset with a fine density (`DNSF`),
/// [`VERSION_MINOR_REFLECTION`] for one with a reflection part (`VREF`, `VRCO`),
/// [`VERSION_MINOR_VIEW`] for one with a harmonic view part, and
/// [`VERSION_MINOR_WITHOUT_VIEW`] for one without any. Readers accept any minor of their major.
pub const VERSION_MINOR: u16 = 4;
/// Minor version this crate writes for an asset with a reflection part and no fine
/// density: such a file is exactly what a 1.3 writer wrote.
pub const VERSION_MINOR_REFLECTION: u16 = 3;
/// Minor version this crate writes for an asset with a harmonic view-dependent part
/// (`VDEP`, `VCOF`): such a file is exactly what a 1.2 writer wrote.
pub const VERSION_MINOR_VIEW: u16 = 2;
/// Minor version this crate writes for an asset without a view-dependent part: such a
/// file is exactly what a 1.1 writer wrote.
pub const VERSION_MINOR_WITHOUT_VIEW: u16 = 1;
/// Size of the fixed header in bytes.
pub const HEADER_SIZE: usize = 256;
/// Size of one section-table entry in bytes.
pub const SECTION_ENTRY_SIZE: usize = 48;
/// Size of one chunk-table entry in a chunked section.
pub const CHUNK_ENTRY_SIZE: usize = 24;
/// Byte offset of the header checksum (the header's last eight bytes).
pub const HEADER_CHECKSUM_OFFSET: usize = 248;

/// Most sections a file may declare.
pub const MAX_SECTIONS: usize = 64;
/// Largest decoded size of one chunk of a chunked section (bounds a reader's
/// working memory for random access and for a damaged chunk).
pub const MAX_CHUNK_RAW_BYTES: u64 = 4 << 20;
/// Largest decoded size of the metadata section.
pub const MAX_METADATA_BYTES: u64 = 1 << 20;
/// No zstd data decodes to more than this many times its size (one 4-byte RLE
/// block expands to at most 128 KiB); a larger declared length is a lie.
pub const MAX_ZSTD_EXPANSION: u64 = 32_768;
/// Header flags: bits a reader must understand (low 32).
pub const REQUIRED_FLAGS_MASK: u64 = 0xFFFF_FFFF;
/// Required flag bit 0 (v1.1): `DENS` may hold negative values; the density along a
/// ray is `max(0, trilinear(σ))`. Set by writers exactly when a stored σ is negative.
pub const FLAG_SIGNED_DENSITY: u64 = 1;
/// The required flag bits this reader understands.
pub const KNOWN_REQUIRED_FLAGS: u64 = FLAG_SIGNED_DENSITY;
/// Section-entry flag bit: a reader that does not know this kind must reject the file.
pub const SECTION_FLAG_REQUIRED: u16 = 1;

/// The four-letter kind of a section.
pub type SectionKind = [u8; 4];
/// Brick coordinates, `u16 × 3` per brick.
pub const KIND_BRICKS: SectionKind = *b"BRCK";
/// Density σ (1/m), `f16` per voxel, chunked.
pub const KIND_DENSITY: SectionKind = *b"DENS";
/// PCA mean and basis, `f32`.
pub const KIND_PCA: SectionKind = *b"PCAB";
/// Dequantisation parameters of 8-bit coefficients, `(scale, offset)` `f32` per component.
pub const KIND_QUANT_PARAMS: SectionKind = *b"QPRM";
/// PCA coefficients, `u8` or `f16` per voxel and component, chunked.
pub const KIND_COEFFICIENTS: SectionKind = *b"COEF";
/// Metadata, UTF-8 JSON object.
pub const KIND_METADATA: SectionKind = *b"META";
/// The view-dependent part's parameters (1.2, optional): a [`ViewHeader`], the lobes'
/// harmonic weights, the view basis and 8-bit dequantisation parameters, `f32`.
pub const KIND_VIEW: SectionKind = *b"VDEP";
/// The view-dependent part's per-voxel coefficients (1.2, optional), `J·K_v` per voxel,
/// `u8` or `f16`, chunked like [`KIND_COEFFICIENTS`].
pub const KIND_VIEW_COEFFICIENTS: SectionKind = *b"VCOF";
/// The reflection part's parameters (1.3, optional): lobe exponent, eyes and the 8-bit
/// dequantisation of `VRCO` (SPEC.md §6).
pub const KIND_REFLECTION: SectionKind = *b"VREF";
/// The reflection part's per-voxel values (1.3, optional): octahedral normal and scale,
/// `u8 × 3` per voxel, chunked like [`KIND_COEFFICIENTS`].
pub const KIND_REFLECTION_VALUES: SectionKind = *b"VRCO";
/// The fine density (1.4, optional): σ (1/m) as `f16` on a lattice `F` times finer per
/// axis than the voxels, `512·F³` values per brick, chunked (SPEC.md §6 `DNSF`).
pub const KIND_FINE_DENSITY: SectionKind = *b"DNSF";
/// Decoded bytes of one brick of `DNSF` at factor `factor` (`2 · 512 · F³`).
pub const fn fine_density_bytes_per_brick(factor: u32) -> u64 {
    2 * BRICK_VOXELS as u64 * (factor as u64).pow(3)
}
/// Every kind this reader knows, in the order the writer lays them out.
pub const KNOWN_KINDS: [SectionKind; 11] = [
    KIND_BRICKS,
    KIND_DENSITY,
    KIND_FINE_DENSITY,
    KIND_PCA,
    KIND_QUANT_PARAMS,
    KIND_COEFFICIENTS,
    KIND_VIEW,
    KIND_VIEW_COEFFICIENTS,
    KIND_REFLECTION,
    KIND_REFLECTION_VALUES,
    KIND_METADATA,
];
/// Decoded length of `VREF` with `eyes` eyes: `u32` eye count, `f32` exponent, the eyes
/// as `f32` triples, then three `(scale, offset)` `f32` pairs.
pub const fn reflection_params_bytes(eyes: usize) -> u64 {
    8 + 12 * eyes as u64 + 24
}
/// Decoded bytes of one brick of `VRCO` (512 voxels × 3 bytes).
pub const REFLECTION_BYTES_PER_BRICK: u64 = 3 * BRICK_VOXELS as u64;
/// Size of the [`ViewHeader`] at the start of `VDEP`.
pub const VIEW_HEADER_SIZE: usize = 16;
/// Largest decoded `VDEP`: its header, 9 lobes, 384 basis vectors and 384 pairs of 8-bit
/// parameters (no file reaches it: `J·K_v ≤ 384`); a larger declared length is refused
/// before anything is decoded.
pub const MAX_VIEW_PARAMS_BYTES: u64 = VIEW_HEADER_SIZE as u64
    + 4 * (VIEW_HARMONICS * VIEW_HARMONICS) as u64
    + 4 * (LT_DIM * LT_DIM) as u64
    + 8 * LT_DIM as u64;

/// Whether this reader knows section kind `kind` (unknown kinds are skipped when optional).
pub fn is_known_kind(kind: SectionKind) -> bool {
    KNOWN_KINDS.contains(&kind)
}

/// A section kind as text for messages (`BRCK`, or escaped bytes if not ASCII).
pub fn kind_name(kind: SectionKind) -> String {
    kind.iter()
        .flat_map(|&b| std::ascii::escape_default(b))
        .map(char::from)
        .collect()
}

/// How a section's bytes are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum SectionCodec {
    /// Stored as is (codec 0).
    Raw,
    /// One zstd stream of the (optionally shuffled) decoded bytes (codec 1).
    Zstd,
    /// A chunk table, then independently zstd-compressed chunks of whole bricks (codec 2).
    ChunkedZstd,
    /// A codec number this reader does not know (allowed only in skipped sections).
    Unknown(u16),
}

impl SectionCodec {
    /// The codec's number in the section table.
    pub fn to_u16(self) -> u16 {
        match self {
            Self::Raw => 0,
            Self::Zstd => 1,
            Self::ChunkedZstd => 2,
            Self::Unknown(v) => v,
        }
    }

    /// The codec with number `v`.
    pub fn from_u16(v: u16) -> Self {
        match v {
            0 => Self::Raw,
            1 => Self::Zstd,
            2 => Self::ChunkedZstd,
            other => Self::Unknown(other),
        }
    }

    /// Short name for display.
    pub fn name(self) -> String {
        match self {
            Self::Raw => "raw".into(),
            Self::Zstd => "zstd".into(),
            Self::ChunkedZstd => "chunked-zstd".into(),
            Self::Unknown(v) => format!("unknown({v})"),
        }
    }
}

/// One entry of the section table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SectionEntry {
    /// Four-letter kind.
    pub kind: SectionKind,
    /// A reader that does not know `kind` must reject the file.
    pub required: bool,
    /// Storage codec.
    pub codec: SectionCodec,
    /// Byte-shuffle record width applied before compression (0 = none).
    pub shuffle: u32,
    /// Offset of the stored bytes from the start of the file (multiple of 8).
    pub offset: u64,
    /// Stored (possibly compressed) length in bytes.
    pub stored_length: u64,
    /// Decoded length in bytes.
    pub raw_length: u64,
    /// xxh3-64 (seed 0) of the stored bytes.
    pub checksum: u64,
}

impl SectionEntry {
    /// The kind as text.
    pub fn name(&self) -> String {
        kind_name(self.kind)
    }

    /// Packs the entry into its 48 bytes.
    pub fn to_bytes(&self) -> [u8; SECTION_ENTRY_SIZE] {
        let mut b = [0u8; SECTION_ENTRY_SIZE];
        b[0..4].copy_from_slice(&self.kind);
        let flags = if self.required { SECTION_FLAG_REQUIRED } else { 0 };
        b[4..6].copy_from_slice(&flags.to_le_bytes());
        b[6..8].copy_from_slice(&self.codec.to_u16().to_le_bytes());
        b[8..12].copy_from_slice(&self.shuffle.to_le_bytes());
        // 12..16 reserved, zero.
        b[16..24].copy_from_slice(&self.offset.to_le_bytes());
        b[24..32].copy_from_slice(&self.stored_length.to_le_bytes());
        b[32..40].copy_from_slice(&self.raw_length.to_le_bytes());
        b[40..48].copy_from_slice(&self.checksum.to_le_bytes());
        b
    }

    /// Unpacks an entry (no validation beyond the layout).
    pub fn from_bytes(b: &[u8; SECTION_ENTRY_SIZE]) -> Self {
        let mut kind = [0u8; 4];
        kind.copy_from_slice(&b[0..4]);
        Self {
            kind,
            required: u16_at(b, 4) & SECTION_FLAG_REQUIRED != 0,
            codec: SectionCodec::from_u16(u16_at(b, 6)),
            shuffle: u32_at(b, 8),
            offset: u64_at(b, 16),
            stored_length: u64_at(b, 24),
            raw_length: u64_at(b, 32),
            checksum: u64_at(b, 40),
        }
    }
}

/// The decoded header of a `.nelf` file.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Major version (1).
    pub version_major: u16,
    /// Minor version.
    pub version_minor: u16,
    /// Sections in the table.
    pub section_count: u32,
    /// Feature flags (low 32 bits required, high 32 optional; [`FLAG_SIGNED_DENSITY`] in v1.1).
    pub flags: u64,
    /// Grid placement and extent.
    pub grid: GridGeometry,
    /// Bricks stored.
    pub brick_count: u32,
    /// Bricks per chunk in chunked sections.
    pub chunk_bricks: u32,
    /// Rotation taking light-frame directions to world directions.
    pub world_from_light: DMat3,
    /// Environment-map rows of the light-transport basis (8).
    pub env_height: u16,
    /// Environment-map columns (16).
    pub env_width: u16,
    /// PCA rank `K`.
    pub pca_rank: u32,
    /// How coefficients are quantized.
    pub coefficient_encoding: CoefficientEncoding,
    /// Total file size in bytes.
    pub file_size: u64,
    /// Fine-density factor `F` (format 1.4, header bytes 196..200): 0 for a file without
    /// `DNSF`, otherwise one of [`FINE_DENSITY_FACTORS`].
    pub fine_density_factor: u32,
}

impl Header {
    /// Whether `DENS` may hold negative values ([`FLAG_SIGNED_DENSITY`]).
    pub fn signed_density(&self) -> bool {
        self.flags & FLAG_SIGNED_DENSITY != 0
    }

    /// Voxels stored (`brick_count × 512`).
    pub fn voxel_count(&self) -> u64 {
        u64::from(self.brick_count) * BRICK_VOXELS as u64
    }

    /// First byte after the section table.
    pub fn data_start(&self) -> u64 {
        HEADER_SIZE as u64 + u64::from(self.section_count) * SECTION_ENTRY_SIZE as u64
    }

    /// Chunks in each chunked section (`⌈brick_count / chunk_bricks⌉`).
    pub fn chunk_count(&self) -> u64 {
        u64::from(self.brick_count).div_ceil(u64::from(self.chunk_bricks.max(1)))
    }

    /// Bricks in chunk `chunk`.
    pub fn bricks_in_chunk(&self, chunk: u64) -> u64 {
        let start = chunk * u64::from(self.chunk_bricks);
        (u64::from(self.brick_count) - start.min(u64::from(self.brick_count)))
            .min(u64::from(self.chunk_bricks))
    }

    /// Decoded bytes of one brick of `DNSF` (0 without a fine density).
    pub fn fine_density_bytes_per_brick(&self) -> u64 {
        if self.fine_density_factor == 0 {
            0
        } else {
            fine_density_bytes_per_brick(self.fine_density_factor)
        }
    }

    /// Decoded bytes of one brick's coefficients.
    pub fn coefficient_bytes_per_brick(&self) -> u64 {
        BRICK_VOXELS as u64 * u64::from(self.pca_rank) * self.coefficient_encoding.bytes_per_value() as u64
    }

    /// Packs the header into 256 bytes; the checksum field is left zero (see [`header_checksum`]).
    pub fn to_bytes(&self) -> [u8; HEADER_SIZE] {
        let mut b = [0u8; HEADER_SIZE];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..10].copy_from_slice(&self.version_major.to_le_bytes());
        b[10..12].copy_from_slice(&self.version_minor.to_le_bytes());
        b[12..16].copy_from_slice(&(HEADER_SIZE as u32).to_le_bytes());
        b[16..20].copy_from_slice(&self.section_count.to_le_bytes());
        b[20..24].copy_from_slice(&(SECTION_ENTRY_SIZE as u32).to_le_bytes());
        b[24..32].copy_from_slice(&self.flags.to_le_bytes());
        let max = self.grid.bbox_max_m();
        for a in 0..3 {
            put_f64(&mut b, 32 + 8 * a, self.grid.bbox_min_m[a]);
            put_f64(&mut b, 56 + 8 * a, max[a]);
            b[88 + 4 * a..92 + 4 * a].copy_from_slice(&self.grid.grid_bricks[a].to_le_bytes());
        }
        put_f64(&mut b, 80, self.grid.voxel_size_m);
        b[100..104].copy_from_slice(&(BRICK_SIZE as u32).to_le_bytes());
        b[104..108].copy_from_slice(&self.brick_count.to_le_bytes());
        b[108..112].copy_from_slice(&self.chunk_bricks.to_le_bytes());
        let rows = self.world_from_light.transpose().to_cols_array();
        for (i, v) in rows.iter().enumerate() {
            put_f64(&mut b, 112 + 8 * i, *v);
        }
        b[184..186].copy_from_slice(&self.env_height.to_le_bytes());
        b[186..188].copy_from_slice(&self.env_width.to_le_bytes());
        b[188..192].copy_from_slice(&self.pca_rank.to_le_bytes());
        b[192..196].copy_from_slice(&self.coefficient_encoding.to_u32().to_le_bytes());
        b[196..200].copy_from_slice(&self.fine_density_factor.to_le_bytes());
        b[200..208].copy_from_slice(&self.file_size.to_le_bytes());
        // 208..248 reserved; 248..256 checksum.
        b
    }

    /// Unpacks and validates a header against the actual file size. Checks, in
    /// order: magic, major version, fixed sizes, `file_size`, section count, then
    /// every field's range. The header checksum is checked by the caller once the
    /// section table has been read.
    pub fn from_bytes(b: &[u8], actual_file_size: u64) -> Result<Self> {
        if b.len() >= MAGIC.len() && b[..MAGIC.len()] != MAGIC {
            let mut found = [0u8; 8];
            found.copy_from_slice(&b[..8]);
            return Err(FormatError::BadMagic { found });
        }
        if b.len() < HEADER_SIZE {
            return Err(FormatError::Truncated {
                what: "header".into(),
                needed: HEADER_SIZE as u64,
                available: b.len() as u64,
            });
        }
        let version_major = u16_at(b, 8);
        let version_minor = u16_at(b, 10);
        if version_major != VERSION_MAJOR {
            return Err(FormatError::UnsupportedVersion {
                major: version_major,
                minor: version_minor,
                supported: VERSION_MAJOR,
            });
        }
        let bad = |field: &'static str, reason: String| FormatError::InvalidHeader { field, reason };
        let header_size = u32_at(b, 12);
        if header_size as usize != HEADER_SIZE {
            return Err(bad(
                "header_size",
                format!("{header_size}, must be {HEADER_SIZE}"),
            ));
        }
        let entry_size = u32_at(b, 20);
        if entry_size as usize != SECTION_ENTRY_SIZE {
            return Err(bad(
                "section_entry_size",
                format!("{entry_size}, must be {SECTION_ENTRY_SIZE}"),
            ));
        }
        let file_size = u64_at(b, 200);
        if file_size != actual_file_size {
            if actual_file_size < file_size {
                return Err(FormatError::Truncated {
                    what: "file".into(),
                    needed: file_size,
                    available: actual_file_size,
                });
            }
            return Err(FormatError::FileSizeMismatch {
                declared: file_size,
                actual: actual_file_size,
            });
        }
        let section_count = u32_at(b, 16);
        if section_count as usize > MAX_SECTIONS {
            return Err(FormatError::TooManySections {
                count: u64::from(section_count),
                max: MAX_SECTIONS,
            });
        }
        let table_end = HEADER_SIZE as u64 + u64::from(section_count) * SECTION_ENTRY_SIZE as u64;
        if table_end > file_size {
            return Err(FormatError::Truncated {
                what: "section table".into(),
                needed: table_end,
                available: file_size,
            });
        }
        let flags = u64_at(b, 24);
        if flags & REQUIRED_FLAGS_MASK & !KNOWN_REQUIRED_FLAGS != 0 {
            return Err(FormatError::UnsupportedFeature {
                flags: flags & REQUIRED_FLAGS_MASK & !KNOWN_REQUIRED_FLAGS,
            });
        }
        let f64s =
            |offset: usize, n: usize| -> Vec<f64> { (0..n).map(|i| f64_at(b, offset + 8 * i)).collect() };
        let finite = |field: &'static str, values: &[f64]| -> Result<()> {
            if values.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err(FormatError::NonFinite {
                    what: format!("header field {field}"),
                })
            }
        };
        let bbox_min = f64s(32, 3);
        let bbox_max = f64s(56, 3);
        let voxel_size_m = f64_at(b, 80);
        finite("bbox_min", &bbox_min)?;
        finite("bbox_max", &bbox_max)?;
        finite("voxel_size", &[voxel_size_m])?;
        let grid_bricks = [u32_at(b, 88), u32_at(b, 92), u32_at(b, 96)];
        let grid = GridGeometry {
            bbox_min_m: [bbox_min[0], bbox_min[1], bbox_min[2]],
            voxel_size_m,
            grid_bricks,
        };
        grid.validate().map_err(|reason| bad("grid", reason))?;
        let expected_max = grid.bbox_max_m();
        for a in 0..3 {
            let extent = expected_max[a] - bbox_min[a];
            let tol = 1e-6 * (extent.abs() + bbox_min[a].abs()) + 1e-12;
            if (bbox_max[a] - expected_max[a]).abs() > tol {
                return Err(bad(
                    "bbox_max",
                    format!(
                        "{bbox_max:?} disagrees with bbox_min + 8·grid_bricks·voxel_size = {expected_max:?}"
                    ),
                ));
            }
        }
        let brick_size = u32_at(b, 100);
        if brick_size as usize != BRICK_SIZE {
            return Err(bad("brick_size", format!("{brick_size}, must be {BRICK_SIZE}")));
        }
        let brick_count = u32_at(b, 104);
        let chunk_bricks = u32_at(b, 108);
        let rows = f64s(112, 9);
        finite("world_from_light", &rows)?;
        let world_from_light = DMat3::from_cols_array(&[
            rows[0], rows[3], rows[6], rows[1], rows[4], rows[7], rows[2], rows[5], rows[8],
        ]);
        if !is_rotation(world_from_light, 1e-5) {
            return Err(bad("world_from_light", format!("{rows:?} is not a rotation")));
        }
        let env_height = u16_at(b, 184);
        let env_width = u16_at(b, 186);
        if env_height as usize != ENV_H || env_width as usize != ENV_W {
            return Err(bad(
                "env_size",
                format!("{env_height}×{env_width}, v1 requires {ENV_H}×{ENV_W}"),
            ));
        }
        let pca_rank = u32_at(b, 188);
        if pca_rank == 0 || pca_rank as usize > LT_DIM {
            return Err(FormatError::BadRank {
                rank: u64::from(pca_rank),
                max: LT_DIM,
            });
        }
        let encoding_code = u32_at(b, 192);
        let coefficient_encoding = CoefficientEncoding::from_u32(encoding_code).ok_or_else(|| {
            bad(
                "coefficient_encoding",
                format!("unknown encoding {encoding_code}"),
            )
        })?;
        // Reserved before 1.4 (writers wrote 0), so an older file reads as factor 0.
        let fine_density_factor = u32_at(b, 196);
        if fine_density_factor != 0 && !FINE_DENSITY_FACTORS.contains(&fine_density_factor) {
            return Err(bad(
                "fine_density_factor",
                format!("{fine_density_factor}, must be 0 (none), 2 or 4"),
            ));
        }
        let header = Self {
            version_major,
            version_minor,
            section_count,
            flags,
            grid,
            brick_count,
            chunk_bricks,
            world_from_light,
            env_height,
            env_width,
            pca_rank,
            coefficient_encoding,
            file_size,
            fine_density_factor,
        };
        if chunk_bricks == 0 {
            return Err(bad("chunk_bricks", "0, must be at least 1".into()));
        }
        let chunk_raw = u64::from(chunk_bricks)
            * header
                .coefficient_bytes_per_brick()
                .max(2 * BRICK_VOXELS as u64)
                .max(header.fine_density_bytes_per_brick());
        if chunk_raw > MAX_CHUNK_RAW_BYTES {
            return Err(FormatError::CountTooLarge {
                what: "chunk_bricks × bytes per brick".into(),
                count: chunk_raw,
                limit: MAX_CHUNK_RAW_BYTES,
            });
        }
        Ok(header)
    }
}

/// The first 16 bytes of `VDEP` (format 1.2): the shape of the view-dependent part,
/// `u32 J`, `u32 K_v`, `u32 encoding`, `u32` reserved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewHeader {
    /// Lobes `J`, 1..=9.
    pub lobes: u32,
    /// View basis rank `K_v`, ≥ 1, with `J·K_v ≤ 384`.
    pub rank: u32,
    /// How `VCOF` stores the coefficients (numbered as the header's `coefficient_encoding`).
    pub encoding: CoefficientEncoding,
}

impl ViewHeader {
    /// Coefficients per voxel, `R = J·K_v`.
    pub fn coefficients_per_voxel(&self) -> u64 {
        u64::from(self.lobes) * u64::from(self.rank)
    }

    /// Decoded length of the whole `VDEP` section: header, `J·9` lobe weights, `K_v·384`
    /// basis values, and `R` (scale, offset) pairs when 8-bit, all `f32`.
    pub fn section_length(&self) -> u64 {
        let params = match self.encoding {
            CoefficientEncoding::U8Affine => 8 * self.coefficients_per_voxel(),
            CoefficientEncoding::F16 => 0,
        };
        VIEW_HEADER_SIZE as u64
            + 4 * VIEW_HARMONICS as u64 * u64::from(self.lobes)
            + 4 * LT_DIM as u64 * u64::from(self.rank)
            + params
    }

    /// Decoded bytes of one brick of `VCOF`: `512·R·w`.
    pub fn bytes_per_brick(&self) -> u64 {
        BRICK_VOXELS as u64 * self.coefficients_per_voxel() * self.encoding.bytes_per_value() as u64
    }

    /// Packs the header (reserved field zero).
    pub fn to_bytes(&self) -> [u8; VIEW_HEADER_SIZE] {
        let mut b = [0u8; VIEW_HEADER_SIZE];
        b[0..4].copy_from_slice(&self.lobes.to_le_bytes());
        b[4..8].copy_from_slice(&self.rank.to_le_bytes());
        b[8..12].copy_from_slice(&self.encoding.to_u32().to_le_bytes());
        b
    }

    /// Unpacks and checks the header from the start of a decoded `VDEP` (any length):
    /// at least 16 bytes, `J` in 1..=9, `K_v ≥ 1` with `J·K_v ≤ 384`, a known encoding,
    /// and a section length equal to [`Self::section_length`]. The reserved field is ignored.
    pub fn from_section(b: &[u8]) -> Result<Self> {
        let bad = |reason: String| FormatError::InvalidView(format!("section VDEP: {reason}"));
        if b.len() < VIEW_HEADER_SIZE {
            return Err(bad(format!(
                "{} decoded bytes, shorter than its {VIEW_HEADER_SIZE}-byte header",
                b.len()
            )));
        }
        let (lobes, rank, code) = (u32_at(b, 0), u32_at(b, 4), u32_at(b, 8));
        if lobes == 0 || lobes as usize > VIEW_HARMONICS {
            return Err(bad(format!("{lobes} lobes, must be 1 to {VIEW_HARMONICS}")));
        }
        let per_voxel = u64::from(lobes) * u64::from(rank);
        if rank == 0 || per_voxel > LT_DIM as u64 {
            return Err(bad(format!(
                "{lobes} lobes × rank {rank} = {per_voxel} coefficients per voxel, must be 1 to {LT_DIM}"
            )));
        }
        let encoding = CoefficientEncoding::from_u32(code)
            .ok_or_else(|| bad(format!("unknown coefficient encoding {code}")))?;
        let header = Self {
            lobes,
            rank,
            encoding,
        };
        if header.section_length() != b.len() as u64 {
            return Err(bad(format!(
                "{} decoded bytes, but {lobes} lobes × rank {rank} with {} coefficients need {}",
                b.len(),
                encoding.name(),
                header.section_length()
            )));
        }
        Ok(header)
    }
}

/// xxh3-64 over the header's first 248 bytes followed by the section table.
pub fn header_checksum(header: &[u8], table: &[u8]) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3Default::new();
    h.update(&header[..HEADER_CHECKSUM_OFFSET]);
    h.update(table);
    h.digest()
}

/// xxh3-64 (seed 0) of `bytes`: the checksum of sections and chunks.
pub fn checksum(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}

/// Records per block in [`shuffle`] and [`unshuffle`]: a block of records stays in
/// L1 cache while its bytes are scattered to (or gathered from) the planes.
const SHUFFLE_BLOCK: usize = 256;

/// Byte shuffle with record width `width`: `out[b·n + r] = data[r·width + b]` for
/// `n = len / width` records (byte `b` of every record goes to plane `b`). Width 0
/// or 1 is the identity. `len` must be a multiple of `width`.
pub fn shuffle(data: &[u8], width: usize) -> Vec<u8> {
    if width <= 1 {
        return data.to_vec();
    }
    let n = data.len() / width;
    let mut out = vec![0u8; data.len()];
    for r0 in (0..n).step_by(SHUFFLE_BLOCK) {
        let r1 = (r0 + SHUFFLE_BLOCK).min(n);
        let block = &data[r0 * width..r1 * width];
        for b in 0..width {
            let plane = &mut out[b * n + r0..b * n + r1];
            for (dst, record) in plane.iter_mut().zip(block.chunks_exact(width)) {
                *dst = record[b];
            }
        }
    }
    out
}

/// Inverse of [`shuffle`].
pub fn unshuffle(data: &[u8], width: usize) -> Vec<u8> {
    if width <= 1 {
        return data.to_vec();
    }
    let n = data.len() / width;
    let mut out = vec![0u8; data.len()];
    for r0 in (0..n).step_by(SHUFFLE_BLOCK) {
        let r1 = (r0 + SHUFFLE_BLOCK).min(n);
        let block = &mut out[r0 * width..r1 * width];
        for b in 0..width {
            let plane = &data[b * n + r0..b * n + r1];
            for (record, &src) in block.chunks_exact_mut(width).zip(plane) {
                record[b] = src;
            }
        }
    }
    out
}

fn put_f64(b: &mut [u8], offset: usize, v: f64) {
    b[offset..offset + 8].copy_from_slice(&v.to_le_bytes());
}

/// Little-endian `u16` at `offset` (caller guarantees bounds).
pub(crate) fn u16_at(b: &[u8], offset: usize) -> u16 {
    u16::from_le_bytes([b[offset], b[offset + 1]])
}

/// Little-endian `u32` at `offset`.
pub(crate) fn u32_at(b: &[u8], offset: usize) -> u32 {
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[offset..offset + 4]);
    u32::from_le_bytes(a)
}

/// Little-endian `u64` at `offset`.
pub(crate) fn u64_at(b: &[u8], offset: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[offset..offset + 8]);
    u64::from_le_bytes(a)
}

/// Little-endian `f64` at `offset`.
pub(crate) fn f64_at(b: &[u8], offset: usize) -> f64 {
    f64::from_bits(u64_at(b, offset))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shuffle_round_trips_and_groups_bytes() {
        let data: Vec<u8> = (0..24u8).collect();
        let s = shuffle(&data, 3);
        assert_eq!(&s[..8], &[0, 3, 6, 9, 12, 15, 18, 21]);
        assert_eq!(unshuffle(&s, 3), data);
        assert_eq!(shuffle(&data, 1), data);
        // Across several blocks, with a partial last block.
        let long: Vec<u8> = (0..7 * 1000).map(|i| (i * 31 % 251) as u8).collect();
        let s = shuffle(&long, 7);
        assert_eq!(s[1000 + 5], long[5 * 7 + 1]);
        assert_eq!(unshuffle(&s, 7), long);
    }

    #[test]
    fn section_entry_round_trips() {
        let e = SectionEntry {
            kind: KIND_COEFFICIENTS,
            required: true,
            codec: SectionCodec::ChunkedZstd,
            shuffle: 16,
            offset: 1024,
            stored_length: 77,
            raw_length: 4096,
            checksum: 0xdead_beef_0123_4567,
        };
        assert_eq!(SectionEntry::from_bytes(&e.to_bytes()), e);
        assert_eq!(e.name(), "COEF");
        assert_eq!(kind_name([b'A', 0, b'\n', 0xff]), "A\\x00\\n\\xff");
    }
}
