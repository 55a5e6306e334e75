//! The one error type of the `.nelf` reader and writer ([`FormatError`]).
//!
//! Every variant names what is wrong and where (the section's four-letter kind,
//! the header field, the path), so that a damaged or hostile file produces a
//! message a person can act on. See `SPEC.md`, "Validation".

use crate::io_error::FileIoError;

/// Everything that can go wrong reading, writing or validating a `.nelf` asset.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// An operating-system error on a file.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// An I/O error on an in-memory or caller-supplied stream.
    #[error("I/O error while {during}: {source}")]
    Stream {
        /// What was being read or written.
        during: String,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// The first eight bytes are not the `.nelf` magic.
    #[error("not a .nelf file: bad magic {found:02x?}")]
    BadMagic {
        /// The bytes found.
        found: [u8; 8],
    },
    /// The major version is not one this reader understands.
    #[error("unsupported .nelf version {major}.{minor} (this reader reads major version {supported})")]
    UnsupportedVersion {
        /// Major version in the file.
        major: u16,
        /// Minor version in the file.
        minor: u16,
        /// Major version this reader supports.
        supported: u16,
    },
    /// The file ends before something it declares.
    #[error("truncated file: {what} needs {needed} bytes but only {available} are there")]
    Truncated {
        /// What could not be read.
        what: String,
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        available: u64,
    },
    /// The header's `file_size` does not match the file.
    #[error("file is {actual} bytes but its header says {declared} (truncated or appended to)")]
    FileSizeMismatch {
        /// Size the header declares.
        declared: u64,
        /// Size of the file.
        actual: u64,
    },
    /// A header field holds a value the format does not allow.
    #[error("invalid header field {field}: {reason}")]
    InvalidHeader {
        /// The field.
        field: &'static str,
        /// Why.
        reason: String,
    },
    /// The header sets a required feature flag this reader does not know.
    #[error("file requires unknown feature flags {flags:#x}")]
    UnsupportedFeature {
        /// The unknown required bits.
        flags: u64,
    },
    /// A floating-point value that must be finite is NaN or infinite.
    #[error("non-finite value in {what}")]
    NonFinite {
        /// Where (header field or section and element).
        what: String,
    },
    /// The PCA rank is zero or larger than the light-transport dimension.
    #[error("PCA rank {rank} is outside 1..={max}")]
    BadRank {
        /// The rank found.
        rank: u64,
        /// The largest rank allowed (384).
        max: usize,
    },
    /// More sections than the format allows.
    #[error("section table declares {count} sections (at most {max})")]
    TooManySections {
        /// Count declared.
        count: u64,
        /// Limit.
        max: usize,
    },
    /// A section lies (partly) outside the data area of the file.
    #[error(
        "section {section} at offset {offset} with length {length} lies outside the data area [{data_start}, {file_size})"
    )]
    SectionOutOfBounds {
        /// The section's kind.
        section: String,
        /// Its offset.
        offset: u64,
        /// Its stored length.
        length: u64,
        /// First byte after the section table.
        data_start: u64,
        /// File size.
        file_size: u64,
    },
    /// A section's offset is not a multiple of 8.
    #[error("section {section} offset {offset} is not 8-byte aligned")]
    Misaligned {
        /// The section's kind.
        section: String,
        /// Its offset.
        offset: u64,
    },
    /// Two sections share bytes.
    #[error("sections {first} and {second} overlap")]
    SectionsOverlap {
        /// One section.
        first: String,
        /// The other.
        second: String,
    },
    /// A section kind appears twice.
    #[error("section {section} appears more than once")]
    DuplicateSection {
        /// The kind.
        section: String,
    },
    /// A section the header requires is absent.
    #[error("required section {section} is missing")]
    MissingSection {
        /// The kind.
        section: String,
    },
    /// A section marked required has a kind this reader does not know.
    #[error("unknown required section {section} (written by a newer writer?)")]
    UnknownRequiredSection {
        /// The kind.
        section: String,
    },
    /// A known section uses a codec or shuffle it may not use.
    #[error("section {section}: {reason}")]
    BadCodec {
        /// The kind.
        section: String,
        /// What is wrong.
        reason: String,
    },
    /// A section's declared decoded length disagrees with the header's counts.
    #[error("section {section} declares {found} decoded bytes but the header's counts need {expected}")]
    SectionLength {
        /// The kind.
        section: String,
        /// Bytes the counts require.
        expected: u64,
        /// Bytes declared.
        found: u64,
    },
    /// A declared decoded length that no valid encoding of the stored bytes can reach.
    #[error("{what}: declared decoded length {raw} is implausible for {stored} stored bytes")]
    ImplausibleLength {
        /// Section (and chunk).
        what: String,
        /// Declared decoded length.
        raw: u64,
        /// Stored length.
        stored: u64,
    },
    /// A count is larger than the file or the format can hold.
    #[error("{what} = {count} is too large (limit {limit})")]
    CountTooLarge {
        /// What is counted.
        what: String,
        /// The count.
        count: u64,
        /// The limit it exceeds.
        limit: u64,
    },
    /// A checksum does not match: the bytes were damaged.
    #[error("checksum mismatch in {what}: stored {stored:#018x}, computed {computed:#018x}")]
    ChecksumMismatch {
        /// Header, section or chunk.
        what: String,
        /// Checksum in the file.
        stored: u64,
        /// Checksum of the bytes read.
        computed: u64,
    },
    /// A section's chunk table is malformed.
    #[error("section {section}: bad chunk table: {reason}")]
    BadChunkTable {
        /// The kind.
        section: String,
        /// What is wrong.
        reason: String,
    },
    /// zstd failed to compress or decompress.
    #[error("zstd error in {what}: {message}")]
    Zstd {
        /// Section (and chunk).
        what: String,
        /// zstd's message.
        message: String,
    },
    /// The metadata section is not a JSON object.
    #[error("metadata JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// The metadata is valid JSON but not an object.
    #[error("metadata must be a JSON object, found {found}")]
    MetadataNotObject {
        /// The JSON type found.
        found: &'static str,
    },
    /// Brick coordinates are out of the grid, unsorted or repeated.
    #[error("invalid brick list: {0}")]
    InvalidBricks(String),
    /// A decoded value is out of its allowed range (e.g. negative density).
    #[error("invalid value in {what}: {reason}")]
    InvalidValue {
        /// Where.
        what: String,
        /// Why.
        reason: String,
    },
    /// An in-memory asset is inconsistent (lengths, ranks) and cannot be written.
    #[error("invalid asset: {0}")]
    InvalidAsset(String),
    /// The view-dependent part (format 1.2) is malformed: `VDEP`'s sizes out of range or
    /// disagreeing with its length, or one of `VDEP` and `VCOF` without the other.
    #[error("invalid view-dependent part: {0}")]
    InvalidView(String),
    /// A byte outside the header, table and sections is not zero.
    #[error("non-zero padding byte at offset {offset} (bytes between sections must be zero)")]
    NonZeroPadding {
        /// Offset of the first non-zero byte.
        offset: u64,
    },
    /// A brick index past the end.
    #[error("brick index {index} out of range (asset has {count} bricks)")]
    BrickOutOfRange {
        /// Index asked for.
        index: usize,
        /// Bricks in the asset.
        count: usize,
    },
}

/// Shorthand for results of this crate's asset functions.
pub type Result<T, E = FormatError> = std::result::Result<T, E>;
