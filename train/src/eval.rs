//! `nelf train eval`: a network scored on held-out heads under held-out lightings
//! (never trained on), at their novel-light target views, given the first 2, 3, 4 or
//! 5 source views (frontal first): the view-count table of the paper's Table 3
//! (30.91 / 32.77 / 33.40 / 33.61 dB for 2–5 views, their data, 512²).
//!
//! Scores are in 8-bit sRGB, as [`crate::run::validate_head`] computes them: whole
//! image, foreground (inside the true mask) and SSIM, each beside the flat-colour
//! baseline of the same views (the true foreground mean inside the true silhouette),
//! so that a network that learned only silhouettes and average colour shows as such.
//! Each row also scores the same renderings scaled by the source-view gain
//! ([`nelf_field::calibrate`]: fitted to the head's own source views under its known
//! source lighting, never to the target), as `nelf bake capture` applied it before the
//! prior, and the network with its light transport normalised point by point to that
//! lighting ([`nelf_field::nelfnet::normalise_to_source`]) with the Lambertian shading
//! prior mixed in ([`nelf_field::prior`]), as `nelf bake capture` applies them now
//! (`train/README.md`). With
//! [`FineTuneFrom`], each head is scored by the network fine-tuned on that head's
//! own source views first ([`crate::finetune`]).

use std::path::Path;

use nelf_field::Model;
use nelf_scene::metrics::{Srgb8Scores, srgb8_scores};
use serde::Serialize;

use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::finetune::{FineTuneConfig, fine_tune};
use crate::run::{ValidationView, validate_head, write_validation_sheet};
/// Re-exported from [`crate::trainer`], where it lives beside the heads it selects
/// from (so that [`crate::finetune`] uses it without depending on this module).
pub use crate::trainer::select_views;
use crate::trainer::{PreparedHead, Trainable};

/// Weights to fine-tune on each head before it is scored, and how.
#[derive(Debug, Clone, Copy)]
pub struct FineTuneFrom<'a> {
    /// The weights (a safetensors file's bytes).
    pub bytes: &'a [u8],
    /// What to name them by in errors.
    pub origin: &'a Path,
    /// The fine-tuning.
    pub tune: FineTuneConfig,
}

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
    /// Whole-image PSNR of the renderings scaled by their source-view gain, dB.
    pub calibrated_psnr: f64,
    /// The same inside the mask, dB.
    pub calibrated_foreground_psnr: f64,
    /// The same's SSIM.
    pub calibrated_ssim: f64,
    /// Median over the heads of the source-view gain.
    pub median_gain: f64,
    /// Whole-image PSNR of the network with its light transport normalised, point by
    /// point, to the head's known source lighting
    /// ([`nelf_field::nelfnet::normalise_to_source`]) and the shading prior given to
    /// [`view_count_table`] mixed in ([`nelf_field::prior`]), dB.
    pub normalised_psnr: f64,
    /// The same inside the mask, dB.
    pub normalised_foreground_psnr: f64,
    /// The same's SSIM.
    pub normalised_ssim: f64,
}

/// `view`'s network rendering scaled by the source-view gain of `head`, scored.
fn calibrated_scores(
    model: &Model,
    head: &PreparedHead,
    view: &ValidationView,
) -> Result<(Srgb8Scores, f32), TrainError> {
    let encoded = model.encode(&head.capture.views)?;
    let fit = nelf_field::calibrate::source_view_gain(
        model,
        &encoded,
        &head.capture.views.masks,
        &head.source_light_net,
        head.capture.head_centre_net(),
    )?;
    let scaled: Vec<[f32; 3]> = view.network.iter().map(|c| c.map(|x| x * fit.gain)).collect();
    let scores = srgb8_scores(
        &scaled,
        &view.truth,
        &view.alpha,
        view.width as u32,
        view.height as u32,
    )
    .map_err(|e| TrainError::Settings(e.to_string()))?;
    Ok((scores, fit.gain))
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
    select_views(head, &(0..views).collect::<Vec<_>>())
}

/// The view-count table of `model` over `heads`, one row per count in `counts`; with
/// `sheet`, the last count's views are written there (truth | network | flat colour).
/// The normalised columns mix in `prior` (`None`: the network's own transport).
pub fn view_count_table(
    model: &Model,
    heads: &[PreparedHead],
    config: &TrainConfig,
    counts: &[usize],
    sheet: Option<&Path>,
    fine_tune_from: Option<&FineTuneFrom<'_>>,
    prior: Option<nelf_field::prior::ShadingPrior>,
) -> Result<Vec<ViewCountRow>, TrainError> {
    if heads.is_empty() {
        return Err(TrainError::Settings("no heads to score".into()));
    }
    let mut rows = Vec::with_capacity(counts.len());
    for &views in counts {
        let mut sum = [0.0f64; 12];
        let mut gains = Vec::with_capacity(heads.len());
        let mut sheet_views = Vec::with_capacity(heads.len());
        for head in heads {
            let head = first_views(head, views)?;
            let tuned = match fine_tune_from {
                Some(from) => {
                    let trainable = Trainable::from_safetensors_bytes(
                        from.bytes,
                        from.origin,
                        *model.config(),
                        model.device(),
                    )?;
                    let (tuned, report) = fine_tune(&trainable, &head, &from.tune, config, |_, _| {})?;
                    eprintln!(
                        "  fine-tuned {} steps on {views} source views in {:.0} s: colour loss {:.5} -> {:.5}",
                        report.steps, report.secs, report.first_loss, report.last_loss
                    );
                    Some(tuned)
                }
                None => None,
            };
            let model = tuned.as_ref().unwrap_or(model);
            let view = validate_head(model, &head, config)?;
            let (c, gain) = calibrated_scores(model, &head, &view)?;
            gains.push(f64::from(gain));
            let normalised = model
                .clone()
                .with_source_normalisation(Some(&head.source_light_net))?
                .with_shading_prior(prior)?;
            let n = validate_head(&normalised, &head, config)?.scores;
            let v = view.scores;
            sheet_views.push(view);
            let values = [
                v.psnr,
                v.foreground_psnr,
                v.ssim,
                v.flat_psnr,
                v.flat_foreground_psnr,
                v.flat_ssim,
                c.psnr,
                c.foreground_psnr,
                c.ssim,
                n.psnr,
                n.foreground_psnr,
                n.ssim,
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
            calibrated_psnr,
            calibrated_foreground_psnr,
            calibrated_ssim,
            normalised_psnr,
            normalised_foreground_psnr,
            normalised_ssim,
        ] = sum.map(|s| s / heads.len() as f64);
        gains.sort_by(f64::total_cmp);
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
            calibrated_psnr,
            calibrated_foreground_psnr,
            calibrated_ssim,
            median_gain: gains[gains.len() / 2],
            normalised_psnr,
            normalised_foreground_psnr,
            normalised_ssim,
        });
    }
    Ok(rows)
}
