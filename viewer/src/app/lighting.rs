//! The viewer's lighting policy. **At start**: `--envmap FILE` if given; else the
//! capture's light beside the asset ([`capture_light_beside`]); else the first built-in
//! map; else a uniform white sky. **Afterwards**: a map chosen, loaded or dropped becomes
//! the lighting at the current rotation, and rotation, PCA rank and relight-view changes
//! reach the renderer once each, as they happen.

use std::path::{Path, PathBuf};

use eframe::egui_wgpu;
use nelf_format::conventions::{LatLong, rotation_y};

use super::config::NamedEnvmap;
use super::paint_callback::with_gpu;
use super::state::{AppliedLighting, CurrentEnv, DebugView, ViewerApp};
use crate::atlas::RelightView;

impl ViewerApp {
    /// Sets the lighting at start: the map in `envmap_path` if given, else the capture's
    /// light beside `asset_path` (the asset shown), else the first built-in map, else a
    /// uniform white sky.
    pub(super) fn start_lighting(
        &mut self,
        state: Option<&egui_wgpu::RenderState>,
        envmap_path: Option<&Path>,
        asset_path: Option<&Path>,
    ) {
        let start_env = envmap_path
            .map(Path::to_path_buf)
            .or_else(|| asset_path.and_then(capture_light_beside));
        let mut have_env = false;
        if let Some(path) = start_env {
            have_env = self.load_env_file(state, &path);
        }
        if !have_env {
            let first = self.builtin.first().cloned().unwrap_or_else(|| NamedEnvmap {
                name: "uniform white".into(),
                env: LatLong::constant(16, 8, [1.0; 3]),
            });
            self.set_env(state, first.name, first.env);
        }
    }

    /// Makes `env` the lighting (projected at the current rotation); true on success.
    pub(super) fn set_env(
        &mut self,
        state: Option<&egui_wgpu::RenderState>,
        name: String,
        env: LatLong,
    ) -> bool {
        let rotation = rotation_y(f64::from(self.rotation_deg).to_radians());
        let has_asset = self.asset_name.is_some();
        let result = if has_asset {
            with_gpu(state, |gpu| gpu.renderer.set_lighting(&env, rotation))
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
    pub(super) fn apply_lighting_changes(&mut self, state: Option<&egui_wgpu::RenderState>) {
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
        let result = with_gpu(state, |gpu| {
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

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use nelf_format::capture::{Capture, CaptureView};
    use nelf_format::conventions::PinholeCamera;

    use super::*;

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
}
