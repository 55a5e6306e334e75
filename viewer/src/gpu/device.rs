//! Device setup of the GPU renderer: the adapter and device (headless, or an existing
//! one such as eframe's), what the device runs (compute and storage bindings, or not:
//! WebGL2), the pipelines of every pass and the uniform buffers every frame writes.

use super::display::DisplayPipelines;
use super::march::{MarchPass, MarchPipelines};
use super::marks::MarkPipelines;
use super::relight::RelightPipeline;
use super::replay::{DEFAULT_REPLAY_BUDGET_BYTES, ReplayPipelines};
use super::{AtlasState, GpuRenderer, Passes, Pipelines};
use crate::atlas::RelightView;
use crate::error::ViewerError;
use crate::shaders::{Counters, DisplayParams, MarchParams};

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

    pub(super) fn storage(&self) -> bool {
        self.passes == Passes::Compute
    }

    /// `STORAGE_BINDING` where the device has storage bindings, else nothing.
    pub(super) fn storage_texture_usage(&self) -> wgpu::TextureUsages {
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
}
