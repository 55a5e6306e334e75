//! Reflection assets (format 1.3, [`nelf_format::Reflection`]; mirrors
//! `nelf_render::reflection`): the relight pass's `relight_lobes` run with no lobes, and
//! the reflect pass (`shaders/reflect.wgsl`).
//!
//! A reflection voxel's radiance toward an eye `e` is
//!
//! `base + s · (max(0, n·ω) E(r) − Ē)`, `Ē = mean_k max(0, n·ω_k) E(r_k)`,
//!
//! with `ω = normalize(e − voxel centre)`, `r = 2 (n·ω) n − ω`, `ω_k`, `r_k` the same toward
//! the part's eyes, `(n, s)` the voxel's normal and scale (8-bit codes), `base` the PCA
//! part's radiance and `E` the lighting filtered by the part's lobe, a `64 × 128` table of
//! light-frame directions interpolated bilinearly. Split by when each part changes:
//!
//! * **per asset**: the lobe tabulated over the table's directions
//!   ([`ReflectionLobe::new`], 4 MiB on the CPU, kept with the asset) and a static buffer
//!   of the codes (one word per voxel: `u`, `v`, `s`);
//! * **per lighting change**: the CPU filters the lighting (in the light frame, the map the
//!   PCA part is shaded with) by the lobe ([`ReflectionLobe::filter`], `E` at 8192 nodes)
//!   and uploads the table; the relight pass's `relight_lobes` writes every voxel's `base`
//!   and σ to the lobe buffer (two words per voxel, no lobes); then `reflect_mean`, which
//!   does not depend on the eye, turns `base` into `base − s·Ē` in place;
//!   A voxel without a scale (`s = 0`: outside the bake's band, about four in five voxels
//!   of a baked head) does not depend on the eye, so `reflect_mean` writes its `[base, σ]`
//!   into the atlas there and then;
//! * **per camera move** (the eye, in lattice coordinates, differs from the one the atlas
//!   was last filled for, or the lighting changed): `reflect_toward_eye`, over the list of
//!   voxels with a scale only, adds `s · max(0, n·ω) E(r)` and writes `[rgb, σ]` into the
//!   atlas texels holding the voxel;
//! * **per frame**: the march, unchanged.
//!
//! Taking `Ē` per lighting change rather than per camera move makes a camera move one
//! table lookup per voxel instead of `1 + M` (`M ≤ 16` eyes); the f16 lobe buffer then
//! holds `base − s·Ē` instead of `base`, a rounding far inside the GPU = CPU tolerance.
//!
//! A view-independent asset creates none of this.

use glam::{DMat3, DVec3};
use nelf_format::conventions::{LatLong, is_rotation, project_envmap};
use nelf_format::{Asset, Reflection};
use nelf_render::{FilteredEnvironment, ProjectedLight, ReflectionLobe, RenderError, project_light_texels};

use super::GpuRenderer;
use super::common::{compute_pipeline, shader_module, storage_entry, storage_texture_entry, uniform_entry};
use super::view::{LobesPipeline, VIEW_LIGHT_ENTRIES, ViewBindings, buffer, voxel_dispatch};
use crate::atlas::{AtlasLayout, pack_coefficients};
use crate::error::ViewerError;
use crate::shaders::{MAX_REFLECT_EYES, REFLECT_WGSL, ReflectParams};

/// Nodes of the filtered environment's table (`64 × 128`).
const FILTERED_NODES: usize = nelf_render::reflection::LOBE_TABLE_NODES;

/// Words per voxel of a reflection asset's lobe buffer: radiance and σ, no lobes
/// (`lobe_buffer_words` in `common.wgsl` with `J = 0`).
pub(super) const REFLECT_LOBE_WORDS: usize = 2;

/// The reflect pass's pipelines, created once per device with the first reflection asset.
pub(super) struct ReflectPipeline {
    layout: wgpu::BindGroupLayout,
    /// `reflect_mean`: `base − s·Ē`, per lighting change.
    mean: wgpu::ComputePipeline,
    /// `reflect_toward_eye`: the radiance toward the eye into the atlas, per camera move.
    toward_eye: wgpu::ComputePipeline,
}

impl ReflectPipeline {
    pub(super) fn new(device: &wgpu::Device) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        use wgpu::TextureViewDimension as D;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("reflect"),
            entries: &[
                uniform_entry(0, S::COMPUTE),
                storage_entry(1, false, S::COMPUTE),
                storage_entry(2, true, S::COMPUTE),
                storage_entry(3, true, S::COMPUTE),
                storage_entry(4, true, S::COMPUTE),
                storage_texture_entry(5, wgpu::TextureFormat::Rgba16Float, D::D3),
                storage_entry(6, true, S::COMPUTE),
                storage_entry(7, true, S::COMPUTE),
            ],
        });
        let module = shader_module(device, "reflect.wgsl", REFLECT_WGSL)?;
        Ok(Self {
            mean: compute_pipeline(device, &[&layout], &module, "reflect_mean", &[]),
            toward_eye: compute_pipeline(device, &[&layout], &module, "reflect_toward_eye", &[]),
            layout,
        })
    }
}

/// A reflection asset's reflection part on the GPU.
pub(super) struct GpuReflection {
    /// The part's lobe over the table's directions, built once per asset.
    lobe: ReflectionLobe,
    /// The reflect pass's uniform but the eye (the part's constants).
    params: ReflectParams,
    params_buffer: wgpu::Buffer,
    /// The codes, one word per voxel (`u | v << 8 | s << 16 | scaled << 24`).
    codes: wgpu::Buffer,
    /// The voxels with a scale, ascending ([`scaled_codes`]).
    scaled_voxels: wgpu::Buffer,
    /// `E` at the table's nodes (`vec4<f32>`, rgb), rewritten per lighting change.
    filtered: wgpu::Buffer,
    /// The lobe buffer (radiance and σ per voxel, as f16 halves).
    voxel_lobes: wgpu::Buffer,
    /// Zeros for `relight_lobes`' view lighting, which it does not read with no lobes.
    no_view_light: wgpu::Buffer,
    /// Brick-cell coordinates (`crate::atlas::pack_brick_cells`), for voxel centres (the
    /// asset's one buffer, counted with it).
    brick_cells: wgpu::Buffer,
    pub lobes_bind_group: Option<wgpu::BindGroup>,
    bind_group: Option<wgpu::BindGroup>,
}

/// `p` (metres, world) in lattice coordinates `(p − bbox_min)/voxel − 0.5`, as the march
/// takes the camera centre.
fn lattice_point(asset: &Asset, p: DVec3) -> [f32; 4] {
    let grid = &asset.grid;
    let u: [f32; 3] = std::array::from_fn(|a| ((p[a] - grid.bbox_min_m[a]) / grid.voxel_size_m - 0.5) as f32);
    [u[0], u[1], u[2], 0.0]
}

/// The reflect pass's codes words (`u | v << 8 | s << 16`, [`pack_coefficients`]) with bit
/// 24 set where the voxel has a scale, `offset + step · s > 0` (the shader's dequantization,
/// here in `f32` as there), and the list of those voxels, ascending: the only ones a camera
/// move recomputes.
fn scaled_codes(coefficients: &nelf_format::Coefficients, offset: f32, step: f32) -> (Vec<u32>, Vec<u32>) {
    let mut words = pack_coefficients(coefficients).words;
    let mut scaled = Vec::new();
    for (v, word) in words.iter_mut().enumerate() {
        let code = (*word >> 16) & 0xff;
        if offset + step * code as f32 > 0.0 {
            *word |= 1 << 24;
            scaled.push(v as u32);
        }
    }
    (words, scaled)
}

impl GpuReflection {
    /// Tabulates `reflection`'s lobe, uploads its codes and creates the lobe buffer, the
    /// table and the uniform for `asset`'s voxels placed by `layout` (`brick_cells`: the
    /// asset's brick-cell buffer); the bind groups come with [`GpuReflection::bind`].
    pub(super) fn upload(
        device: &wgpu::Device,
        asset: &Asset,
        reflection: &Reflection,
        layout: &AtlasLayout,
        brick_cells: wgpu::Buffer,
        storage: impl Fn(&str, &[u8]) -> wgpu::Buffer,
    ) -> Result<Self, ViewerError> {
        use wgpu::BufferUsages as U;
        let voxels = asset.voxel_count();
        if reflection.eyes_m.len() > MAX_REFLECT_EYES {
            return Err(ViewerError::TooLarge(format!(
                "the reflection part averages over {} eyes, the reflect pass over at most {MAX_REFLECT_EYES}",
                reflection.eyes_m.len()
            )));
        }
        let (offset, scale) = match &reflection.coefficients {
            nelf_format::Coefficients::U8Affine { offset, scale, .. }
                if offset.len() == 3 && scale.len() == 3 =>
            {
                (
                    [offset[0], offset[1], offset[2], 0.0],
                    [scale[0], scale[1], scale[2], 0.0],
                )
            }
            other => {
                return Err(ViewerError::Format(nelf_format::FormatError::InvalidView(
                    format!(
                        "reflection part: {:?} values, {} per voxel (8-bit, three per voxel expected)",
                        other.encoding(),
                        other.rank()
                    ),
                )));
            }
        };
        let light_from_world = asset.world_from_light.transpose().as_mat3();
        let mut eyes_u = [[0.0f32; 4]; MAX_REFLECT_EYES];
        for (slot, eye) in eyes_u.iter_mut().zip(&reflection.eyes_m) {
            *slot = lattice_point(asset, DVec3::from_array(eye.map(f64::from)));
        }
        let (_, per_row) = voxel_dispatch(voxels);
        let (codes, scaled_voxels) = scaled_codes(&reflection.coefficients, offset[2], scale[2]);
        let (_, scaled_per_row) = voxel_dispatch(scaled_voxels.len());
        let column = |i: usize| {
            let c = light_from_world.col(i);
            [c.x, c.y, c.z, 0.0]
        };
        let params = ReflectParams {
            atlas: [
                layout.x_bits,
                layout.y_bits,
                voxels as u32,
                reflection.eyes_m.len() as u32,
            ],
            eye_u: [0.0; 4],
            dispatch: [per_row, scaled_per_row, scaled_voxels.len() as u32, 0],
            code_offset: offset,
            code_scale: scale,
            light_from_world: [column(0), column(1), column(2)],
            eyes_u,
        };
        let buffer = |label: &str, size: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        Ok(Self {
            lobe: ReflectionLobe::new(reflection.exponent, asset.world_from_light),
            params,
            params_buffer: buffer(
                "reflect params",
                size_of::<ReflectParams>(),
                U::UNIFORM | U::COPY_DST,
            ),
            codes: storage("reflection codes", bytemuck::cast_slice(&codes)),
            // A binding may not be empty: one out-of-range entry where no voxel has a scale
            // (the dispatch then reads none).
            scaled_voxels: storage(
                "voxels with a scale",
                bytemuck::cast_slice(if scaled_voxels.is_empty() {
                    &[u32::MAX]
                } else {
                    &scaled_voxels
                }),
            ),
            filtered: buffer(
                "filtered environment",
                FILTERED_NODES * 16,
                U::STORAGE | U::COPY_DST,
            ),
            voxel_lobes: buffer(
                "voxel radiance (reflection)",
                voxels.max(1) * REFLECT_LOBE_WORDS * 4,
                U::STORAGE,
            ),
            no_view_light: buffer("no view light", VIEW_LIGHT_ENTRIES * 16, U::UNIFORM),
            brick_cells,
            lobes_bind_group: None,
            bind_group: None,
        })
    }

    /// Bytes of GPU memory the reflection part takes.
    pub(super) fn bytes(&self) -> u64 {
        self.params_buffer.size()
            + self.codes.size()
            + self.scaled_voxels.size()
            + self.filtered.size()
            + self.voxel_lobes.size()
            + self.no_view_light.size()
    }

    /// Creates the bind groups of `relight_lobes` (no lobes: the view lighting is zeros
    /// and the codes stand in for the view coefficients, neither read) and of the reflect
    /// pass.
    pub(super) fn bind(
        &mut self,
        device: &wgpu::Device,
        lobes: &LobesPipeline,
        reflect: &ReflectPipeline,
        b: &ViewBindings<'_>,
    ) {
        self.lobes_bind_group = Some(lobes.bind_group(
            device,
            b.relight,
            &self.no_view_light,
            &self.codes,
            &self.voxel_lobes,
        ));
        self.bind_group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("reflect"),
            layout: &reflect.layout,
            entries: &[
                buffer(0, &self.params_buffer),
                buffer(1, &self.voxel_lobes),
                buffer(2, &self.brick_cells),
                buffer(3, &self.codes),
                buffer(4, b.neighbour_blocks),
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(b.atlas),
                },
                buffer(6, &self.filtered),
                buffer(7, &self.scaled_voxels),
            ],
        }));
    }

    /// The lighting `env` turned by `world_from_env`, resampled once into the asset's light
    /// frame (`world_from_light`) and used twice: projected onto the PCA basis `pca` (what
    /// `nelf_render::project_light` returns) and filtered by the part's lobe (what
    /// `nelf_render::filtered_environment` returns, without tabulating the lobe again).
    pub(super) fn project_and_filter(
        &self,
        pca: &nelf_format::PcaModel,
        world_from_light: DMat3,
        env: &LatLong,
        world_from_env: DMat3,
    ) -> Result<(ProjectedLight, FilteredEnvironment), ViewerError> {
        if !is_rotation(world_from_env, 1e-5) {
            return Err(RenderError::NotARotation {
                what: "world_from_env",
                matrix: world_from_env.to_cols_array(),
            }
            .into());
        }
        let light = project_envmap(env, world_from_env.transpose() * world_from_light)?;
        Ok((project_light_texels(pca, &light)?, self.lobe.filter(&light)))
    }

    /// Uploads the filtered environment's table (before `reflect_mean`).
    pub(super) fn write_filtered(&self, queue: &wgpu::Queue, filtered: &FilteredEnvironment) {
        let nodes: Vec<[f32; 4]> = filtered.nodes().iter().map(|&[r, g, b]| [r, g, b, 0.0]).collect();
        queue.write_buffer(&self.filtered, 0, bytemuck::cast_slice(&nodes));
    }

    /// Encodes `reflect_mean` (after `relight_lobes` and [`GpuReflection::write_filtered`]).
    pub(super) fn encode_mean(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        pipeline: &ReflectPipeline,
    ) -> Result<(), ViewerError> {
        let voxels = self.params.atlas[2] as usize;
        self.encode(
            queue,
            encoder,
            &pipeline.mean,
            &self.params,
            voxels,
            "reflect mean",
        )
    }

    /// Writes the uniform (`params`) and dispatches `pipeline`, one invocation per item
    /// (`items`: voxels, or entries of the list of voxels with a scale).
    fn encode(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        pipeline: &wgpu::ComputePipeline,
        params: &ReflectParams,
        items: usize,
        label: &str,
    ) -> Result<(), ViewerError> {
        let bind_group = self.bind_group.as_ref().ok_or(ViewerError::NoAsset)?;
        // Both entries read the same uniform, and the last write before a submission is
        // the one every pass of it sees: `params` always holds the part's constants.
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(params));
        let (groups, _) = voxel_dispatch(items);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_pipeline(pipeline);
        pass.dispatch_workgroups(groups[0], groups[1], 1);
        Ok(())
    }
}

impl GpuRenderer {
    /// Encodes the reflect pass toward `eye_u` (the eye in lattice coordinates, as the
    /// march's `origin_u`) if the loaded asset has a reflection part, the atlas shows
    /// radiance ([`crate::RelightView::Shaded`]) and the eye differs from the one the
    /// atlas was last filled for (a relight resets that). Call after the relight pass.
    pub(super) fn encode_reflect_if_needed(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        eye_u: [f32; 3],
    ) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let Some(reflection) = &asset.reflection else {
            return Ok(());
        };
        if self.relight_view != crate::RelightView::Shaded || self.view_eye == Some(eye_u) {
            return Ok(());
        }
        let pipeline = self.pipelines.reflect.as_ref().ok_or(ViewerError::NoAsset)?;
        let params = ReflectParams {
            eye_u: [eye_u[0], eye_u[1], eye_u[2], 0.0],
            ..reflection.params
        };
        let scaled = params.dispatch[2] as usize;
        if scaled > 0 {
            reflection.encode(
                &self.queue,
                encoder,
                &pipeline.toward_eye,
                &params,
                scaled,
                "reflect toward eye",
            )?;
        }
        self.view_eye = Some(eye_u);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_voxels_with_a_scale_are_listed_and_marked() {
        // Three voxels: scale codes 0, 1 and 255 with the scale's code 0 at 0 (the bake's
        // band) and at −0.01 (a quantizer whose range dips below 0: code 1 is then ≤ 0).
        let codes = vec![7, 9, 0, 1, 2, 1, 3, 4, 255];
        for (offset, want) in [(0.0f32, vec![1u32, 2]), (-0.01, vec![2])] {
            let coefficients = nelf_format::Coefficients::U8Affine {
                rank: 3,
                scale: vec![0.01, 0.01, 0.01],
                offset: vec![-1.0, -1.0, offset],
                codes: codes.clone(),
            };
            let (words, scaled) = scaled_codes(&coefficients, offset, 0.01);
            assert_eq!(scaled, want);
            for (v, word) in words.iter().enumerate() {
                let c = &codes[v * 3..v * 3 + 3];
                let marked = u32::from(scaled.contains(&(v as u32)));
                let want_word = u32::from(c[0]) | u32::from(c[1]) << 8 | u32::from(c[2]) << 16 | marked << 24;
                assert_eq!(*word, want_word, "voxel {v}");
            }
        }
    }
}
