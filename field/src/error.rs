//! Errors of the NeLF network crate: tensor backend failures, bad inputs (shapes,
//! view counts, image sizes), unreadable weights or capture files.

use std::path::PathBuf;

/// Errors building or running the NeLF network.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// The tensor backend (candle) failed: a missing or mis-shaped weight, a device error.
    #[error("tensor backend: {0}")]
    Candle(#[from] candle_core::Error),
    /// An input has the wrong size or value.
    #[error("invalid input: {0}")]
    Input(String),
    /// A file could not be read or decoded.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The capture description is invalid.
    #[error(transparent)]
    Capture(#[from] nelf_format::capture::CaptureError),
    /// A conventions helper refused its input (e.g. not a rotation).
    #[error(transparent)]
    Convention(#[from] nelf_format::conventions::ConventionError),
}

impl NetError {
    /// An [`NetError::Input`] from anything printable.
    pub(crate) fn input(message: impl Into<String>) -> Self {
        Self::Input(message.into())
    }

    /// A [`NetError::File`] for `path`.
    pub(crate) fn file(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::File {
            path: path.into(),
            message: message.into(),
        }
    }
}

impl From<NetError> for nelf_scene::field::FieldError {
    /// A network failure seen by the baker: [`nelf_scene::field::FieldError::Backend`].
    fn from(e: NetError) -> Self {
        Self::Backend(e.to_string())
    }
}
