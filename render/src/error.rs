//! The one error type of the reference renderer ([`RenderError`]): every variant
//! names the input that is wrong and why, so a bad asset, camera or lighting gives
//! a message a person can act on, never a panic.

use nelf_format::FormatError;
use nelf_format::conventions::ConventionError;

/// Everything that can go wrong preparing or running a render.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The grid geometry is out of range (origin, voxel size, extent).
    #[error("invalid grid: {0}")]
    InvalidGrid(String),
    /// Brick coordinates are outside the grid, unsorted or repeated.
    #[error("invalid bricks: {0}")]
    InvalidBricks(String),
    /// A per-voxel array does not have one entry per voxel of the grid.
    #[error("{what} has {found} entries but the grid has {expected} voxels")]
    LengthMismatch {
        /// Which array.
        what: &'static str,
        /// Entries the grid needs.
        expected: usize,
        /// Entries supplied.
        found: usize,
    },
    /// A matrix that must be a rotation is not.
    #[error("{what} is not a rotation (orthonormal, det +1): {matrix:?}")]
    NotARotation {
        /// Which matrix.
        what: &'static str,
        /// Its columns.
        matrix: [f64; 9],
    },
    /// A camera or lat-long map is unusable.
    #[error(transparent)]
    Convention(#[from] ConventionError),
    /// The asset (or its PCA model) breaks the file format's rules.
    #[error("invalid asset: {0}")]
    Asset(#[from] FormatError),
    /// Ray-marching settings out of range.
    #[error("invalid march settings: {0}")]
    BadSettings(String),
}
