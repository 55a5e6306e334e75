//! Files reaching the viewer: read from paths (the asset and map given at start, the
//! path field), dropped on the window (natively as paths, in a browser as bytes read
//! asynchronously, arriving on a later frame) or sent by the host
//! ([`ViewerConfig::incoming`]: the web page's fetches). A `.nelf` replaces the asset, an
//! EXR/HDR becomes the lighting; a file that cannot be read or shown keeps what was
//! shown and says why in the window.
//!
//! [`ViewerConfig::incoming`]: super::config::ViewerConfig::incoming

use std::path::Path;
use std::sync::mpsc::TryRecvError;

use eframe::{egui, egui_wgpu};
use nelf_format::envmap_file::{EnvmapKind, decode_envmap};

use super::camera_input::Orbit;
use super::config::{IncomingFile, NamedEnvmap};
use super::paint_callback::with_gpu;
use super::state::{AppliedLighting, AssetParts, ViewerApp};

impl ViewerApp {
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
    pub(super) fn load_asset_file(&mut self, state: Option<&egui_wgpu::RenderState>, path: &Path) -> bool {
        self.read_file(path)
            .is_some_and(|bytes| self.load_asset(state, &path.display().to_string(), &bytes))
    }

    /// Reads and uploads an asset from its file's bytes; on any failure keeps the
    /// previous one and shows why. True on success.
    pub(super) fn load_asset(
        &mut self,
        state: Option<&egui_wgpu::RenderState>,
        name: &str,
        bytes: &[u8],
    ) -> bool {
        let asset = match nelf_format::read_asset_bytes(bytes) {
            Ok(a) => a,
            Err(e) => {
                self.errors.push(format!("cannot load {name}: {e}"));
                return false;
            }
        };
        let result = with_gpu(state, |gpu| gpu.renderer.load_asset(&asset));
        match result {
            Some(Ok(info)) => {
                self.asset_name = Some(name.to_owned());
                self.asset_rank = info.rank;
                self.asset_parts = AssetParts {
                    view: info.view,
                    reflection: info.reflection,
                    ignored: info.view_part_ignored,
                    fine_density: info.fine_density,
                    fine_density_ignored: info.fine_density_ignored,
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
    pub(super) fn load_env_file(&mut self, state: Option<&egui_wgpu::RenderState>, path: &Path) -> bool {
        self.read_file(path)
            .is_some_and(|bytes| self.load_env(state, &path.display().to_string(), &bytes))
    }

    /// Decodes an EXR/HDR map (`name`'s extension says which) and makes it the
    /// lighting; true on success.
    pub(super) fn load_env(
        &mut self,
        state: Option<&egui_wgpu::RenderState>,
        name: &str,
        bytes: &[u8],
    ) -> bool {
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

    /// Files dropped on the window (natively paths, in a browser bytes) and files the
    /// host sent ([`ViewerConfig::incoming`](super::config::ViewerConfig::incoming)).
    pub(super) fn handle_new_files(&mut self, ctx: &egui::Context, state: Option<&egui_wgpu::RenderState>) {
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
}

/// The last component of a path or URL (what the picker and the stats line show).
pub(super) fn file_name_of(name: &str) -> &str {
    name.rsplit(['/', '\\']).next().unwrap_or(name)
}
