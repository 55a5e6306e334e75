//! What went wrong writing a report ([`ReportError`]), naming the file.

use std::path::{Path, PathBuf};

/// What went wrong writing a report, and where.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file could not be written.
    #[error("could not write {}: {source}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file the report embeds could not be read.
    #[error("could not read {}: {source}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A value could not be serialised to JSON.
    #[error("could not serialise JSON for {}: {source}", .path.display())]
    Json {
        /// The file it was for.
        path: PathBuf,
        /// The serialisation error.
        source: serde_json::Error,
    },
    /// `plotters` failed to draw a chart.
    #[error("could not draw the chart \"{title}\": {message}")]
    Chart {
        /// The chart's title.
        title: String,
        /// What `plotters` reported.
        message: String,
    },
}

impl ReportError {
    /// Maps the I/O error of writing `path` (with `nelf_format::atomic`, or creating a
    /// folder) to [`ReportError::Write`].
    pub(super) fn writing(path: &Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        |source| Self::Write {
            path: path.to_path_buf(),
            source,
        }
    }
}
