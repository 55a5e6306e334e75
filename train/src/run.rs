//! `nelf train run`: the resumable training loop. Starts from the run folder's
//! checkpoint when there is one (same training settings required), trains until
//! the step target or the time limit, validates on held-out heads (novel-light
//! views, never trained on) into `validation.csv` (and `validation.png`: truth,
//! network and flat colour side by side), and checkpoints every few minutes
//! and at the end: `checkpoint.safetensors` + `checkpoint.json` (resume state) and
//! `weights.safetensors` (the network alone, official key names, loadable by
//! `nelf_field::Model::load`; the weight average when `--ema-decay` keeps one,
//! which is also what validation scores), each written atomically (`crate::files`).

use std::io::Write as _;
use std::path::Path;
use std::time::Instant;

use candle_core::{Device, Tensor};
use indicatif::ProgressBar;
use nelf_field::Model;
use nelf_format::io_error::{FileIoError, IoResultExt};
use nelf_scene::metrics::{Srgb8Scores, flat_colour_baseline, srgb8_scores};
use serde::Serialize;

use crate::adam::Adam;
use crate::config::TrainConfig;
use crate::data::{Dataset, TargetMode};
use crate::error::TrainError;
use crate::files::{write_bytes, write_tensors};
use crate::forward::{encode, irradiance};
use crate::trainer::{
    CHECKPOINT_INFO, CheckpointInfo, Jitter, LossParts, PreparedHead, RunPaths, Trainable, load_checkpoint,
    prepare_heads, read_checkpoint_info, render_passes, save_checkpoint, target_rays, train_step,
};

/// Rays per validation chunk (bounds memory).
const VAL_CHUNK_RAYS: usize = 512;

/// A validation result: the mean over held-out heads.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Validation {
    /// Whole-image PSNR, 8-bit sRGB, dB.
    pub psnr: f64,
    /// PSNR inside the true mask (alpha > 0.5), 8-bit sRGB, dB.
    pub foreground_psnr: f64,
    /// The trivial baseline on the same views: the true foreground's mean colour
    /// inside the true silhouette, black outside; whole image, dB.
    pub flat_psnr: f64,
    /// The same baseline inside the mask, dB.
    pub flat_foreground_psnr: f64,
}

/// What a run did.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Step reached.
    pub step: u64,
    /// Steps taken in this invocation.
    pub steps_now: u64,
    /// Seconds of training in this invocation.
    pub secs_now: f64,
    /// Seconds of training over all invocations.
    pub train_secs: f64,
    /// The last step's losses.
    pub last_loss: LossParts,
    /// The last validation, if any ran.
    pub validation: Option<Validation>,
}

/// One held-out view as validated: linear RGB images, row-major.
#[derive(Debug, Clone)]
pub struct ValidationView {
    /// The scores.
    pub validation: Validation,
    /// The same with SSIM (8-bit sRGB, beside the flat colour's).
    pub scores: Srgb8Scores,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// The path-traced truth.
    pub truth: Vec<[f32; 3]>,
    /// Its coverage (the true mask).
    pub alpha: Vec<f32>,
    /// The network's rendering.
    pub network: Vec<[f32; 3]>,
    /// The flat-colour baseline.
    pub flat: Vec<[f32; 3]>,
}

/// Renders the novel-light target of `head` with `model` (a [`Trainable::snapshot`]:
/// fine network, evenly spaced samples) and scores it against the truth in 8-bit
/// sRGB, beside the flat-colour baseline.
pub fn validate_head(
    model: &Model,
    head: &PreparedHead,
    config: &TrainConfig,
) -> Result<ValidationView, TrainError> {
    let target = head
        .targets
        .iter()
        .find(|t| t.mode == TargetMode::NovelLight)
        .or_else(|| head.targets.first())
        .ok_or_else(|| TrainError::Settings("a head without target views".into()))?;
    let (w, h) = (target.camera.width, target.camera.height);
    let model = &config.model_for_head(model, &head.source_light_net)?;
    let encoded = encode(model, &head.capture.views)?;
    let irr = irradiance(&target.light_net, model.device())?;
    let centre = head.capture.head_centre_net();
    let radius = model.config().head_radius_mm;
    let mut rendered = Vec::with_capacity(w * h);
    let pixels: Vec<usize> = (0..w * h).collect();
    for chunk in pixels.chunks(VAL_CHUNK_RAYS) {
        let rays = target_rays(target, chunk, centre, radius);
        let (coarse, fine) = render_passes(model, &encoded, head, &rays, &irr, config, &mut Jitter::Centred)?;
        let pass = fine.unwrap_or(coarse);
        let rgb = pass.rgb.detach().to_vec2::<f32>()?;
        rendered.extend(rgb.into_iter().map(|c| [c[0], c[1], c[2]]));
    }
    let scores = srgb8_scores(&rendered, &target.image, &target.alpha, w as u32, h as u32)
        .map_err(|e| TrainError::Settings(e.to_string()))?;
    Ok(ValidationView {
        validation: Validation {
            psnr: scores.psnr,
            foreground_psnr: scores.foreground_psnr,
            flat_psnr: scores.flat_psnr,
            flat_foreground_psnr: scores.flat_foreground_psnr,
        },
        scores,
        width: w,
        height: h,
        truth: target.image.clone(),
        alpha: target.alpha.clone(),
        network: rendered,
        flat: flat_colour_baseline(&target.image, &target.alpha),
    })
}

/// Writes the validated views as one PNG, a row per head: truth | network | flat colour.
pub fn write_validation_sheet(path: &Path, views: &[ValidationView]) -> Result<(), TrainError> {
    let Some(first) = views.first() else {
        return Ok(());
    };
    let (w, h) = (first.width, first.height);
    if views.iter().any(|v| v.width != w || v.height != h) {
        return Err(TrainError::Settings("validation views of different sizes".into()));
    }
    let sheet_w = 3 * w;
    let mut sheet = vec![[0.0f32; 3]; sheet_w * h * views.len()];
    for (row, view) in views.iter().enumerate() {
        for (col, image) in [&view.truth, &view.network, &view.flat].into_iter().enumerate() {
            for y in 0..h {
                let dst = (row * h + y) * sheet_w + col * w;
                sheet[dst..dst + w].copy_from_slice(&image[y * w..(y + 1) * w]);
            }
        }
    }
    nelf_scene::image_io::write_png_srgb(path, sheet_w as u32, (h * views.len()) as u32, &sheet, 0.0)
        .map_err(|e| TrainError::Settings(format!("{}: {e}", path.display())))
}

/// Mean validation over `heads`; when `sheet` is given, the views are written there
/// as a PNG ([`write_validation_sheet`]).
pub fn validate(
    model: &Model,
    heads: &[PreparedHead],
    config: &TrainConfig,
    sheet: Option<&Path>,
) -> Result<Option<Validation>, TrainError> {
    if heads.is_empty() {
        return Ok(None);
    }
    let mut sum = [0.0f64; 4];
    let mut views = Vec::with_capacity(heads.len());
    for head in heads {
        let view = validate_head(model, head, config)?;
        let v = view.validation;
        views.push(view);
        for (s, x) in sum
            .iter_mut()
            .zip([v.psnr, v.foreground_psnr, v.flat_psnr, v.flat_foreground_psnr])
        {
            *s += x;
        }
    }
    if let Some(path) = sheet {
        write_validation_sheet(path, &views)?;
    }
    let [p, f, fp, ff] = sum.map(|s| s / heads.len() as f64);
    Ok(Some(Validation {
        psnr: p,
        foreground_psnr: f,
        flat_psnr: fp,
        flat_foreground_psnr: ff,
    }))
}

/// Appends the row `fields` to the CSV file `path`, writing `header` first when the
/// file is new.
fn append_csv(path: &Path, header: &str, fields: &[String]) -> Result<(), TrainError> {
    let mut text = String::new();
    if !path.exists() {
        text.push_str(header);
        text.push('\n');
    }
    text.push_str(&fields.join(","));
    text.push('\n');
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .and_then(|mut f| f.write_all(text.as_bytes()))
        .map_err(|source| TrainError::Io(FileIoError::new(path.to_path_buf(), source)))
}

/// Appends a validation to the validation log.
fn log_validation(
    path: &Path,
    step: u64,
    train_secs: f64,
    loss: &LossParts,
    v: &Validation,
) -> Result<(), TrainError> {
    append_csv(
        path,
        "step,train_secs,loss,rgb_fine,val_psnr_db,val_foreground_psnr_db,flat_psnr_db,flat_foreground_psnr_db",
        &[
            step.to_string(),
            format!("{train_secs:.1}"),
            format!("{:.5}", loss.total),
            format!("{:.5}", loss.rgb_fine),
            format!("{:.3}", v.psnr),
            format!("{:.3}", v.foreground_psnr),
            format!("{:.3}", v.flat_psnr),
            format!("{:.3}", v.flat_foreground_psnr),
        ],
    )
}

/// Steps between lines of the loss log.
const LOSS_LOG_EVERY: u64 = 50;

/// Appends a step's losses to `loss.csv` (the training curve).
fn log_loss(path: &Path, step: u64, train_secs: f64, loss: &LossParts) -> Result<(), TrainError> {
    let values = [
        loss.total,
        loss.rgb_coarse,
        loss.rgb_fine,
        loss.depth,
        loss.alpha,
        loss.light,
        loss.distill,
    ];
    let mut fields = vec![step.to_string(), format!("{train_secs:.1}")];
    fields.extend(values.iter().map(|v| format!("{v:.5}")));
    fields.extend(loss.phase_secs.iter().map(|v| format!("{v:.4}")));
    append_csv(
        path,
        "step,train_secs,loss,rgb_coarse,rgb_fine,depth,alpha,light,distill,encode_s,render_s,losses_s,backward_s,adam_s",
        &fields,
    )
}

/// Validates on `heads`, appends the result to the log and prints it.
#[allow(clippy::too_many_arguments, reason = "the loop's state, passed through once")]
fn validate_and_log(
    trainable: &Trainable,
    adam: &Adam,
    heads: &[PreparedHead],
    config: &TrainConfig,
    paths: &RunPaths,
    step: u64,
    train_secs: f64,
    loss: &LossParts,
    progress: &ProgressBar,
) -> Result<Option<Validation>, TrainError> {
    let model = trainable.snapshot_of(run_weights(trainable, adam)?)?;
    let Some(v) = validate(&model, heads, config, Some(&paths.dir.join("validation.png")))? else {
        return Ok(None);
    };
    log_validation(&paths.log(), step, train_secs, loss, &v)?;
    let line = format!(
        "step {step}: validation PSNR {:.2} dB, foreground {:.2} dB (flat colour: {:.2}, {:.2} dB)",
        v.psnr, v.foreground_psnr, v.flat_psnr, v.flat_foreground_psnr
    );
    if progress.is_hidden() {
        eprintln!("{line}");
    } else {
        progress.println(line);
    }
    Ok(Some(v))
}

/// Writes the network alone (official key names) for `Model::load`, with the image
/// side it was trained at (`nelf_field::model::WORKING_IMAGE_SIZE_KEY`), whether its
/// lightings were source-relative and the shading prior it rendered through
/// (`nelf_field::model::SHADING_PRIOR_MM_KEY`).
pub fn export_weights(trainable: &Trainable, config: &TrainConfig, path: &Path) -> Result<(), TrainError> {
    export_named_weights(trainable.weights()?, config, path)
}

/// The weights a run validates and exports: the moving average when it keeps one
/// (`--ema-decay`), else the last step's.
pub fn run_weights(trainable: &Trainable, adam: &Adam) -> Result<Vec<(String, Tensor)>, TrainError> {
    match adam.averaged_weights() {
        Some(average) => Ok(average),
        None => trainable.weights(),
    }
}

/// [`export_weights`] of named tensors (the official key names).
pub fn export_named_weights(
    weights: Vec<(String, Tensor)>,
    config: &TrainConfig,
    path: &Path,
) -> Result<(), TrainError> {
    let mut tensors: std::collections::HashMap<String, Tensor> = weights.into_iter().collect();
    tensors.insert(
        nelf_field::model::WORKING_IMAGE_SIZE_KEY.into(),
        Tensor::new(&[config.image_size as f32], &Device::Cpu)?,
    );
    if config.source_relative_light {
        tensors.insert(
            nelf_field::model::SOURCE_RELATIVE_LIGHT_KEY.into(),
            Tensor::new(&[1.0f32], &Device::Cpu)?,
        );
    }
    if let Some(prior) = config.shading_prior() {
        for (key, value) in [
            (nelf_field::model::SHADING_PRIOR_MM_KEY, prior.step_mm),
            (nelf_field::model::SHADING_PRIOR_WEIGHT_KEY, prior.weight),
        ] {
            tensors.insert(key.into(), Tensor::new(&[value], &Device::Cpu)?);
        }
    }
    write_tensors(&tensors, path)
}

/// Saves the checkpoint and the exported weights.
fn checkpoint(
    paths: &RunPaths,
    trainable: &Trainable,
    adam: &Adam,
    info: &CheckpointInfo,
) -> Result<(), TrainError> {
    save_checkpoint(&paths.dir, trainable, adam, info)?;
    export_named_weights(run_weights(trainable, adam)?, &info.config, &paths.weights())
}

/// Trains per `config` (module docs).
pub fn run(config: &TrainConfig, device: &Device, progress: &ProgressBar) -> Result<RunReport, TrainError> {
    config.validate()?;
    let paths = RunPaths {
        dir: config.out.clone(),
    };
    std::fs::create_dir_all(&paths.dir).with_path(&paths.dir)?;
    // A checkpoint of another network is refused before any work.
    let resume_from = if paths.dir.join(CHECKPOINT_INFO).exists() {
        let info = read_checkpoint_info(&paths.dir)?;
        if !info.config.same_network(config) {
            return Err(TrainError::Settings(format!(
                "{}: the checkpoint has other widths, image size or seed ({} at {} px, seed {}); \
                 use the same to resume, or another --out",
                paths.dir.join(CHECKPOINT_INFO).display(),
                info.config.arch,
                info.config.image_size,
                info.config.seed
            )));
        }
        Some(info)
    } else {
        None
    };
    let dataset = Dataset::open(&config.data)?;
    let train_ids = dataset.train_ids();
    if train_ids.is_empty() {
        return Err(TrainError::Settings(format!(
            "{}: no finished training heads (run `nelf train data` first)",
            config.data.display()
        )));
    }
    progress.set_message(format!("loading {} training heads", train_ids.len()));
    let heads = prepare_heads(
        &dataset,
        &train_ids,
        config.image_size,
        config.source_relative_light,
    )?;
    let val_ids: Vec<u32> = dataset.val_ids().into_iter().take(config.val_heads).collect();
    let val_heads = prepare_heads(
        &dataset,
        &val_ids,
        config.image_size,
        config.source_relative_light,
    )?;

    let real = match &config.real_images {
        Some(dir) => {
            progress.set_message(format!("loading real portraits from {}", dir.display()));
            Some(crate::domain::RealImages::load(dir, config.image_size)?)
        }
        None => None,
    };
    let trainable = Trainable::init(config, device)?;
    let mut adam = trainable.optimizer(config)?;
    let mut train_secs = 0.0;
    let mut last_loss = LossParts::default();
    if resume_from.is_some() {
        let info = load_checkpoint(&paths.dir, &trainable, &mut adam)?;
        train_secs = info.train_secs;
        last_loss = info.last_loss;
    }
    let serialized = serde_json::to_vec_pretty(config).map_err(|e| TrainError::Settings(e.to_string()))?;
    let config_path = paths.dir.join("train_config.json");
    write_bytes(&config_path, &serialized)?;

    progress.set_length(config.steps);
    progress.set_position(adam.steps());
    progress.reset_eta();
    let start = Instant::now();
    let mut last_checkpoint = Instant::now();
    let first_step = adam.steps();
    let mut validation = None;
    let mut validated_at = None;
    while adam.steps() < config.steps {
        if config.max_secs > 0.0 && start.elapsed().as_secs_f64() >= config.max_secs {
            break;
        }
        let step_start = Instant::now();
        last_loss = train_step(&trainable, &mut adam, &heads, real.as_ref(), config)?;
        train_secs += step_start.elapsed().as_secs_f64();
        let step = adam.steps();
        progress.set_position(step);
        progress.set_message(format!(
            "loss {:.4} (colour {:.4})",
            last_loss.total, last_loss.rgb_fine
        ));
        if step % LOSS_LOG_EVERY == 0 {
            log_loss(&paths.dir.join("loss.csv"), step, train_secs, &last_loss)?;
            if real.is_some() {
                append_csv(
                    &paths.dir.join("real.csv"),
                    "step,real_loss",
                    &[step.to_string(), format!("{:.5}", last_loss.real)],
                )?;
            }
            if progress.is_hidden() {
                let p = last_loss.phase_secs;
                eprintln!(
                    "step {step}: loss {:.4} (colour {:.4}), {:.3} s/step; last step: encode {:.3}, render {:.3}, losses {:.3}, backward {:.3}, adam {:.3} s",
                    last_loss.total,
                    last_loss.rgb_fine,
                    train_secs / step.max(1) as f64,
                    p[0],
                    p[1],
                    p[2],
                    p[3],
                    p[4]
                );
            }
        }
        if config.val_every > 0 && step % config.val_every == 0 {
            validation = validate_and_log(
                &trainable, &adam, &val_heads, config, &paths, step, train_secs, &last_loss, progress,
            )?;
            validated_at = Some(step);
        }
        if last_checkpoint.elapsed().as_secs_f64() >= config.checkpoint_secs {
            let info = CheckpointInfo {
                step,
                train_secs,
                config: config.clone(),
                last_loss,
            };
            checkpoint(&paths, &trainable, &adam, &info)?;
            last_checkpoint = Instant::now();
        }
    }
    // The network as it ends is always validated (also when no step was taken: a
    // run to the step it is at validates its checkpoint).
    if config.val_every > 0 && validated_at != Some(adam.steps()) {
        validation = validate_and_log(
            &trainable,
            &adam,
            &val_heads,
            config,
            &paths,
            adam.steps(),
            train_secs,
            &last_loss,
            progress,
        )?;
    }
    let info = CheckpointInfo {
        step: adam.steps(),
        train_secs,
        config: config.clone(),
        last_loss,
    };
    checkpoint(&paths, &trainable, &adam, &info)?;
    Ok(RunReport {
        step: adam.steps(),
        steps_now: adam.steps() - first_step,
        secs_now: start.elapsed().as_secs_f64(),
        train_secs,
        last_loss,
        validation,
    })
}
