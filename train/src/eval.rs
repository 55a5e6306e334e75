//! `nelf train eval`: a network scored on held-out heads under held-out lightings
//! (never trained on), at their novel-light target views, given the first 2, 3, 4 or
//! 5 source views (frontal first): the view-count table of the paper's Table 3
//! (30.91 / 32.77 / 33.40 / 33.61 dB for 2–5 views, their data, 512²).
//!
//! Scores are in 8-bit sRGB, as [`crate::run::validate_head`] computes them: whole
//! image, foreground (inside the true mask) and SSIM, each beside the flat-colour
//! baseline of the same views (the true foreground mean inside the true silhouette),
//! so that a network that learned only silhouettes and average colour shows as such.

use std::path::Path;

use nelf_field::{EncodedViews, Model};
use serde::Serialize;

use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::run::{validate_head, write_validation_sheet};
use crate::trainer::PreparedHead;

/// One row of the view-count table: means over the heads.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ViewCountRow {
    /// Source views given to the network.
    pub views: usize,
    /// Heads averaged.
    pub heads: usize,
    /// Whole-image PSNR, dB.
    pub psnr: f64,
    /// PSNR inside the true mask, dB.
    pub foreground_psnr: f64,
    /// SSIM of the whole image.
    pub ssim: f64,
    /// The flat-colour baseline's whole-image PSNR, dB.
    pub flat_psnr: f64,
    /// The flat-colour baseline inside the mask, dB.
    pub flat_foreground_psnr: f64,
    /// The flat-colour baseline's SSIM.
    pub flat_ssim: f64,
}

/// `head` with only its first `views` source views (view 0, the frontal one, keeps
/// the light frame).
pub fn first_views(head: &PreparedHead, views: usize) -> Result<PreparedHead, TrainError> {
    let all = head.capture.views.views();
    if views < 2 || views > all {
        return Err(TrainError::Settings(format!(
            "{views} source views asked for; the head has {all} and the network needs at least 2"
        )));
    }
    let mut out = head.clone();
    let sv = &mut out.capture.views;
    let pixels = sv.width * sv.height;
    sv.images.truncate(views * pixels * 3);
    sv.masks.truncate(views * pixels);
    sv.cameras.truncate(views);
    out.capture.cameras.truncate(views);
    out.geometry = EncodedViews::geometry_only(&out.capture.views)?;
    Ok(out)
}

/// The view-count table of `model` over `heads`, one row per count in `counts`; with
/// `sheet`, the last count's views are written there (truth | network | flat colour).
pub fn view_count_table(
    model: &Model,
    heads: &[PreparedHead],
    config: &TrainConfig,
    counts: &[usize],
    sheet: Option<&Path>,
) -> Result<Vec<ViewCountRow>, TrainError> {
    if heads.is_empty() {
        return Err(TrainError::Settings("no heads to score".into()));
    }
    let mut rows = Vec::with_capacity(counts.len());
    for &views in counts {
        let mut sum = [0.0f64; 6];
        let mut sheet_views = Vec::with_capacity(heads.len());
        for head in heads {
            let head = first_views(head, views)?;
            let view = validate_head(model, &head, config)?;
            let v = view.scores;
            sheet_views.push(view);
            let values = [
                v.psnr,
                v.foreground_psnr,
                v.ssim,
                v.flat_psnr,
                v.flat_foreground_psnr,
                v.flat_ssim,
            ];
            for (s, x) in sum.iter_mut().zip(values) {
                *s += x;
            }
        }
        let [
            psnr,
            foreground_psnr,
            ssim_mean,
            flat_psnr,
            flat_foreground_psnr,
            flat_ssim,
        ] = sum.map(|s| s / heads.len() as f64);
        if let (Some(path), Some(&last)) = (sheet, counts.last())
            && last == views
        {
            write_validation_sheet(path, &sheet_views)?;
        }
        rows.push(ViewCountRow {
            views,
            heads: heads.len(),
            psnr,
            foreground_psnr,
            ssim: ssim_mean,
            flat_psnr,
            flat_foreground_psnr,
            flat_ssim,
        });
    }
    Ok(rows)
}
