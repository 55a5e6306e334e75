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
//!
//! **Layout.** `config.rs` holds what the host gives and gets back (re-exported here);
//! `state.rs` the app's state and its start; each frame
//! ([`eframe::App::ui`] below) reads new files (`files.rs`), applies lighting changes
//! (`lighting.rs`: also the lighting policy at start), draws the panels (`panels.rs`,
//! with the camera input of `camera_input.rs` and the paint callback of
//! `paint_callback.rs`), saves screenshots (`screenshot.rs`) and reports to the host
//! (`report.rs`).

mod camera_input;
mod config;
mod files;
mod lighting;
mod paint_callback;
mod panels;
mod report;
mod screenshot;
mod state;

use eframe::egui;

pub use self::config::{
    FrameHook, FrameReport, IncomingFile, NamedEnvmap, OrbitStart, StartView, ViewerConfig,
};
pub use self::lighting::capture_light_beside;
use self::state::ViewerApp;

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
            self.screenshots.request(&ctx, None);
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
                egui::ScrollArea::vertical().show(ui, |ui| self.controls_ui(ui, state));
            });
        egui::CentralPanel::no_frame().show(ui, |ui| {
            if self.gpu_ok {
                self.viewport_ui(ui);
            } else {
                ui.centered_and_justified(|ui| {
                    ui.colored_label(egui::Color32::from_rgb(255, 90, 90), "GPU renderer unavailable");
                });
            }
        });
        self.screenshots.save_arrived(&ctx, &mut self.errors);
        self.report_frame();
        self.screenshots.frame_shown(&ctx);
    }
}
