//! Submission and read-back: the headless entry points that render (or relight, or count
//! samples) and copy the result to memory — linear radiance ([`GpuRenderer::render`]),
//! display colour ([`GpuRenderer::render_display`]), the relit atlas
//! ([`GpuRenderer::read_atlas`]) and the march's sample counters
//! ([`GpuRenderer::count_samples`]) — and the texture/buffer copies they share (rows
//! padded to wgpu's 256-byte copy alignment, mapped and unpadded).

use nelf_format::conventions::PinholeCamera;
use nelf_render::Image;

use super::common::fullscreen_pass;
use super::{AtlasState, DisplayImage, DisplaySettings, GpuRenderer, ViewSettings};
use crate::error::ViewerError;
use crate::shaders::Counters;

/// Bytes per row of a texture copy, padded to wgpu's 256-byte alignment.
fn padded_row_bytes(unpadded: u32) -> u32 {
    unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

impl GpuRenderer {
    /// Submits `encoder` and waits for the device to finish.
    pub(super) fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<(), ViewerError> {
        self.queue.submit([encoder.finish()]);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| ViewerError::Readback(e.to_string()))?;
        Ok(())
    }

    pub(super) fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
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
    ///
    /// [`MarchView::Shaded`]: super::MarchView::Shaded
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
            let mut pass = fullscreen_pass(&mut encoder, "display", &view, wgpu::Color::BLACK);
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
    /// size [`AssetInfo::atlas_texels`]), relighting first if needed. For tests. A
    /// view-dependent asset's atlas shows the radiance toward the last frame's eye (the
    /// view pass runs first if needed), or holds zeros before any frame.
    ///
    /// [`AssetInfo::atlas_texels`]: super::AssetInfo::atlas_texels
    pub fn read_atlas(&mut self) -> Result<Vec<[f32; 4]>, ViewerError> {
        let mut encoder = self.encoder("relight");
        // The whole atlas, not only the voxels the last camera reads.
        if self.atlas_state == AtlasState::Stale {
            self.relight_dirty = true;
        }
        self.encode_relight_if_needed(&mut encoder, false)?;
        if let Some(eye) = self.last_eye {
            self.encode_view_if_needed(&mut encoder, eye)?;
        }
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
}

/// Renders one image of `asset` on a new headless device (`nelf render --gpu`): the
/// same camera, lighting (`env` turned by `world_from_env`), rank and march settings as
/// the CPU reference (`nelf_render::render_asset`), no jitter, read back as the same
/// premultiplied linear [`Image`]. Creating the device and uploading the asset are
/// part of the call.
pub fn render_asset_gpu(
    asset: &nelf_format::Asset,
    camera: &PinholeCamera,
    env: &nelf_format::conventions::LatLong,
    world_from_env: glam::DMat3,
    rank: Option<usize>,
    march: nelf_render::MarchSettings,
) -> Result<Image, ViewerError> {
    let mut gpu = GpuRenderer::new_headless()?;
    gpu.load_asset(asset)?;
    gpu.set_lighting(env, world_from_env)?;
    gpu.set_rank(rank);
    let view = ViewSettings {
        march,
        jitter: false,
        frame_index: 0,
        view: super::MarchView::Shaded,
        pass: gpu.preferred_march_pass(),
    };
    gpu.render(camera, &view)
}
