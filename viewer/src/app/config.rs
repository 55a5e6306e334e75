//! What the host gives the viewer and gets back: the start configuration
//! ([`ViewerConfig`], [`StartView`], [`OrbitStart`]), built-in maps ([`NamedEnvmap`]),
//! files arriving after start ([`IncomingFile`]) and the per-frame report
//! ([`FrameReport`], [`FrameHook`]).

use std::path::PathBuf;
use std::sync::mpsc::Receiver;

use nelf_format::conventions::{LatLong, PinholeCamera};

use crate::gpu::{DisplaySettings, ToneMap};

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
