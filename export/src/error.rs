//! The errors of `nelf-export` ([`ExportError`], and [`VdbError`] for the OpenVDB
//! writer): each names what is wrong so that a bad option or asset gives a message a
//! person can act on, never a panic.

use std::path::PathBuf;

use nelf_format::FormatError;
use nelf_format::io_error::FileIoError;
use nelf_render::RenderError;
use nelf_scene::shot::ShotError;

/// What the OpenVDB writer refuses.
#[derive(Debug, thiserror::Error)]
pub enum VdbError {
    /// Grids need a name (OpenVDB renames unnamed ones).
    #[error("a grid needs a non-empty name")]
    EmptyName,
    /// Two grids with one name (OpenVDB would rename the second).
    #[error("two grids are named {0:?}")]
    DuplicateGrid(String),
    /// Voxel size not finite and positive, or translation not finite.
    #[error("invalid transform: voxel size {voxel_size}, translation {translation:?}")]
    BadTransform {
        /// Voxel edge length.
        voxel_size: f64,
        /// World position of index (0, 0, 0).
        translation: [f64; 3],
    },
    /// A leaf origin that is not a multiple of 8.
    #[error("leaf origin {0:?} is not a multiple of 8 on every axis")]
    LeafOrigin([i32; 3]),
    /// A leaf without exactly 512 values.
    #[error("a leaf holds 512 values, not {0}")]
    LeafSize(usize),
    /// Two leaves at one origin.
    #[error("two leaves at origin {0:?}")]
    DuplicateLeaf([i32; 3]),
    /// A NaN or infinite value.
    #[error("grid {grid:?}: value {offset} of the leaf at {origin:?} is not finite")]
    NotFinite {
        /// Grid name.
        grid: String,
        /// Leaf origin.
        origin: [i32; 3],
        /// Index in the leaf.
        offset: usize,
    },
    /// Grid metadata keys the writer sets itself (`name`, `class`, `file_*`).
    #[error("grid metadata key {0:?} is reserved for the writer")]
    ReservedKey(String),
    /// A count or length beyond the file format's 32-bit fields.
    #[error("too many {0} for an OpenVDB file")]
    TooLarge(&'static str),
}

/// Everything that can go wrong exporting an asset.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// An export option out of range.
    #[error("invalid option: {0}")]
    BadOption(String),
    /// The asset breaks the `.nelf` rules.
    #[error("invalid asset: {0}")]
    Asset(#[from] FormatError),
    /// Relighting failed (bad lighting or PCA model).
    #[error("relighting failed: {0}")]
    Render(#[from] RenderError),
    /// The asset's stored lighting (`estimated_light` metadata) is malformed.
    #[error("the asset's metadata `estimated_light` is invalid: {0}")]
    StoredLight(String),
    /// Metadata that cannot be written as JSON.
    #[error("metadata: {0}")]
    Metadata(String),
    /// The OpenVDB writer refused the grids.
    #[error("OpenVDB: {0}")]
    Vdb(#[from] VdbError),
    /// Translating the WGSL shaders for engines failed.
    #[error("engine shaders: {0}")]
    Shader(String),
    /// Reading or writing a file.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// The asset file could not be read, or is not a valid `.nelf` file.
    #[error("cannot read {}", .path.display())]
    ReadAsset {
        /// The asset file.
        path: PathBuf,
        /// Why.
        #[source]
        source: FormatError,
    },
    /// An environment map given as an option could not be loaded (boxed: the
    /// error is large).
    #[error(transparent)]
    Lighting(Box<ShotError>),
    /// A file's size could not be read.
    #[error("cannot stat {}", .path.display())]
    Stat {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// An export's settings record (`<out>.export.json`) could not be written.
    #[error("cannot write {}", .path.display())]
    WriteRecord {
        /// The record's file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// One step of an export command failed: `step` says which, of what
    /// (`cannot export head.nelf to head.vdb`), `source` why.
    #[error("{step}")]
    Step {
        /// The step and its files.
        step: String,
        /// Why it failed.
        #[source]
        source: Box<ExportError>,
    },
}

impl ExportError {
    /// Wraps an error of the step `step` ([`ExportError::Step`]), for `map_err`.
    pub fn step(step: String) -> impl FnOnce(Self) -> Self {
        move |source| Self::Step {
            step,
            source: Box::new(source),
        }
    }
}
