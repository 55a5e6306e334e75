//! The baker's one error type, [`BakeError`]. Every variant about an input names
//! the file (and the view, where there is one), so a user can fix the capture
//! without reading the baker's code.

use std::path::PathBuf;

use nelf_format::FormatError;
use nelf_format::capture::CaptureError;
use nelf_format::colmap::ColmapError;
use nelf_format::io_error::FileIoError;
use nelf_render::RenderError;
use nelf_scene::error::SceneError;
use nelf_scene::field::FieldError;
use nelf_scene::synth::SynthError;

/// Everything that can go wrong loading a capture or baking an asset.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// A file could not be read or written.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// An image or mask could not be decoded.
    #[error("{path}: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        source: image::ImageError,
    },
    /// A JSON file could not be read or written.
    #[error("{path}: {message}")]
    Json {
        /// The file.
        path: PathBuf,
        /// What went wrong (with line and column when parsing).
        message: String,
    },
    /// `cameras.json` is invalid or names a missing file.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// A COLMAP text model is invalid.
    #[error(transparent)]
    Colmap(#[from] ColmapError),
    /// The folder holds neither a `cameras.json` nor a COLMAP text model.
    #[error(
        "{dir}: no capture found (expected cameras.json, or a COLMAP text model: cameras.txt and \
         images.txt in the folder or in sparse/0/)"
    )]
    NoCapture {
        /// The folder.
        dir: PathBuf,
    },
    /// A file a view needs does not exist.
    #[error("{path}: {what} does not exist")]
    MissingFile {
        /// The file looked for.
        path: PathBuf,
        /// What it is (`image of view "IMG_1.jpg"`).
        what: String,
    },
    /// The capture has fewer views than the baker needs.
    #[error("{path}: the capture has {count} view(s); baking needs at least 2")]
    TooFewViews {
        /// The camera file.
        path: PathBuf,
        /// Views found.
        count: usize,
    },
    /// An image or mask does not have the size the camera (or the image) says.
    #[error("{path}: {what} is {found_w}×{found_h} pixels but must be {expected_w}×{expected_h}{hint}")]
    SizeMismatch {
        /// The image or mask file.
        path: PathBuf,
        /// What it is.
        what: String,
        /// Width required.
        expected_w: u32,
        /// Height required.
        expected_h: u32,
        /// Width found.
        found_w: u32,
        /// Height found.
        found_h: u32,
        /// What may have happened (empty, or a sentence starting with a separator).
        hint: String,
    },
    /// A view has no mask file and its image has no alpha channel.
    #[error("{path}: view {view:?} has no mask (no mask file, and the image has no alpha channel)")]
    NoMask {
        /// The image file.
        path: PathBuf,
        /// The view.
        view: String,
    },
    /// A mask has no foreground pixel (> 0.5).
    #[error("{path}: the mask of view {view:?} has no foreground pixel (> 0.5)")]
    EmptyMask {
        /// The mask (or image) file.
        path: PathBuf,
        /// The view.
        view: String,
    },
    /// A pixel of an image is NaN or infinite.
    #[error("{path}: pixel ({x}, {y}) is not finite")]
    NonFinitePixel {
        /// The image file.
        path: PathBuf,
        /// Column.
        x: u32,
        /// Row.
        y: u32,
    },
    /// A camera's pose or intrinsics are unusable (non-finite, not a rotation, …).
    #[error("{path}: view {view:?}: {reason}")]
    BadCamera {
        /// The camera file.
        path: PathBuf,
        /// The view.
        view: String,
        /// What is wrong.
        reason: String,
    },
    /// The head centre (the point nearest every optical axis) is behind a camera.
    #[error(
        "{path}: view {view:?}: the head centre {centre_m:?} m (the point nearest all optical axes) \
         is behind the camera (depth {depth_m:.4} m); check the pose's convention (world-to-camera, OpenCV axes)"
    )]
    CameraBehindHead {
        /// The camera file.
        path: PathBuf,
        /// The view.
        view: String,
        /// Estimated head centre, metres.
        centre_m: [f64; 3],
        /// Its depth in this camera, metres (≤ 0).
        depth_m: f64,
    },
    /// The optical axes are (nearly) parallel, so no head centre can be located.
    #[error("{path}: the cameras' optical axes are (nearly) parallel; cannot locate the subject")]
    ParallelAxes {
        /// The camera file.
        path: PathBuf,
    },
    /// The visual hull is empty or unbounded.
    #[error("visual hull: {0}")]
    Hull(String),
    /// The field source failed.
    #[error(transparent)]
    Field(#[from] FieldError),
    /// The asset could not be built or written.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The reference renderer failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// An image metric could not be computed (sizes differ, image too small).
    #[error(transparent)]
    Metric(#[from] nelf_scene::metrics::MetricError),
    /// The ground-truth path tracer could not render a reference view.
    #[error(transparent)]
    GroundTruthRender(#[from] nelf_scene::render::RenderError),
    /// The ground-truth path tracer could not be set up.
    #[error(transparent)]
    Trace(#[from] nelf_scene::tracer::TraceError),
    /// A mesh, map or image could not be read.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The ground-truth mesh could not be rebuilt from `synth_config.json`.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// A setting is out of range.
    #[error("invalid bake settings: {0}")]
    Settings(String),
    /// Nothing is left to bake (every brick was dropped).
    #[error("nothing to bake: {0}")]
    Empty(String),
    /// The PCA failed (non-finite light transport, no weight).
    #[error("PCA: {0}")]
    Pca(String),
}

/// Shorthand for results of this crate.
pub type Result<T, E = BakeError> = std::result::Result<T, E>;

pub(crate) fn io_error(path: impl Into<PathBuf>, source: std::io::Error) -> BakeError {
    BakeError::Io(FileIoError::new(path.into(), source))
}
