//! What can go wrong in a batch: a plan that cannot be read (named by file and line),
//! an index outside the plan, an item whose command failed, files that cannot be
//! written, a scheduler that refused a submission.

use std::path::PathBuf;

/// Errors of `nelf-batch`.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// A file or folder could not be read, written, renamed or removed.
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    /// A line of a plan is not what `nelf batch plan` writes.
    #[error("{path} line {line}: {message}")]
    PlanLine {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// Settings that make no plan (no inputs, a chunk of 0, duplicate ids …).
    #[error("{0}")]
    Settings(String),
    /// An index outside the plan's array, or none given.
    #[error("{0}")]
    Index(String),
    /// A scheduler command (sbatch) could not run or refused the job.
    #[error("{0}")]
    Scheduler(String),
}

impl BatchError {
    pub(crate) fn io(path: impl Into<PathBuf>, error: &std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            message: error.to_string(),
        }
    }
}

/// Results of this crate.
pub type Result<T> = std::result::Result<T, BatchError>;
