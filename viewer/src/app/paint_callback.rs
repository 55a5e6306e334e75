//! The 3D view's drawing through `egui_wgpu`: the renderer lives in egui's callback
//! resources ([`ViewerGpu`]) and each frame adds a paint callback ([`FrameCallback`])
//! that relights and marches in `prepare` and draws the tone-mapped image in `paint`.

use std::sync::{Arc, Mutex};

use eframe::egui;
use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait};
use nelf_format::conventions::PinholeCamera;

use crate::gpu::{DisplaySettings, GpuRenderer, ViewSettings};

/// GPU state kept in `egui_wgpu`'s callback resources (shared with the paint callback).
pub(super) struct ViewerGpu {
    pub(super) renderer: GpuRenderer,
    pub(super) format: eframe::wgpu::TextureFormat,
    /// Error of the last frame's GPU work, shown by the UI.
    pub(super) frame_error: Arc<Mutex<Option<String>>>,
    /// Whether the last `prepare` succeeded (so `paint` has something to draw).
    pub(super) frame_ready: bool,
}

/// One frame's drawing request.
pub(super) struct FrameCallback {
    pub(super) camera: PinholeCamera,
    pub(super) settings: ViewSettings,
    pub(super) display: DisplaySettings,
}

impl CallbackTrait for FrameCallback {
    fn prepare(
        &self,
        _device: &eframe::wgpu::Device,
        _queue: &eframe::wgpu::Queue,
        _screen: &egui_wgpu::ScreenDescriptor,
        encoder: &mut eframe::wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<eframe::wgpu::CommandBuffer> {
        if let Some(gpu) = resources.get_mut::<ViewerGpu>() {
            match gpu.renderer.encode_frame(encoder, &self.camera, &self.settings) {
                Ok(()) => {
                    gpu.renderer
                        .prepare_display(gpu.format, &self.display, self.settings.view);
                    gpu.frame_ready = true;
                }
                Err(e) => {
                    gpu.frame_ready = false;
                    if let Ok(mut slot) = gpu.frame_error.lock() {
                        *slot = Some(e.to_string());
                    }
                }
            }
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut eframe::wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        if let Some(gpu) = resources.get::<ViewerGpu>()
            && gpu.frame_ready
        {
            gpu.renderer.paint(pass, gpu.format);
        }
    }
}

/// Runs `f` on the renderer in `state`'s callback resources; `None` without a render
/// state or renderer.
pub(super) fn with_gpu<R>(
    state: Option<&egui_wgpu::RenderState>,
    f: impl FnOnce(&mut ViewerGpu) -> R,
) -> Option<R> {
    let state = state?;
    let mut renderer = state.renderer.write();
    renderer.callback_resources.get_mut::<ViewerGpu>().map(f)
}
