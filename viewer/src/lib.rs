//! `nelf-viewer`: real-time viewing of `.nelf` light-transport assets.
//!
//! * [`gpu::GpuRenderer`] — the wgpu renderer, usable without a window: a brick atlas
//!   with 1-voxel aprons and a march grid for empty-space skipping ([`atlas`]), a relight
//!   compute pass run once per lighting change (the environment map projected onto the
//!   asset's PCA basis, then a `K`-term dot product per voxel; at a held camera only for
//!   the voxels it reads), and a ray-march pass per frame that
//!   mirrors the CPU reference renderer `nelf_render` (same rays, sample lattice,
//!   trilinear interpolation, compositing and early termination). A view-dependent asset
//!   (format 1.2) adds a per-voxel view pass between them, run when the eye or the
//!   lighting changes, that adds the radiance's view-dependent lobes toward the eye.
//! * [`app`] — the interactive viewer (eframe/egui on the same renderer): orbit, zoom,
//!   pan, environment maps, rotation, exposure, PCA rank, debug views, screenshots.
//! * [`shaders`] — the WGSL passes in `../shaders/` and their Rust mirrors.
//!
//! The CPU reference renderer itself is the `nelf-render` crate, which this crate
//! compares against in its tests.

pub mod app;
pub mod atlas;
pub mod error;
pub mod gpu;
pub mod shaders;

#[cfg(not(target_arch = "wasm32"))]
pub use app::run_viewer;
pub use app::{
    FrameHook, FrameReport, IncomingFile, NamedEnvmap, OrbitStart, StartView, ViewerConfig, create_app,
};
pub use atlas::{GpuMemory, RelightView};
pub use error::ViewerError;
pub use gpu::{
    AssetInfo, DEFAULT_REPLAY_BUDGET_BYTES, DisplayImage, DisplaySettings, GpuRenderer, MarchPass, MarchView,
    ReflectionInfo, RelightKind, ToneMap, ViewInfo, ViewSettings, render_asset_gpu,
};
