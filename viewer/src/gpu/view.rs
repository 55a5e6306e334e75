//! View-dependent assets (format 1.2, [`nelf_format::ViewDependence`]; mirrors
//! `nelf_render::view`): the relight pass's `relight_lobes` variant and the view pass
//! (`shaders/view.wgsl`).
//!
//! A view-dependent voxel's radiance toward an eye `e` is `base + Σ_j Y_j(ω) c_j` with
//! `ω = normalize(e − voxel centre)`, `base` the PCA part's radiance and `c_j = Σ_i d_ji
//! P^v_i` the lobe colours under the current lighting. Split by when each part changes:
//!
//! * **per lighting change** (as for any asset): the CPU projects the lighting onto the
//!   view basis ([`nelf_render::project_view_light`], `3·K_v` numbers) beside the PCA
//!   projection, and the relight pass (`relight_lobes`) computes every voxel's `base` and
//!   `c_j` and writes them with σ, as f16 halves, to the per-voxel **lobe buffer**
//!   (`lobe_buffer_words` in `common.wgsl`: `2 + ⌈3J/2⌉` words per voxel) rather than
//!   to the atlas;
//! * **per camera move** (the eye, in lattice coordinates, differs from the one the atlas
//!   was last filled for, or the lighting changed): the view pass evaluates the view
//!   harmonics (degrees 0–2) per voxel, adds the `J` lobes and writes `[rgb, σ]` to the
//!   atlas texels holding the voxel (its slot and the neighbours' aprons), as the relight
//!   pass does for a view-independent asset;
//! * **per frame**: the march, unchanged: one trilinear atlas fetch per sample.
//!
//! The lobe buffer holds f16 rather than f32: the atlas it feeds is f16 anyway (so the
//! result differs from an f32 buffer by a few f16 ulps of the terms, far inside the
//! GPU = CPU tolerance), it halves the bytes the per-camera pass reads and it keeps the
//! buffer within one storage binding
//! (WebGPU's default 128 MiB) for 2.1 M voxels at `J = 9` and 4.8 M at `J = 3`, against
//! 1.1 M and 2.6 M in f32. Halves are converted by hand (`f32_to_half`, `half_to_f32` in
//! `common.wgsl`), so no f16 shader capability is needed.
//!
//! A view-independent asset creates none of this: no lobe buffer, no view pipelines
//! (they are created with the first view-dependent asset), no view pass. A reflection
//! asset (format 1.3) runs `relight_lobes` with no lobes and its own pass instead of this
//! one ([`super::reflect`]).

use nelf_format::conventions::{LT_DIM, VIEW_HARMONICS};
use nelf_format::{Coefficients, ViewDependence};

use super::GpuRenderer;
use super::common::{compute_pipeline, shader_module, storage_entry, storage_texture_entry, uniform_entry};
use crate::atlas::{Dequantization, MAX_LOBES, PackedCoefficients};
use crate::error::ViewerError;
use crate::shaders::{RELIGHT_WGSL, VIEW_WGSL, ViewParams};

/// Entries of the view lighting uniform (`view_light` in `relight.wgsl`).
pub(super) const VIEW_LIGHT_ENTRIES: usize = MAX_LOBES + LT_DIM;

/// Words per voxel of the lobe buffer (`lobe_buffer_words` in `common.wgsl`).
pub(super) fn lobe_buffer_words(lobes: usize) -> usize {
    2 + (3 * lobes).div_ceil(2)
}

/// The relight pass's `relight_lobes` entry (each voxel's radiance, σ and lobe colours
/// into the lobe buffer), created once per device with the first view-dependent asset of
/// either kind (format 1.2 or 1.3).
pub(super) struct LobesPipeline {
    layout: wgpu::BindGroupLayout,
    pub(super) pipeline: wgpu::ComputePipeline,
}

impl LobesPipeline {
    pub(super) fn new(device: &wgpu::Device) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("relight lobes"),
            entries: &[
                uniform_entry(0, S::COMPUTE),
                uniform_entry(1, S::COMPUTE),
                storage_entry(2, true, S::COMPUTE),
                storage_entry(3, true, S::COMPUTE),
                uniform_entry(6, S::COMPUTE),
                storage_entry(7, true, S::COMPUTE),
                storage_entry(8, false, S::COMPUTE),
            ],
        });
        let relight = shader_module(device, "relight.wgsl", RELIGHT_WGSL)?;
        let pipeline = compute_pipeline(device, &[&layout], &relight, "relight_lobes", &[]);
        Ok(Self { layout, pipeline })
    }

    /// The bind group of `relight_lobes`: the relight pass's uniform, lighting, coefficients
    /// and densities (bindings 0–3), the folded view lighting (6, at least
    /// [`VIEW_LIGHT_ENTRIES`] entries), the view coefficients (7) and the lobe buffer (8).
    pub(super) fn bind_group(
        &self,
        device: &wgpu::Device,
        relight: [&wgpu::Buffer; 4],
        view_light: &wgpu::Buffer,
        view_coefficients: &wgpu::Buffer,
        voxel_lobes: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        let [params, light, coefficients, density] = relight;
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("relight lobes"),
            layout: &self.layout,
            entries: &[
                buffer(0, params),
                buffer(1, light),
                buffer(2, coefficients),
                buffer(3, density),
                buffer(6, view_light),
                buffer(7, view_coefficients),
                buffer(8, voxel_lobes),
            ],
        })
    }
}

/// The view pass's pipeline, created once per device with the first view-dependent asset
/// (format 1.2).
pub(super) struct ViewPipeline {
    layout: wgpu::BindGroupLayout,
    pub(super) pipeline: wgpu::ComputePipeline,
}

impl ViewPipeline {
    pub(super) fn new(device: &wgpu::Device) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        use wgpu::TextureViewDimension as D;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[
                uniform_entry(0, S::COMPUTE),
                storage_entry(1, true, S::COMPUTE),
                storage_entry(2, true, S::COMPUTE),
                storage_entry(4, true, S::COMPUTE),
                storage_texture_entry(5, wgpu::TextureFormat::Rgba16Float, D::D3),
            ],
        });
        let module = shader_module(device, "view.wgsl", VIEW_WGSL)?;
        let pipeline = compute_pipeline(device, &[&layout], &module, "view", &[]);
        Ok(Self { layout, pipeline })
    }
}

/// The buffers of a view-dependent asset's relight and view (or reflect) passes that
/// [`GpuView::bind`] (or `GpuReflection::bind`) binds.
pub(super) struct ViewBindings<'a> {
    /// The relight pass's uniform, lighting, coefficients and densities (bindings 0–3).
    pub relight: [&'a wgpu::Buffer; 4],
    /// Where each voxel is written (`crate::atlas::neighbour_blocks`).
    pub neighbour_blocks: &'a wgpu::Buffer,
    /// The atlas the view (or reflect) pass fills.
    pub atlas: &'a wgpu::TextureView,
}

/// A view-dependent asset's view part on the GPU.
pub(super) struct GpuView {
    /// The view part without its per-voxel coefficients (what the lighting projection
    /// reads: lobes and basis).
    pub model: ViewDependence,
    pub dequantization: Dequantization,
    pub coefficient_words_per_voxel: u32,
    pub coefficient_encoding: i32,
    /// Lobe weights as `ViewParams::lobes` holds them.
    pub lobe_weights: [[f32; 4]; 3 * MAX_LOBES],
    pub view_light: wgpu::Buffer,
    pub view_params: wgpu::Buffer,
    pub coefficients: wgpu::Buffer,
    pub voxel_lobes: wgpu::Buffer,
    /// Brick-cell coordinates (`crate::atlas::pack_brick_cells`), for voxel centres (the
    /// asset's one buffer, shared with the marked relight and counted with it).
    pub brick_cells: wgpu::Buffer,
    pub lobes_bind_group: Option<wgpu::BindGroup>,
    pub view_bind_group: Option<wgpu::BindGroup>,
}

impl GpuView {
    /// Uploads `view`'s coefficients (packed as `packed`) and creates the lobe buffer and
    /// uniforms for `voxels` voxels (`brick_cells`: the asset's brick-cell buffer); the
    /// bind groups come with [`GpuView::bind`].
    pub(super) fn upload(
        device: &wgpu::Device,
        view: &ViewDependence,
        packed: &PackedCoefficients,
        brick_cells: wgpu::Buffer,
        voxels: usize,
        storage: impl Fn(&str, &[u8]) -> wgpu::Buffer,
    ) -> Self {
        let lobes = view.lobe_count().min(MAX_LOBES);
        let mut lobe_weights = [[0.0f32; 4]; 3 * MAX_LOBES];
        for (j, w) in view.lobes.chunks_exact(VIEW_HARMONICS).take(lobes).enumerate() {
            // The shader's 9 harmonics end with the convention's (which may leave out
            // degree 0): weight l goes to slot l + 9 − VIEW_HARMONICS.
            for (l, &weight) in w.iter().enumerate() {
                let slot = l + MAX_LOBES - VIEW_HARMONICS;
                lobe_weights[3 * j + slot / 4][slot % 4] = weight;
            }
        }
        let uniform = |label: &str, size: usize| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let voxel_lobes = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("voxel lobes"),
            size: (voxels.max(1) * lobe_buffer_words(lobes) * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        Self {
            model: ViewDependence {
                lobes: view.lobes.clone(),
                basis: view.basis.clone(),
                coefficients: Coefficients::F16 {
                    rank: view.coefficients.rank(),
                    values: Vec::new(),
                },
            },
            dequantization: Dequantization::of(&view.coefficients),
            coefficient_words_per_voxel: packed.words_per_voxel,
            coefficient_encoding: packed.encoding,
            lobe_weights,
            view_light: uniform("view light", VIEW_LIGHT_ENTRIES * 16),
            view_params: uniform("view params", size_of::<ViewParams>()),
            coefficients: storage("view coefficients", bytemuck::cast_slice(&packed.words)),
            voxel_lobes,
            brick_cells,
            lobes_bind_group: None,
            view_bind_group: None,
        }
    }

    /// Bytes of GPU memory the view part takes.
    pub(super) fn bytes(&self) -> u64 {
        self.view_light.size() + self.view_params.size() + self.coefficients.size() + self.voxel_lobes.size()
    }

    /// Creates the bind groups of `relight_lobes` and of the view pass.
    pub(super) fn bind(
        &mut self,
        device: &wgpu::Device,
        lobes: &LobesPipeline,
        view: &ViewPipeline,
        b: &ViewBindings<'_>,
    ) {
        self.lobes_bind_group = Some(lobes.bind_group(
            device,
            b.relight,
            &self.view_light,
            &self.coefficients,
            &self.voxel_lobes,
        ));
        self.view_bind_group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view"),
            layout: &view.layout,
            entries: &[
                buffer(0, &self.view_params),
                buffer(1, &self.voxel_lobes),
                buffer(2, &self.brick_cells),
                buffer(4, b.neighbour_blocks),
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(b.atlas),
                },
            ],
        }));
    }
}

impl GpuRenderer {
    /// Encodes the view pass if the loaded asset is view-dependent, the atlas shows
    /// radiance ([`crate::RelightView::Shaded`]) and `eye_u` (the eye in lattice
    /// coordinates, as the march's `origin_u`) differs from the eye the atlas was last
    /// filled for (a relight resets that). Call after the relight pass.
    pub(super) fn encode_view_if_needed(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        eye_u: [f32; 3],
    ) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let Some(view) = &asset.view else {
            return Ok(());
        };
        if self.relight_view != crate::RelightView::Shaded || self.view_eye == Some(eye_u) {
            return Ok(());
        }
        let pipeline = self.pipelines.view.as_ref().ok_or(ViewerError::NoAsset)?;
        let bind_group = view.view_bind_group.as_ref().ok_or(ViewerError::NoAsset)?;
        let (groups, per_row) = voxel_dispatch(asset.voxel_count);
        let params = ViewParams {
            atlas: [
                asset.layout.x_bits,
                asset.layout.y_bits,
                view.model.lobe_count().min(MAX_LOBES) as u32,
                asset.voxel_count as u32,
            ],
            eye_u: [eye_u[0], eye_u[1], eye_u[2], 0.0],
            dispatch: [per_row, 0, 0, 0],
            lobes: view.lobe_weights,
        };
        self.queue
            .write_buffer(&view.view_params, 0, bytemuck::bytes_of(&params));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("view"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_pipeline(&pipeline.pipeline);
        pass.dispatch_workgroups(groups[0], groups[1], 1);
        drop(pass);
        self.view_eye = Some(eye_u);
        Ok(())
    }
}

/// A bind group entry for a whole buffer.
pub(super) fn buffer(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// Workgroups (of 64 invocations) of a one-invocation-per-voxel dispatch, in rows of at
/// most 32768 workgroups, and the invocations per row.
pub(super) fn voxel_dispatch(voxels: usize) -> ([u32; 2], u32) {
    let groups = (voxels as u32).div_ceil(64).max(1);
    let groups = [groups.min(32_768), groups.div_ceil(32_768)];
    (groups, groups[0] * 64)
}
