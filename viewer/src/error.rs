//! Errors of the viewer library.

use nelf_format::FormatError;
use nelf_format::conventions::ConventionError;
use nelf_render::RenderError;

/// Everything that can go wrong loading, relighting or rendering on the GPU.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// No wgpu adapter (headless: Mesa's lavapipe provides one on machines without a GPU).
    #[error(
        "no GPU adapter found ({0}); on a machine without a GPU install Mesa's software Vulkan driver: \
         apt-get install -y mesa-vulkan-drivers"
    )]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("cannot create a GPU device: {0}")]
    Device(String),
    /// The asset file could not be read or is invalid.
    #[error("asset: {0}")]
    Format(#[from] FormatError),
    /// The reference renderer's checks (lighting projection, grid) failed.
    #[error("{0}")]
    Render(#[from] RenderError),
    /// A camera or environment map is invalid.
    #[error("{0}")]
    Convention(#[from] ConventionError),
    /// The asset does not fit this device's limits.
    #[error("asset too large for this GPU: {0}")]
    TooLarge(String),
    /// Rendering was asked for before an asset was loaded.
    #[error("no asset loaded")]
    NoAsset,
    /// Rendering was asked for before lighting was set.
    #[error("no lighting set")]
    NoLighting,
    /// A setting is out of range.
    #[error("invalid setting: {0}")]
    BadSetting(String),
    /// A GPU read-back or submission failed.
    #[error("GPU read-back failed: {0}")]
    Readback(String),
    /// The window or event loop failed.
    #[error("viewer window: {0}")]
    App(String),
    /// Something needs compute shaders and storage bindings, which the device (WebGL2)
    /// lacks.
    #[error(
        "{0} needs compute shaders and storage buffers, which this GPU device lacks (WebGL2): \
         use a WebGPU browser or the native viewer"
    )]
    NoCompute(&'static str),
    /// A shader failed to preprocess (a bug: shaders are embedded).
    #[error("shader: {0}")]
    Shader(#[from] crate::shaders::PreprocessError),
}
