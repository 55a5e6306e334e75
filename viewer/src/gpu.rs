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
//! shading every sample; a frame without a lighting change costs only the march.

use glam::DMat3;
use nelf_format::conventions::{LT_DIM, LatLong, PinholeCamera};
use nelf_format::spec::BRICK_SIZE;
use nelf_format::{Asset, GridGeometry, PcaModel};
use nelf_render::{Image, MarchSettings, ProjectedLight, project_light};
use wgpu::util::DeviceExt as _;

use crate::atlas::{
    AtlasLayout, Dequantization, GpuMemory, RelightView, fold_light, indirection_grid, neighbour_slots,
    pack_coefficients, pack_density,
};
use crate::error::ViewerError;
use crate::shaders::{
    Counters, DISPLAY_WGSL, DisplayParams, MARCH_WGSL, MarchParams, RELIGHT_WGSL, RelightParams, preprocess,
};

/// What the march shows.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum MarchView {
    /// Relit radiance, composited (premultiplied rgb, alpha).
    #[default]
    Shaded,
    /// Largest density along the ray, grey, with `sigma_white_per_m` shown as white.
    Density {
        /// Density (1/m) mapped to 1.
        sigma_white_per_m: f32,
    },
    /// Final alpha `1 − T_end`, grey.
    Alpha,
    /// Cost per pixel: `rgb` = (trilinear samples taken, loop iterations, lattice samples
    /// between box entry and exit); alpha 1. Raw counts, for benchmarks and the app's
    /// heat map (the display pass scales them by [`DisplaySettings`]'s exposure).
    Cost,
}

/// Per-frame march settings.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ViewSettings {
    /// Step and early termination, as for the CPU reference.
    pub march: MarchSettings,
    /// Jitter each ray's first sample in `[0, 1)` steps (per pixel and frame) against
    /// banding; off reproduces the CPU reference's lattice `t_entry + (i + 0.5)Δ`.
    pub jitter: bool,
    /// Frame number, the jitter seed.
    pub frame_index: u32,
    /// What to show.
    pub view: MarchView,
    /// Which pass marches (the same `march_pixel` either way).
    pub pass: MarchPass,
}

/// How the march runs: both give the same image; which is faster depends on the device
/// (the benchmark measures both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MarchPass {
    /// A compute dispatch writing a storage texture.
    Compute,
    /// A full-screen triangle rasterised into a colour target.
    #[default]
    Fragment,
}

/// Tone curve of the display pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ToneMap {
    /// Clamp to [0, 1].
    Linear,
    /// ACES filmic (Narkowicz's fit).
    #[default]
    Aces,
}

/// How the display pass turns linear radiance into display colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisplaySettings {
    /// Exposure in stops: radiance is multiplied by `2^exposure_ev`.
    pub exposure_ev: f32,
    /// Tone curve.
    pub tone_map: ToneMap,
    /// Background radiance behind the asset (linear rgb).
    pub background: [f32; 3],
}

impl Default for DisplaySettings {
    fn default() -> Self {
        Self {
            exposure_ev: 0.0,
            tone_map: ToneMap::Aces,
            background: [0.02, 0.02, 0.025],
        }
    }
}

/// An 8-bit RGBA image (sRGB-encoded display colour), row-major from the top-left.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DisplayImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height × 4` bytes.
    pub rgba: Vec<u8>,
}

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
}

/// Compute and render pipelines, created once per device.
struct Pipelines {
    relight_layout: wgpu::BindGroupLayout,
    relight: wgpu::ComputePipeline,
    march_layout: wgpu::BindGroupLayout,
    march: wgpu::ComputePipeline,
    march_counting: wgpu::ComputePipeline,
    march_fragment_layout: wgpu::BindGroupLayout,
    march_fragment: wgpu::RenderPipeline,
    display_layout: wgpu::BindGroupLayout,
    display_module: wgpu::ShaderModule,
    display_pipeline_layout: wgpu::PipelineLayout,
    display: Vec<(wgpu::TextureFormat, wgpu::RenderPipeline)>,
    sampler: wgpu::Sampler,
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
    indirection_view: wgpu::TextureView,
    relight_params: wgpu::Buffer,
    light: wgpu::Buffer,
    relight_bind_group: wgpu::BindGroup,
    voxel_count: usize,
    info: AssetInfo,
}

/// The lighting in use.
struct Lighting {
    env: LatLong,
    world_from_env: DMat3,
    projected: ProjectedLight,
}

/// The march's output image and the bind groups that use it.
struct Target {
    width: u32,
    height: u32,
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    march_bind_group: wgpu::BindGroup,
    march_fragment_bind_group: wgpu::BindGroup,
    display_bind_group: wgpu::BindGroup,
}

/// The GPU renderer. Create it headless ([`GpuRenderer::new_headless`]) or on an existing
/// device ([`GpuRenderer::from_device`], as the app does with eframe's).
pub struct GpuRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter_info: Option<wgpu::AdapterInfo>,
    pipelines: Pipelines,
    march_params: wgpu::Buffer,
    display_params: wgpu::Buffer,
    counters: wgpu::Buffer,
    asset: Option<GpuAsset>,
    lighting: Option<Lighting>,
    rank: Option<usize>,
    relight_view: RelightView,
    relight_dirty: bool,
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

/// Format of the march's output: linear premultiplied rgb and alpha.
const MARCH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// Bytes per row of a texture copy, padded to wgpu's 256-byte alignment.
fn padded_row_bytes(unpadded: u32) -> u32 {
    unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

fn storage_entry(
    binding: u32,
    read_only: bool,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn texture_entry(
    binding: u32,
    sample_type: wgpu::TextureSampleType,
    view_dimension: wgpu::TextureViewDimension,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type,
            view_dimension,
            multisampled: false,
        },
        count: None,
    }
}

fn storage_texture_entry(
    binding: u32,
    format: wgpu::TextureFormat,
    view_dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension,
        },
        count: None,
    }
}

fn shader_module(device: &wgpu::Device, name: &str, source: &str) -> Result<wgpu::ShaderModule, ViewerError> {
    let text = preprocess(name, source)?;
    Ok(device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(text.into()),
    }))
}

impl Pipelines {
    fn new(device: &wgpu::Device) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        use wgpu::TextureViewDimension as D;
        let relight_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("relight"),
            entries: &[
                uniform_entry(0, S::COMPUTE),
                uniform_entry(1, S::COMPUTE),
                storage_entry(2, true, S::COMPUTE),
                storage_entry(3, true, S::COMPUTE),
                storage_entry(4, true, S::COMPUTE),
                storage_texture_entry(5, wgpu::TextureFormat::Rgba16Float, D::D3),
            ],
        });
        let march_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("march"),
            entries: &[
                uniform_entry(0, S::COMPUTE),
                texture_entry(
                    1,
                    wgpu::TextureSampleType::Float { filterable: true },
                    D::D3,
                    S::COMPUTE,
                ),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: S::COMPUTE,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                texture_entry(3, wgpu::TextureSampleType::Uint, D::D3, S::COMPUTE),
                storage_texture_entry(4, wgpu::TextureFormat::Rgba32Float, D::D2),
                storage_entry(5, false, S::COMPUTE),
            ],
        });
        let march_fragment_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("march (fragment)"),
            entries: &[
                uniform_entry(0, S::FRAGMENT),
                texture_entry(
                    1,
                    wgpu::TextureSampleType::Float { filterable: true },
                    D::D3,
                    S::FRAGMENT,
                ),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: S::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                texture_entry(3, wgpu::TextureSampleType::Uint, D::D3, S::FRAGMENT),
            ],
        });
        let display_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("display"),
            entries: &[
                uniform_entry(0, S::FRAGMENT),
                texture_entry(
                    1,
                    wgpu::TextureSampleType::Float { filterable: false },
                    D::D2,
                    S::FRAGMENT,
                ),
            ],
        });
        let compute =
            |layout: &wgpu::BindGroupLayout, module: &wgpu::ShaderModule, entry: &str, constants| {
                let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some(entry),
                    bind_group_layouts: &[Some(layout)],
                    immediate_size: 0,
                });
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&pipeline_layout),
                    module,
                    entry_point: Some(entry),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants,
                        zero_initialize_workgroup_memory: false,
                    },
                    cache: None,
                })
            };
        let relight_module = shader_module(device, "relight.wgsl", RELIGHT_WGSL)?;
        let march_module = shader_module(device, "march.wgsl", MARCH_WGSL)?;
        let display_module = shader_module(device, "display.wgsl", DISPLAY_WGSL)?;
        let relight = compute(&relight_layout, &relight_module, "relight", &[]);
        let march = compute(&march_layout, &march_module, "march", &[]);
        let march_counting = compute(&march_layout, &march_module, "march", &[("COUNT_SAMPLES", 1.0)]);
        let march_fragment_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("march (fragment)"),
            bind_group_layouts: &[Some(&march_fragment_layout)],
            immediate_size: 0,
        });
        let march_fragment = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("march (fragment)"),
            layout: Some(&march_fragment_pipeline_layout),
            vertex: wgpu::VertexState {
                module: &march_module,
                entry_point: Some("march_vs"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &march_module,
                entry_point: Some("march_fs"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: MARCH_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let display_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("display"),
            bind_group_layouts: &[Some(&display_layout)],
            immediate_size: 0,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("atlas"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            address_mode_w: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Nearest,
            ..Default::default()
        });
        Ok(Self {
            relight_layout,
            relight,
            march_layout,
            march,
            march_counting,
            march_fragment_layout,
            march_fragment,
            display_layout,
            display_module,
            display_pipeline_layout,
            display: Vec::new(),
            sampler,
        })
    }

    /// The display pipeline for `format`, created on first use.
    fn display_for(&mut self, device: &wgpu::Device, format: wgpu::TextureFormat) -> &wgpu::RenderPipeline {
        let index = if let Some(i) = self.display.iter().position(|(f, _)| *f == format) {
            i
        } else {
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("display"),
                layout: Some(&self.display_pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &self.display_module,
                    entry_point: Some("vs_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &self.display_module,
                    entry_point: Some("fs_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            });
            self.display.push((format, pipeline));
            self.display.len() - 1
        };
        &self.display[index].1
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
    /// default features and limits.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> Result<Self, ViewerError> {
        let pipelines = Pipelines::new(&device)?;
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
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Ok(Self {
            device,
            queue,
            adapter_info: None,
            pipelines,
            march_params,
            display_params,
            counters,
            asset: None,
            lighting: None,
            rank: None,
            relight_view: RelightView::Shaded,
            relight_dirty: true,
            target: None,
        })
    }

    /// The adapter's description (headless renderers only).
    pub fn adapter_info(&self) -> Option<&wgpu::AdapterInfo> {
        self.adapter_info.as_ref()
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
    /// and an atlas the relight pass fills. Lighting, if set, is re-projected onto the
    /// new basis.
    pub fn load_asset(&mut self, asset: &Asset) -> Result<AssetInfo, ViewerError> {
        asset.validate()?;
        let limits = self.device.limits();
        let grid_bricks = asset.grid.grid_bricks;
        if grid_bricks.iter().any(|&n| n > limits.max_texture_dimension_3d) {
            return Err(ViewerError::TooLarge(format!(
                "grid of {grid_bricks:?} bricks exceeds 3D textures of {} texels",
                limits.max_texture_dimension_3d
            )));
        }
        let indirection = indirection_grid(grid_bricks, &asset.bricks)?;
        let layout = AtlasLayout::for_bricks(indirection.slot_cells.len(), limits.max_texture_dimension_3d)?;
        let coefficients = pack_coefficients(&asset.coefficients);
        let density = pack_density(&asset.density);
        let neighbours = neighbour_slots(&indirection, grid_bricks, &asset.bricks);
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let voxel_count = asset.voxel_count();
        for (what, bytes) in [
            ("coefficients", coefficients.words.len() as u64 * 4),
            ("densities", density.len() as u64 * 4),
            ("neighbour slots", neighbours.len() as u64 * 4),
        ] {
            if bytes > max_binding {
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
        let coefficient_buffer = storage("coefficients", bytemuck::cast_slice(&coefficients.words));
        let density_buffer = storage("density", bytemuck::cast_slice(&density));
        let neighbour_buffer = storage("neighbour slots", bytemuck::cast_slice(&neighbours));
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
        let indirection_texture = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some("indirection"),
                size: wgpu::Extent3d {
                    width: grid_bricks[0],
                    height: grid_bricks[1],
                    depth_or_array_layers: grid_bricks[2],
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::R32Uint,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&indirection.entries),
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
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let atlas_view = atlas.create_view(&wgpu::TextureViewDescriptor::default());
        let indirection_view = indirection_texture.create_view(&wgpu::TextureViewDescriptor::default());
        let relight_bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("relight"),
            layout: &self.pipelines.relight_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: relight_params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: light.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: coefficient_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: density_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: neighbour_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(&atlas_view),
                },
            ],
        });
        let memory = GpuMemory {
            atlas_bytes: u64::from(texels[0]) * u64::from(texels[1]) * u64::from(texels[2]) * 8,
            coefficient_bytes: coefficient_buffer.size(),
            density_bytes: density_buffer.size(),
            indirection_bytes: indirection.entries.len() as u64 * 4,
            neighbour_bytes: neighbour_buffer.size(),
            other_bytes: light.size() + relight_params.size(),
        };
        let max_density_per_m = asset.density.iter().map(|d| d.to_f32()).fold(0.0f32, f32::max);
        let info = AssetInfo {
            bricks: asset.bricks.len(),
            halo_slots: indirection.halo_count(asset.bricks.len()),
            rank,
            atlas_texels: texels,
            memory,
            max_density_per_m,
        };
        self.asset = Some(GpuAsset {
            layout,
            grid: asset.grid,
            pca: asset.pca.clone(),
            world_from_light: asset.world_from_light,
            dequantization: Dequantization::of(&asset.coefficients),
            coefficient_words_per_voxel: coefficients.words_per_voxel,
            coefficient_encoding: coefficients.encoding,
            atlas,
            atlas_view,
            indirection_view,
            relight_params,
            light,
            relight_bind_group,
            voxel_count,
            info,
        });
        // Bind groups of the old atlas are stale.
        self.target = None;
        self.relight_dirty = true;
        if let Some(lighting) = self.lighting.take() {
            self.set_lighting(&lighting.env, lighting.world_from_env)?;
        }
        Ok(info)
    }

    /// Sets the environment map (any resolution, lat-long, world frame) and its rotation
    /// `world_from_env`, projecting it onto the asset's basis
    /// ([`nelf_render::project_light`]). Needs an asset. The relight pass runs before the
    /// next frame.
    pub fn set_lighting(&mut self, env: &LatLong, world_from_env: DMat3) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let projected = project_light(&asset.pca, asset.world_from_light, env, world_from_env)?;
        self.lighting = Some(Lighting {
            env: env.clone(),
            world_from_env,
            projected,
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

    /// Makes the next frame relight even if nothing changed (benchmarks).
    pub fn invalidate_lighting(&mut self) {
        self.relight_dirty = true;
    }

    /// Encodes the relight pass if the lighting, rank or view changed since the last one.
    fn encode_relight_if_needed(&mut self, encoder: &mut wgpu::CommandEncoder) -> Result<(), ViewerError> {
        if !self.relight_dirty {
            return Ok(());
        }
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let lighting = self.lighting.as_ref().ok_or(ViewerError::NoLighting)?;
        let rank = self.rank.unwrap_or(asset.info.rank).min(asset.info.rank);
        let folded = fold_light(
            &lighting.projected,
            &asset.dequantization,
            rank,
            self.relight_view,
        );
        // Zeros up to the next multiple of 4: the shader applies whole words of codes.
        let mut components = folded.components.clone();
        components.resize(
            folded.components.len().next_multiple_of(4).clamp(4, LT_DIM),
            [0.0; 4],
        );
        self.queue
            .write_buffer(&asset.light, 0, bytemuck::cast_slice(&components));
        let g = asset.grid.grid_bricks;
        // 64 voxels per workgroup, rows of at most 32768 workgroups.
        let groups = (asset.voxel_count as u32).div_ceil(64).max(1);
        let groups = [groups.min(32_768), groups.div_ceil(32_768)];
        let params = RelightParams {
            atlas: [
                asset.layout.x_bits,
                asset.layout.y_bits,
                asset.layout.slot_count,
                folded.components.len() as u32,
            ],
            grid_bricks: [g[0] as i32, g[1] as i32, g[2] as i32, asset.coefficient_encoding],
            words: [
                asset.info.rank as u32,
                asset.coefficient_words_per_voxel,
                u32::from(matches!(self.relight_view, RelightView::Component(_))),
                0,
            ],
            light_mean: [folded.mean_rgb[0], folded.mean_rgb[1], folded.mean_rgb[2], 0.0],
            dispatch: [asset.voxel_count as u32, groups[0] * 64, 0, 0],
        };
        self.queue
            .write_buffer(&asset.relight_params, 0, bytemuck::bytes_of(&params));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("relight"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &asset.relight_bind_group, &[]);
        pass.set_pipeline(&self.pipelines.relight);
        pass.dispatch_workgroups(groups[0], groups[1], 1);
        drop(pass);
        self.relight_dirty = false;
        Ok(())
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
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let march_bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("march"),
            layout: &self.pipelines.march_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: self.march_params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&asset.atlas_view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&self.pipelines.sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&asset.indirection_view),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: self.counters.as_entire_binding(),
                },
            ],
        });
        let march_fragment_bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("march (fragment)"),
            layout: &self.pipelines.march_fragment_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: self.march_params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&asset.atlas_view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&self.pipelines.sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&asset.indirection_view),
                },
            ],
        });
        let display_bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("display"),
            layout: &self.pipelines.display_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: self.display_params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
            ],
        });
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

    /// The march uniform for a camera and settings.
    fn march_params(
        &self,
        camera: &PinholeCamera,
        settings: &ViewSettings,
    ) -> Result<MarchParams, ViewerError> {
        camera.validate()?;
        settings.march.validate()?;
        if settings.march.pixel_grid != 1 {
            return Err(ViewerError::BadSetting(format!(
                "pixel_grid = {}: the GPU renderer takes one ray per pixel (antialias with jitter)",
                settings.march.pixel_grid
            )));
        }
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let grid = &asset.grid;
        let voxel = grid.voxel_size_m;
        let centre = camera.centre();
        let origin: [f32; 3] =
            std::array::from_fn(|a| ((centre[a] - grid.bbox_min_m[a]) / voxel - 0.5) as f32);
        let row = |i: usize| {
            let r = camera.rotation.row(i);
            [r.x as f32, r.y as f32, r.z as f32, 0.0]
        };
        let n = grid
            .grid_bricks
            .map(|b| (f64::from(b) * BRICK_SIZE as f64 - 0.5) as f32);
        let texels = asset.layout.texels();
        let (view, scale) = match settings.view {
            MarchView::Shaded => (0, 0.0),
            MarchView::Density { sigma_white_per_m } => (1, 1.0 / sigma_white_per_m.max(1e-12)),
            MarchView::Alpha => (2, 0.0),
            MarchView::Cost => (3, 0.0),
        };
        Ok(MarchParams {
            world_from_camera_x: row(0),
            world_from_camera_y: row(1),
            world_from_camera_z: row(2),
            origin_u: [origin[0], origin[1], origin[2], (1.0 / voxel) as f32],
            intrinsics: [
                camera.fx as f32,
                camera.fy as f32,
                camera.cx as f32,
                camera.cy as f32,
            ],
            box_max_u: [
                n[0],
                n[1],
                n[2],
                (f64::from(settings.march.step_voxels) * voxel) as f32,
            ],
            atlas_inv_size: [
                1.0 / texels[0] as f32,
                1.0 / texels[1] as f32,
                1.0 / texels[2] as f32,
                settings.march.min_transmittance,
            ],
            grid_bricks: [
                grid.grid_bricks[0] as i32,
                grid.grid_bricks[1] as i32,
                grid.grid_bricks[2] as i32,
                0,
            ],
            image: [
                camera.width,
                camera.height,
                settings.frame_index,
                u32::from(settings.jitter),
            ],
            view: [view, asset.layout.x_bits, asset.layout.y_bits, 0],
            scales: [scale, 0.0, 0.0, 0.0],
        })
    }

    /// Encodes the relight pass (if needed) and the march of `camera` into `encoder`;
    /// the result lands in the internal target that [`GpuRenderer::paint`] displays.
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
        self.encode_relight_if_needed(encoder)?;
        self.ensure_target(camera.width, camera.height)?;
        self.queue
            .write_buffer(&self.march_params, 0, bytemuck::bytes_of(&params));
        let target = self.target.as_ref().ok_or(ViewerError::NoAsset)?;
        if settings.pass == MarchPass::Fragment && !count_samples {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("march (fragment)"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target.view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipelines.march_fragment);
            pass.set_bind_group(0, &target.march_fragment_bind_group, &[]);
            pass.draw(0..3, 0..1);
            return Ok(());
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("march"),
            timestamp_writes: None,
        });
        pass.set_pipeline(if count_samples {
            &self.pipelines.march_counting
        } else {
            &self.pipelines.march
        });
        pass.set_bind_group(0, &target.march_bind_group, &[]);
        pass.dispatch_workgroups(camera.width.div_ceil(8), camera.height.div_ceil(8), 1);
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
        let params = DisplayParams {
            background: [
                display.background[0],
                display.background[1],
                display.background[2],
                display.exposure_ev.exp2(),
            ],
            mode: [
                u32::from(display.tone_map == ToneMap::Aces),
                u32::from(!format.is_srgb()),
                u32::from(view != MarchView::Shaded),
                0,
            ],
        };
        self.queue
            .write_buffer(&self.display_params, 0, bytemuck::bytes_of(&params));
        self.pipelines.display_for(&self.device, format);
    }

    /// Draws the last marched image, tone-mapped, over the render pass's viewport
    /// (after [`GpuRenderer::prepare_display`] for the pass's format). Draws nothing if
    /// no frame was marched yet.
    pub fn paint(&self, pass: &mut wgpu::RenderPass<'_>, format: wgpu::TextureFormat) {
        let Some(target) = &self.target else { return };
        let Some((_, pipeline)) = self.pipelines.display.iter().find(|(f, _)| *f == format) else {
            return;
        };
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &target.display_bind_group, &[]);
        pass.draw(0..3, 0..1);
    }

    /// Submits `encoder` and waits for the device to finish.
    fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<(), ViewerError> {
        self.queue.submit([encoder.finish()]);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| ViewerError::Readback(e.to_string()))?;
        Ok(())
    }

    fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    /// Copies `texture` (one mip, `extent`) to memory: rows of `bytes_per_texel × width`.
    fn read_texture(
        &self,
        texture: &wgpu::Texture,
        extent: wgpu::Extent3d,
        bytes_per_texel: u32,
    ) -> Result<Vec<u8>, ViewerError> {
        let row = extent.width * bytes_per_texel;
        let padded = padded_row_bytes(row);
        let rows = extent.height * extent.depth_or_array_layers;
        let size = u64::from(padded) * u64::from(rows);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read-back"),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self.encoder("read-back");
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(extent.height),
                },
            },
            extent,
        );
        self.submit_and_wait(encoder)?;
        let bytes = self.map_read(&buffer)?;
        let mut out = Vec::with_capacity((row * rows) as usize);
        for r in 0..rows as usize {
            let start = r * padded as usize;
            out.extend_from_slice(&bytes[start..start + row as usize]);
        }
        Ok(out)
    }

    /// Maps a `MAP_READ` buffer and copies it out.
    fn map_read(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, ViewerError> {
        let (sender, receiver) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |result| {
            let _ = sender.send(result);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| ViewerError::Readback(e.to_string()))?;
        receiver
            .recv()
            .map_err(|e| ViewerError::Readback(e.to_string()))?
            .map_err(|e| ViewerError::Readback(e.to_string()))?;
        let bytes = buffer
            .get_mapped_range(..)
            .map_err(|e| ViewerError::Readback(e.to_string()))?
            .to_vec();
        buffer.unmap();
        Ok(bytes)
    }

    /// Renders `camera`'s view and reads it back: linear radiance, premultiplied over
    /// black, and alpha — the CPU reference's [`Image`] (for [`MarchView::Shaded`];
    /// debug views put their grey in rgb with alpha 1).
    pub fn render(&mut self, camera: &PinholeCamera, settings: &ViewSettings) -> Result<Image, ViewerError> {
        let mut encoder = self.encoder("render");
        self.encode_frame(&mut encoder, camera, settings)?;
        self.submit_and_wait(encoder)?;
        let target = self.target.as_ref().ok_or(ViewerError::NoAsset)?;
        let extent = target.texture.size();
        let bytes = self.read_texture(&target.texture, extent, 16)?;
        let texels: &[[f32; 4]] =
            bytemuck::try_cast_slice(&bytes).map_err(|e| ViewerError::Readback(e.to_string()))?;
        let mut image = Image::new(camera.width, camera.height);
        for ((rgb, alpha), t) in image.rgb.iter_mut().zip(image.alpha.iter_mut()).zip(texels) {
            *rgb = [t[0], t[1], t[2]];
            *alpha = t[3];
        }
        Ok(image)
    }

    /// Renders `camera`'s view through the display pass (exposure, tone map, background,
    /// sRGB) and reads back 8-bit RGBA, as the app shows it.
    pub fn render_display(
        &mut self,
        camera: &PinholeCamera,
        settings: &ViewSettings,
        display: &DisplaySettings,
    ) -> Result<DisplayImage, ViewerError> {
        let format = wgpu::TextureFormat::Rgba8Unorm;
        let mut encoder = self.encoder("render display");
        self.encode_frame(&mut encoder, camera, settings)?;
        self.prepare_display(format, display, settings.view);
        let extent = wgpu::Extent3d {
            width: camera.width,
            height: camera.height,
            depth_or_array_layers: 1,
        };
        let output = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("display output"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = output.create_view(&wgpu::TextureViewDescriptor::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("display"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.paint(&mut pass, format);
        }
        self.submit_and_wait(encoder)?;
        let rgba = self.read_texture(&output, extent, 4)?;
        Ok(DisplayImage {
            width: camera.width,
            height: camera.height,
            rgba,
        })
    }

    /// Reads the relit atlas back (`[r, g, b, σ]` per texel, x fastest, then y, then z;
    /// size [`AssetInfo::atlas_texels`]), relighting first if needed. For tests.
    pub fn read_atlas(&mut self) -> Result<Vec<[f32; 4]>, ViewerError> {
        let mut encoder = self.encoder("relight");
        self.encode_relight_if_needed(&mut encoder)?;
        self.submit_and_wait(encoder)?;
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let bytes = self.read_texture(&asset.atlas, asset.atlas.size(), 8)?;
        let halves: &[u16] =
            bytemuck::try_cast_slice(&bytes).map_err(|e| ViewerError::Readback(e.to_string()))?;
        Ok(halves
            .chunks_exact(4)
            .map(|t| std::array::from_fn(|c| half::f16::from_bits(t[c]).to_f32()))
            .collect())
    }

    /// Runs the relight pass now and waits for it (benchmarks).
    pub fn relight_blocking(&mut self) -> Result<(), ViewerError> {
        self.relight_dirty = true;
        let mut encoder = self.encoder("relight");
        self.encode_relight_if_needed(&mut encoder)?;
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

    /// Marches `camera`'s view with the counting pipeline and returns how many trilinear
    /// atlas samples and lattice steps it took.
    pub fn count_samples(
        &mut self,
        camera: &PinholeCamera,
        settings: &ViewSettings,
    ) -> Result<Counters, ViewerError> {
        self.queue
            .write_buffer(&self.counters, 0, bytemuck::bytes_of(&Counters::default()));
        let mut encoder = self.encoder("count");
        self.encode_frame_with(&mut encoder, camera, settings, true)?;
        let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("counters read-back"),
            size: size_of::<Counters>() as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(&self.counters, 0, &readback, 0, size_of::<Counters>() as u64);
        self.submit_and_wait(encoder)?;
        let bytes = self.map_read(&readback)?;
        bytemuck::try_pod_read_unaligned(&bytes).map_err(|e| ViewerError::Readback(e.to_string()))
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
