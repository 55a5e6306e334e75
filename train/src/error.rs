//! Errors of `nelf-train`. Every error that concerns a file names it.

use std::path::PathBuf;

use nelf_format::io_error::FileIoError;

/// Errors making, reading or training on a dataset.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The operating system refused to read, write, rename or list a file or folder.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// A file exists but its content is damaged, of the wrong size or unreadable.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// A dataset folder was made with other settings than the ones given now.
    #[error(
        "{path}: the dataset in this folder was made with other settings ({differences}); \
         rerun with the same settings to resume, or choose another folder"
    )]
    ConfigMismatch {
        /// The settings file of the existing dataset.
        path: PathBuf,
        /// The settings that differ, `name: was → now`.
        differences: String,
    },
    /// A setting is out of range or inconsistent.
    #[error("invalid settings: {0}")]
    Settings(String),
    /// A head is not (or not yet) in the dataset.
    #[error("{dir}: head {id} is not a finished head of this dataset")]
    MissingHead {
        /// The head's folder.
        dir: PathBuf,
        /// The head's id.
        id: u32,
    },
    /// Rendering a head's synthetic capture failed.
    #[error("rendering head {id} into {path}: {source}")]
    Synth {
        /// The head's id.
        id: u32,
        /// The (temporary) folder it was written to.
        path: PathBuf,
        /// What went wrong (boxed: it is large).
        source: Box<nelf_scene::synth::SynthError>,
    },
    /// The ground-truth tracer or field of a head could not be built or evaluated.
    #[error("ground truth of head {id}: {message}")]
    GroundTruth {
        /// The head's id.
        id: u32,
        /// What went wrong.
        message: String,
    },
    /// A capture folder's description (`cameras.json`) is invalid.
    #[error(transparent)]
    Capture(#[from] nelf_format::capture::CaptureError),
    /// The network rejected its inputs or weights.
    #[error(transparent)]
    Net(#[from] nelf_field::NetError),
    /// A tensor operation failed (shapes, devices, a missing gradient).
    #[error("tensor operation: {0}")]
    Candle(#[from] candle_core::Error),
}

impl TrainError {
    /// A [`TrainError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io(FileIoError::new(path.into(), source))
    }

    /// A [`TrainError::File`] for `path`.
    pub fn file(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::File {
            path: path.into(),
            message: message.into(),
        }
    }
}
