//! The viewer's egui panels: the controls on the left ([`ViewerApp::controls_ui`]:
//! asset and GPU stats, lighting, exposure and tone curve, PCA rank and debug views,
//! rendering options, errors) and the 3D view in the centre
//! ([`ViewerApp::viewport_ui`]: camera input, then the frame's paint callback).

use std::path::PathBuf;

use eframe::{egui, egui_wgpu};
use nelf_render::MarchSettings;

use super::config::NamedEnvmap;
use super::files::file_name_of;
use super::paint_callback::{FrameCallback, with_gpu};
use super::state::{AssetParts, DebugView, ViewerApp};
use crate::gpu::{DisplaySettings, MarchView, RelightKind, ToneMap, ViewSettings};

impl ViewerApp {
    /// The controls panel.
    pub(super) fn controls_ui(&mut self, ui: &mut egui::Ui, state: Option<&egui_wgpu::RenderState>) {
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
        let relight = with_gpu(state, |gpu| {
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
            self.screenshots.request(ui.ctx(), None);
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

    /// The 3D view: moves the camera by the frame's input and adds the frame's paint
    /// callback (or says that no asset is shown).
    pub(super) fn viewport_ui(&mut self, ui: &mut egui::Ui) {
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
        orbit.steer(ui, &response, rect, &self.fingers, fingers_changed);
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

/// The stats line of an asset: its PCA rank, whether it is view-dependent (format
/// 1.2: `J` lobes over a view basis of rank `K_v`) and whether it has a fine density
/// (format 1.4).
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
    let shown = match (parts.fine_density, parts.fine_density_ignored) {
        (Some(f), _) => format!("{shown}; fine density ({f}× finer)"),
        (None, Some(f)) => format!(
            "{shown}\nnot shown: its fine density ({f}× finer), whose atlas exceeds this \
             device's 3D textures; this is the voxels' density"
        ),
        (None, None) => shown,
    };
    match parts.ignored {
        Some(part) => format!(
            "{shown}\nnot shown: its {part}, which needs compute shaders \
             (WebGPU or the native viewer); this is the view-averaged asset"
        ),
        None => shown,
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::{ReflectionInfo, ViewInfo};

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
        // A fine density (format 1.4), shown or left out.
        let parts = AssetParts {
            fine_density: Some(4),
            ..AssetParts::default()
        };
        assert_eq!(
            asset_stats(12, &parts),
            "K = 12; view-independent; fine density (4× finer)"
        );
        let parts = AssetParts {
            fine_density_ignored: Some(2),
            ..AssetParts::default()
        };
        let line = asset_stats(12, &parts);
        assert!(
            line.starts_with("K = 12; view-independent\nnot shown: its fine density (2× finer)"),
            "{line}"
        );
    }
}
