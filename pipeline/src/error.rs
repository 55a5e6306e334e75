//! Errors of the pipeline: the libraries' own, and what the pipeline was doing when
//! one happened ([`Context`]).

use nelf_format::io_error::FileIoError;

/// What can go wrong between a capture and an asset.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A step failed; `source` says how.
    #[error("{context}")]
    Context {
        /// What the pipeline was doing.
        context: String,
        /// Why it failed.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Something expected is missing or a setting is unusable.
    #[error("{0}")]
    Invalid(String),
    /// The baker failed.
    #[error(transparent)]
    Bake(#[from] nelf_bake::BakeError),
    /// The network failed.
    #[error(transparent)]
    Net(#[from] nelf_field::NetError),
    /// A field refused a batch or a setting.
    #[error(transparent)]
    Field(#[from] nelf_scene::field::FieldError),
    /// The file format or its conventions refused something.
    #[error(transparent)]
    Format(#[from] nelf_format::FormatError),
    /// Rendering an asset failed.
    #[error(transparent)]
    Render(#[from] nelf_render::RenderError),
    /// An image metric refused its inputs.
    #[error(transparent)]
    Metric(#[from] nelf_scene::metrics::MetricError),
    /// Reading or writing an image or an environment map failed.
    #[error(transparent)]
    Scene(#[from] nelf_scene::error::SceneError),
    /// A synthetic capture could not be made.
    #[error(transparent)]
    Synth(#[from] nelf_scene::synth::SynthError),
    /// A frame or lighting convention was broken.
    #[error(transparent)]
    Convention(#[from] nelf_format::conventions::ConventionError),
    /// Camera or lighting setup failed (boxed: a large error).
    #[error(transparent)]
    Shot(Box<nelf_scene::shot::ShotError>),
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// Encoding JSON failed.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

impl From<nelf_scene::shot::ShotError> for PipelineError {
    fn from(e: nelf_scene::shot::ShotError) -> Self {
        Self::Shot(Box::new(e))
    }
}

/// Results of the pipeline.
pub type Result<T> = std::result::Result<T, PipelineError>;

/// Says what the pipeline was doing when a step failed, or what was missing.
pub trait Context<T> {
    /// The value, or an error saying `context()` with the failure as its source.
    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T>;

    /// As [`Context::with_context`] with a fixed message.
    fn context(self, context: &str) -> Result<T>
    where
        Self: Sized,
    {
        self.with_context(|| context)
    }
}

impl<T, E: std::error::Error + Send + Sync + 'static> Context<T> for std::result::Result<T, E> {
    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T> {
        self.map_err(|e| PipelineError::Context {
            context: context().into(),
            source: Box::new(e),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T> {
        self.ok_or_else(|| PipelineError::Invalid(context().into()))
    }
}

/// An error saying `message`, for `?` in a pipeline function.
pub(crate) fn invalid(message: impl Into<String>) -> PipelineError {
    PipelineError::Invalid(message.into())
}
