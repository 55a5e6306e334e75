//! The GPU renderer (wgpu): loads an asset into a brick atlas, relights it with a
//! compute pass once per lighting change, ray-marches it with a compute pass per frame,
//! and either reads the linear image back (headless) or draws it, tone-mapped, into a
//! render pass (the app). It mirrors the CPU reference renderer `nelf_render` step for
//! step (see `shaders/march.wgsl`), so the two agree to f16 precision.
//!
//! Relighting (DESIGN.md, "view"): the environment map is projected onto the asset's PCA
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
//! One module per pass, as the shaders are (`shaders/*.wgsl`): `relight` (relight.wgsl),
//! `marks` (the marked relight: relight.wgsl's `relight_marked`, march.wgsl's marking),
//! `replay` (replay.wgsl: a held camera's frame relit per pixel),
//! `view` (view.wgsl and relight.wgsl's `relight_lobes`), `reflect` (reflect.wgsl and
//! `relight_lobes` with no lobes), `march` (march.wgsl, compute, counting and fragment
//! variants), `display` (display.wgsl: exposure, tone map, sRGB);
//! `common` holds the layout and pipeline helpers they share and `readback` the headless
//! read-back. This module owns the device, the asset upload, the public API and the frame
//! encoding that calls the passes.

mod common;
mod display;
mod march;
mod marks;
mod readback;
mod reflect;
mod relight;
mod replay;
mod view;

use glam::DMat3;
use nelf_format::conventions::{LT_DIM, LatLong, PinholeCamera};
use nelf_format::{Asset, CoefficientEncoding, GridGeometry, PcaModel};
use nelf_render::{FilteredEnvironment, ProjectedLight, project_light, project_view_light};
use wgpu::util::DeviceExt as _;

pub use self::display::{DisplayImage, DisplaySettings, ToneMap};
use self::display::{DisplayPipelines, display_params};
use self::march::{MARCH_FORMAT, MarchPipelines};
pub use self::march::{MarchPass, MarchView, ViewSettings};
pub use self::marks::RelightKind;
use self::marks::{GpuMarks, MarkPipelines};
use self::reflect::{GpuReflection, REFLECT_LOBE_WORDS, ReflectPipeline};
use self::relight::RelightPipeline;
pub use self::replay::DEFAULT_REPLAY_BUDGET_BYTES;
use self::replay::{GpuReplay, ReplayInputs, ReplayPipelines};
use self::view::{GpuView, LobesPipeline, ViewBindings, ViewPipeline, lobe_buffer_words};
use crate::atlas::{
    AtlasLayout, Dequantization, GpuMemory, PackedCoefficients, RelightView, atlas_sources, indirection_grid,
    march_grid, neighbour_blocks, pack_brick_cells, pack_coefficients, pack_density,
};
use crate::error::ViewerError;
use crate::shaders::{Counters, DisplayParams, MarchParams, RelightParams};

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

impl Pipelines {
    fn new(device: &wgpu::Device, storage: bool) -> Result<Self, ViewerError> {
        let (relight, marks) = if storage {
            let relight = RelightPipeline::new(device)?;
            let marks = MarkPipelines::new(device, &relight)?;
            (Some(relight), Some(marks))
        } else {
            (None, None)
        };
        let march = MarchPipelines::new(device, storage)?;
        let replay = match march.compute_layout() {
            Some(layout) => Some(ReplayPipelines::new(device, layout)?),
            None => None,
        };
        Ok(Self {
            marks,
            relight,
            replay,
            march,
            display: DisplayPipelines::new(device)?,
            lobes: None,
            view: None,
            reflect: None,
        })
    }
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

impl GpuRenderer {
    /// A renderer on the default adapter without a window (on a machine without a GPU:
    /// Mesa's lavapipe). Prefers Vulkan/Metal/DX12 and falls back to any backend.
    pub fn new_headless() -> Result<Self, ViewerError> {
        pollster::block_on(async {
            let mut last_error = String::from("no backend tried");
            for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::all()] {
                let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
                if wgpu::Backends::from_env().is_none() {
                    descriptor.backends = backends;
                }
                let instance = wgpu::Instance::new(descriptor);
                let adapter = match instance
                    .request_adapter(&wgpu::RequestAdapterOptions {
                        power_preference: wgpu::PowerPreference::HighPerformance,
                        ..Default::default()
                    })
                    .await
                {
                    Ok(a) => a,
                    Err(e) => {
                        last_error = e.to_string();
                        continue;
                    }
                };
                let limits = adapter.limits();
                let (device, queue) = adapter
                    .request_device(&wgpu::DeviceDescriptor {
                        label: Some("nelf-viewer"),
                        required_features: wgpu::Features::empty(),
                        required_limits: wgpu::Limits::default().using_resolution(limits.clone()),
                        ..Default::default()
                    })
                    .await
                    .map_err(|e| ViewerError::Device(e.to_string()))?;
                let mut renderer = Self::from_device(device, queue)?;
                renderer.adapter_info = Some(adapter.get_info());
                return Ok(renderer);
            }
            Err(ViewerError::NoAdapter(last_error))
        })
    }

    /// A renderer on an existing device (the app passes eframe's). Needs only WebGPU's
    /// default features and limits, or, on a device without compute shaders or storage
    /// bindings (WebGL2, where creating a compute pipeline is a fatal error), none of
    /// them: there it relights on the CPU ([`crate::atlas::relight_atlas_cpu`], uploaded once per
    /// lighting change) and marches with the storage-free fragment pass; the same image.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> Result<Self, ViewerError> {
        let limits = device.limits();
        let storage = limits.max_compute_invocations_per_workgroup > 0
            && limits.max_storage_buffers_per_shader_stage > 0
            && limits.max_storage_textures_per_shader_stage > 0;
        Self::with_storage(device, queue, storage)
    }

    /// A renderer that uses no compute shader and no storage binding on any device, as on
    /// WebGL2 ([`GpuRenderer::from_device`]); tests run that path on any adapter.
    pub fn from_device_without_storage(
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Result<Self, ViewerError> {
        Self::with_storage(device, queue, false)
    }

    /// Whether the renderer uses compute shaders and storage bindings (else it relights
    /// on the CPU).
    pub fn uses_storage(&self) -> bool {
        self.storage()
    }

    fn storage(&self) -> bool {
        self.passes == Passes::Compute
    }

    /// `STORAGE_BINDING` where the device has storage bindings, else nothing.
    fn storage_texture_usage(&self) -> wgpu::TextureUsages {
        if self.storage() {
            wgpu::TextureUsages::STORAGE_BINDING
        } else {
            wgpu::TextureUsages::empty()
        }
    }

    fn with_storage(device: wgpu::Device, queue: wgpu::Queue, storage: bool) -> Result<Self, ViewerError> {
        let pipelines = Pipelines::new(&device, storage)?;
        let uniform = |label: &str, size: usize| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let march_params = uniform("march params", size_of::<MarchParams>());
        let display_params = uniform("display params", size_of::<DisplayParams>());
        let counters = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("counters"),
            size: size_of::<Counters>() as u64,
            usage: if storage {
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC
            } else {
                wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC
            },
            mapped_at_creation: false,
        });
        Ok(Self {
            device,
            queue,
            adapter_info: None,
            passes: if storage {
                Passes::Compute
            } else {
                Passes::StorageFree
            },
            pipelines,
            march_params,
            display_params,
            counters,
            asset: None,
            lighting: None,
            rank: None,
            relight_view: RelightView::Shaded,
            relight_dirty: true,
            marks_key: None,
            last_mark_key: None,
            atlas_state: AtlasState::Unlit,
            marks_listed: false,
            last_relight: None,
            replay: None,
            replay_budget_bytes: DEFAULT_REPLAY_BUDGET_BYTES,
            view_eye: None,
            last_eye: None,
            target: None,
        })
    }

    /// The adapter's description (headless renderers only).
    pub fn adapter_info(&self) -> Option<&wgpu::AdapterInfo> {
        self.adapter_info.as_ref()
    }

    /// Records the adapter of a renderer made [`from_device`](Self::from_device), for
    /// [`preferred_march_pass`](Self::preferred_march_pass).
    #[must_use]
    pub fn with_adapter_info(mut self, info: wgpu::AdapterInfo) -> Self {
        self.adapter_info = Some(info);
        self
    }

    /// The march pass that is faster on this renderer's device ([`MarchPass::for_device`];
    /// the default pass when the adapter is unknown).
    pub fn preferred_march_pass(&self) -> MarchPass {
        self.adapter_info
            .as_ref()
            .map_or_else(MarchPass::default, |info| MarchPass::for_device(info.device_type))
    }

    /// The device.
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// The loaded asset's description.
    pub fn asset_info(&self) -> Option<AssetInfo> {
        self.asset.as_ref().map(|a| a.info)
    }

    /// Reads a `.nelf` file (fully validated by the reader) and uploads it; a missing,
    /// damaged or hostile file is an error and leaves the previous asset in place.
    pub fn load_asset_file(&mut self, path: &std::path::Path) -> Result<AssetInfo, ViewerError> {
        let asset = nelf_format::read_asset(path)?;
        self.load_asset(&asset)
    }

    /// Uploads `asset` (validated first; an invalid one is an error and leaves the
    /// previous asset in place): coefficients, densities, brick list, indirection grid,
    /// and an atlas the relight pass fills; for a view-dependent asset also its view
    /// coefficients and a per-voxel lobe buffer (`gpu/view.rs`), for a reflection asset its
    /// tabulated lobe, codes and lobe buffer (`gpu/reflect.rs`). Lighting, if set, is
    /// re-projected onto the new basis. A device without compute shaders (WebGL2) leaves
    /// the view-dependent part out and shows the view-averaged asset
    /// ([`AssetInfo::view_part_ignored`] names what it left out).
    pub fn load_asset(&mut self, asset: &Asset) -> Result<AssetInfo, ViewerError> {
        asset.validate()?;
        // Without compute (WebGL2) the view-dependent parts cannot be shaded; the PCA part
        // alone is the view-averaged asset every reader can show (SPEC.md §6), so the
        // renderer shows that and says what it left out.
        let compute = self.storage();
        let view_part = asset.view.as_ref().filter(|_| compute);
        let reflection_part = asset.reflection.as_ref().filter(|_| compute);
        let view_part_ignored = match (&asset.view, &asset.reflection) {
            _ if compute => None,
            (Some(_), _) => Some("view-dependent part (format 1.2)"),
            (None, Some(_)) => Some("reflection part (format 1.3)"),
            (None, None) => None,
        };
        let limits = self.device.limits();
        let grid_bricks = asset.grid.grid_bricks;
        if grid_bricks.iter().any(|&n| n > limits.max_texture_dimension_3d) {
            return Err(ViewerError::TooLarge(format!(
                "grid of {grid_bricks:?} bricks exceeds 3D textures of {} texels",
                limits.max_texture_dimension_3d
            )));
        }
        let indirection = indirection_grid(grid_bricks, &asset.bricks)?;
        let march_grid = march_grid(
            grid_bricks,
            &indirection,
            &asset.bricks,
            &asset.density,
            limits.max_texture_dimension_3d,
        )?;
        let layout = AtlasLayout::for_bricks(indirection.slot_cells.len(), limits.max_texture_dimension_3d)?;
        let coefficients = pack_coefficients(&asset.coefficients);
        let density = pack_density(&asset.density);
        let neighbours = neighbour_blocks(&indirection, grid_bricks, &asset.bricks);
        let view_coefficients = view_part.map(|v| pack_coefficients(&v.coefficients));
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let voxel_count = asset.voxel_count();
        let lobe_words = match (view_part, reflection_part) {
            (Some(v), _) => lobe_buffer_words(v.lobe_count()),
            (None, Some(_)) => REFLECT_LOBE_WORDS,
            (None, None) => 0,
        };
        let lobe_bytes = (voxel_count * lobe_words) as u64 * 4;
        for (what, bytes) in [
            ("coefficients", coefficients.words.len() as u64 * 4),
            ("densities", density.len() as u64 * 4),
            ("neighbour blocks", neighbours.len() as u64 * 32),
            (
                "view coefficients",
                view_coefficients.as_ref().map_or(0, |p| p.words.len() as u64 * 4),
            ),
            ("per-voxel view lobes", lobe_bytes),
            (
                "reflection codes",
                reflection_part.map_or(0, |_| voxel_count as u64 * 4),
            ),
        ] {
            // Without storage bindings these stay on the CPU.
            if self.storage() && bytes > max_binding {
                return Err(ViewerError::TooLarge(format!(
                    "{what} take {bytes} bytes, the device binds at most {max_binding}"
                )));
            }
        }
        let storage = |label: &str, data: &[u8]| {
            // Storage bindings must not be empty.
            let padded;
            let contents = if data.is_empty() {
                padded = [0u8; 16];
                &padded[..]
            } else {
                data
            };
            self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        // Without storage bindings (WebGL2) the relight reads these on the CPU.
        let has_storage = self.storage();
        let storage = |label: &str, data: &[u8]| {
            if has_storage {
                storage(label, data)
            } else {
                self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: 16,
                    usage: wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            }
        };
        let coefficient_buffer = storage("coefficients", bytemuck::cast_slice(&coefficients.words));
        let density_buffer = storage("density", bytemuck::cast_slice(&density));
        let neighbour_buffer = storage("neighbour blocks", bytemuck::cast_slice(&neighbours));
        let rank = asset.rank();
        let light = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("light"),
            size: (LT_DIM * 16) as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let relight_params = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("relight params"),
            size: size_of::<RelightParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let march_grid_texture = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some("march grid"),
                size: wgpu::Extent3d {
                    width: march_grid.dims[0],
                    height: march_grid.dims[1],
                    depth_or_array_layers: march_grid.dims[2],
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::R32Uint,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&march_grid.texels),
        );
        let texels = layout.texels();
        let atlas = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("atlas"),
            size: wgpu::Extent3d {
                width: texels[0],
                height: texels[1],
                depth_or_array_layers: texels[2],
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::Rgba16Float,
            // Written by the relight pass, or by an upload of the CPU relight.
            usage: self.storage_texture_usage()
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let atlas_view = atlas.create_view(&wgpu::TextureViewDescriptor::default());
        let march_grid_view = march_grid_texture.create_view(&wgpu::TextureViewDescriptor::default());
        let relight_bind_group = self.pipelines.relight.as_ref().map(|relight| {
            relight.bind_group(
                &self.device,
                [
                    &relight_params,
                    &light,
                    &coefficient_buffer,
                    &density_buffer,
                    &neighbour_buffer,
                ],
                &atlas_view,
            )
        });
        // Read by the view pass and the marked relight's listing.
        let brick_cells = storage(
            "brick cells",
            bytemuck::cast_slice(&pack_brick_cells(&asset.bricks)),
        );
        let view_bindings = ViewBindings {
            relight: [&relight_params, &light, &coefficient_buffer, &density_buffer],
            neighbour_blocks: &neighbour_buffer,
            atlas: &atlas_view,
        };
        if (view_part.is_some() || reflection_part.is_some()) && self.pipelines.lobes.is_none() {
            self.pipelines.lobes = Some(LobesPipeline::new(&self.device)?);
        }
        let view = match (view_part, &view_coefficients) {
            (Some(v), Some(packed)) => {
                if self.pipelines.view.is_none() {
                    self.pipelines.view = Some(ViewPipeline::new(&self.device)?);
                }
                let lobes = self.pipelines.lobes.as_ref().ok_or(ViewerError::NoAsset)?;
                let pipeline = self.pipelines.view.as_ref().ok_or(ViewerError::NoAsset)?;
                let mut view =
                    GpuView::upload(&self.device, v, packed, brick_cells.clone(), voxel_count, storage);
                view.bind(&self.device, lobes, pipeline, &view_bindings);
                Some(view)
            }
            _ => None,
        };
        let reflection = match reflection_part {
            Some(r) => {
                if self.pipelines.reflect.is_none() {
                    self.pipelines.reflect = Some(ReflectPipeline::new(&self.device)?);
                }
                let lobes = self.pipelines.lobes.as_ref().ok_or(ViewerError::NoAsset)?;
                let pipeline = self.pipelines.reflect.as_ref().ok_or(ViewerError::NoAsset)?;
                let mut reflection =
                    GpuReflection::upload(&self.device, asset, r, &layout, brick_cells.clone(), storage)?;
                reflection.bind(&self.device, lobes, pipeline, &view_bindings);
                Some(reflection)
            }
            None => None,
        };
        let marks =
            self.pipelines.marks.as_ref().map(|pipelines| {
                GpuMarks::new(&self.device, pipelines, grid_bricks, voxel_count, &brick_cells)
            });
        let memory = GpuMemory {
            atlas_bytes: u64::from(texels[0]) * u64::from(texels[1]) * u64::from(texels[2]) * 8,
            coefficient_bytes: coefficient_buffer.size(),
            density_bytes: density_buffer.size(),
            march_grid_bytes: march_grid.texels.len() as u64 * 4,
            neighbour_bytes: neighbour_buffer.size(),
            view_bytes: view.as_ref().map_or(0, GpuView::bytes)
                + reflection.as_ref().map_or(0, GpuReflection::bytes),
            other_bytes: light.size()
                + relight_params.size()
                + brick_cells.size()
                + marks.as_ref().map_or(0, GpuMarks::bytes),
        };
        let max_density_per_m = asset.density.iter().map(|d| d.to_f32()).fold(0.0f32, f32::max);
        let info = AssetInfo {
            bricks: asset.bricks.len(),
            halo_slots: indirection.halo_count(asset.bricks.len()),
            rank,
            atlas_texels: texels,
            memory,
            max_density_per_m,
            view: view_part.map(|v| ViewInfo {
                lobes: v.lobe_count(),
                rank: v.rank(),
                encoding: v.coefficients.encoding(),
            }),
            reflection: reflection_part.map(|r| ReflectionInfo {
                exponent: r.exponent,
                eyes: r.eyes_m.len(),
            }),
            view_part_ignored,
        };
        let dequantization = Dequantization::of(&asset.coefficients);
        let replay = self.pipelines.replay.is_some().then(|| ReplayInputs {
            coefficients: coefficient_buffer.clone(),
            dequantization: storage(
                "replay dequantization",
                bytemuck::cast_slice(&dequantization.offset_scale()),
            ),
        });
        self.asset = Some(GpuAsset {
            layout,
            grid: asset.grid,
            pca: asset.pca.clone(),
            world_from_light: asset.world_from_light,
            dequantization,
            coefficient_words_per_voxel: coefficients.words_per_voxel,
            coefficient_encoding: coefficients.encoding,
            atlas,
            atlas_view,
            march_grid_view,
            march_grid_factor: march_grid.factor,
            relight_params,
            light,
            relight_bind_group,
            marks,
            replay,
            cpu_relight: (!self.storage()).then(|| CpuRelight {
                sources: atlas_sources(&layout, &indirection, grid_bricks, asset.bricks.len()),
                coefficients,
                density: asset.density.clone(),
            }),
            view,
            reflection,
            voxel_count,
            info,
        });
        // Bind groups of the old atlas are stale.
        self.target = None;
        self.relight_dirty = true;
        self.marks_key = None;
        self.last_mark_key = None;
        self.replay = None;
        self.atlas_state = AtlasState::Unlit;
        self.view_eye = None;
        self.last_eye = None;
        if let Some(lighting) = self.lighting.take() {
            self.set_lighting(&lighting.env, lighting.world_from_env)?;
        }
        Ok(info)
    }

    /// Sets the environment map (any resolution, lat-long, world frame) and its rotation
    /// `world_from_env`, projecting it onto the asset's basis
    /// ([`nelf_render::project_light`]), a view-dependent asset's view basis
    /// ([`nelf_render::project_view_light`]) and filtering it by a reflection asset's lobe
    /// ([`nelf_render::ReflectionLobe::filter`]). Needs an asset. The relight pass runs
    /// before the next frame.
    pub fn set_lighting(&mut self, env: &LatLong, world_from_env: DMat3) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let (projected, filtered) = match &asset.reflection {
            Some(reflection) => {
                let (projected, filtered) =
                    reflection.project_and_filter(&asset.pca, asset.world_from_light, env, world_from_env)?;
                (projected, Some(filtered))
            }
            None => (
                project_light(&asset.pca, asset.world_from_light, env, world_from_env)?,
                None,
            ),
        };
        let view_projected = match &asset.view {
            Some(view) => Some(project_view_light(
                &view.model,
                asset.world_from_light,
                env,
                world_from_env,
            )?),
            None => None,
        };
        self.lighting = Some(Lighting {
            env: env.clone(),
            world_from_env,
            projected,
            view_projected,
            filtered,
        });
        self.relight_dirty = true;
        Ok(())
    }

    /// Turns the current environment map to `world_from_env` (re-projects it; no need to
    /// pass the map again).
    pub fn set_light_rotation(&mut self, world_from_env: DMat3) -> Result<(), ViewerError> {
        let lighting = self.lighting.take().ok_or(ViewerError::NoLighting)?;
        let result = self.set_lighting(&lighting.env, world_from_env);
        if result.is_err() {
            self.lighting = Some(lighting);
        }
        result
    }

    /// Uses only the first `rank` PCA components (`None`: all).
    pub fn set_rank(&mut self, rank: Option<usize>) {
        if self.rank != rank {
            self.rank = rank;
            self.relight_dirty = true;
        }
    }

    /// What the relight pass writes: radiance, or one component's contribution.
    pub fn set_relight_view(&mut self, view: RelightView) {
        if self.relight_view != view {
            self.relight_view = view;
            self.relight_dirty = true;
        }
    }

    /// Caps the per-pixel cache of a held camera (`replay.rs`; default
    /// [`DEFAULT_REPLAY_BUDGET_BYTES`]): frames needing more relight the voxels their march
    /// reads instead (0 turns the replay off).
    pub fn set_replay_budget_bytes(&mut self, bytes: u64) {
        self.replay_budget_bytes = bytes;
        if self.replay.as_ref().is_none_or(|r| r.bytes() > bytes) {
            self.replay = None;
        }
    }

    /// GPU memory of the per-pixel cache of a held camera, if one is allocated.
    pub fn replay_bytes(&self) -> u64 {
        self.replay.as_ref().map_or(0, GpuReplay::bytes)
    }

    /// Makes the next frame relight even if nothing changed (benchmarks).
    pub fn invalidate_lighting(&mut self) {
        self.relight_dirty = true;
    }

    /// Makes the march target `width × height` (recreating it and its bind groups on change).
    fn ensure_target(&mut self, width: u32, height: u32) -> Result<(), ViewerError> {
        if self
            .target
            .as_ref()
            .is_some_and(|t| t.width == width && t.height == height)
        {
            return Ok(());
        }
        let max = self.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(ViewerError::BadSetting(format!(
                "image {width}×{height} must be 1..={max} pixels a side"
            )));
        }
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let texture = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("march output"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: MARCH_FORMAT,
            usage: self.storage_texture_usage()
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let (march_bind_group, march_fragment_bind_group) =
            self.pipelines
                .march
                .bind_groups(&self.device, &self.march_params, asset, &view, &self.counters);
        let display_bind_group = self
            .pipelines
            .display
            .bind_group(&self.device, &self.display_params, &view);
        self.target = Some(Target {
            width,
            height,
            texture,
            view,
            march_bind_group,
            march_fragment_bind_group,
            display_bind_group,
        });
        Ok(())
    }

    /// Encodes the relight pass (if needed), for a view-dependent or reflection asset the
    /// view or reflect pass (if the eye or the lighting changed) and the march of `camera`
    /// into `encoder`; the result lands in the internal target that [`GpuRenderer::paint`]
    /// displays.
    pub fn encode_frame(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &PinholeCamera,
        settings: &ViewSettings,
    ) -> Result<(), ViewerError> {
        self.encode_frame_with(encoder, camera, settings, false)
    }

    fn encode_frame_with(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &PinholeCamera,
        settings: &ViewSettings,
        count_samples: bool,
    ) -> Result<(), ViewerError> {
        let params = self.march_params(camera, settings)?;
        if self.lighting.is_none() {
            return Err(ViewerError::NoLighting);
        }
        // The marked relight serves a camera whose read voxels are marked; any other
        // frame needs the whole atlas lit (marks.rs).
        let key = self.mark_key(&params, settings);
        // Whether the camera (and march) is the last frame's.
        let held = key.is_some() && key == self.last_mark_key;
        self.last_mark_key = key;
        let eye = [params.origin_u[0], params.origin_u[1], params.origin_u[2]];
        self.last_eye = Some(eye);
        self.ensure_target(camera.width, camera.height)?;
        self.queue
            .write_buffer(&self.march_params, 0, bytemuck::bytes_of(&params));
        // At a held camera whose frame fits the per-pixel cache, lighting changes replay
        // the pixels (replay.rs) instead of relighting voxels and marching.
        if let Some(key) = key.filter(|_| !count_samples)
            && let Some(rect) = self.replay_fits(camera)
        {
            let replayed = self.replay.as_ref().is_some_and(|r| r.key == Some(key));
            if (replayed && (self.relight_dirty || self.atlas_state == AtlasState::Stale))
                || (held && self.relight_dirty)
            {
                // The first lighting change here fills the cache (a march over the atlas's
                // densities, which no lighting changes; relit once if it holds nothing
                // yet), then every change relights it.
                if !replayed {
                    if self.atlas_state == AtlasState::Unlit {
                        self.encode_relight_if_needed(encoder, false)?;
                    }
                    self.encode_replay_build(encoder, key, rect)?;
                }
                return self.encode_replay_relight(encoder, settings.pass);
            }
        }
        let marked = key.is_some() && key == self.marks_key;
        if self.atlas_state == AtlasState::Stale && !marked {
            self.relight_dirty = true;
        }
        let relit = self.encode_relight_if_needed(encoder, marked)?;
        // A lighting change at a camera held since the last frame relights in full and
        // marks what the camera reads, so that the next ones relight only that.
        let mark = !count_samples && relit == Some(RelightKind::Full) && held && key != self.marks_key;
        self.encode_view_if_needed(encoder, eye)?;
        self.encode_reflect_if_needed(encoder, eye)?;
        let target = self.target.as_ref().ok_or(ViewerError::NoAsset)?;
        if mark {
            let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
            let marks = asset.marks.as_ref().ok_or(ViewerError::NoAsset)?;
            marks.encode_clear(encoder);
            self.marks_key = key;
            self.marks_listed = false;
        }
        self.pipelines
            .march
            .encode(encoder, target, settings.pass, count_samples, mark);
        Ok(())
    }

    /// Prepares the display pass for a target of `format` (call before
    /// [`GpuRenderer::paint`], outside the render pass).
    pub fn prepare_display(
        &mut self,
        format: wgpu::TextureFormat,
        display: &DisplaySettings,
        view: MarchView,
    ) {
        let params = display_params(format, display, view);
        self.queue
            .write_buffer(&self.display_params, 0, bytemuck::bytes_of(&params));
        self.pipelines.display.pipeline_for(&self.device, format);
    }

    /// Draws the last marched image, tone-mapped, over the render pass's viewport
    /// (after [`GpuRenderer::prepare_display`] for the pass's format). Draws nothing if
    /// no frame was marched yet.
    pub fn paint(&self, pass: &mut wgpu::RenderPass<'_>, format: wgpu::TextureFormat) {
        let Some(target) = &self.target else { return };
        self.pipelines
            .display
            .paint(pass, &target.display_bind_group, format);
    }

    /// Runs the relight pass now and waits for it (benchmarks).
    pub fn relight_blocking(&mut self) -> Result<(), ViewerError> {
        self.relight_dirty = true;
        let mut encoder = self.encoder("relight");
        self.encode_relight_if_needed(&mut encoder, false)?;
        self.submit_and_wait(encoder)
    }

    /// Runs the view pass of a view-dependent asset (or the reflect pass of a reflection
    /// asset) toward `camera`'s eye now (relighting first if needed) and waits
    /// (benchmarks); nothing for a view-independent asset.
    pub fn view_pass_blocking(&mut self, camera: &PinholeCamera) -> Result<(), ViewerError> {
        let params = self.march_params(camera, &ViewSettings::default())?;
        let eye = [params.origin_u[0], params.origin_u[1], params.origin_u[2]];
        let mut encoder = self.encoder("view");
        self.encode_relight_if_needed(&mut encoder, false)?;
        self.view_eye = None;
        self.encode_view_if_needed(&mut encoder, eye)?;
        self.encode_reflect_if_needed(&mut encoder, eye)?;
        self.submit_and_wait(encoder)
    }

    /// Relights if needed, marches `camera`'s view and waits, without reading back
    /// (benchmarks: the GPU work of one frame).
    pub fn frame_blocking(
        &mut self,
        camera: &PinholeCamera,
        settings: &ViewSettings,
    ) -> Result<(), ViewerError> {
        let mut encoder = self.encoder("frame");
        self.encode_frame(&mut encoder, camera, settings)?;
        self.submit_and_wait(encoder)
    }

    /// How the last relight ran: every voxel, or only those the current camera reads
    /// (`None` before the first).
    pub fn last_relight(&self) -> Option<RelightKind> {
        self.last_relight
    }

    /// Edge length of one voxel of the loaded asset, metres.
    pub fn voxel_size_m(&self) -> Option<f64> {
        self.asset.as_ref().map(|a| a.grid.voxel_size_m)
    }

    /// The loaded asset's grid box `(min, max)` in metres.
    pub fn bounds_m(&self) -> Option<([f64; 3], [f64; 3])> {
        self.asset
            .as_ref()
            .map(|a| (a.grid.bbox_min_m, a.grid.bbox_max_m()))
    }
}
