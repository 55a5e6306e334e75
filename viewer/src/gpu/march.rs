//! The ray-march pass (`shaders/march.wgsl`), run every frame: one ray per pixel through
//! the relit brick atlas, mirroring the CPU reference `nelf_render::march` step for step.
//!
//! Each pixel centre's ray of the pinhole camera is clipped against the grid box and
//! sampled at `t_i = t_entry + (i + o)Δ` (`o = 0.5`, or per pixel and frame in `[0, 1)`
//! with jitter); trilinear `σ_i` and radiance `L_i` come from the atlas (hardware filtering
//! inside a brick's slot, exact thanks to the aprons), and the samples are composited
//! front to back (emission–absorption, Max 1995):
//!
//! ```text
//! α_i = 1 − exp(−σ_i Δ),   C = Σ_i T_i α_i L_i,   T_{i+1} = T_i (1 − α_i),
//! ```
//!
//! stopping right after `T < min_transmittance`; the output is `C` (premultiplied, over
//! black) and alpha `1 − T_end` in an RGBA32F target. Empty space is skipped through the
//! march grid (`atlas::MarchGrid`: per cube of voxels the distance to σ > 0 and its
//! slot) without leaving the reference's sample lattice. An asset with a fine density
//! (format 1.4) takes `σ_i` from its fine density atlas at the same point and steps
//! `step_voxels` fine voxels, as `nelf_render::render_volume_fine`.
//!
//! Two pipelines run the same `march_pixel`: a compute dispatch writing a storage texture
//! (`march`; a second build with `COUNT_SAMPLES` counts samples into a buffer) and a
//! full-screen triangle rasterised into a colour target (`march_vs`/`march_fs`).

use nelf_format::conventions::PinholeCamera;
use nelf_format::spec::BRICK_SIZE;
use nelf_render::MarchSettings;

use super::common::{
    compute_pipeline, fullscreen_pass, fullscreen_pipeline, shader_module, storage_entry,
    storage_texture_entry, texture_entry, uniform_entry,
};
use super::{GpuAsset, GpuRenderer, Target};
use crate::error::ViewerError;
use crate::shaders::{MARCH_NOSTORAGE_WGSL, MARCH_WGSL, MarchParams};

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
    ///
    /// [`DisplaySettings`]: super::DisplaySettings
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

impl MarchPass {
    /// The faster pass on a device of this type, as measured: the fragment pass on a CPU
    /// device (lavapipe: as fast as the compute pass or faster, its rasteriser writes
    /// tiles faster than per-invocation storage stores), the compute pass on a GPU (an
    /// NVIDIA H100 under Vulkan ran the fragment pass 7× slower at 512² and 20× at 1080p;
    /// docs/measurements/2026-11-26-h100-viewer-bench.md).
    pub fn for_device(device_type: wgpu::DeviceType) -> Self {
        match device_type {
            wgpu::DeviceType::Cpu => Self::Fragment,
            _ => Self::Compute,
        }
    }
}

/// Format of the march's output: linear premultiplied rgb and alpha.
pub(super) const MARCH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// The march's bind group layouts, pipelines and atlas sampler, created once per device:
/// `march.wgsl`'s compute and fragment entries, or on a device without storage bindings
/// (WebGL2) only `march_nostorage.wgsl`'s fragment entry.
pub(super) struct MarchPipelines {
    /// The compute march and its variants (`None` without storage bindings).
    compute: Option<ComputeMarch>,
    fragment_layout: wgpu::BindGroupLayout,
    fragment: wgpu::RenderPipeline,
    /// The fragment march with `MARK_VOXELS` (`None` without storage bindings).
    fragment_marking: Option<wgpu::RenderPipeline>,
    sampler: wgpu::Sampler,
}

/// The compute march: plain, marking the voxels it reads (`marks.rs`), counting samples.
struct ComputeMarch {
    layout: wgpu::BindGroupLayout,
    plain: wgpu::ComputePipeline,
    marking: wgpu::ComputePipeline,
    counting: wgpu::ComputePipeline,
}

impl MarchPipelines {
    pub(super) fn new(device: &wgpu::Device, storage: bool) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        use wgpu::TextureViewDimension as D;
        // The bindings every march reads: uniform, atlas, sampler, fine density atlas,
        // march grid.
        let read_entries = |stage: S| {
            vec![
                uniform_entry(0, stage),
                texture_entry(
                    1,
                    wgpu::TextureSampleType::Float { filterable: true },
                    D::D3,
                    stage,
                ),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: stage,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                texture_entry(
                    3,
                    wgpu::TextureSampleType::Float { filterable: true },
                    D::D3,
                    stage,
                ),
                texture_entry(6, wgpu::TextureSampleType::Uint, D::D3, stage),
            ]
        };
        let (module, compute) = if storage {
            let module = shader_module(device, "march.wgsl", MARCH_WGSL)?;
            let mut entries = read_entries(S::COMPUTE);
            entries.extend([
                storage_texture_entry(4, wgpu::TextureFormat::Rgba32Float, D::D2),
                storage_entry(5, false, S::COMPUTE),
                storage_entry(7, false, S::COMPUTE),
            ]);
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("march"),
                entries: &entries,
            });
            let compute = ComputeMarch {
                plain: compute_pipeline(device, &[&layout], &module, "march", &[]),
                counting: compute_pipeline(device, &[&layout], &module, "march", &[("COUNT_SAMPLES", 1.0)]),
                marking: compute_pipeline(device, &[&layout], &module, "march", &[("MARK_VOXELS", 1.0)]),
                layout,
            };
            (module, Some(compute))
        } else {
            (
                shader_module(device, "march_nostorage.wgsl", MARCH_NOSTORAGE_WGSL)?,
                None,
            )
        };
        let mut fragment_entries = read_entries(S::FRAGMENT);
        if storage {
            fragment_entries.push(storage_entry(7, false, S::FRAGMENT));
        }
        let fragment_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("march (fragment)"),
            entries: &fragment_entries,
        });
        let fragment_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("march (fragment)"),
            bind_group_layouts: &[Some(&fragment_layout)],
            immediate_size: 0,
        });
        let fragment_pipeline = |constants: &[(&str, f64)]| {
            fullscreen_pipeline(
                device,
                &fragment_pipeline_layout,
                &module,
                ["march_vs", "march_fs"],
                MARCH_FORMAT,
                constants,
            )
        };
        let fragment = fragment_pipeline(&[]);
        let fragment_marking = storage.then(|| fragment_pipeline(&[("MARK_VOXELS", 1.0)]));
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
            compute,
            fragment_layout,
            fragment,
            fragment_marking,
            sampler,
        })
    }

    /// The compute march's bind group layout (group 0 of the replay passes too; `None`
    /// without storage bindings).
    pub(super) fn compute_layout(&self) -> Option<&wgpu::BindGroupLayout> {
        self.compute.as_ref().map(|c| &c.layout)
    }

    /// The bind groups of the compute and the fragment march: uniform `march_params`, the
    /// relit atlas, the fine density atlas (a placeholder without one), the march grid,
    /// the voxel marks (`marks.rs`), the output `view`
    /// (compute only) and the sample `counters` (compute only). Without storage bindings
    /// only the fragment march's, without marks.
    pub(super) fn bind_groups(
        &self,
        device: &wgpu::Device,
        march_params: &wgpu::Buffer,
        asset: &GpuAsset,
        view: &wgpu::TextureView,
        counters: &wgpu::Buffer,
    ) -> (Option<wgpu::BindGroup>, wgpu::BindGroup) {
        // Both read the uniform, atlas, sampler, fine density atlas, march grid and marks;
        // the compute march also writes the output view and the counters.
        let mut shared = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: march_params.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(&asset.atlas_view),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::Sampler(&self.sampler),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(&asset.fine.view),
            },
            wgpu::BindGroupEntry {
                binding: 6,
                resource: wgpu::BindingResource::TextureView(&asset.march_grid_view),
            },
        ];
        if let Some(marks) = &asset.marks {
            shared.push(wgpu::BindGroupEntry {
                binding: 7,
                resource: marks.voxel_marks.as_entire_binding(),
            });
        }
        let march_bind_group = self.compute.as_ref().map(|compute| {
            let mut entries = shared.clone();
            entries.extend([
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::TextureView(view),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: counters.as_entire_binding(),
                },
            ]);
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("march"),
                layout: &compute.layout,
                entries: &entries,
            })
        });
        let march_fragment_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("march (fragment)"),
            layout: &self.fragment_layout,
            entries: &shared,
        });
        (march_bind_group, march_fragment_bind_group)
    }

    /// Encodes the march into `target` (its uniform already written): the fragment
    /// pipeline for [`MarchPass::Fragment`] unless counting samples, else a compute
    /// dispatch of 8 × 8 workgroups over the target; with `mark`, the pipeline that also
    /// marks the voxels it reads (`marks.rs`; not when counting). Without storage
    /// bindings always the plain fragment pipeline.
    pub(super) fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        target: &Target,
        pass_kind: MarchPass,
        count_samples: bool,
        mark: bool,
    ) {
        let compute = match (&self.compute, &target.march_bind_group) {
            (Some(compute), Some(bind_group)) if pass_kind == MarchPass::Compute || count_samples => {
                Some((compute, bind_group))
            }
            _ => None,
        };
        let Some((compute, bind_group)) = compute else {
            let mut pass = fullscreen_pass(
                encoder,
                "march (fragment)",
                &target.view,
                wgpu::Color::TRANSPARENT,
            );
            pass.set_pipeline(match (&self.fragment_marking, mark) {
                (Some(marking), true) => marking,
                _ => &self.fragment,
            });
            pass.set_bind_group(0, &target.march_fragment_bind_group, &[]);
            pass.draw(0..3, 0..1);
            return;
        };
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("march"),
            timestamp_writes: None,
        });
        pass.set_pipeline(if count_samples {
            &compute.counting
        } else if mark {
            &compute.marking
        } else {
            &compute.plain
        });
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(target.width.div_ceil(8), target.height.div_ceil(8), 1);
    }
}

impl GpuRenderer {
    /// The march uniform for a camera and settings.
    pub(super) fn march_params(
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
        // With a fine density the step is `step_voxels` fine voxels (voxel / F), as the
        // reference's `render_volume_fine`.
        let step_voxel = match asset.fine.factor {
            0 => voxel,
            f => voxel / f64::from(f),
        };
        let fine_texels = asset.fine.texels;
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
                (f64::from(settings.march.step_voxels) * step_voxel) as f32,
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
                asset.march_grid_factor as i32,
            ],
            image: [
                camera.width,
                camera.height,
                settings.frame_index,
                u32::from(settings.jitter),
            ],
            view: [view, asset.layout.x_bits, asset.layout.y_bits, 0],
            scales: [scale, 0.0, 0.0, 0.0],
            fine: [
                1.0 / fine_texels[0] as f32,
                1.0 / fine_texels[1] as f32,
                1.0 / fine_texels[2] as f32,
                asset.fine.factor as f32,
            ],
        })
    }
}
