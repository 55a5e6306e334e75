//! Screenshots of the window: the scripted one (`--screenshot`, after a number of
//! frames, optionally closing the window) and the numbered ones the F12 key and the
//! button ask for; egui hands the image over after the frame, and it is saved as PNG.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};

use eframe::egui;

/// A screenshot on its way: the path to save it to (`None`: a numbered file) and the image.
type ScreenshotMessage = (Option<PathBuf>, Arc<egui::ColorImage>);

/// Screenshot requests: the scripted one (`--screenshot`) and the key/button ones.
pub(super) struct Screenshots {
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

impl Screenshots {
    /// No screenshot taken yet; the scripted one goes to `path` (if any) after
    /// `after_frames` frames and closes the window if `exit_after`.
    pub(super) fn new(path: Option<PathBuf>, after_frames: u32, exit_after: bool) -> Self {
        let (sender, receiver) = channel();
        Self {
            path,
            after_frames,
            exit_after,
            requested: false,
            taken: 0,
            frames_shown: 0,
            sender,
            receiver,
        }
    }

    /// Asks egui for a screenshot of the next frame, saved to `path` (`None`: a numbered
    /// file).
    pub(super) fn request(&self, ctx: &egui::Context, path: Option<PathBuf>) {
        let sender = self.sender.clone();
        let waker = ctx.clone();
        ctx.request_screenshot(move |image| {
            let _ = sender.send((path, image));
            // The screenshot arrives after the frame: wake the app to save it.
            waker.request_repaint();
        });
        ctx.request_repaint();
    }

    /// Saves the screenshots that arrived, adding failures to `errors`; closes the window
    /// after the scripted one if asked to.
    pub(super) fn save_arrived(&mut self, ctx: &egui::Context, errors: &mut Vec<String>) {
        while let Ok((path, image)) = self.receiver.try_recv() {
            let scripted = path.is_some();
            let path = path.unwrap_or_else(|| {
                self.taken += 1;
                PathBuf::from(format!("nelf-screenshot-{:03}.png", self.taken))
            });
            match save_color_image(&image, &path) {
                Ok(()) => eprintln!("nelf view: saved screenshot {}", path.display()),
                Err(e) => errors.push(format!("cannot save screenshot {}: {e}", path.display())),
            }
            if scripted && self.exit_after {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }

    /// Counts a frame shown; requests the scripted screenshot once enough frames were
    /// shown (redrawing until then).
    pub(super) fn frame_shown(&mut self, ctx: &egui::Context) {
        self.frames_shown = self.frames_shown.saturating_add(1);
        if let Some(path) = self.path.clone()
            && !self.requested
        {
            ctx.request_repaint();
            if self.frames_shown >= self.after_frames {
                self.requested = true;
                self.request(ctx, Some(path));
            }
        }
    }
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
