//! The display pass (`shaders/display.wgsl`): a full-screen triangle that turns the
//! march's linear premultiplied image into display colour, per pixel
//!
//! ```text
//! c = tonemap(2^exposure · rgb + (1 − alpha) · background)
//! ```
//!
//! (tonemap: identity clamped to `[0, 1]`, or ACES), then the sRGB transfer function
//! unless the target format encodes sRGB itself; debug views skip exposure and tone
//! mapping. The app paints it into egui's render pass; headless, it renders into an
//! RGBA8 texture that is read back ([`GpuRenderer::render_display`]).
//!
//! [`GpuRenderer::render_display`]: super::GpuRenderer::render_display

use super::common::{fullscreen_pipeline, shader_module, texture_entry, uniform_entry};
use super::march::MarchView;
use crate::error::ViewerError;
use crate::shaders::{DISPLAY_WGSL, DisplayParams};

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

/// The display pass's bind group layout and shader, and one pipeline per target format
/// (created on first use), created once per device.
pub(super) struct DisplayPipelines {
    layout: wgpu::BindGroupLayout,
    module: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: Vec<(wgpu::TextureFormat, wgpu::RenderPipeline)>,
}

impl DisplayPipelines {
    pub(super) fn new(device: &wgpu::Device) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        use wgpu::TextureViewDimension as D;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
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
        let module = shader_module(device, "display.wgsl", DISPLAY_WGSL)?;
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("display"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        Ok(Self {
            layout,
            module,
            pipeline_layout,
            pipelines: Vec::new(),
        })
    }

    /// The display pipeline for `format`, created on first use.
    pub(super) fn pipeline_for(
        &mut self,
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
    ) -> &wgpu::RenderPipeline {
        let index = if let Some(i) = self.pipelines.iter().position(|(f, _)| *f == format) {
            i
        } else {
            let pipeline = fullscreen_pipeline(
                device,
                &self.pipeline_layout,
                &self.module,
                ["vs_main", "fs_main"],
                format,
                &[],
            );
            self.pipelines.push((format, pipeline));
            self.pipelines.len() - 1
        };
        &self.pipelines[index].1
    }

    /// The bind group that shows the march's output `view` with uniform `display_params`.
    pub(super) fn bind_group(
        &self,
        device: &wgpu::Device,
        display_params: &wgpu::Buffer,
        view: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("display"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: display_params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(view),
                },
            ],
        })
    }

    /// Draws the full-screen triangle with `bind_group` if a pipeline for `format`
    /// exists ([`DisplayPipelines::pipeline_for`]); nothing otherwise.
    pub(super) fn paint(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        bind_group: &wgpu::BindGroup,
        format: wgpu::TextureFormat,
    ) {
        let Some((_, pipeline)) = self.pipelines.iter().find(|(f, _)| *f == format) else {
            return;
        };
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// The display uniform for a target of `format`, `display` settings and march `view`.
pub(super) fn display_params(
    format: wgpu::TextureFormat,
    display: &DisplaySettings,
    view: MarchView,
) -> DisplayParams {
    DisplayParams {
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
    }
}
