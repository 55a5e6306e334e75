//! Judging a baked asset against ground truth: render it with the reference
//! renderer (`nelf-render`) at a view and lighting for which a ground-truth image
//! exists, and score the pair.
//!
//! Both images are linear radiance composited over black (a capture's images are
//! already multiplied by their mask; the renderer's output is premultiplied). PSNR
//! and SSIM (`nelf_scene::metrics`, scikit-image's definitions) use a data range
//! equal to the reference image's largest value, so scores do not depend on the
//! lighting's overall intensity.

use std::path::Path;

use glam::DMat3;
use nelf_format::Asset;
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_render::{Image, MarchSettings, render_asset};
use nelf_scene::metrics::{psnr, ssim};
use serde::Serialize;

use crate::error::{BakeError, Result};

/// Scores of one rendered view against its reference.
#[derive(Debug, Clone, Serialize)]
pub struct ViewScore {
    /// View name.
    pub name: String,
    /// PSNR in dB (data range: the reference's largest value).
    pub psnr_db: f64,
    /// SSIM (same data range).
    pub ssim: f64,
    /// Seconds the reference renderer took.
    pub render_secs: f64,
}

/// The largest value of an image (at least 1e-6), its data range for metrics.
pub fn data_range(image: &[[f32; 3]]) -> f32 {
    image.iter().flatten().fold(0.0f32, |m, &v| m.max(v)).max(1e-6)
}

/// Renders `asset` at `camera` under `env` (world frame, as stored) and scores it
/// against `reference`. Returns the score and the render.
pub fn score_view(
    asset: &Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    reference: &[[f32; 3]],
    name: &str,
) -> Result<(ViewScore, Image)> {
    let start = std::time::Instant::now();
    let image = render_asset(
        asset,
        camera,
        env,
        DMat3::IDENTITY,
        None,
        &MarchSettings::default(),
    )?;
    let render_secs = start.elapsed().as_secs_f64();
    let range = f64::from(data_range(reference));
    let score = ViewScore {
        name: name.to_string(),
        psnr_db: psnr(&image.rgb, reference, range)?,
        ssim: ssim(&image.rgb, reference, camera.width, camera.height, range)?,
        render_secs,
    };
    Ok((score, image))
}

/// Reads a linear RGB image (EXR as stored; 8-bit formats as their values / 255).
pub fn read_linear_rgb(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    let img = image::open(path)
        .map_err(|source| BakeError::Image {
            path: path.to_path_buf(),
            source,
        })?
        .to_rgb32f();
    Ok((img.width(), img.height(), img.pixels().map(|p| p.0).collect()))
}
