//! The GPU renderer (wgpu): loads an asset into a brick atlas, relights it with a
//! compute pass once per lighting change, ray-marches it with a compute pass per frame,
//! and either reads the linear image back (headless) or draws it, tone-mapped, into a
//! render pass (the app). It mirrors the CPU reference renderer `nelf_render` step for
//! step (see `shaders/march.wgsl`), so the two agree to f16 precision.
//!
//! Relighting (`docs/CONVENTIONS.md`, "Light frame and projection of a user's map"): the environment map is projected onto the asset's PCA
//! basis on the CPU ([`nelf_render::project_light`], `3(K + 1)` numbers), then every
//! voxel's radiance is its `K`-term dot product, written with its density into an RGBA16F
//! atlas ([`crate::atlas`]). Shading is linear, so marching the relit atlas equals
//! shading every sample; a frame without a lighting change costs only the march. A
//! lighting change at a held camera caches its frame per pixel, and the next lighting
//! changes at that camera are a dot product per pixel with no march (`replay`); where the
//! cache would be too large, that first change marks the voxels its march reads (about
//! 7 % of a head's) and the next ones relight only those (`marks`).
//!
//! A view-dependent asset (format 1.2) adds one small per-voxel pass between the two,
//! run only when the camera's eye or the lighting changed: the relight pass then writes
//! each voxel's radiance and lobe colours to a buffer and the view pass adds the lobes
//! toward the eye into the atlas (`gpu/view.rs`); the march is the same. A reflection
//! asset (format 1.3) does the same with its reflect pass (`gpu/reflect.rs`: the radiance
//! of a glossy lobe about the mirror direction, looked up in the lighting filtered by the
//! lobe). A view-independent asset takes exactly the path above.
//!
//! An asset with a fine density (format 1.4) adds a second, σ-only atlas at the fine
//! resolution, built once at load (`atlas::fine_density_atlas`): the march takes σ from
//! it and the radiance from the relit atlas at the same point, with a step of
//! `step_voxels` fine voxels (`nelf_render::render_volume_fine`); every other pass is
//! unchanged.
//!
//! One module per pass, as the shaders are (`shaders/*.wgsl`): `relight` (relight.wgsl),
//! `marks` (the marked relight: relight.wgsl's `relight_marked`, march.wgsl's marking),
//! `replay` (replay.wgsl: a held camera's frame relit per pixel),
//! `view` (view.wgsl and relight.wgsl's `relight_lobes`), `reflect` (reflect.wgsl and
//! `relight_lobes` with no lobes), `march` (march.wgsl, compute, counting and fragment
//! variants), `display` (display.wgsl: exposure, tone map, sRGB);
//! `common` holds the layout and pipeline helpers they share and `readback` the headless
//! read-back. Around them: `device` (adapter, device, pipelines), `upload` (the asset's
//! GPU resources), `lighting` (the lighting, rank and relight view the next frames use)
//! and `frame` (the march target and one frame's encoding, calling the passes). This
//! module holds the renderer's types and the public API's re-exports.

mod common;
mod device;
mod display;
mod frame;
mod lighting;
mod march;
mod marks;
mod readback;
mod reflect;
mod relight;
mod replay;
mod upload;
mod view;

use glam::DMat3;
use nelf_format::conventions::LatLong;
use nelf_format::{CoefficientEncoding, GridGeometry, PcaModel};
use nelf_render::{FilteredEnvironment, ProjectedLight};

use self::display::DisplayPipelines;
pub use self::display::{DisplayImage, DisplaySettings, ToneMap};
use self::march::MarchPipelines;
pub use self::march::{MarchPass, MarchView, ViewSettings};
pub use self::marks::RelightKind;
use self::marks::{GpuMarks, MarkPipelines};
pub use self::readback::render_asset_gpu;
use self::reflect::{GpuReflection, ReflectPipeline};
use self::relight::RelightPipeline;
pub use self::replay::DEFAULT_REPLAY_BUDGET_BYTES;
use self::replay::{GpuReplay, ReplayInputs, ReplayPipelines};
use self::view::{GpuView, LobesPipeline, ViewPipeline};
use crate::atlas::{AtlasLayout, Dequantization, GpuMemory, PackedCoefficients, RelightView};
use crate::shaders::MarchParams;

/// What loading an asset produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssetInfo {
    /// Bricks (their atlas slots come first).
    pub bricks: usize,
    /// Halo slots: missing bricks next to present ones (zeros plus aprons).
    pub halo_slots: usize,
    /// PCA rank `K`.
    pub rank: usize,
    /// Atlas size in texels.
    pub atlas_texels: [u32; 3],
    /// GPU memory by part.
    pub memory: GpuMemory,
    /// Largest voxel density (1/m).
    pub max_density_per_m: f32,
    /// The view-dependent part (format 1.2), if the asset has one.
    pub view: Option<ViewInfo>,
    /// The reflection part (format 1.3), if the asset has one.
    pub reflection: Option<ReflectionInfo>,
    /// The asset's view-dependent or reflection part, named, where this renderer left it
    /// out because its device has no compute shaders (WebGL2): it then shows the
    /// view-averaged light transport every reader can show. `None` where nothing was
    /// left out.
    pub view_part_ignored: Option<&'static str>,
    /// The factor `F` of the asset's fine density (format 1.4) where the march takes σ
    /// from it; `None` where the asset has none or it was left out.
    pub fine_density: Option<u32>,
    /// The factor of the asset's fine density where this renderer left it out because
    /// its atlas does not fit the device's 3D textures (WebGL2 promises only 256 texels a
    /// side): it then shows the voxels' density, the coarse asset every reader can show.
    /// `None` where nothing was left out.
    pub fine_density_ignored: Option<u32>,
}

/// What a view-dependent asset's view part holds ([`nelf_format::ViewDependence`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewInfo {
    /// Lobes `J`.
    pub lobes: usize,
    /// View basis rank `K_v`.
    pub rank: usize,
    /// Encoding of its per-voxel coefficients.
    pub encoding: CoefficientEncoding,
}

/// What a reflection asset's reflection part holds ([`nelf_format::Reflection`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectionInfo {
    /// The lobe's exponent λ.
    pub exponent: f32,
    /// The eyes the PCA part averages over.
    pub eyes: usize,
}

/// Compute and render pipelines, created once per device: one set per pass. A device
/// without storage bindings (WebGL2) gets no compute pipelines: its relight runs on the
/// CPU (`atlas::relight_atlas_cpu`) and its march is `march_nostorage.wgsl`.
struct Pipelines {
    relight: Option<RelightPipeline>,
    marks: Option<MarkPipelines>,
    /// The per-pixel replay of a held camera (`None` without storage bindings).
    replay: Option<ReplayPipelines>,
    march: MarchPipelines,
    display: DisplayPipelines,
    /// `relight_lobes`, created with the first view-dependent asset of either kind.
    lobes: Option<LobesPipeline>,
    /// Created with the first view-dependent asset (format 1.2).
    view: Option<ViewPipeline>,
    /// Created with the first reflection asset (format 1.3).
    reflect: Option<ReflectPipeline>,
}

/// An asset resident on the GPU.
struct GpuAsset {
    layout: AtlasLayout,
    grid: GridGeometry,
    pca: PcaModel,
    world_from_light: DMat3,
    dequantization: Dequantization,
    coefficient_words_per_voxel: u32,
    coefficient_encoding: i32,
    atlas: wgpu::Texture,
    atlas_view: wgpu::TextureView,
    /// The fine density atlas (format 1.4), or a placeholder.
    fine: GpuFineDensity,
    /// The march grid (`atlas::MarchGrid`): distances for empty-space skipping and slots.
    march_grid_view: wgpu::TextureView,
    /// Voxels per march-grid texel edge.
    march_grid_factor: u32,
    relight_params: wgpu::Buffer,
    light: wgpu::Buffer,
    /// The relight pass's bindings (`None` without storage bindings).
    relight_bind_group: Option<wgpu::BindGroup>,
    /// The voxels a marking march read (`marks.rs`; `None` without storage bindings).
    marks: Option<GpuMarks>,
    /// What the per-pixel replay reads (`replay.rs`; `None` without storage bindings).
    replay: Option<ReplayInputs>,
    /// What the CPU relight reads, on a device without storage bindings.
    cpu_relight: Option<CpuRelight>,
    /// The view part of a view-dependent asset.
    view: Option<GpuView>,
    /// The reflection part of a reflection asset.
    reflection: Option<GpuReflection>,
    voxel_count: usize,
    info: AssetInfo,
}

/// An asset's fine density on the GPU (format 1.4; `atlas::fine_density_atlas`): the
/// march reads σ from it where `factor > 0`. An asset without one (or whose fine density
/// was left out) binds a 1-texel placeholder with `factor = 0`.
struct GpuFineDensity {
    /// `F`, or 0 for none.
    factor: u32,
    /// Its atlas's size in texels.
    texels: [u32; 3],
    view: wgpu::TextureView,
}

/// Which passes a device runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Passes {
    /// Compute shaders and storage bindings: every pass on the GPU.
    Compute,
    /// Neither (WebGL2): the relight on the CPU, the storage-free march.
    StorageFree,
}

/// An asset's stored data as the CPU relight reads it ([`crate::atlas::relight_atlas_cpu`]).
struct CpuRelight {
    coefficients: PackedCoefficients,
    density: Vec<half::f16>,
    /// The voxel each atlas texel mirrors ([`crate::atlas::atlas_sources`]).
    sources: Vec<u32>,
}

/// What the atlas holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AtlasState {
    /// Nothing yet: no relight since the asset was loaded.
    Unlit,
    /// Every voxel's radiance under the current lighting, and its density.
    Lit,
    /// Every voxel's density (no lighting changes it), but radiance under the current
    /// lighting only where the current camera reads it (the marked relight) or nowhere
    /// (the per-pixel replay): the next other camera relights in full.
    Stale,
}

/// The lighting in use.
struct Lighting {
    env: LatLong,
    world_from_env: DMat3,
    projected: ProjectedLight,
    /// A view-dependent asset's lighting projected onto its view basis (`P^v_i`, rgb).
    view_projected: Option<Vec<[f32; 3]>>,
    /// A reflection asset's lighting filtered by its lobe (`E` at the table's nodes).
    filtered: Option<FilteredEnvironment>,
}

/// The march's output image and the bind groups that use it.
struct Target {
    width: u32,
    height: u32,
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    /// The compute march's bindings (`None` without storage bindings).
    march_bind_group: Option<wgpu::BindGroup>,
    march_fragment_bind_group: wgpu::BindGroup,
    display_bind_group: wgpu::BindGroup,
}

/// The GPU renderer. Create it headless ([`GpuRenderer::new_headless`]) or on an existing
/// device ([`GpuRenderer::from_device`], as the app does with eframe's).
pub struct GpuRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter_info: Option<wgpu::AdapterInfo>,
    /// Which passes the device runs (compute and storage bindings, or not: WebGL2).
    passes: Passes,
    pipelines: Pipelines,
    march_params: wgpu::Buffer,
    display_params: wgpu::Buffer,
    counters: wgpu::Buffer,
    asset: Option<GpuAsset>,
    lighting: Option<Lighting>,
    rank: Option<usize>,
    relight_view: RelightView,
    relight_dirty: bool,
    /// The march whose read voxels the marks list (`marks.rs`), if any.
    marks_key: Option<MarchParams>,
    /// The mark key of the last frame encoded.
    last_mark_key: Option<MarchParams>,
    /// What the atlas holds.
    atlas_state: AtlasState,
    /// Whether the list of marked stored voxels is built from the latest marks.
    marks_listed: bool,
    /// How the last relight ran.
    last_relight: Option<RelightKind>,
    /// The per-pixel cache of a held camera (`replay.rs`), allocated on first use.
    replay: Option<GpuReplay>,
    /// Largest per-pixel cache to allocate; larger frames use the marked relight.
    replay_budget_bytes: u64,
    /// The eye (lattice coordinates) the atlas of a view-dependent or reflection asset
    /// shows radiance toward; `None` when the view (or reflect) pass must run before the
    /// next march.
    view_eye: Option<[f32; 3]>,
    /// The eye of the last frame encoded.
    last_eye: Option<[f32; 3]>,
    target: Option<Target>,
}

impl std::fmt::Debug for GpuRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuRenderer")
            .field("adapter", &self.adapter_info.as_ref().map(|a| &a.name))
            .field("asset", &self.asset.as_ref().map(|a| a.info))
            .field("rank", &self.rank)
            .field("relight_view", &self.relight_view)
            .finish_non_exhaustive()
    }
}
