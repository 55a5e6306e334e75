//! Errors of the scene loaders (meshes, textures, environment maps): every
//! variant names the file it is about, and parse errors name the line, so a
//! user can fix the file without reading our code. [`error_chain`] puts any
//! error and its causes on one line (for reports that keep only text).

use std::path::PathBuf;

use nelf_format::io_error::FileIoError;

use crate::mesh::MeshError;

/// An error loading or writing a scene file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The operating system refused to read or write the file.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// A text file is malformed at a line.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong there.
        message: String,
    },
    /// A file is malformed or unsupported (no single line to blame).
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The file's extension names no format we read.
    #[error("{path}: unsupported file type (expected {expected})")]
    UnsupportedExtension {
        /// The file.
        path: PathBuf,
        /// The extensions we read.
        expected: &'static str,
    },
    /// An image (texture, HDR map, preview) could not be decoded or encoded.
    #[error("{path}: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The image crate's error.
        source: image::ImageError,
    },
    /// The file parsed but the mesh it describes is invalid.
    #[error("{path}: {source}")]
    Mesh {
        /// The file.
        path: PathBuf,
        /// Why the mesh is invalid.
        source: MeshError,
    },
}

impl SceneError {
    /// A parse error at `line` (1-based) of `path`.
    pub(crate) fn parse(path: &std::path::Path, line: usize, message: impl Into<String>) -> Self {
        Self::Parse {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    /// A whole-file format error.
    pub(crate) fn format(path: &std::path::Path, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    /// An I/O error on `path`.
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Self::Io(FileIoError::new(path.to_path_buf(), source))
    }
}

/// An error's message and those of its causes, joined by `": "` (a cause that
/// repeats the message before it, as a transparent wrapper's does, is left out).
pub fn error_chain(error: &dyn std::error::Error) -> String {
    let mut messages = vec![error.to_string()];
    let mut source = error.source();
    while let Some(cause) = source {
        let message = cause.to_string();
        if messages.last() != Some(&message) {
            messages.push(message);
        }
        source = cause.source();
    }
    messages.join(": ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("inner cause")]
    struct Inner;

    #[derive(Debug, thiserror::Error)]
    enum Outer {
        #[error("while doing it")]
        Context(#[source] Inner),
        #[error(transparent)]
        Transparent(#[from] Inner),
    }

    #[test]
    fn the_chain_names_every_cause_once() {
        assert_eq!(error_chain(&Outer::Context(Inner)), "while doing it: inner cause");
        assert_eq!(error_chain(&Outer::Transparent(Inner)), "inner cause");
    }
}
