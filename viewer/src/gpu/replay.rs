//! Relighting a held camera's frame per pixel (`shaders/replay.wgsl`): lighting changes
//! at a camera that does not move cost a dot product per pixel, not a relight and a march.
//!
//! The march is linear in the radiance and its weights depend on σ alone, so a pixel is
//! linear in the projected lighting (the PRT argument, Sloan et al. 2002, applied to the
//! frame instead of the vertices; lighting-preview systems cache deferred buffers at a
//! fixed camera the same way, Pellacini et al. 2005, Ragan-Kelley et al. 2007):
//!
//! ```text
//! C_p = W_p P_mean + Σ_k C_pk P_k,   W_p = Σ_i w_i Σ_{c present} a_c,   C_pk = Σ_i w_i Σ_c a_c c_k(c)
//! ```
//!
//! (`w_i` the march's compositing weights, `a_c` the trilinear weights of a sample's corner
//! voxels). The first lighting change at a camera held since the last frame runs
//! `replay_build`, which marches every pixel once through the atlas's densities (no
//! lighting changes them, so the atlas need not be relit) and stores `W_p`, the alpha and
//! `C_pk` (halves); that change and every later one at that camera is then the per-pixel
//! relight (`replay_fs`, or `replay_relight` as a compute pass), and the atlas is left
//! stale (the next camera relights it in full, as after the marked relight).
//!
//! The cache takes `4 (2 + ⌈K/2⌉)` bytes per pixel (34 MiB at 512² for K = 64); a frame
//! over the budget ([`DEFAULT_REPLAY_BUDGET_BYTES`], or the device's binding limit) falls
//! back to the marked relight (`marks.rs`). The image differs from a march of the relit
//! atlas only by rounding (f16 sums here, f16 radiance in the atlas).

use glam::{DVec2, DVec3};
use nelf_format::conventions::{LT_DIM, PinholeCamera};

use super::common::{
    compute_pipeline, fullscreen_pass, fullscreen_pipeline, shader_module, storage_entry, uniform_entry,
};
use super::march::MARCH_FORMAT;
use super::{AtlasState, GpuRenderer, MarchPass, RelightKind};
use crate::error::ViewerError;
use crate::shaders::{MarchParams, REPLAY_WGSL, ReplayParams};

/// Largest per-pixel cache the renderer allocates by default: 128 MiB (1280 × 720 at
/// K = 64; WebGPU's default storage binding limit).
pub const DEFAULT_REPLAY_BUDGET_BYTES: u64 = 128 << 20;

/// Components one `replay_build` dispatch sums (`BUILD_COMPONENTS` in `replay.wgsl`).
const BUILD_COMPONENTS: usize = 64;

/// The replay pipelines and the layout of their group 1 (group 0 is the compute march's),
/// created once per device with storage bindings.
pub(super) struct ReplayPipelines {
    layout: wgpu::BindGroupLayout,
    build: wgpu::ComputePipeline,
    relight: wgpu::ComputePipeline,
    /// `replay_fs`'s group 1: the uniform, the lighting and the cache, read-only.
    fragment_layout: wgpu::BindGroupLayout,
    fragment: wgpu::RenderPipeline,
}

impl ReplayPipelines {
    pub(super) fn new(
        device: &wgpu::Device,
        march_layout: &wgpu::BindGroupLayout,
    ) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("replay"),
            entries: &[
                uniform_entry(0, S::COMPUTE),
                storage_entry(1, true, S::COMPUTE),
                storage_entry(2, true, S::COMPUTE),
                storage_entry(3, false, S::COMPUTE),
                uniform_entry(4, S::COMPUTE),
            ],
        });
        let fragment_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("replay (fragment)"),
            entries: &[
                uniform_entry(0, S::FRAGMENT),
                uniform_entry(4, S::FRAGMENT),
                storage_entry(5, true, S::FRAGMENT),
            ],
        });
        let module = shader_module(device, "replay.wgsl", REPLAY_WGSL)?;
        let layouts = [march_layout, &layout];
        let fragment_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("replay (fragment)"),
            bind_group_layouts: &[None, Some(&fragment_layout)],
            immediate_size: 0,
        });
        Ok(Self {
            build: compute_pipeline(device, &layouts, &module, "replay_build", &[]),
            relight: compute_pipeline(device, &layouts, &module, "replay_relight", &[]),
            fragment: fullscreen_pipeline(
                device,
                &fragment_pipeline_layout,
                &module,
                ["march_vs", "replay_fs"],
                MARCH_FORMAT,
                &[],
            ),
            fragment_layout,
            layout,
        })
    }
}

/// What an asset gives the replay: its coefficients (the relight pass's buffer) and their
/// dequantisation per component (`Dequantization::offset_scale`, a storage buffer).
pub(super) struct ReplayInputs {
    pub(super) coefficients: wgpu::Buffer,
    pub(super) dequantization: wgpu::Buffer,
}

/// A held camera's per-pixel cache and what runs on it.
pub(super) struct GpuReplay {
    /// The march (camera, settings, image size) the cache holds; `None` until built.
    pub(super) key: Option<MarchParams>,
    /// The rectangle of that march's image the cache holds ([`box_rect`]).
    rect: [u32; 4],
    /// Pixels the cache has room for.
    pixels: u64,
    cache: wgpu::Buffer,
    /// Uniform slots: the relight's at 0, build dispatch `i`'s at `i + 1`.
    params: wgpu::Buffer,
    params_stride: u64,
    light: wgpu::Buffer,
    /// One bind group per uniform slot.
    bind_groups: Vec<wgpu::BindGroup>,
    /// `replay_fs`'s (uniform slot 0).
    fragment_bind_group: wgpu::BindGroup,
}

impl GpuReplay {
    /// GPU memory of the cache and its uniforms.
    pub(super) fn bytes(&self) -> u64 {
        self.cache.size() + self.params.size() + self.light.size()
    }
}

/// The rectangle `[x0, y0, width, height]` of `camera`'s image holding every pixel whose
/// ray (through its centre) meets the box `[lo, hi]`: the box's corners projected, with a
/// pixel of margin; the whole image when a corner is not in front of the camera.
pub(super) fn box_rect(camera: &PinholeCamera, lo: [f64; 3], hi: [f64; 3]) -> [u32; 4] {
    let whole = [0, 0, camera.width, camera.height];
    let (mut min, mut max) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for corner in 0..8 {
        let p = DVec3::new(
            if corner & 1 == 0 { lo[0] } else { hi[0] },
            if corner & 2 == 0 { lo[1] } else { hi[1] },
            if corner & 4 == 0 { lo[2] } else { hi[2] },
        );
        match camera.project(p) {
            Some(pixel) if pixel.is_finite() => {
                min = min.min(pixel);
                max = max.max(pixel);
            }
            _ => return whole,
        }
    }
    let size = DVec2::new(f64::from(camera.width), f64::from(camera.height));
    let first = (min.floor() - 1.0).clamp(DVec2::ZERO, size);
    let end = (max.ceil() + 1.0).clamp(first, size);
    let extent = end - first;
    [first.x as u32, first.y as u32, extent.x as u32, extent.y as u32]
}

/// Bytes of the cache of `pixels` pixels at rank `rank`.
fn cache_bytes(pixels: u64, rank: usize) -> u64 {
    pixels * (2 + rank.div_ceil(2) as u64) * 4
}

impl GpuRenderer {
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

    /// The cached rectangle of `camera`'s frame if it may be replayed: a device with
    /// storage bindings, an asset loaded, and a cache within the budget and the binding
    /// limit.
    pub(super) fn replay_fits(&self, camera: &PinholeCamera) -> Option<[u32; 4]> {
        let asset = self.asset.as_ref()?;
        if self.pipelines.replay.is_none() || asset.replay.is_none() {
            return None;
        }
        let rect = box_rect(camera, asset.grid.bbox_min_m, asset.grid.bbox_max_m());
        let limits = self.device.limits();
        let limit = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let bytes = cache_bytes(u64::from(rect[2]) * u64::from(rect[3]), asset.info.rank);
        (bytes <= self.replay_budget_bytes.min(limit)).then_some(rect)
    }

    /// The replay's pipelines (none on a device without storage bindings).
    fn replay_pipelines(&self) -> Result<&ReplayPipelines, ViewerError> {
        self.pipelines
            .replay
            .as_ref()
            .ok_or(ViewerError::NoCompute("the replay"))
    }

    /// The march target and its compute bind group (group 0 of the replay passes).
    fn replay_target(&self) -> Result<(&super::Target, &wgpu::BindGroup), ViewerError> {
        let target = self.target.as_ref().ok_or(ViewerError::NoAsset)?;
        let group = target
            .march_bind_group
            .as_ref()
            .ok_or(ViewerError::NoCompute("the replay"))?;
        Ok((target, group))
    }

    /// A cache of room for `pixels` pixels, reallocated only to grow.
    fn ensure_replay(&mut self, pixels: u64) -> Result<(), ViewerError> {
        if self.replay.as_ref().is_some_and(|r| r.pixels >= pixels) {
            return Ok(());
        }
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let inputs = asset
            .replay
            .as_ref()
            .ok_or(ViewerError::NoCompute("the replay"))?;
        let pipelines = self.replay_pipelines()?;
        let rank = asset.info.rank;
        let cache = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("replay cache"),
            size: cache_bytes(pixels, rank).max(16),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let dispatches = rank.div_ceil(BUILD_COMPONENTS).max(1);
        let alignment = u64::from(self.device.limits().min_uniform_buffer_offset_alignment);
        let params_stride = (size_of::<ReplayParams>() as u64).div_ceil(alignment) * alignment;
        let params = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("replay params"),
            size: params_stride * (dispatches as u64 + 1),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let light = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("replay light"),
            size: (LT_DIM * 16) as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_groups = (0..=dispatches as u64)
            .map(|slot| {
                self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("replay"),
                    layout: &pipelines.layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: &params,
                                offset: slot * params_stride,
                                size: wgpu::BufferSize::new(size_of::<ReplayParams>() as u64),
                            }),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: inputs.coefficients.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: inputs.dequantization.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: cache.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 4,
                            resource: light.as_entire_binding(),
                        },
                    ],
                })
            })
            .collect();
        let fragment_bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("replay (fragment)"),
            layout: &pipelines.fragment_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &params,
                        offset: 0,
                        size: wgpu::BufferSize::new(size_of::<ReplayParams>() as u64),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: light.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: cache.as_entire_binding(),
                },
            ],
        });
        self.replay = Some(GpuReplay {
            key: None,
            rect: [0; 4],
            pixels,
            cache,
            params,
            params_stride,
            light,
            bind_groups,
            fragment_bind_group,
        });
        Ok(())
    }

    /// The uniform of one replay dispatch over `rect`: components `[k0, k0 + count)` for
    /// a build, or the `used` ones for the relight.
    fn replay_params(
        &self,
        rect: [u32; 4],
        k0: usize,
        count: usize,
        used: usize,
    ) -> Result<ReplayParams, ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        Ok(ReplayParams {
            components: [k0 as u32, count as u32, used as u32, rect[2] * rect[3]],
            coefficients: [
                (asset.voxel_count / nelf_format::spec::BRICK_VOXELS) as u32,
                asset.coefficient_words_per_voxel,
                asset.coefficient_encoding as u32,
                asset.info.rank as u32,
            ],
            light_mean: [0.0; 4],
            rect,
        })
    }

    /// Encodes `replay_build` for the march `key` over `rect` (the march uniform written,
    /// the atlas holding its densities): the cache, in ⌈K/64⌉ dispatches.
    pub(super) fn encode_replay_build(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        key: MarchParams,
        rect: [u32; 4],
    ) -> Result<(), ViewerError> {
        self.ensure_replay(u64::from(rect[2]) * u64::from(rect[3]))?;
        let rank = self.asset.as_ref().ok_or(ViewerError::NoAsset)?.info.rank;
        let dispatches = rank.div_ceil(BUILD_COMPONENTS).max(1);
        let mut uniforms = Vec::with_capacity(dispatches);
        for i in 0..dispatches {
            let k0 = i * BUILD_COMPONENTS;
            uniforms.push(self.replay_params(rect, k0, BUILD_COMPONENTS.min(rank - k0), rank)?);
        }
        let replay = self.replay.as_mut().ok_or(ViewerError::NoAsset)?;
        for (i, uniform) in uniforms.iter().enumerate() {
            self.queue.write_buffer(
                &replay.params,
                (i as u64 + 1) * replay.params_stride,
                bytemuck::bytes_of(uniform),
            );
        }
        replay.key = Some(key);
        replay.rect = rect;
        let replay = self.replay.as_ref().ok_or(ViewerError::NoAsset)?;
        let (_, march_group) = self.replay_target()?;
        let pipelines = self.replay_pipelines()?;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("replay build"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipelines.build);
        pass.set_bind_group(0, march_group, &[]);
        for bind_group in &replay.bind_groups[1..] {
            pass.set_bind_group(1, bind_group, &[]);
            pass.dispatch_workgroups(rect[2].div_ceil(8), rect[3].div_ceil(8), 1);
        }
        Ok(())
    }

    /// Encodes the per-pixel relight under the current lighting and rank into the target
    /// (`replay_fs`, or `replay_relight` for [`MarchPass::Compute`]): the frame, without a
    /// march. The atlas is left stale.
    pub(super) fn encode_replay_relight(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        pass_kind: MarchPass,
    ) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let lighting = self.lighting.as_ref().ok_or(ViewerError::NoLighting)?;
        let stored = asset.info.rank.min(lighting.projected.rank());
        let used = self.rank.unwrap_or(stored).min(stored);
        let replay = self.replay.as_ref().ok_or(ViewerError::NoAsset)?;
        let mut uniform = self.replay_params(replay.rect, 0, 0, used)?;
        let mean = lighting.projected.mean_rgb;
        uniform.light_mean = [mean[0], mean[1], mean[2], 0.0];
        // P_k for the components used, 0 after (the shader reads whole pairs).
        let mut light = vec![[0.0f32; 4]; LT_DIM];
        for (slot, p) in light.iter_mut().zip(&lighting.projected.component_rgb[..used]) {
            *slot = [p[0], p[1], p[2], 0.0];
        }
        self.queue
            .write_buffer(&replay.params, 0, bytemuck::bytes_of(&uniform));
        self.queue
            .write_buffer(&replay.light, 0, bytemuck::cast_slice(&light));
        let (target, march_group) = self.replay_target()?;
        let pipelines = self.replay_pipelines()?;
        if pass_kind == MarchPass::Compute {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("replay relight"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipelines.relight);
            pass.set_bind_group(0, march_group, &[]);
            pass.set_bind_group(1, &replay.bind_groups[0], &[]);
            pass.dispatch_workgroups(target.width.div_ceil(32), target.height.div_ceil(8), 1);
        } else {
            // Cleared to 0 (what the march gives where no ray meets the box), then drawn over
            // the cached rectangle only.
            let [x0, y0, w, h] = replay.rect;
            let mut pass = fullscreen_pass(encoder, "replay relight", &target.view, wgpu::Color::TRANSPARENT);
            if w > 0 && h > 0 {
                pass.set_scissor_rect(x0, y0, w, h);
                pass.set_pipeline(&pipelines.fragment);
                pass.set_bind_group(1, &replay.fragment_bind_group, &[]);
                pass.draw(0..3, 0..1);
            }
        }
        self.relight_dirty = false;
        self.atlas_state = AtlasState::Stale;
        self.last_relight = Some(RelightKind::Replay);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use nelf_format::conventions::PinholeCamera;

    use nelf_render::march::ray_box;

    use super::box_rect;

    #[test]
    fn the_cached_rectangle_holds_every_pixel_whose_ray_meets_the_box() {
        let (lo, hi) = ([-0.1, -0.12, -0.09], [0.11, 0.1, 0.1]);
        let cameras = [
            // Framed, off centre, close enough to fill most of the image, and inside the box.
            PinholeCamera::look_at(DVec3::new(0.2, 0.1, 0.5), DVec3::ZERO, DVec3::Y, 96, 80, 0.65),
            PinholeCamera::look_at(
                DVec3::new(-0.4, 0.0, 0.2),
                DVec3::new(0.2, 0.1, 0.0),
                DVec3::Y,
                64,
                64,
                0.5,
            ),
            PinholeCamera::look_at(DVec3::new(0.0, 0.0, 0.16), DVec3::ZERO, DVec3::Y, 50, 40, 1.2),
            PinholeCamera::look_at(
                DVec3::new(0.0, 0.0, 0.05),
                DVec3::new(0.0, 0.0, -1.0),
                DVec3::Y,
                30,
                20,
                1.0,
            ),
            PinholeCamera::look_at(DVec3::new(0.3, 0.2, 1.2), DVec3::ZERO, DVec3::Y, 64, 48, 0.6),
        ];
        let mut sizes = Vec::new();
        for camera in &cameras {
            let [x0, y0, w, h] = box_rect(camera, lo, hi);
            assert!(x0 + w <= camera.width && y0 + h <= camera.height);
            let mut hits = 0;
            for y in 0..camera.height {
                for x in 0..camera.width {
                    let (o, d) = camera.pixel_ray(x, y);
                    if ray_box(o, d, DVec3::from_array(lo), DVec3::from_array(hi)).is_some() {
                        hits += 1;
                        assert!(
                            (x0..x0 + w).contains(&x) && (y0..y0 + h).contains(&y),
                            "pixel ({x}, {y}) meets the box outside {:?}",
                            [x0, y0, w, h]
                        );
                    }
                }
            }
            assert!(hits > 0);
            sizes.push((w * h) as f64 / f64::from(camera.width * camera.height));
        }
        // Not the whole image where the box is framed in it; the whole image from inside.
        assert!(sizes[0] < 0.8 && sizes[1] < 0.8 && sizes[4] < 0.25, "{sizes:?}");
        assert_eq!(sizes[3], 1.0);
    }
}
