//! Errors of `nelf eval`: every one names the file or setting at fault.

use std::path::PathBuf;

/// What can go wrong while evaluating.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// Baking or loading a capture failed.
    #[error(transparent)]
    Bake(#[from] nelf_bake::BakeError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] nelf_render::RenderError),
    /// An image metric refused its inputs.
    #[error(transparent)]
    Metric(#[from] nelf_scene::metrics::MetricError),
    /// A synthetic capture could not be made.
    #[error(transparent)]
    Synth(#[from] nelf_scene::synth::SynthError),
    /// Camera or lighting setup failed (boxed: the largest error by far).
    #[error(transparent)]
    Shot(Box<nelf_scene::shot::ShotError>),
    /// The file format refused an asset.
    #[error(transparent)]
    Format(#[from] nelf_format::FormatError),
    /// The GPU renderer failed.
    #[error(transparent)]
    Viewer(#[from] nelf_viewer::ViewerError),
    /// Perturbing a capture failed.
    #[error(transparent)]
    Perturb(#[from] crate::perturb::PerturbError),
    /// Writing a report failed.
    #[error(transparent)]
    Report(#[from] crate::report::ReportError),
    /// A pipeline step (the photographs' reconstruction, the network) failed (boxed:
    /// it is large).
    #[error(transparent)]
    Pipeline(Box<nelf_pipeline::error::PipelineError>),
    /// Reading or writing a file failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The input or a setting is unusable.
    #[error("{0}")]
    Input(String),
}

impl From<nelf_scene::shot::ShotError> for EvalError {
    fn from(e: nelf_scene::shot::ShotError) -> Self {
        Self::Shot(Box::new(e))
    }
}

/// Results of `nelf-eval`.
pub type Result<T> = std::result::Result<T, EvalError>;

impl From<nelf_pipeline::error::PipelineError> for EvalError {
    fn from(e: nelf_pipeline::error::PipelineError) -> Self {
        Self::Pipeline(Box::new(e))
    }
}
