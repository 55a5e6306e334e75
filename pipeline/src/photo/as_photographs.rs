//! A capture written as a camera and the usual tools give one: 8-bit sRGB JPEG
//! photographs under one fixed exposure, 8-bit PNG masks and a COLMAP text model
//! (`PINHOLE` cameras, `format/CAPTURE.md`), with no lighting named. Tests and
//! benchmarks make such captures from synthetic ones (path-traced scans) to run the
//! photographs path on what a user has, not on our own linear EXR.

use std::path::Path;

use nelf_bake::LoadedCapture;
use nelf_format::io_error::FileIoError;
use nelf_scene::image_io::{write_jpeg_srgb, write_png_gray};

use crate::error::{PipelineError, Result, invalid};

/// What [`write_as_photographs`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotographedCapture {
    /// The one exposure gain applied to every view's linear radiance before
    /// encoding (the 99th percentile of the foreground's brightest channel goes to
    /// 0.9, as a camera's fixed exposure would put it).
    pub exposure_gain: f32,
}

/// Writes `capture`'s views into `dir` as `images/<name>.jpg` (quality
/// `jpeg_quality`), `masks/<name>.png` and `cameras.txt` / `images.txt` /
/// `points3D.txt` (metres: one model unit is one metre).
pub fn write_as_photographs(
    capture: &LoadedCapture,
    dir: &Path,
    jpeg_quality: u8,
) -> Result<PhotographedCapture> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |e: std::io::Error| FileIoError::new(path, e)
    };
    for sub in ["images", "masks"] {
        let path = dir.join(sub);
        std::fs::create_dir_all(&path).map_err(io(&path))?;
    }
    let mut brightest: Vec<f32> = capture
        .images
        .iter()
        .zip(&capture.masks)
        .flat_map(|(image, mask)| {
            image
                .iter()
                .zip(mask)
                .filter(|(_, m)| **m > 0.5)
                .map(|(p, _)| p[0].max(p[1]).max(p[2]))
        })
        .collect();
    if brightest.is_empty() {
        return Err(invalid("the capture has no foreground to expose for".to_string()));
    }
    let k = (brightest.len() * 99 / 100).min(brightest.len() - 1);
    let (_, p99, _) = brightest.select_nth_unstable_by(k, f32::total_cmp);
    let exposure_gain = if *p99 > 0.0 { 0.9 / *p99 } else { 1.0 };
    let mut views = Vec::with_capacity(capture.len());
    for (v, camera) in capture.cameras.iter().enumerate() {
        let name = format!("{}.jpg", capture.names[v]);
        let (w, h) = (camera.width, camera.height);
        let exposed: Vec<[f32; 3]> = capture.images[v]
            .iter()
            .map(|p| p.map(|c| c * exposure_gain))
            .collect();
        write_jpeg_srgb(dir.join("images").join(&name), w, h, &exposed, jpeg_quality)?;
        let mask = dir.join("masks").join(format!("{}.png", capture.names[v]));
        write_png_gray(mask, w, h, &capture.masks[v])?;
        views.push((name, *camera));
    }
    nelf_format::colmap::write_colmap_text(dir, &views).map_err(|e| PipelineError::Invalid(e.to_string()))?;
    Ok(PhotographedCapture { exposure_gain })
}
