//! Scoring one asset: renders it at held-aside views under held-aside lightings with
//! the CPU reference renderer ([`EVAL_PIXEL_GRID`]² rays per pixel, as the
//! antialiased ground truth) and compares with the truth images:
//!
//! * PSNR and SSIM, data range = each reference's largest value (scikit-image's
//!   definitions, `nelf_scene::metrics`), whole image and foreground only (the
//!   truth's mask as per-pixel weights);
//! * ꟻLIP (`nelf_scene::flip`, NVIDIA's implementation) on 8-bit sRGB at an
//!   exposure that puts the reference's largest value at 0.5, mean over the image
//!   and mask-weighted mean;
//! * the **trivial baseline** on the same views: the mean foreground colour of the
//!   truth, flat inside the true silhouette (weighted by the mask), black outside.
//!
//! Speed: the CPU reference renderer's time for one ray per pixel, and GPU frame
//! times (`nelf_viewer::GpuRenderer`, relit once, then marched; the minimum of a few
//! frames after two warm-ups).

use std::path::Path;
use std::time::Instant;

use glam::{DMat3, DVec3};
use nelf_bake::eval::{EVAL_PIXEL_GRID, HeldAside, data_range};
use nelf_format::Asset;
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_render::{Image, MarchSettings, render_asset};
use nelf_scene::flip::{DEFAULT_PIXELS_PER_DEGREE, flip_map, pooled_mean};
use nelf_scene::metrics::{psnr, psnr_masked, ssim, ssim_masked};

use crate::error::{EvalError, Result};
use crate::rows::Scores;

/// Scores of one view, and the images behind them.
#[derive(Debug, Clone)]
pub struct ViewResult {
    /// View name.
    pub name: String,
    /// The view's scores (`views` = 1).
    pub scores: Scores,
    /// The render (premultiplied linear RGB over black).
    pub render: Image,
    /// The ꟻLIP map (per pixel, in [0, 1]).
    pub flip_map: Vec<f32>,
}

/// Exposure (stops) that puts `image`'s largest value at 0.5: the tone of every
/// 8-bit figure and picture `nelf eval` makes.
pub fn exposure_stops(image: &[[f32; 3]]) -> f32 {
    (0.5 / data_range(image)).log2()
}

fn scaled(rgb: &[[f32; 3]], gain: f32) -> Vec<[f32; 3]> {
    rgb.iter().map(|p| p.map(|v| v * gain)).collect()
}

/// The trivial baseline of a truth image: its mask-weighted mean colour inside the
/// silhouette (`mask · mean`), black outside.
pub fn flat_baseline(truth: &[[f32; 3]], mask: &[f32]) -> Vec<[f32; 3]> {
    let total: f64 = mask.iter().map(|&m| f64::from(m)).sum();
    let mut mean = [0.0f64; 3];
    if total > 0.0 {
        // Truth is premultiplied (p = m · colour), so Σ p / Σ m is the
        // mask-weighted mean colour.
        for p in truth {
            for c in 0..3 {
                mean[c] += f64::from(p[c]);
            }
        }
        for v in &mut mean {
            *v /= total;
        }
    }
    let mean = mean.map(|v| v as f32);
    mask.iter().map(|&m| mean.map(|v| v * m)).collect()
}

/// Scores `render` against `truth` (with its `mask`), for a `width × height` view.
pub fn score_images(
    render: &[[f32; 3]],
    truth: &[[f32; 3]],
    mask: &[f32],
    width: u32,
    height: u32,
) -> Result<(Scores, Vec<f32>)> {
    let range = f64::from(data_range(truth));
    let has_fg = mask.iter().any(|&m| m > 0.0);
    let baseline = flat_baseline(truth, mask);
    let gain = exposure_stops(truth).exp2();
    let flip = flip_map(
        &scaled(truth, gain),
        &scaled(render, gain),
        width,
        height,
        DEFAULT_PIXELS_PER_DEGREE,
    )?;
    let fg = |value: Result<f64>| -> Result<f64> { if has_fg { value } else { Ok(f64::NAN) } };
    let scores = Scores {
        psnr_db: psnr(render, truth, range)?,
        psnr_fg_db: fg(psnr_masked(render, truth, mask, range).map_err(EvalError::from))?,
        ssim: ssim(render, truth, width, height, range)?,
        ssim_fg: fg(ssim_masked(render, truth, mask, width, height, range).map_err(EvalError::from))?,
        flip: pooled_mean(&flip, None)?.unwrap_or(f64::NAN),
        flip_fg: if has_fg {
            pooled_mean(&flip, Some(mask))?.unwrap_or(f64::NAN)
        } else {
            f64::NAN
        },
        baseline_psnr_db: psnr(&baseline, truth, range)?,
        baseline_psnr_fg_db: fg(psnr_masked(&baseline, truth, mask, range).map_err(EvalError::from))?,
        views: 1,
    };
    Ok((scores, flip))
}

/// Renders `asset` at one view under `env` (world frame) and scores it.
pub fn score_view(
    asset: &Asset,
    name: &str,
    camera: &PinholeCamera,
    env: &LatLong,
    truth: &[[f32; 3]],
    mask: &[f32],
    step_voxels: f32,
) -> Result<ViewResult> {
    let settings = MarchSettings {
        step_voxels,
        pixel_grid: EVAL_PIXEL_GRID,
        ..MarchSettings::default()
    };
    let render = render_asset(asset, camera, env, DMat3::IDENTITY, None, &settings)?;
    let (scores, flip_map) = score_images(&render.rgb, truth, mask, camera.width, camera.height)?;
    Ok(ViewResult {
        name: name.to_string(),
        scores,
        render,
        flip_map,
    })
}

/// Means of per-view scores (NaN figures, such as foreground scores of a view with
/// no foreground, are left out of their mean).
pub fn mean_scores(views: &[Scores]) -> Scores {
    let mean = |f: fn(&Scores) -> f64| {
        let values: Vec<f64> = views.iter().map(f).filter(|v| !v.is_nan()).collect();
        if values.is_empty() {
            f64::NAN
        } else {
            values.iter().sum::<f64>() / values.len() as f64
        }
    };
    Scores {
        psnr_db: mean(|s| s.psnr_db),
        psnr_fg_db: mean(|s| s.psnr_fg_db),
        ssim: mean(|s| s.ssim),
        ssim_fg: mean(|s| s.ssim_fg),
        flip: mean(|s| s.flip),
        flip_fg: mean(|s| s.flip_fg),
        baseline_psnr_db: mean(|s| s.baseline_psnr_db),
        baseline_psnr_fg_db: mean(|s| s.baseline_psnr_fg_db),
        views: views.len(),
    }
}

/// Scores `asset` at every held-aside view; returns the mean and each view's result.
pub fn score_held_aside(
    asset: &Asset,
    held: &HeldAside,
    step_voxels: f32,
) -> Result<(Scores, Vec<ViewResult>)> {
    if held.is_empty() {
        return Err(EvalError::Input("no held-aside views to score at".into()));
    }
    let mut views = Vec::with_capacity(held.len());
    for i in 0..held.len() {
        views.push(score_view(
            asset,
            &held.names[i],
            &held.cameras[i],
            &held.envs[i],
            &held.images[i],
            &held.masks[i],
            step_voxels,
        )?);
    }
    let mean = mean_scores(&views.iter().map(|v| v.scores).collect::<Vec<_>>());
    Ok((mean, views))
}

/// Milliseconds the CPU reference renderer takes for one ray per pixel at `camera`.
pub fn cpu_render_ms(asset: &Asset, camera: &PinholeCamera, env: &LatLong, step_voxels: f32) -> Result<f64> {
    let settings = MarchSettings {
        step_voxels,
        ..MarchSettings::default()
    };
    let start = Instant::now();
    render_asset(asset, camera, env, DMat3::IDENTITY, None, &settings)?;
    Ok(start.elapsed().as_secs_f64() * 1e3)
}

/// A GPU to time frames on (`None` when no adapter is available: the figures are
/// then left out, not faked).
#[derive(Debug)]
pub struct GpuTimer {
    renderer: nelf_viewer::GpuRenderer,
    adapter: String,
}

impl GpuTimer {
    /// The headless GPU renderer, or `None` with the reason.
    pub fn new() -> std::result::Result<Self, String> {
        let renderer = nelf_viewer::GpuRenderer::new_headless().map_err(|e| e.to_string())?;
        let adapter = renderer.adapter_info().map_or_else(
            || "unknown adapter".to_string(),
            |a| format!("{} ({:?})", a.name, a.backend),
        );
        Ok(Self { renderer, adapter })
    }

    /// The adapter's name and backend.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// Frame milliseconds (minimum over `frames` after two warm-ups; lighting
    /// projected and relit once) of `asset` at `width × height`, seen from the front
    /// at a distance where its bounding sphere fills the view.
    pub fn frame_ms(
        &mut self,
        asset: &Asset,
        env: &LatLong,
        width: u32,
        height: u32,
        frames: usize,
    ) -> Result<f64> {
        self.renderer.load_asset(asset)?;
        self.renderer.set_lighting(env, DMat3::IDENTITY)?;
        self.renderer.set_rank(None);
        let lo = DVec3::from_array(asset.grid.bbox_min_m);
        let hi = DVec3::from_array(asset.grid.bbox_max_m());
        let camera = nelf_scene::shot::orbit_camera(0.0, 0.0, None, width, height, 30.0, (lo, hi))?;
        let settings = nelf_viewer::ViewSettings {
            march: MarchSettings::default(),
            jitter: false,
            frame_index: 0,
            view: nelf_viewer::MarchView::Shaded,
            pass: self.renderer.preferred_march_pass(),
        };
        for _ in 0..2 {
            self.renderer.frame_blocking(&camera, &settings)?;
        }
        let mut best = f64::INFINITY;
        for _ in 0..frames.max(1) {
            let start = Instant::now();
            self.renderer.frame_blocking(&camera, &settings)?;
            best = best.min(start.elapsed().as_secs_f64() * 1e3);
        }
        Ok(best)
    }
}

/// Writes `truth | ours | ꟻLIP map` side by side as an sRGB PNG (the two images at
/// the truth's exposure; the ꟻLIP map in grey, white = 1).
pub fn write_gallery_png(path: &Path, truth: &[[f32; 3]], view: &ViewResult) -> Result<()> {
    let (w, h) = (view.render.width as usize, view.render.height as usize);
    let gain = exposure_stops(truth).exp2();
    let mut strip = vec![[0.0f32; 3]; 3 * w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            strip[y * 3 * w + x] = truth[i].map(|v| v * gain);
            strip[y * 3 * w + w + x] = view.render.rgb[i].map(|v| v * gain);
            // The map is shown as its value in sRGB, i.e. linear value^2.2.
            let f = view.flip_map[i].clamp(0.0, 1.0).powf(2.2);
            strip[y * 3 * w + 2 * w + x] = [f; 3];
        }
    }
    nelf_scene::image_io::write_png_srgb(path, (3 * w) as u32, h as u32, &strip, 0.0).map_err(|e| {
        EvalError::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    })
}

/// Longest side of a report thumbnail, pixels.
pub const THUMBNAIL_SIDE: u32 = 128;

/// Writes `ours` alone as an sRGB PNG at the truth's exposure, box-filtered to at
/// most [`THUMBNAIL_SIDE`] pixels a side (report thumbnails).
pub fn write_thumbnail_png(path: &Path, truth: &[[f32; 3]], view: &ViewResult) -> Result<()> {
    let (w, h) = (view.render.width, view.render.height);
    let factor = w.max(h).div_ceil(THUMBNAIL_SIDE).max(1);
    let small = nelf_bake::rank::box_downsample(&view.render.rgb, w, h, factor);
    nelf_scene::image_io::write_png_srgb(
        path,
        (w / factor).max(1),
        (h / factor).max(1),
        &small,
        exposure_stops(truth),
    )
    .map_err(|e| EvalError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_perfect_render_beats_the_flat_baseline() -> std::result::Result<(), Box<dyn std::error::Error>> {
        let (w, h) = (32u32, 32u32);
        let mut truth = vec![[0.0f32; 3]; (w * h) as usize];
        let mut mask = vec![0.0f32; (w * h) as usize];
        for y in 8..24 {
            for x in 8..24 {
                let i = (y * w + x) as usize;
                mask[i] = 1.0;
                truth[i] = [x as f32 / 32.0, y as f32 / 32.0, 0.5];
            }
        }
        let (same, _) = score_images(&truth, &truth, &mask, w, h)?;
        assert!(same.psnr_db.is_infinite() && (same.ssim - 1.0).abs() < 1e-12 && same.flip == 0.0);
        assert!(same.baseline_psnr_db.is_finite() && same.baseline_psnr_fg_db < same.baseline_psnr_db);
        // The baseline scored as a render equals the baseline figure.
        let base = flat_baseline(&truth, &mask);
        let (scored, _) = score_images(&base, &truth, &mask, w, h)?;
        assert!((scored.psnr_db - same.baseline_psnr_db).abs() < 1e-9);
        assert!(scored.flip > 0.0 && scored.flip_fg > scored.flip);
        let m = mean_scores(&[same, scored]);
        assert_eq!(m.views, 2);
        assert!(m.psnr_db.is_infinite());
        assert!((m.flip - scored.flip / 2.0).abs() < 1e-12);
        Ok(())
    }
}
