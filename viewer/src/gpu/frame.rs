//! A frame: the march target, and the encoding of one frame's passes in order (the
//! relight if due, or the per-pixel replay at a held camera; the view or reflect pass
//! toward a new eye; the march, marking what it reads where the next relights can use
//! it), the display pass that draws it, and the blocking variants benchmarks time.

use nelf_format::conventions::PinholeCamera;

use super::display::{DisplaySettings, display_params};
use super::march::{MARCH_FORMAT, MarchView, ViewSettings};
use super::marks::RelightKind;
use super::{AtlasState, GpuRenderer, Target};
use crate::error::ViewerError;

impl GpuRenderer {
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

    pub(super) fn encode_frame_with(
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
}
