//! The viewer app's state ([`ViewerApp`]) and the small types it keeps, and how it
//! starts: the GPU renderer on eframe's device, the asset given, then the lighting
//! (`lighting.rs`). What the app does each frame lives beside it: `files.rs` (loading),
//! `lighting.rs`, `panels.rs`, `report.rs`, `screenshot.rs`, `camera_input.rs`.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

use nelf_format::conventions::{LatLong, PinholeCamera};

use super::camera_input::{Fingers, Orbit};
use super::config::{FrameHook, IncomingFile, NamedEnvmap, OrbitStart, ViewerConfig};
use super::paint_callback::ViewerGpu;
use super::screenshot::Screenshots;
use crate::atlas::RelightView;
use crate::gpu::{GpuRenderer, MarchPass, ReflectionInfo, ToneMap, ViewInfo};

/// The debug views offered in the UI.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum DebugView {
    Shaded,
    Density,
    Alpha,
    Component,
}

/// The loaded map and its name.
pub(super) struct CurrentEnv {
    pub(super) name: String,
    pub(super) env: LatLong,
}

/// The interactive viewer: what it shows and how, and what it was last told.
pub(super) struct ViewerApp {
    pub(super) builtin: Vec<NamedEnvmap>,
    /// The fingers on the screen (touch screens).
    pub(super) fingers: Fingers,
    pub(super) loaded_envs: Vec<NamedEnvmap>,
    pub(super) env: Option<CurrentEnv>,
    /// The path field's text (natively; a browser has no paths).
    #[cfg_attr(target_arch = "wasm32", allow(dead_code))]
    pub(super) env_path_text: String,
    /// The shown asset's name (file name or URL).
    pub(super) asset_name: Option<String>,
    pub(super) incoming: Option<Receiver<IncomingFile>>,
    /// The orbit of the first asset, until one is shown.
    pub(super) start_orbit: Option<OrbitStart>,
    pub(super) on_frame: Option<FrameHook>,
    /// Dropped files read asynchronously (in a browser) arrive here.
    pub(super) dropped_sender: Sender<IncomingFile>,
    pub(super) dropped_receiver: Receiver<IncomingFile>,
    pub(super) frames_with_asset: u32,
    pub(super) view_rect_px: [f32; 4],
    pub(super) asset_rank: usize,
    /// The loaded asset's view-dependent parts as the renderer shows them (the stats line).
    pub(super) asset_parts: AssetParts,
    pub(super) max_density_per_m: f32,
    pub(super) orbit: Option<Orbit>,
    pub(super) rotation_deg: f32,
    pub(super) auto_rotate: bool,
    pub(super) auto_rotate_deg_per_s: f32,
    pub(super) exposure_ev: f32,
    pub(super) tone_map: ToneMap,
    pub(super) background: [f32; 3],
    pub(super) rank: usize,
    pub(super) debug_view: DebugView,
    pub(super) component: usize,
    pub(super) rendering: Rendering,
    pub(super) frame_index: u32,
    /// The camera the jitter pattern (`frame_index`) was drawn for.
    pub(super) jitter_camera: Option<PinholeCamera>,
    pub(super) frame_ms_smoothed: f32,
    pub(super) march_size: [u32; 2],
    pub(super) errors: Vec<String>,
    pub(super) frame_error: Arc<Mutex<Option<String>>>,
    pub(super) gpu_ok: bool,
    /// The march pass faster on the device ([`MarchPass::for_device`]).
    pub(super) march_pass: MarchPass,
    /// The backend and adapter, and where the relight runs (stats line, frame reports).
    pub(super) gpu_description: String,
    pub(super) screenshots: Screenshots,
    pub(super) applied: AppliedLighting,
}

/// The view-dependent parts and the fine density of the loaded asset, as the renderer
/// reported them.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct AssetParts {
    pub(super) view: Option<ViewInfo>,
    pub(super) reflection: Option<ReflectionInfo>,
    /// The part the renderer left out (no compute shaders: WebGL2).
    pub(super) ignored: Option<&'static str>,
    /// The factor of the fine density (format 1.4) the march samples.
    pub(super) fine_density: Option<u32>,
    /// The factor of a fine density the renderer left out (its atlas does not fit).
    pub(super) fine_density_ignored: Option<u32>,
}

/// Rendering options of the UI.
#[derive(Debug, Clone, Copy)]
pub(super) struct Rendering {
    /// March resolution relative to the viewport's pixels.
    pub(super) scale: f32,
    /// Jitter the first sample of each ray (per pixel and frame).
    pub(super) jitter: bool,
    /// Redraw every frame (shows the frame time; costs the CPU when idle).
    pub(super) continuous: bool,
}

/// What the renderer was last told, to send only changes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct AppliedLighting {
    pub(super) rotation_deg: f32,
    pub(super) rank: usize,
    pub(super) view: RelightView,
}

impl ViewerApp {
    /// Starts the app: the GPU renderer on eframe's device (errors shown, not fatal), the
    /// asset given, then the lighting at start ([`ViewerApp::start_lighting`]).
    pub(super) fn new(cc: &eframe::CreationContext<'_>, config: ViewerConfig) -> Self {
        let (dropped_sender, dropped_receiver) = channel();
        let mut app = Self {
            builtin: config.builtin_envmaps,
            fingers: Fingers::default(),
            loaded_envs: Vec::new(),
            env: None,
            env_path_text: String::new(),
            asset_name: None,
            incoming: config.incoming,
            start_orbit: config.start.orbit,
            on_frame: config.on_frame,
            dropped_sender,
            dropped_receiver,
            frames_with_asset: 0,
            view_rect_px: [0.0; 4],
            asset_rank: 0,
            asset_parts: AssetParts::default(),
            max_density_per_m: 1.0,
            orbit: None,
            rotation_deg: config.start.rotation_deg,
            auto_rotate: false,
            auto_rotate_deg_per_s: 30.0,
            exposure_ev: config.start.exposure_ev,
            tone_map: config.start.tone_map,
            background: config.start.background,
            rank: 0,
            debug_view: DebugView::Shaded,
            component: 0,
            rendering: Rendering {
                scale: 1.0,
                jitter: config.start.jitter,
                continuous: config.start.continuous,
            },
            frame_index: 0,
            jitter_camera: None,
            frame_ms_smoothed: 0.0,
            march_size: [0, 0],
            errors: Vec::new(),
            frame_error: Arc::new(Mutex::new(None)),
            gpu_ok: false,
            march_pass: MarchPass::default(),
            gpu_description: String::new(),
            screenshots: Screenshots::new(
                config.screenshot_path,
                config.screenshot_after_frames,
                config.exit_after_screenshot,
            ),
            applied: AppliedLighting::default(),
        };
        match &cc.wgpu_render_state {
            Some(state) => match GpuRenderer::from_device(state.device.clone(), state.queue.clone()) {
                Ok(renderer) => {
                    let info = state.adapter.get_info();
                    app.gpu_description = format!(
                        "{:?} ({}), relight on the {}",
                        info.backend,
                        info.name,
                        if renderer.uses_storage() { "GPU" } else { "CPU" }
                    );
                    let renderer = renderer.with_adapter_info(info);
                    app.march_pass = renderer.preferred_march_pass();
                    state.renderer.write().callback_resources.insert(ViewerGpu {
                        renderer,
                        format: state.target_format,
                        frame_error: Arc::clone(&app.frame_error),
                        frame_ready: false,
                    });
                    app.gpu_ok = true;
                }
                Err(e) => app.errors.push(format!("GPU renderer: {e}")),
            },
            None => app
                .errors
                .push("no wgpu render state: the viewer needs eframe's wgpu renderer".into()),
        }
        let mut asset_loaded = false;
        if let Some(path) = &config.asset_path {
            asset_loaded = app.load_asset_file(cc.wgpu_render_state.as_ref(), path);
        }
        app.start_lighting(
            cc.wgpu_render_state.as_ref(),
            config.envmap_path.as_deref(),
            config.asset_path.as_deref().filter(|_| asset_loaded),
        );
        app
    }
}
