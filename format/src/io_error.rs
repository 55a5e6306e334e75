//! The one shape of an operating-system error on a named file, shared by every
//! crate of the workspace: [`FileIoError`] holds the path and the `std::io::Error`
//! and displays as `path: error`. A crate's error enum wraps it in one variant,
//! `Io(#[from] FileIoError)`, and an I/O call names its file with
//! [`IoResultExt::with_path`]:
//!
//! ```
//! use nelf_format::io_error::{FileIoError, IoResultExt};
//! let err: FileIoError = std::fs::read("/no/such/file").with_path("/no/such/file").unwrap_err();
//! assert!(err.to_string().starts_with("/no/such/file: "));
//! ```

use std::path::{Path, PathBuf};

/// An I/O error on a file or folder, with the path it concerns.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct FileIoError {
    /// The file or folder.
    pub path: PathBuf,
    /// The operating system's error.
    #[source]
    pub source: std::io::Error,
}

impl FileIoError {
    /// The error `source` on `path`.
    pub fn new(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self {
            path: path.into(),
            source,
        }
    }

    /// The kind of the operating system's error.
    pub fn kind(&self) -> std::io::ErrorKind {
        self.source.kind()
    }
}

/// Names the file of an I/O result's error.
pub trait IoResultExt<T> {
    /// The result, its error turned into a [`FileIoError`] on `path`.
    fn with_path(self, path: impl AsRef<Path>) -> Result<T, FileIoError>;
}

impl<T> IoResultExt<T> for std::io::Result<T> {
    fn with_path(self, path: impl AsRef<Path>) -> Result<T, FileIoError> {
        self.map_err(|source| FileIoError::new(path.as_ref(), source))
    }
}
