//! The per-frame report to the host ([`FrameReport`] through
//! [`ViewerConfig::on_frame`]): frames drawn with an asset, the 3D view's rectangle and
//! camera, the frame interval, the GPU and the errors shown. The web page writes it into
//! the DOM for its tests and timings.
//!
//! [`ViewerConfig::on_frame`]: super::config::ViewerConfig::on_frame

use super::config::FrameReport;
use super::state::ViewerApp;

impl ViewerApp {
    /// Tells the host what this frame showed.
    pub(super) fn report_frame(&mut self) {
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
}
