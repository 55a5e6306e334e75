//! The interactive viewer (`nelf view ASSET`): an eframe/egui window whose central
//! area is drawn by [`GpuRenderer`] on eframe's own wgpu device, through an
//! `egui_wgpu` paint callback (relight + march in `prepare`, the tone-mapping display
//! pass in `paint`).
//!
//! Controls: drag to orbit, right/middle-drag (or shift-drag) to pan, scroll to zoom;
//! environment maps from a built-in list (given by the caller), a path field, or
//! drag-and-drop of EXR/HDR files (and of `.nelf` files, which replace the asset);
//! rotation slider and auto-rotate; exposure and tone curve; a PCA rank slider that
//! truncates `K`; debug views (density, alpha, one PCA component); frame time; F12 or
//! the button saves a screenshot of the window.
//!
//! **Lighting at start**: `--envmap FILE` if given; else the capture's light sitting
//! beside the asset — `<asset stem>.light.exr` / `.light.hdr` in the asset's folder, or
//! the `envmap` of a capture folder (`cameras.json`) that holds the asset; else the
//! first built-in map; else a uniform white sky.
//!
//! **Files as bytes.** Assets and maps are read from bytes (`read_asset_bytes`,
//! `decode_envmap`), so the same app runs natively (paths, dropped files) and in a
//! browser, where files arrive by fetch or drag-and-drop through
//! [`ViewerConfig::incoming`]; [`StartView`] sets camera and lighting at start (the web
//! page's URL parameters) and [`ViewerConfig::on_frame`] reports each frame to the host
//! (the page writes it into the DOM for tests and timings).
//!
//! **Errors never end the app**: an unreadable or damaged asset or environment map, or
//! a GPU error, is shown in the window (red text) and the app keeps running.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::sync::{Arc, Mutex};

use eframe::egui;
use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait};
use glam::DVec3;
use nelf_format::conventions::{LatLong, PinholeCamera, rotation_y};
use nelf_format::envmap_file::{EnvmapKind, decode_envmap};
use nelf_render::MarchSettings;

use crate::atlas::RelightView;
use crate::gpu::{
    DisplaySettings, GpuRenderer, MarchPass, MarchView, ReflectionInfo, RelightKind, ToneMap, ViewInfo,
    ViewSettings,
};

/// A named environment map offered in the picker.
#[derive(Debug, Clone)]
pub struct NamedEnvmap {
    /// Name shown.
    pub name: String,
    /// The map (lat-long, linear, world frame).
    pub env: LatLong,
}

/// A file reaching the viewer as bytes after start (the web page's fetches): a `.nelf`
/// replaces the asset, an `.exr`/`.hdr` becomes the lighting.
#[derive(Debug, Clone)]
pub struct IncomingFile {
    /// File name (its extension says what it is) or URL, shown in messages.
    pub name: String,
    /// The bytes, or why they could not be had (e.g. an HTTP error).
    pub bytes: Result<Vec<u8>, String>,
}

/// Camera, lighting and display at start (the web page's URL parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartView {
    /// Orbit of the first asset: azimuth and elevation (degrees, 0/0 looks from +z at
    /// the box centre) and distance (metres; `None`: the framing distance).
    pub orbit: Option<OrbitStart>,
    /// Rotation of the environment about +y (degrees).
    pub rotation_deg: f32,
    /// Exposure (stops).
    pub exposure_ev: f32,
    /// Tone curve.
    pub tone_map: ToneMap,
    /// Background radiance behind the asset (linear rgb).
    pub background: [f32; 3],
    /// Jitter the first sample of each ray.
    pub jitter: bool,
    /// Redraw every frame.
    pub continuous: bool,
}

impl Default for StartView {
    fn default() -> Self {
        Self {
            orbit: None,
            rotation_deg: 0.0,
            exposure_ev: 0.0,
            tone_map: ToneMap::Aces,
            background: DisplaySettings::default().background,
            jitter: true,
            continuous: false,
        }
    }
}

/// An orbit camera around the asset's box centre, as [`StartView::orbit`] gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrbitStart {
    /// Azimuth about +y (degrees; positive moves the eye toward +x).
    pub azimuth_deg: f64,
    /// Elevation (degrees; positive looks from above).
    pub elevation_deg: f64,
    /// Distance from the box centre (metres); `None`: the framing distance.
    pub distance_m: Option<f64>,
}

/// What a frame showed, for the host ([`ViewerConfig::on_frame`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameReport {
    /// Frames drawn with an asset so far (0 until an asset and lighting are shown).
    pub frames_with_asset: u32,
    /// The 3D view's rectangle in physical pixels: x, y, width, height.
    pub view_rect_px: [f32; 4],
    /// The march resolution.
    pub march_size: [u32; 2],
    /// The camera of the 3D view, if an asset is shown.
    pub camera: Option<PinholeCamera>,
    /// Smoothed frame interval (ms).
    pub frame_ms: f32,
    /// The GPU backend and adapter, and where the relight runs (e.g. `Gl (…), relight on
    /// the CPU` on WebGL2).
    pub gpu: String,
    /// Errors shown in the window, oldest first.
    pub errors: Vec<String>,
}

/// Called once per frame with its [`FrameReport`].
pub type FrameHook = Box<dyn FnMut(&FrameReport)>;

/// How to start the viewer.
pub struct ViewerConfig {
    /// The asset to show (`None`: start empty; drop a `.nelf` on the window).
    pub asset_path: Option<PathBuf>,
    /// An environment map file to light it with.
    pub envmap_path: Option<PathBuf>,
    /// Built-in maps for the picker (e.g. procedural skies).
    pub builtin_envmaps: Vec<NamedEnvmap>,
    /// Files arriving after start (the web page's fetches).
    pub incoming: Option<Receiver<IncomingFile>>,
    /// Camera, lighting and display at start.
    pub start: StartView,
    /// Called after every frame (the web page reports frames to the DOM).
    pub on_frame: Option<FrameHook>,
    /// Save a screenshot of the window here after [`ViewerConfig::screenshot_after_frames`] frames.
    pub screenshot_path: Option<PathBuf>,
    /// Frames drawn before the screenshot is taken.
    pub screenshot_after_frames: u32,
    /// Close the window once the screenshot is saved.
    pub exit_after_screenshot: bool,
    /// Initial window size in points.
    pub window_size: [f32; 2],
}

impl std::fmt::Debug for ViewerConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewerConfig")
            .field("asset_path", &self.asset_path)
            .field("envmap_path", &self.envmap_path)
            .field("builtin_envmaps", &self.builtin_envmaps.len())
            .field("incoming", &self.incoming.is_some())
            .field("start", &self.start)
            .field("on_frame", &self.on_frame.is_some())
            .field("screenshot_path", &self.screenshot_path)
            .field("screenshot_after_frames", &self.screenshot_after_frames)
            .field("exit_after_screenshot", &self.exit_after_screenshot)
            .field("window_size", &self.window_size)
            .finish_non_exhaustive()
    }
}

impl ViewerConfig {
    /// A configuration showing `asset_path` (a file) with the default start view.
    pub fn new(asset_path: Option<PathBuf>) -> Self {
        Self {
            asset_path,
            envmap_path: None,
            builtin_envmaps: Vec::new(),
            incoming: None,
            start: StartView::default(),
            on_frame: None,
            screenshot_path: None,
            screenshot_after_frames: 3,
            exit_after_screenshot: false,
            window_size: [1280.0, 800.0],
        }
    }
}

/// Opens the viewer window and runs until it is closed.
#[cfg(not(target_arch = "wasm32"))]
pub fn run_viewer(config: ViewerConfig) -> Result<(), crate::ViewerError> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("nelf view")
            .with_inner_size(config.window_size)
            .with_drag_and_drop(true),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    eframe::run_native(
        "nelf view",
        options,
        Box::new(move |cc| Ok(create_app(cc, config))),
    )
    .map_err(|e| crate::ViewerError::App(e.to_string()))
}

/// Creates the app on eframe's context (the web page's `WebRunner` calls this).
pub fn create_app(cc: &eframe::CreationContext<'_>, config: ViewerConfig) -> Box<dyn eframe::App> {
    Box::new(ViewerApp::new(cc, config))
}

/// GPU state kept in `egui_wgpu`'s callback resources (shared with the paint callback).
struct ViewerGpu {
    renderer: GpuRenderer,
    format: eframe::wgpu::TextureFormat,
    /// Error of the last frame's GPU work, shown by the UI.
    frame_error: Arc<Mutex<Option<String>>>,
    /// Whether the last `prepare` succeeded (so `paint` has something to draw).
    frame_ready: bool,
}

/// One frame's drawing request.
struct FrameCallback {
    camera: PinholeCamera,
    settings: ViewSettings,
    display: DisplaySettings,
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

/// The debug views offered in the UI.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DebugView {
    Shaded,
    Density,
    Alpha,
    Component,
}

/// Orbit camera around a target.
#[derive(Debug, Clone, Copy)]
struct Orbit {
    target: DVec3,
    yaw_rad: f64,
    pitch_rad: f64,
    distance_m: f64,
    fov_x_rad: f64,
}

impl Orbit {
    /// Frames a box: looks at its centre from +z (the front of a head).
    fn framing(min: [f64; 3], max: [f64; 3]) -> Self {
        let lo = DVec3::from_array(min);
        let hi = DVec3::from_array(max);
        let radius = 0.5 * (hi - lo).length();
        let fov_x_rad = 40f64.to_radians();
        Self {
            target: 0.5 * (lo + hi),
            yaw_rad: 0.0,
            pitch_rad: 0.0,
            distance_m: (radius / (0.5 * fov_x_rad).sin()).max(1e-3),
            fov_x_rad,
        }
    }

    /// The framing of the box, turned and moved as `start` says.
    fn started(min: [f64; 3], max: [f64; 3], start: OrbitStart) -> Self {
        let mut orbit = Self::framing(min, max);
        orbit.yaw_rad = start.azimuth_deg.to_radians();
        orbit.pitch_rad = start.elevation_deg.to_radians().clamp(-1.5, 1.5);
        if let Some(d) = start.distance_m.filter(|d| d.is_finite() && *d > 0.0) {
            orbit.distance_m = d;
        }
        orbit
    }

    fn eye(&self) -> DVec3 {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        self.target + self.distance_m * DVec3::new(cp * sy, sp, cp * cy)
    }

    fn camera(&self, width: u32, height: u32) -> PinholeCamera {
        PinholeCamera::look_at(self.eye(), self.target, DVec3::Y, width, height, self.fov_x_rad)
    }

    /// Moves the target in the image plane by `(dx, dy)` points of a view `width` points wide.
    fn pan(&mut self, dx: f64, dy: f64, width: f64) {
        let forward = (self.target - self.eye()).normalize();
        let right = forward.cross(DVec3::Y).normalize();
        let up = right.cross(forward);
        let metres_per_point = 2.0 * self.distance_m * (0.5 * self.fov_x_rad).tan() / width.max(1.0);
        self.target += (-dx * right + dy * up) * metres_per_point;
    }
}

/// The fingers on a touch screen, counted from egui's own touch events. egui's
/// multi-touch state starts a frame after the second finger lands, and the pointer it
/// emulates from the fingers can jump from one finger to another as fingers come and go;
/// the 3D view orbits with one finger only, and moves nothing in a frame where a finger
/// landed or lifted.
#[derive(Debug, Default)]
struct Fingers {
    down: std::collections::BTreeSet<egui::TouchId>,
}

impl Fingers {
    /// Takes one frame's input events; returns whether a finger landed or lifted.
    fn update(&mut self, events: &[egui::Event]) -> bool {
        let mut changed = false;
        for event in events {
            if let egui::Event::Touch { id, phase, .. } = event {
                match phase {
                    egui::TouchPhase::Start => changed |= self.down.insert(*id),
                    egui::TouchPhase::End | egui::TouchPhase::Cancel => changed |= self.down.remove(id),
                    egui::TouchPhase::Move => {}
                }
            }
        }
        changed
    }

    fn count(&self) -> usize {
        self.down.len()
    }
}

/// The loaded map and its name.
struct CurrentEnv {
    name: String,
    env: LatLong,
}

struct ViewerApp {
    builtin: Vec<NamedEnvmap>,
    /// The fingers on the screen (touch screens).
    fingers: Fingers,
    loaded_envs: Vec<NamedEnvmap>,
    env: Option<CurrentEnv>,
    /// The path field's text (natively; a browser has no paths).
    #[cfg_attr(target_arch = "wasm32", allow(dead_code))]
    env_path_text: String,
    /// The shown asset's name (file name or URL).
    asset_name: Option<String>,
    incoming: Option<Receiver<IncomingFile>>,
    /// The orbit of the first asset, until one is shown.
    start_orbit: Option<OrbitStart>,
    on_frame: Option<FrameHook>,
    /// Dropped files read asynchronously (in a browser) arrive here.
    dropped_sender: Sender<IncomingFile>,
    dropped_receiver: Receiver<IncomingFile>,
    frames_with_asset: u32,
    view_rect_px: [f32; 4],
    asset_rank: usize,
    /// The loaded asset's view-dependent parts as the renderer shows them (the stats line).
    asset_parts: AssetParts,
    max_density_per_m: f32,
    orbit: Option<Orbit>,
    rotation_deg: f32,
    auto_rotate: bool,
    auto_rotate_deg_per_s: f32,
    exposure_ev: f32,
    tone_map: ToneMap,
    background: [f32; 3],
    rank: usize,
    debug_view: DebugView,
    component: usize,
    rendering: Rendering,
    frame_index: u32,
    /// The camera the jitter pattern (`frame_index`) was drawn for.
    jitter_camera: Option<PinholeCamera>,
    frame_ms_smoothed: f32,
    march_size: [u32; 2],
    errors: Vec<String>,
    frame_error: Arc<Mutex<Option<String>>>,
    gpu_ok: bool,
    /// The march pass faster on the device ([`MarchPass::for_device`]).
    march_pass: MarchPass,
    /// The backend and adapter, and where the relight runs (stats line, frame reports).
    gpu_description: String,
    screenshots: Screenshots,
    applied: AppliedLighting,
}

/// A screenshot on its way: the path to save it to (`None`: a numbered file) and the image.
type ScreenshotMessage = (Option<PathBuf>, Arc<egui::ColorImage>);

/// Screenshot requests: the scripted one (`--screenshot`) and the key/button ones.
struct Screenshots {
    /// Scripted screenshot path.
    path: Option<PathBuf>,
    /// Frames before the scripted screenshot.
    after_frames: u32,
    /// Close the window after the scripted screenshot.
    exit_after: bool,
    /// Whether the scripted screenshot was requested.
    requested: bool,
    /// Numbered screenshots saved so far.
    taken: u32,
    /// Frames shown so far.
    frames_shown: u32,
    sender: Sender<ScreenshotMessage>,
    receiver: Receiver<ScreenshotMessage>,
}

/// The stats line of an asset: its PCA rank and whether it is view-dependent (format
/// 1.2: `J` lobes over a view basis of rank `K_v`).
fn asset_stats(rank: usize, parts: &AssetParts) -> String {
    let shown = match (parts.view, parts.reflection) {
        (Some(v), _) => format!(
            "K = {rank}; view-dependent: J = {} lobe{}, K_v = {} ({:?})",
            v.lobes,
            if v.lobes == 1 { "" } else { "s" },
            v.rank,
            v.encoding
        ),
        (None, Some(r)) => format!(
            "K = {rank}; reflection lobe: exponent {}, averaged over {} eye{}",
            r.exponent,
            r.eyes,
            if r.eyes == 1 { "" } else { "s" }
        ),
        (None, None) => format!("K = {rank}; view-independent"),
    };
    match parts.ignored {
        Some(part) => format!(
            "{shown}\nnot shown: its {part}, which needs compute shaders \
             (WebGPU or the native viewer); this is the view-averaged asset"
        ),
        None => shown,
    }
}

/// The view-dependent parts of the loaded asset, as the renderer reported them.
#[derive(Debug, Clone, Copy, Default)]
struct AssetParts {
    view: Option<ViewInfo>,
    reflection: Option<ReflectionInfo>,
    /// The part the renderer left out (no compute shaders: WebGL2).
    ignored: Option<&'static str>,
}

/// The stats line of the last lighting change on the GPU: which voxels it relit, or
/// that the held camera's pixels were replayed (with the per-pixel cache's memory).
/// `None` before the first one (and where the relight runs on the CPU).
fn relight_stats(kind: Option<RelightKind>, replay_bytes: u64) -> Option<String> {
    let text = match kind? {
        RelightKind::Full => "last relight: every voxel".to_owned(),
        RelightKind::Marked => "last relight: the voxels this view reads".to_owned(),
        RelightKind::Replay => format!(
            "last relight: pixels replayed (cache {:.1} MiB)",
            replay_bytes as f64 / f64::from(1u32 << 20)
        ),
    };
    Some(text)
}

/// Rendering options of the UI.
#[derive(Debug, Clone, Copy)]
struct Rendering {
    /// March resolution relative to the viewport's pixels.
    scale: f32,
    /// Jitter the first sample of each ray (per pixel and frame).
    jitter: bool,
    /// Redraw every frame (shows the frame time; costs the CPU when idle).
    continuous: bool,
}

/// What the renderer was last told, to send only changes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct AppliedLighting {
    rotation_deg: f32,
    rank: usize,
    view: RelightView,
}

impl ViewerApp {
    fn new(cc: &eframe::CreationContext<'_>, config: ViewerConfig) -> Self {
        let (screenshot_sender, screenshot_receiver) = channel();
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
            screenshots: Screenshots {
                path: config.screenshot_path,
                after_frames: config.screenshot_after_frames,
                exit_after: config.exit_after_screenshot,
                requested: false,
                taken: 0,
                frames_shown: 0,
                sender: screenshot_sender,
                receiver: screenshot_receiver,
            },
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
        // Lighting at start: --envmap, else the capture's light beside the asset, else a built-in.
        let start_env = config.envmap_path.clone().or_else(|| {
            config
                .asset_path
                .as_deref()
                .filter(|_| asset_loaded)
                .and_then(capture_light_beside)
        });
        let mut have_env = false;
        if let Some(path) = start_env {
            have_env = app.load_env_file(cc.wgpu_render_state.as_ref(), &path);
        }
        if !have_env {
            let first = app.builtin.first().cloned().unwrap_or_else(|| NamedEnvmap {
                name: "uniform white".into(),
                env: LatLong::constant(16, 8, [1.0; 3]),
            });
            app.set_env(cc.wgpu_render_state.as_ref(), first.name, first.env);
        }
        app
    }

    fn with_gpu<R>(state: Option<&egui_wgpu::RenderState>, f: impl FnOnce(&mut ViewerGpu) -> R) -> Option<R> {
        let state = state?;
        let mut renderer = state.renderer.write();
        renderer.callback_resources.get_mut::<ViewerGpu>().map(f)
    }

    /// Reads a file's bytes, or shows why not.
    fn read_file(&mut self, path: &Path) -> Option<Vec<u8>> {
        match std::fs::read(path) {
            Ok(bytes) => Some(bytes),
            Err(e) => {
                self.errors.push(format!("cannot read {}: {e}", path.display()));
                None
            }
        }
    }

    /// Reads and shows the asset in a file; true on success.
    fn load_asset_file(&mut self, state: Option<&egui_wgpu::RenderState>, path: &Path) -> bool {
        self.read_file(path)
            .is_some_and(|bytes| self.load_asset(state, &path.display().to_string(), &bytes))
    }

    /// Reads and uploads an asset from its file's bytes; on any failure keeps the
    /// previous one and shows why. True on success.
    fn load_asset(&mut self, state: Option<&egui_wgpu::RenderState>, name: &str, bytes: &[u8]) -> bool {
        let asset = match nelf_format::read_asset_bytes(bytes) {
            Ok(a) => a,
            Err(e) => {
                self.errors.push(format!("cannot load {name}: {e}"));
                return false;
            }
        };
        let result = Self::with_gpu(state, |gpu| gpu.renderer.load_asset(&asset));
        match result {
            Some(Ok(info)) => {
                self.asset_name = Some(name.to_owned());
                self.asset_rank = info.rank;
                self.asset_parts = AssetParts {
                    view: info.view,
                    reflection: info.reflection,
                    ignored: info.view_part_ignored,
                };
                self.rank = info.rank;
                self.component = self.component.min(info.rank.saturating_sub(1));
                self.max_density_per_m = info.max_density_per_m.max(1e-6);
                let (min, max) = (asset.grid.bbox_min_m, asset.grid.bbox_max_m());
                self.orbit = Some(match self.start_orbit.take() {
                    Some(start) => Orbit::started(min, max, start),
                    None => Orbit::framing(min, max),
                });
                self.applied = AppliedLighting::default();
                if let Some(env) = &self.env {
                    let (name, env) = (env.name.clone(), env.env.clone());
                    self.set_env(state, name, env);
                }
                true
            }
            Some(Err(e)) => {
                self.errors.push(format!("cannot show {name}: {e}"));
                false
            }
            None => {
                self.errors.push(format!("cannot show {name}: no GPU renderer"));
                false
            }
        }
    }

    /// Loads an EXR/HDR map file; true on success.
    fn load_env_file(&mut self, state: Option<&egui_wgpu::RenderState>, path: &Path) -> bool {
        self.read_file(path)
            .is_some_and(|bytes| self.load_env(state, &path.display().to_string(), &bytes))
    }

    /// Decodes an EXR/HDR map (`name`'s extension says which) and makes it the
    /// lighting; true on success.
    fn load_env(&mut self, state: Option<&egui_wgpu::RenderState>, name: &str, bytes: &[u8]) -> bool {
        match EnvmapKind::from_name(name).and_then(|kind| decode_envmap(bytes, kind)) {
            Ok(env) => {
                let name = file_name_of(name).to_owned();
                self.loaded_envs.retain(|e| e.name != name);
                self.loaded_envs.push(NamedEnvmap {
                    name: name.clone(),
                    env: env.clone(),
                });
                self.set_env(state, name, env)
            }
            Err(e) => {
                self.errors
                    .push(format!("cannot load environment map {name}: {e}"));
                false
            }
        }
    }

    /// Makes `env` the lighting (projected at the current rotation); true on success.
    fn set_env(&mut self, state: Option<&egui_wgpu::RenderState>, name: String, env: LatLong) -> bool {
        let rotation = rotation_y(f64::from(self.rotation_deg).to_radians());
        let has_asset = self.asset_name.is_some();
        let result = if has_asset {
            Self::with_gpu(state, |gpu| gpu.renderer.set_lighting(&env, rotation))
        } else {
            Some(Ok(()))
        };
        match result {
            Some(Ok(())) => {
                self.applied.rotation_deg = self.rotation_deg;
                self.env = Some(CurrentEnv { name, env });
                true
            }
            Some(Err(e)) => {
                self.errors
                    .push(format!("cannot use environment map {name}: {e}"));
                false
            }
            None => false,
        }
    }

    /// Sends rotation, rank and relight-view changes to the renderer.
    fn apply_lighting_changes(&mut self, state: Option<&egui_wgpu::RenderState>) {
        if self.asset_name.is_none() || self.env.is_none() {
            return;
        }
        let view = if self.debug_view == DebugView::Component {
            RelightView::Component(self.component)
        } else {
            RelightView::Shaded
        };
        let wanted = AppliedLighting {
            rotation_deg: self.rotation_deg,
            rank: self.rank,
            view,
        };
        if wanted == self.applied {
            return;
        }
        let rotation = rotation_y(f64::from(self.rotation_deg).to_radians());
        let rotate = wanted.rotation_deg != self.applied.rotation_deg;
        let rank = self.rank;
        let result = Self::with_gpu(state, |gpu| {
            gpu.renderer.set_rank(Some(rank));
            gpu.renderer.set_relight_view(view);
            if rotate {
                gpu.renderer.set_light_rotation(rotation)
            } else {
                Ok(())
            }
        });
        if let Some(Err(e)) = result {
            self.errors.push(format!("relight: {e}"));
        }
        self.applied = wanted;
    }

    /// Files dropped on the window (natively paths, in a browser bytes) and files the
    /// host sent ([`ViewerConfig::incoming`]).
    fn handle_new_files(&mut self, ctx: &egui::Context, state: Option<&egui_wgpu::RenderState>) {
        let dropped: Vec<egui::DroppedFileHandle> = ctx.input(|i| i.raw.dropped_files.clone());
        for file in dropped {
            let name = file.path().display().to_string();
            #[cfg(not(target_arch = "wasm32"))]
            let _ = self.dropped_sender.send(IncomingFile {
                name,
                bytes: file.bytes(),
            });
            // A browser reads a dropped file asynchronously: it arrives on a later frame.
            #[cfg(target_arch = "wasm32")]
            {
                let sender = self.dropped_sender.clone();
                let waker = ctx.clone();
                wasm_bindgen_futures::spawn_local(async move {
                    let bytes = file.bytes_async().await;
                    let _ = sender.send(IncomingFile { name, bytes });
                    waker.request_repaint();
                });
            }
        }
        let mut files: Vec<IncomingFile> = self.dropped_receiver.try_iter().collect();
        if let Some(receiver) = &self.incoming {
            loop {
                match receiver.try_recv() {
                    Ok(file) => files.push(file),
                    Err(TryRecvError::Empty) => {
                        // More may come (a fetch in flight): look again soon.
                        ctx.request_repaint_after(std::time::Duration::from_millis(50));
                        break;
                    }
                    Err(TryRecvError::Disconnected) => {
                        self.incoming = None;
                        break;
                    }
                }
            }
        }
        for file in files {
            match file.bytes {
                Err(e) => self.errors.push(format!("cannot load {}: {e}", file.name)),
                Ok(bytes) if file.name.to_ascii_lowercase().ends_with(".nelf") => {
                    self.load_asset(state, &file.name, &bytes);
                }
                Ok(bytes) => {
                    self.load_env(state, &file.name, &bytes);
                }
            }
        }
    }

    fn controls(&mut self, ui: &mut egui::Ui, state: Option<&egui_wgpu::RenderState>) {
        ui.heading("nelf view");
        match &self.asset_name {
            Some(name) => ui.label(format!("asset: {}", file_name_of(name))),
            None => ui.label("no asset: drop a .nelf file here"),
        };
        if self.asset_name.is_some() {
            ui.label(asset_stats(self.asset_rank, &self.asset_parts));
        }
        ui.label(&self.gpu_description);
        ui.label(format!(
            "frame interval {:.1} ms ({:.0} fps), march {}×{}",
            self.frame_ms_smoothed,
            if self.frame_ms_smoothed > 0.0 {
                1000.0 / self.frame_ms_smoothed
            } else {
                0.0
            },
            self.march_size[0],
            self.march_size[1]
        ));
        let relight = Self::with_gpu(state, |gpu| {
            relight_stats(gpu.renderer.last_relight(), gpu.renderer.replay_bytes())
        });
        if let Some(Some(text)) = relight {
            ui.label(text);
        }
        ui.separator();

        ui.label("Lighting");
        let current = self.env.as_ref().map(|e| e.name.clone()).unwrap_or_default();
        let mut choice: Option<NamedEnvmap> = None;
        egui::ComboBox::from_id_salt("envmap")
            .selected_text(current.clone())
            .show_ui(ui, |ui| {
                for e in self.builtin.iter().chain(&self.loaded_envs) {
                    if ui.selectable_label(e.name == current, &e.name).clicked() {
                        choice = Some(e.clone());
                    }
                }
            });
        if let Some(e) = choice {
            self.set_env(state, e.name, e.env);
        }
        #[cfg(not(target_arch = "wasm32"))]
        ui.horizontal(|ui| {
            ui.add(
                egui::TextEdit::singleline(&mut self.env_path_text)
                    .hint_text("EXR/HDR path")
                    .desired_width(150.0),
            );
            if ui.button("Load").clicked() {
                let path = PathBuf::from(self.env_path_text.trim());
                self.load_env_file(state, &path);
            }
        });
        ui.label("(or drop an EXR/HDR file on the window)");
        ui.add(egui::Slider::new(&mut self.rotation_deg, -180.0..=180.0).text("rotation °"));
        ui.horizontal(|ui| {
            ui.checkbox(&mut self.auto_rotate, "auto-rotate");
            ui.add(
                egui::DragValue::new(&mut self.auto_rotate_deg_per_s)
                    .speed(1.0)
                    .suffix(" °/s"),
            );
        });
        ui.add(egui::Slider::new(&mut self.exposure_ev, -8.0..=8.0).text("exposure EV"));
        egui::ComboBox::from_id_salt("tonemap")
            .selected_text(match self.tone_map {
                ToneMap::Aces => "ACES",
                ToneMap::Linear => "linear",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut self.tone_map, ToneMap::Aces, "ACES");
                ui.selectable_value(&mut self.tone_map, ToneMap::Linear, "linear");
            });
        ui.separator();

        ui.label("PCA");
        ui.add(egui::Slider::new(&mut self.rank, 0..=self.asset_rank).text("rank used"));
        egui::ComboBox::from_id_salt("view")
            .selected_text(match self.debug_view {
                DebugView::Shaded => "shaded",
                DebugView::Density => "density",
                DebugView::Alpha => "alpha",
                DebugView::Component => "one component",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut self.debug_view, DebugView::Shaded, "shaded");
                ui.selectable_value(&mut self.debug_view, DebugView::Density, "density");
                ui.selectable_value(&mut self.debug_view, DebugView::Alpha, "alpha");
                ui.selectable_value(&mut self.debug_view, DebugView::Component, "one component");
            });
        if self.debug_view == DebugView::Component {
            ui.add(
                egui::Slider::new(&mut self.component, 0..=self.asset_rank.saturating_sub(1))
                    .text("component"),
            );
        }
        ui.separator();

        ui.label("Rendering");
        ui.add(egui::Slider::new(&mut self.rendering.scale, 0.25..=1.0).text("resolution scale"));
        ui.checkbox(&mut self.rendering.jitter, "jitter samples");
        ui.checkbox(&mut self.rendering.continuous, "redraw continuously (frame time)");
        #[cfg(not(target_arch = "wasm32"))]
        if ui.button("Screenshot (F12)").clicked() {
            self.request_screenshot(ui.ctx(), None);
        }
        if !self.errors.is_empty() {
            ui.separator();
            for e in &self.errors {
                ui.colored_label(egui::Color32::from_rgb(255, 90, 90), e);
            }
            if ui.button("Clear errors").clicked() {
                self.errors.clear();
            }
        }
    }

    /// Tells the host what this frame showed.
    fn report_frame(&mut self) {
        let shown = self.gpu_ok && self.asset_name.is_some() && self.env.is_some() && self.orbit.is_some();
        if shown {
            self.frames_with_asset = self.frames_with_asset.saturating_add(1);
        }
        let Some(hook) = self.on_frame.as_mut() else {
            return;
        };
        let [width, height] = self.march_size;
        hook(&FrameReport {
            frames_with_asset: self.frames_with_asset,
            view_rect_px: self.view_rect_px,
            march_size: self.march_size,
            camera: self.orbit.filter(|_| shown).map(|o| o.camera(width, height)),
            frame_ms: self.frame_ms_smoothed,
            gpu: self.gpu_description.clone(),
            errors: self.errors.clone(),
        });
    }

    fn request_screenshot(&mut self, ctx: &egui::Context, path: Option<PathBuf>) {
        let sender = self.screenshots.sender.clone();
        let waker = ctx.clone();
        ctx.request_screenshot(move |image| {
            let _ = sender.send((path, image));
            // The screenshot arrives after the frame: wake the app to save it.
            waker.request_repaint();
        });
        ctx.request_repaint();
    }

    fn save_screenshots(&mut self, ctx: &egui::Context) {
        while let Ok((path, image)) = self.screenshots.receiver.try_recv() {
            let scripted = path.is_some();
            let path = path.unwrap_or_else(|| {
                self.screenshots.taken += 1;
                PathBuf::from(format!("nelf-screenshot-{:03}.png", self.screenshots.taken))
            });
            match save_color_image(&image, &path) {
                Ok(()) => eprintln!("nelf view: saved screenshot {}", path.display()),
                Err(e) => self
                    .errors
                    .push(format!("cannot save screenshot {}: {e}", path.display())),
            }
            if scripted && self.screenshots.exit_after {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }

    fn viewport(&mut self, ui: &mut egui::Ui) {
        let rect = ui.available_rect_before_wrap();
        let ppp = ui.ctx().pixels_per_point();
        self.view_rect_px = [
            rect.min.x * ppp,
            rect.min.y * ppp,
            rect.width() * ppp,
            rect.height() * ppp,
        ];
        // Drags only: a view that also sensed clicks would take a finger held still for
        // egui's press-and-hold time (0.8 s) as a context-menu click and drop the drag
        // that follows.
        let response = ui.allocate_rect(rect, egui::Sense::drag());
        let fingers_changed = ui.input(|i| self.fingers.update(&i.events));
        let Some(orbit) = self.orbit.as_mut() else {
            // Files the host is still fetching (the web page's asset) may be on their way.
            let text = if self.incoming.is_some() {
                "Loading…"
            } else {
                "No asset loaded. Drop a .nelf file on the window."
            };
            ui.centered_and_justified(|ui| {
                ui.label(text);
            });
            return;
        };
        let shift = ui.input(|i| i.modifiers.shift);
        // The frame a drag starts moves nothing: with drags sensed from the press on, that
        // frame's pointer delta runs from wherever the pointer was before. Nor does a frame
        // where a finger landed or lifted (`Fingers`).
        let delta = if response.drag_started() || fingers_changed {
            egui::Vec2::ZERO
        } else {
            response.drag_delta()
        };
        if self.fingers.count() >= 2 {
            // Two or more fingers over the view pan (their mean translation) and
            // pinch-zoom (egui's zoom delta, below); the first finger, which egui also
            // reports as a dragging pointer, does not orbit meanwhile.
            let touch = ui
                .input(egui::InputState::multi_touch)
                .filter(|_| response.hovered());
            if let Some(touch) = touch {
                let pan = touch.translation_delta;
                orbit.pan(f64::from(pan.x), f64::from(pan.y), f64::from(rect.width()));
            }
        } else if response.dragged_by(egui::PointerButton::Primary) && !shift {
            orbit.yaw_rad -= f64::from(delta.x) * 0.01;
            orbit.pitch_rad = (orbit.pitch_rad + f64::from(delta.y) * 0.01).clamp(-1.5, 1.5);
        } else if response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (response.dragged_by(egui::PointerButton::Primary) && shift)
        {
            orbit.pan(f64::from(delta.x), f64::from(delta.y), f64::from(rect.width()));
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            let zoom = ui.input(egui::InputState::zoom_delta);
            orbit.distance_m *= (-f64::from(scroll) * 0.002).exp() / f64::from(zoom.max(1e-3));
        }
        let width = ((rect.width() * ppp * self.rendering.scale).round() as u32).max(1);
        let height = ((rect.height() * ppp * self.rendering.scale).round() as u32).max(1);
        self.march_size = [width, height];
        let camera = orbit.camera(width, height);
        let view = match self.debug_view {
            DebugView::Shaded | DebugView::Component => MarchView::Shaded,
            DebugView::Density => MarchView::Density {
                sigma_white_per_m: self.max_density_per_m,
            },
            DebugView::Alpha => MarchView::Alpha,
        };
        // A new jitter pattern per camera, not per frame: there is no temporal
        // accumulation, so a held camera keeps one pattern (no flicker while the lighting
        // changes) and its relights can replay its pixels (gpu/replay.rs) or stay on the
        // voxels it reads (gpu/marks.rs).
        if self.jitter_camera != Some(camera) {
            self.jitter_camera = Some(camera);
            self.frame_index = self.frame_index.wrapping_add(1);
        }
        let callback = FrameCallback {
            camera,
            settings: ViewSettings {
                march: MarchSettings::default(),
                jitter: self.rendering.jitter,
                frame_index: self.frame_index,
                view,
                pass: self.march_pass,
            },
            display: DisplaySettings {
                exposure_ev: self.exposure_ev,
                tone_map: self.tone_map,
                background: self.background,
            },
        };
        ui.painter()
            .add(egui_wgpu::Callback::new_paint_callback(rect, callback));
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        let state = frame.wgpu_render_state().cloned();
        let state = state.as_ref();
        // Frame interval, smoothed; egui redraws only on input or animation, so an interval
        // after idling (over half a second) says nothing about the frame's cost.
        let dt = ctx.input(|i| i.unstable_dt);
        if dt < 0.5 {
            self.frame_ms_smoothed = if self.frame_ms_smoothed == 0.0 {
                dt * 1000.0
            } else {
                0.9 * self.frame_ms_smoothed + 0.1 * dt * 1000.0
            };
        }
        if self.rendering.continuous {
            ctx.request_repaint();
        }
        self.handle_new_files(&ctx, state);
        if self.auto_rotate {
            self.rotation_deg += self.auto_rotate_deg_per_s * dt.min(0.1);
            if self.rotation_deg > 180.0 {
                self.rotation_deg -= 360.0;
            } else if self.rotation_deg < -180.0 {
                self.rotation_deg += 360.0;
            }
            ctx.request_repaint();
        }
        if ctx.input(|i| i.key_pressed(egui::Key::F12)) {
            self.request_screenshot(&ctx, None);
        }
        if let Ok(mut slot) = self.frame_error.lock()
            && let Some(e) = slot.take()
            && self.errors.last() != Some(&e)
        {
            self.errors.push(e);
        }
        self.apply_lighting_changes(state);
        egui::Panel::left("controls")
            .resizable(false)
            .default_size(280.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui, state));
            });
        egui::CentralPanel::no_frame().show(ui, |ui| {
            if self.gpu_ok {
                self.viewport(ui);
            } else {
                ui.centered_and_justified(|ui| {
                    ui.colored_label(egui::Color32::from_rgb(255, 90, 90), "GPU renderer unavailable");
                });
            }
        });
        self.save_screenshots(&ctx);
        self.report_frame();
        self.screenshots.frames_shown = self.screenshots.frames_shown.saturating_add(1);
        if let Some(path) = self.screenshots.path.clone()
            && !self.screenshots.requested
        {
            ctx.request_repaint();
            if self.screenshots.frames_shown >= self.screenshots.after_frames {
                self.screenshots.requested = true;
                self.request_screenshot(&ctx, Some(path));
            }
        }
    }
}

/// The light of the capture beside `asset`: `<stem>.light.exr|hdr` next to it, or the
/// `envmap` of a capture folder (`cameras.json`) in the asset's folder.
pub fn capture_light_beside(asset: &Path) -> Option<PathBuf> {
    let dir = asset.parent()?;
    let stem = asset.file_stem()?.to_string_lossy().into_owned();
    for ext in ["exr", "hdr"] {
        let candidate = dir.join(format!("{stem}.light.{ext}"));
        if candidate.is_file() {
            return Some(candidate);
        }
    }
    let capture_dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    if capture_dir.join("cameras.json").is_file()
        && let Ok(capture) = nelf_format::capture::Capture::load(capture_dir)
    {
        return capture.envmap_path(capture_dir).filter(|p| p.is_file());
    }
    None
}

/// The last component of a path or URL (what the picker and the stats line show).
fn file_name_of(name: &str) -> &str {
    name.rsplit(['/', '\\']).next().unwrap_or(name)
}

/// Writes an egui screenshot as PNG.
fn save_color_image(image: &egui::ColorImage, path: &Path) -> Result<(), String> {
    let [w, h] = image.size;
    let bytes: Vec<u8> = image.pixels.iter().flat_map(egui::Color32::to_array).collect();
    let buffer =
        image::RgbaImage::from_raw(w as u32, h as u32, bytes).ok_or("screenshot has the wrong size")?;
    if let Some(parent) = path.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent).map_err(|e| e.to_string())?;
    }
    nelf_format::atomic::write_atomically(path, |w| {
        buffer
            .write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use nelf_format::capture::{Capture, CaptureView};

    use super::*;

    #[test]
    fn fingers_are_counted_from_touch_events() {
        let touch = |id: u64, phase: egui::TouchPhase| egui::Event::Touch {
            device_id: egui::TouchDeviceId(0),
            id: egui::TouchId(id),
            phase,
            pos: egui::Pos2::ZERO,
            force: None,
        };
        let mut fingers = Fingers::default();
        assert!(!fingers.update(&[]));
        assert!(fingers.update(&[touch(7, egui::TouchPhase::Start)]));
        assert_eq!(fingers.count(), 1);
        assert!(!fingers.update(&[touch(7, egui::TouchPhase::Move)]));
        assert!(fingers.update(&[
            touch(8, egui::TouchPhase::Start),
            touch(7, egui::TouchPhase::Move)
        ]));
        assert_eq!(fingers.count(), 2);
        assert!(fingers.update(&[touch(7, egui::TouchPhase::Cancel)]));
        assert_eq!(fingers.count(), 1);
        // An end for a finger never seen (it landed outside the view) changes nothing.
        assert!(!fingers.update(&[touch(3, egui::TouchPhase::End)]));
        assert!(fingers.update(&[touch(8, egui::TouchPhase::End)]));
        assert_eq!(fingers.count(), 0);
    }

    #[test]
    fn capture_light_is_found_beside_the_asset() {
        let dir = tempfile::tempdir().unwrap();
        let asset = dir.path().join("head.nelf");
        assert_eq!(capture_light_beside(&asset), None);
        // A capture folder holding the asset: the lighting its cameras.json names.
        let camera = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO, DVec3::Y, 8, 8, 0.5);
        let mut capture = Capture::new(vec![CaptureView {
            name: "v0".into(),
            image: "images/v0.exr".into(),
            mask: None,
            camera,
        }]);
        capture.envmap = Some("lighting/studio.exr".into());
        for file in ["images/v0.exr", "lighting/studio.exr"] {
            let path = dir.path().join(file);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, b"").unwrap();
        }
        capture.save(dir.path()).unwrap();
        assert_eq!(
            capture_light_beside(&asset),
            Some(dir.path().join("lighting/studio.exr"))
        );
        // An estimated light named after the asset (`nelf light … -o head.light.exr`) wins.
        std::fs::write(dir.path().join("head.light.exr"), b"").unwrap();
        assert_eq!(
            capture_light_beside(&asset),
            Some(dir.path().join("head.light.exr"))
        );
    }

    #[test]
    fn stats_line_says_how_the_lighting_was_last_applied() {
        assert_eq!(relight_stats(None, 0), None);
        assert_eq!(
            relight_stats(Some(RelightKind::Full), 0).as_deref(),
            Some("last relight: every voxel")
        );
        assert_eq!(
            relight_stats(Some(RelightKind::Marked), 0).as_deref(),
            Some("last relight: the voxels this view reads")
        );
        assert_eq!(
            relight_stats(Some(RelightKind::Replay), 3 << 20).as_deref(),
            Some("last relight: pixels replayed (cache 3.0 MiB)")
        );
    }

    #[test]
    fn stats_line_says_whether_the_asset_is_view_dependent() {
        assert_eq!(
            asset_stats(12, &AssetParts::default()),
            "K = 12; view-independent"
        );
        let view = ViewInfo {
            lobes: 3,
            rank: 8,
            encoding: nelf_format::CoefficientEncoding::U8Affine,
        };
        let parts = AssetParts {
            view: Some(view),
            ..AssetParts::default()
        };
        assert_eq!(
            asset_stats(12, &parts),
            "K = 12; view-dependent: J = 3 lobes, K_v = 8 (U8Affine)"
        );
        let parts = AssetParts {
            reflection: Some(ReflectionInfo {
                exponent: 20.0,
                eyes: 5,
            }),
            ..AssetParts::default()
        };
        assert_eq!(
            asset_stats(12, &parts),
            "K = 12; reflection lobe: exponent 20, averaged over 5 eyes"
        );
        // WebGL2 shows the view-averaged asset and says so.
        let parts = AssetParts {
            ignored: Some("reflection part (format 1.3)"),
            ..AssetParts::default()
        };
        let line = asset_stats(12, &parts);
        assert!(
            line.starts_with("K = 12; view-independent\nnot shown: its reflection part"),
            "{line}"
        );
    }

    #[test]
    fn orbit_frames_the_box_and_pans_in_the_image_plane() {
        let mut orbit = Orbit::framing([-0.1, -0.2, -0.1], [0.1, 0.2, 0.1]);
        let camera = orbit.camera(64, 64);
        camera.validate().unwrap();
        // Every corner of the box projects inside the image.
        for corner in 0..8 {
            let p = DVec3::new(
                if corner & 1 == 0 { -0.1 } else { 0.1 },
                if corner & 2 == 0 { -0.2 } else { 0.2 },
                if corner & 4 == 0 { -0.1 } else { 0.1 },
            );
            let px = camera.project(p).unwrap();
            assert!(
                (0.0..64.0).contains(&px.x) && (0.0..64.0).contains(&px.y),
                "{px:?}"
            );
        }
        // The camera starts in front (+z) and a pan right moves the target left in the world.
        assert!(camera.centre().z > 0.0);
        orbit.pan(10.0, 0.0, 64.0);
        assert!(orbit.target.x < 0.0);
    }
}
