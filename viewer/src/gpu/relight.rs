//! The relight pass (`shaders/relight.wgsl`, compute), run once per lighting change
//! rather than per frame.
//!
//! The environment map, projected onto the asset's PCA basis on the CPU
//! ([`nelf_render::project_light`]: `P_mean` and `P_k`, `3(K + 1)` numbers), is folded
//! with the coefficient dequantisation ([`crate::atlas::fold_light`]); then every stored
//! voxel's radiance is its `K`-term dot product
//!
//! ```text
//! L(voxel) = light_mean + Σ_{k < K} q_k(voxel) · light[k]
//! ```
//!
//! (`q_k` the stored codes), written with its density σ as `[r, g, b, σ]` into the
//! RGBA16F brick atlas — the voxel's own slot and the aprons of the neighbouring slots
//! ([`crate::atlas`], `neighbour_blocks`). Shading is linear, so marching the relit atlas
//! equals shading every sample.
//!
//! A view-dependent asset runs the `relight_lobes` entry instead (see [`super::view`]):
//! the same dot product plus the lobe colours, into the lobe buffer the view pass reads;
//! a reflection asset runs it with no lobes, then the reflect pass's `reflect_mean`
//! (see [`super::reflect`]).

use nelf_format::conventions::LT_DIM;

use super::common::{compute_pipeline, shader_module, storage_entry, storage_texture_entry, uniform_entry};
use super::view::{VIEW_LIGHT_ENTRIES, voxel_dispatch};
use super::{AtlasState, GpuRenderer, RelightKind};
use crate::atlas::{MAX_LOBES, RelightView, fold_light, fold_view_light, relight_atlas_cpu};
use crate::error::ViewerError;
use crate::shaders::{RELIGHT_WGSL, RelightParams};

/// The relight pass's bind group layout and pipeline, created once per device.
pub(super) struct RelightPipeline {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl RelightPipeline {
    pub(super) fn new(device: &wgpu::Device) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        use wgpu::TextureViewDimension as D;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
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
        let module = shader_module(device, "relight.wgsl", RELIGHT_WGSL)?;
        let pipeline = compute_pipeline(device, &[&layout], &module, "relight", &[]);
        Ok(Self { layout, pipeline })
    }

    /// The layout of the relight bind group (group 0 of the marked relight too).
    pub(super) fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout
    }

    /// The bind group of an asset: `buffers` = (relight params, light, coefficients,
    /// densities, neighbour blocks), bindings 0 to 4, and the atlas the pass writes.
    pub(super) fn bind_group(
        &self,
        device: &wgpu::Device,
        buffers: [&wgpu::Buffer; 5],
        atlas_view: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        let [
            relight_params,
            light,
            coefficient_buffer,
            density_buffer,
            neighbour_buffer,
        ] = buffers;
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("relight"),
            layout: &self.layout,
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
                    resource: wgpu::BindingResource::TextureView(atlas_view),
                },
            ],
        })
    }
}

impl GpuRenderer {
    /// Encodes the relight pass if the lighting, rank or view changed since the last one:
    /// `relight` into the atlas, or for a view-dependent asset showing radiance
    /// `relight_lobes` into its lobe buffer (the view pass then fills the atlas), for a
    /// reflection asset the same with no lobes followed by `reflect_mean` (the reflect
    /// pass then fills the atlas).
    ///
    /// With `marked` (the current camera's read voxels are marked, `marks.rs`), only those
    /// are relit and the rest of the atlas is left stale. Returns how it relit, if it did.
    pub(super) fn encode_relight_if_needed(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        marked: bool,
    ) -> Result<Option<RelightKind>, ViewerError> {
        if !self.relight_dirty {
            return Ok(None);
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
        // No compute shaders (WebGL2): the same atlas relit on the CPU and uploaded.
        if let Some(cpu) = &asset.cpu_relight {
            let texels = relight_atlas_cpu(
                &cpu.sources,
                &cpu.coefficients,
                &cpu.density,
                &folded,
                matches!(self.relight_view, RelightView::Component(_)),
            );
            let size = asset.layout.texels();
            self.queue.write_texture(
                asset.atlas.as_image_copy(),
                bytemuck::cast_slice(&texels),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(size[0] * 8),
                    rows_per_image: Some(size[1]),
                },
                wgpu::Extent3d {
                    width: size[0],
                    height: size[1],
                    depth_or_array_layers: size[2],
                },
            );
            self.relight_dirty = false;
            self.atlas_state = AtlasState::Lit;
            self.last_relight = Some(RelightKind::Full);
            return Ok(self.last_relight);
        }
        let relight_pipeline = self
            .pipelines
            .relight
            .as_ref()
            .ok_or(ViewerError::NoCompute("the relight pass"))?;
        let relight_bind_group = asset
            .relight_bind_group
            .as_ref()
            .ok_or(ViewerError::NoCompute("the relight pass"))?;
        // Zeros up to the next multiple of 4: the shader applies whole words of codes.
        let mut components = folded.components.clone();
        components.resize(
            folded.components.len().next_multiple_of(4).clamp(4, LT_DIM),
            [0.0; 4],
        );
        self.queue
            .write_buffer(&asset.light, 0, bytemuck::cast_slice(&components));
        let g = asset.grid.grid_bricks;
        let (groups, per_row) = voxel_dispatch(asset.voxel_count);
        // `relight` shades four voxels per invocation.
        let quarter = asset.voxel_count.div_ceil(4);
        let (quarter_groups, quarter_per_row) = voxel_dispatch(quarter);
        // The view or reflection part, when the atlas is to show radiance: the
        // `relight_lobes` pipeline, its bind group and (lobes, rank, words, encoding); a
        // reflection part has no lobes (its filtered environment is uploaded here).
        let shaded = self.relight_view == RelightView::Shaded;
        let lobes = match (&self.pipelines.lobes, &asset.view, &asset.reflection) {
            (Some(pipeline), Some(view), _) if shaded => {
                let view_light = lighting.view_projected.as_ref().ok_or(ViewerError::NoLighting)?;
                let lobes = view.model.lobe_count().min(MAX_LOBES);
                let folded_view = fold_view_light(view_light, &view.dequantization, lobes);
                debug_assert_eq!(folded_view.len(), VIEW_LIGHT_ENTRIES);
                self.queue
                    .write_buffer(&view.view_light, 0, bytemuck::cast_slice(&folded_view));
                let bind_group = view.lobes_bind_group.as_ref().ok_or(ViewerError::NoAsset)?;
                let shape = [
                    lobes as u32,
                    view.model.rank() as u32,
                    view.coefficient_words_per_voxel,
                    view.coefficient_encoding as u32,
                ];
                Some((&pipeline.pipeline, bind_group, shape))
            }
            (Some(pipeline), None, Some(reflection)) if shaded => {
                let filtered = lighting.filtered.as_ref().ok_or(ViewerError::NoLighting)?;
                reflection.write_filtered(&self.queue, filtered);
                let bind_group = reflection.lobes_bind_group.as_ref().ok_or(ViewerError::NoAsset)?;
                Some((&pipeline.pipeline, bind_group, [0; 4]))
            }
            _ => None,
        };
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
            dispatch: [asset.voxel_count as u32, per_row, quarter as u32, quarter_per_row],
            view: lobes.map_or([0; 4], |(_, _, shape)| shape),
        };
        self.queue
            .write_buffer(&asset.relight_params, 0, bytemuck::bytes_of(&params));
        if marked && lobes.is_none() {
            self.encode_marked_relight(encoder)?;
            self.relight_dirty = false;
            self.atlas_state = AtlasState::Stale;
            self.last_relight = Some(RelightKind::Marked);
            return Ok(self.last_relight);
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("relight"),
            timestamp_writes: None,
        });
        if let Some((pipeline, bind_group, _)) = lobes {
            pass.set_bind_group(0, bind_group, &[]);
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(groups[0], groups[1], 1);
        } else {
            pass.set_bind_group(0, relight_bind_group, &[]);
            pass.set_pipeline(&relight_pipeline.pipeline);
            pass.dispatch_workgroups(quarter_groups[0], quarter_groups[1], 1);
        }
        drop(pass);
        if let (Some(reflection), Some(pipeline), true) = (&asset.reflection, &self.pipelines.reflect, shaded)
        {
            reflection.encode_mean(&self.queue, encoder, pipeline)?;
        }
        self.relight_dirty = false;
        self.atlas_state = AtlasState::Lit;
        self.last_relight = Some(RelightKind::Full);
        // The atlas no longer shows radiance toward any eye.
        self.view_eye = None;
        Ok(self.last_relight)
    }
}
