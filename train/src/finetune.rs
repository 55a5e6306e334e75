//! Test-time fine-tuning: a few optimiser steps on one capture's own source views,
//! under their known lighting, before its novel views are rendered; the per-scene
//! optimisation that generalising radiance fields allow (pixelNeRF, Yu et al. 2021,
//! §5; IBRNet, Wang et al. 2021, §3.4), here with NeLF's own training loss
//! ([`step_loss_on`]: colour, alpha against the mask, the lighting estimate, free
//! space where the mask is empty; no depth, which a capture has not).
//!
//! By default each step renders one source view from all of them; with
//! `leave_one_out` it renders a view `k ≥ 1` from the others (view 0 keeps the light
//! frame), which is what training asks of the network, and which measured worse.
//! Neither was adopted by `nelf bake capture`: the fit to the source views improves
//! while the novel-light views gain little over the one-number source-view
//! calibration (`nelf_field::calibrate`), at a high cost per capture
//! (train/README.md, "Test-time fine-tuning"). Only the
//! capture's inputs are used, never a target: the figures of `nelf train eval
//! --fine-tune-steps` stay honest.

use std::time::Instant;

use candle_core::Tensor;
use nelf_field::Model;
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::config::{ColourLoss, TrainConfig};
use crate::data::TargetMode;
use crate::error::TrainError;
use crate::trainer::{
    PreparedHead, PreparedTarget, Trainable, secs_since, select_views, step_loss_on, step_rng,
};

/// Settings of a fine-tuning.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FineTuneConfig {
    /// Optimiser steps (0: none).
    pub steps: u64,
    /// Rays per step.
    pub rays: usize,
    /// Adam step size of the per-point MLPs.
    pub lr_mlp: f64,
    /// Adam step size of the image encoder.
    pub lr_encoder: f64,
    /// Render each step's view from the other source views only (module docs).
    pub leave_one_out: bool,
    /// Seed of the steps' pixel and sample draws.
    pub seed: u64,
    /// How colours are compared (the shipped network was trained with sRGB L2).
    pub colour_loss: ColourLoss,
    /// Weight of the free-space loss on rays the mask says are empty.
    pub free_space_weight: f64,
}

impl Default for FineTuneConfig {
    fn default() -> Self {
        Self {
            steps: 0,
            rays: 256,
            lr_mlp: 1e-4,
            lr_encoder: 1e-4,
            leave_one_out: false,
            seed: 0,
            colour_loss: ColourLoss::SrgbL2,
            free_space_weight: 0.5,
        }
    }
}

/// What a fine-tuning did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct FineTuneReport {
    /// Steps taken.
    pub steps: u64,
    /// Seconds spent.
    pub secs: f64,
    /// Mean colour loss of the fine pass over the first tenth of the steps.
    pub first_loss: f64,
    /// The same over the last tenth.
    pub last_loss: f64,
}

/// `head`'s source views as targets under the source lighting: colour and mask,
/// no depth (`depth_mm` is 0, which the depth loss skips).
pub fn source_targets(head: &PreparedHead) -> Vec<PreparedTarget> {
    let views = &head.capture.views;
    let pixels = views.width * views.height;
    views
        .cameras
        .iter()
        .enumerate()
        .map(|(k, camera)| PreparedTarget {
            mode: TargetMode::SelfRotation,
            camera: *camera,
            image: views.images[k * pixels * 3..(k + 1) * pixels * 3]
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            alpha: views.masks[k * pixels..(k + 1) * pixels].to_vec(),
            depth_mm: vec![0.0; pixels],
            light_net: head.source_light_net.clone(),
        })
        .collect()
}

/// `head` without source view `k` (`k ≥ 1`: view 0 keeps the light frame).
pub fn without_view(head: &PreparedHead, k: usize) -> Result<PreparedHead, TrainError> {
    let all = head.capture.views.views();
    if k == 0 || k >= all || all < 3 {
        return Err(TrainError::Settings(format!(
            "cannot leave out view {k} of {all}: view 0 keeps the light frame and the network needs 2 views"
        )));
    }
    let keep: Vec<usize> = (0..all).filter(|&v| v != k).collect();
    select_views(head, &keep)
}

/// Fine-tunes `trainable` on `head`'s source views (module docs) and returns the
/// tuned network (plain tensors, [`Trainable::snapshot`]). `train` gives the loss
/// weights and samples per ray; its distillation is switched off, so `head`'s
/// targets and distillation points are not used.
pub fn fine_tune(
    trainable: &Trainable,
    head: &PreparedHead,
    tune: &FineTuneConfig,
    train: &TrainConfig,
    mut on_step: impl FnMut(u64, f64),
) -> Result<(Model, FineTuneReport), TrainError> {
    let clock = Instant::now();
    let targets = source_targets(head);
    let views = targets.len();
    let config = TrainConfig {
        rays: tune.rays,
        lr_mlp: tune.lr_mlp,
        lr_encoder: tune.lr_encoder,
        distill_weight: 0.0,
        distill_sigma_weight: Some(0.0),
        distill_shape_weight: 0.0,
        ema_decay: 0.0,
        colour_loss: tune.colour_loss,
        free_space_weight: tune.free_space_weight,
        ..train.clone()
    };
    // With leave-one-out, the heads each step encodes: all views but the rendered one.
    let left_out: Vec<PreparedHead> = if tune.leave_one_out {
        (1..views)
            .map(|k| without_view(head, k))
            .collect::<Result<_, _>>()?
    } else {
        Vec::new()
    };
    let mut adam = trainable.optimizer(&config)?;
    let mut losses = Vec::with_capacity(tune.steps as usize);
    for step in 0..tune.steps {
        let mut rng = step_rng(tune.seed, step);
        let (input, target) = if tune.leave_one_out {
            let k = rng.random_range(1..views);
            (&left_out[k - 1], &targets[k])
        } else {
            (head, &targets[rng.random_range(0..views)])
        };
        let (loss, parts): (Tensor, _) = step_loss_on(&trainable.model, input, target, &config, &mut rng)?;
        let grads = loss.backward()?;
        adam.step(&grads)?;
        losses.push(parts.rgb_fine);
        on_step(step + 1, parts.total);
    }
    adam.sync()?;
    let tenth = (losses.len() / 10).max(1);
    let mean = |xs: &[f64]| {
        if xs.is_empty() {
            0.0
        } else {
            xs.iter().sum::<f64>() / xs.len() as f64
        }
    };
    let report = FineTuneReport {
        steps: tune.steps,
        secs: secs_since(clock),
        first_loss: mean(&losses[..tenth.min(losses.len())]),
        last_loss: mean(&losses[losses.len().saturating_sub(tenth)..]),
    };
    Ok((trainable.snapshot()?, report))
}
