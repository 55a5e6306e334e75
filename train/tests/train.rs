//! The training contract on a tiny network and a synthetic head (seconds, not
//! hours): one step lowers the loss on a fixed batch, gradients match finite
//! differences, and a run resumed from a checkpoint equals an unbroken one bit for
//! bit.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use candle_core::{Device, Tensor};
use glam::DVec3;
use nelf_field::capture::default_net_from_world;
use nelf_field::{EncodedViews, NetCapture};
use nelf_format::conventions::PinholeCamera;
use nelf_train::TrainConfig;
use nelf_train::config::ColourLoss;
use nelf_train::data::TargetMode;
use nelf_train::trainer::{
    CheckpointInfo, LossParts, PreparedHead, PreparedTarget, Trainable, load_checkpoint, relit_by_shape,
    save_checkpoint, step_loss, step_rng, train_step,
};
use rand::Rng;

const SIZE: u32 = 32;

fn tiny_config() -> TrainConfig {
    TrainConfig {
        arch: "tiny".into(),
        image_size: SIZE as usize,
        rays: 48,
        coarse_samples: 12,
        fine_samples: 6,
        lr_mlp: 1e-3,
        lr_encoder: 1e-3,
        distill_weight: 0.1,
        distill_points: 32,
        ..TrainConfig::default()
    }
}

/// A smooth ball of colour, seen by 3 source cameras and one target camera about
/// 1 m away, with its true lighting (a constant sky) and a few σ samples.
fn synthetic_head() -> PreparedHead {
    let centre = DVec3::new(0.0, 1.6, 0.0);
    let camera = |az: f64, el: f64| {
        let eye = centre + DVec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos());
        PinholeCamera::look_at(eye, centre, DVec3::Y, SIZE, SIZE, 0.3)
    };
    let cameras = [camera(0.0, 0.0), camera(0.4, 0.1), camera(-0.4, -0.1)];
    let n = (SIZE * SIZE) as usize;
    let disc = |cam: &PinholeCamera| -> Vec<f32> {
        let c = cam.project(centre).unwrap();
        (0..n)
            .map(|p| {
                let d =
                    ((p % SIZE as usize) as f64 + 0.5 - c.x).hypot((p / SIZE as usize) as f64 + 0.5 - c.y);
                if d < 0.3 * f64::from(SIZE) { 1.0 } else { 0.0 }
            })
            .collect()
    };
    let image = |mask: &[f32], shift: f32| -> Vec<[f32; 3]> {
        mask.iter()
            .enumerate()
            .map(|(p, m)| {
                let x = (p % SIZE as usize) as f32 / SIZE as f32;
                [
                    m * (0.5 + 0.3 * (5.0 * x + shift).sin()),
                    m * 0.4,
                    m * (0.3 + 0.2 * x),
                ]
            })
            .collect()
    };
    let masks: Vec<Vec<f32>> = cameras.iter().map(disc).collect();
    let images: Vec<Vec<[f32; 3]>> = masks
        .iter()
        .enumerate()
        .map(|(i, m)| image(m, i as f32))
        .collect();
    let capture = NetCapture::new(&cameras, &images, &masks, centre, default_net_from_world()).unwrap();
    let geometry = EncodedViews::geometry_only(&capture.views).unwrap();
    let target_cam = camera(0.2, 0.05);
    let alpha = disc(&target_cam);
    let target = PreparedTarget {
        mode: TargetMode::NovelLight,
        camera: capture.net_camera(&target_cam),
        image: image(&alpha, 0.5),
        depth_mm: alpha.iter().map(|a| a * 850.0).collect(),
        alpha,
        light_net: vec![0.5; 384],
    };
    let distill_points: Vec<[f32; 3]> = (0..64)
        .map(|i| {
            let t = i as f64 / 64.0;
            capture.to_net_point(centre + DVec3::new(0.1 * (t - 0.5), 0.05 * (6.0 * t).sin(), 0.02))
        })
        .collect();
    PreparedHead {
        capture,
        geometry,
        source_light_net: vec![0.5; 384],
        targets: vec![
            PreparedTarget {
                mode: TargetMode::SelfRotation,
                ..target.clone()
            },
            target,
        ],
        distill_sigma: (0..64).map(|i| if i % 2 == 0 { 0.05 } else { 0.0 }).collect(),
        distill_dirs: vec![[0.0, -1.0, 0.0]; 64],
        distill_lights: vec![vec![0.5; 384], vec![0.25; 384]],
        distill_radiance: (0..64 * 2 * 3).map(|i| 0.1 + 0.01 * (i % 7) as f32).collect(),
        shape_lights: vec![
            vec![0.25; 384],
            (0..384).map(|k| if k % 128 < 16 { 4.0 } else { 0.0 }).collect(),
        ],
        shape_radiance: (0..64 * 2 * 3).map(|i| 0.05 + 0.02 * (i % 5) as f32).collect(),
        distill_points,
    }
}

fn loss_at(
    trainable: &Trainable,
    head: &PreparedHead,
    config: &TrainConfig,
    seed: u64,
) -> (Tensor, LossParts) {
    step_loss(&trainable.model, head, config, &mut step_rng(seed, 0)).unwrap()
}

/// The loss of [`loss_at`] as a number.
fn loss_value(trainable: &Trainable, head: &PreparedHead, config: &TrainConfig, seed: u64) -> f64 {
    f64::from(
        loss_at(trainable, head, config, seed)
            .0
            .to_scalar::<f32>()
            .unwrap(),
    )
}

#[test]
fn one_step_lowers_the_loss_on_a_fixed_batch() {
    let config = tiny_config();
    let head = synthetic_head();
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam = trainable.optimizer(&config).unwrap();
    let (loss, before) = loss_at(&trainable, &head, &config, 11);
    assert!(before.total.is_finite() && before.total > 0.0, "{before:?}");
    assert!(
        before.rgb_fine > 0.0 && before.light > 0.0 && before.distill > 0.0,
        "{before:?}"
    );
    adam.step(&loss.backward().unwrap()).unwrap();
    let (_, after) = loss_at(&trainable, &head, &config, 11);
    assert!(
        after.total < before.total,
        "loss {} → {}",
        before.total,
        after.total
    );
}

/// Training through the shading prior: one optimiser step on the head lowers the
/// loss of the mixed transport, and the mix is what the step trains (the loss differs
/// from the network's own).
#[test]
fn one_step_through_the_shading_prior_lowers_its_loss() {
    let plain = tiny_config();
    let config = TrainConfig {
        shading_prior_mm: 8.0,
        ..tiny_config()
    };
    assert!(config.validate().is_ok());
    let head = synthetic_head();
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam = trainable.optimizer(&config).unwrap();
    let with_prior = |t: &Trainable| config.model_for_head(&t.model, &head.source_light_net).unwrap();
    let loss = |model: &nelf_field::Model, config: &TrainConfig| {
        step_loss(model, &head, config, &mut step_rng(11, 0)).unwrap()
    };
    let (graph, before) = loss(&with_prior(&trainable), &config);
    let (_, own) = loss(&trainable.model, &plain);
    assert!(before.total.is_finite() && before.total > 0.0, "{before:?}");
    assert!(
        (before.rgb_fine - own.rgb_fine).abs() > 1e-6,
        "the prior changed nothing: {before:?} vs {own:?}"
    );
    adam.step(&graph.backward().unwrap()).unwrap();
    let (_, after) = loss(&with_prior(&trainable), &config);
    assert!(
        after.total < before.total,
        "loss {} → {}",
        before.total,
        after.total
    );
    // Bad settings are refused before any work.
    for (mm, weight) in [(-1.0, 0.5), (8.0, 1.5), (f32::NAN, 0.5)] {
        let bad = TrainConfig {
            shading_prior_mm: mm,
            shading_prior_weight: weight,
            ..tiny_config()
        };
        assert!(bad.validate().is_err(), "{mm} {weight}");
    }
}

/// Central differences (step `h`, f32 losses near 1) against the analytic gradient
/// of the entry of each named parameter with the largest gradient.
fn check_gradients(config: &TrainConfig, names: &[&str]) {
    let head = synthetic_head();
    let trainable = Trainable::init(config, &Device::Cpu).unwrap();
    let (loss, _) = loss_at(&trainable, &head, config, 5);
    let grads = loss.backward().unwrap();
    let vars = trainable.varmap.data().lock().unwrap().clone();
    for name in names {
        let var = &vars[*name];
        let g = grads
            .get(var.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let (k, &gk) = g
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .unwrap();
        let base = var.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        // Small enough for the L1 kinks and the group norms of 2 × 2 light patches,
        // large enough for f32 round-off in a loss near 1.
        let h = 3e-3f32;
        let at = |delta: f32| {
            let mut v = base.clone();
            v[k] += delta;
            var.set(&Tensor::from_vec(v, var.dims(), &Device::Cpu).unwrap())
                .unwrap();
            let l = loss_at(&trainable, &head, config, 5).1.total;
            var.set(&Tensor::from_vec(base.clone(), var.dims(), &Device::Cpu).unwrap())
                .unwrap();
            l
        };
        let numeric = (at(h) - at(-h)) / (2.0 * f64::from(h));
        let analytic = f64::from(gk);
        assert!(analytic.abs() > 1e-5, "{name}: no gradient ({analytic})");
        let rel = (numeric - analytic).abs() / analytic.abs().max(1e-4);
        assert!(
            rel < 0.1,
            "{name}[{k}]: analytic {analytic:.6e}, numeric {numeric:.6e}"
        );
    }
}

#[test]
fn gradients_match_finite_differences() {
    // The image losses: one parameter in each part (light head, decoder, the
    // per-point networks of both passes).
    let images_only = TrainConfig {
        distill_weight: 0.0,
        ..tiny_config()
    };
    check_gradients(
        &images_only,
        &[
            "image_encoder.lightpred_final.norm.bias",
            "image_encoder.catconvs.2.conv.bias",
            "fine_appearance_encoder.lt_mlp.input_layer.bias",
            "coarse_appearance_encoder.density_mlp.layers.2.bias",
            "fine_appearance_encoder.blend_mlp.layers.0.bias",
        ],
    );
    // The free-space loss (σ at samples the truth knows are empty) reaches both
    // density heads.
    let free_space = TrainConfig {
        distill_weight: 0.0,
        free_space_weight: 1.0,
        ..tiny_config()
    };
    check_gradients(
        &free_space,
        &[
            "coarse_appearance_encoder.density_mlp.layers.2.bias",
            "fine_appearance_encoder.density_mlp.layers.2.bias",
        ],
    );
    // The distillation loss (σ and radiance through T) adds to the fine network.
    let distill_heavy = TrainConfig {
        distill_weight: 1.0,
        ..tiny_config()
    };
    check_gradients(
        &distill_heavy,
        &[
            "fine_appearance_encoder.lt_mlp.input_layer.bias",
            "fine_appearance_encoder.density_mlp.layers.2.bias",
        ],
    );
}

/// The distillation's σ term has its own weight: unset it is the distillation's,
/// and the loss is linear in it (the synthetic head's distillation points have σ
/// and its network a density, so the term is not zero).
#[test]
fn the_sigma_distillation_weight_scales_its_term_alone() {
    let trainable = Trainable::init(&tiny_config(), &Device::Cpu).unwrap();
    let head = synthetic_head();
    let total = |distill_weight: f64, sigma: Option<f64>| {
        let config = TrainConfig {
            distill_weight,
            distill_sigma_weight: sigma,
            ..tiny_config()
        };
        loss_value(&trainable, &head, &config, 5)
    };
    assert_eq!(total(0.1, None).to_bits(), total(0.1, Some(0.1)).to_bits());
    let images = total(0.0, None);
    let (half, one) = (total(0.0, Some(0.5)) - images, total(0.0, Some(1.0)) - images);
    assert!(half > 1e-4, "the σ term adds to the loss ({half})");
    assert!(
        (one - 2.0 * half).abs() <= 1e-4 * one,
        "linear in its weight: {half} then {one}"
    );
    // The radiance term stays with --distill-weight.
    assert!(total(1.0, Some(0.0)) > images + 1e-4);
}

/// The free-space loss adds a positive term, linear in its weight (the tiny
/// network's density is not zero in front of the synthetic head's true depth).
#[test]
fn the_free_space_loss_adds_a_term_linear_in_its_weight() {
    let trainable = Trainable::init(&tiny_config(), &Device::Cpu).unwrap();
    let head = synthetic_head();
    let total = |free_space_weight: f64| {
        let config = TrainConfig {
            free_space_weight,
            ..tiny_config()
        };
        loss_value(&trainable, &head, &config, 3)
    };
    let base = total(0.0);
    let (one, two) = (total(1.0) - base, total(2.0) - base);
    assert!(one > 1e-5, "free space adds to the loss ({one})");
    assert!(
        (two - 2.0 * one).abs() <= 1e-3 * two,
        "linear in its weight: {one} then {two}"
    );
}

/// A tensor's values as bits (`f64` as they are, `f32` widened), for exact comparisons.
fn tensor_bits(t: &Tensor) -> Vec<u64> {
    let flat = t.flatten_all().unwrap();
    if t.dtype() == candle_core::DType::F64 {
        flat.to_vec1::<f64>()
            .unwrap()
            .iter()
            .map(|v| v.to_bits())
            .collect()
    } else {
        flat.to_vec1::<f32>()
            .unwrap()
            .iter()
            .map(|v| u64::from(v.to_bits()))
            .collect()
    }
}

fn weights_bits(trainable: &Trainable) -> Vec<(String, Vec<u64>)> {
    trainable
        .weights()
        .unwrap()
        .into_iter()
        .map(|(n, t)| (n, tensor_bits(&t)))
        .collect()
}

fn named_bits(weights: Vec<(String, Tensor)>) -> Vec<(String, Vec<u64>)> {
    weights.into_iter().map(|(n, t)| (n, tensor_bits(&t))).collect()
}

/// With the weight average on (it is saved in the checkpoint and restored).
#[test]
fn a_resumed_run_equals_an_unbroken_one_bit_for_bit() {
    let config = TrainConfig {
        ema_decay: 0.9,
        ..tiny_config()
    };
    let heads = vec![synthetic_head()];
    let (n, m) = (2, 2);
    let unbroken = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam = unbroken.optimizer(&config).unwrap();
    for _ in 0..n + m {
        train_step(&unbroken, &mut adam, &heads, None, &config).unwrap();
    }

    let dir = tempfile::tempdir().unwrap();
    let first = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam1 = first.optimizer(&config).unwrap();
    let mut last = LossParts::default();
    for _ in 0..n {
        last = train_step(&first, &mut adam1, &heads, None, &config).unwrap();
    }
    let info = CheckpointInfo {
        step: adam1.steps(),
        train_secs: 1.0,
        config: config.clone(),
        last_loss: last,
    };
    save_checkpoint(dir.path(), &first, &adam1, &info).unwrap();
    drop((first, adam1));

    // A fresh process: different initial weights, then the checkpoint.
    let other = TrainConfig {
        seed: 99,
        ..config.clone()
    };
    let resumed = Trainable::init(&other, &Device::Cpu).unwrap();
    let mut adam2 = resumed.optimizer(&config).unwrap();
    let loaded = load_checkpoint(dir.path(), &resumed, &mut adam2).unwrap();
    assert_eq!(loaded.step, n as u64);
    for _ in 0..m {
        train_step(&resumed, &mut adam2, &heads, None, &config).unwrap();
    }
    assert_eq!(adam2.steps(), (n + m) as u64);
    assert!(
        weights_bits(&unbroken) == weights_bits(&resumed),
        "weights differ after resuming"
    );
    assert!(
        named_bits(adam.averaged_weights().unwrap()) == named_bits(adam2.averaged_weights().unwrap()),
        "weight averages differ after resuming"
    );
}

/// The weight average is `β·θ̄ + (1−β)·θ` after every step, starts from the weights
/// it is given (a fresh network, or a checkpoint saved without one), is absent when
/// off, and a decay outside [0, 1) is refused.
#[test]
fn the_weight_average_follows_each_step() {
    let beta = 0.75;
    let config = TrainConfig {
        ema_decay: beta,
        ..tiny_config()
    };
    let heads = vec![synthetic_head()];
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam = trainable.optimizer(&config).unwrap();
    let start = named_bits(trainable.weights().unwrap());
    assert!(start == named_bits(adam.averaged_weights().unwrap()));
    let values = |w: Vec<(String, Tensor)>| -> Vec<Vec<f32>> {
        w.into_iter()
            .map(|(_, t)| t.flatten_all().unwrap().to_vec1::<f32>().unwrap())
            .collect()
    };
    let mut expected = values(trainable.weights().unwrap());
    for _ in 0..3 {
        train_step(&trainable, &mut adam, &heads, None, &config).unwrap();
        for (e, w) in expected.iter_mut().zip(values(trainable.weights().unwrap())) {
            for (a, b) in e.iter_mut().zip(w) {
                *a = beta as f32 * *a + (1.0 - beta as f32) * b;
            }
        }
    }
    let average = values(adam.averaged_weights().unwrap());
    let worst = average
        .iter()
        .flatten()
        .zip(expected.iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "the average is off by {worst}");
    assert!(
        values(trainable.weights().unwrap()) != average,
        "the average is the weights"
    );

    // Saved without an average, resumed with one: it starts from the weights.
    let off = tiny_config();
    let plain = Trainable::init(&off, &Device::Cpu).unwrap();
    let mut plain_adam = plain.optimizer(&off).unwrap();
    assert!(plain_adam.averaged_weights().is_none());
    train_step(&plain, &mut plain_adam, &heads, None, &off).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let info = CheckpointInfo {
        step: 1,
        train_secs: 1.0,
        config: off.clone(),
        last_loss: LossParts::default(),
    };
    save_checkpoint(dir.path(), &plain, &plain_adam, &info).unwrap();
    let resumed = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut resumed_adam = resumed.optimizer(&config).unwrap();
    load_checkpoint(dir.path(), &resumed, &mut resumed_adam).unwrap();
    assert!(named_bits(resumed_adam.averaged_weights().unwrap()) == weights_bits(&plain));

    for bad in [1.0, -0.1, f64::NAN] {
        let config = TrainConfig {
            ema_decay: bad,
            ..tiny_config()
        };
        let message = config.validate().unwrap_err().to_string();
        assert!(message.contains("--ema-decay"), "{bad}: {message}");
    }
}

/// Tensors of a checkpoint file by name, as bits.
fn checkpoint_bits(dir: &std::path::Path) -> std::collections::BTreeMap<String, Vec<u64>> {
    let path = dir.join(nelf_train::trainer::CHECKPOINT_TENSORS);
    candle_core::safetensors::load(&path, &Device::Cpu)
        .unwrap()
        .into_iter()
        .map(|(n, t)| (n, tensor_bits(&t)))
        .collect()
}

#[test]
fn a_density_reset_changes_only_the_density_output_layers() {
    let config = tiny_config();
    let heads = vec![synthetic_head()];
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam = trainable.optimizer(&config).unwrap();
    for _ in 0..2 {
        train_step(&trainable, &mut adam, &heads, None, &config).unwrap();
    }
    let info = CheckpointInfo {
        step: adam.steps(),
        train_secs: 1.0,
        config: config.clone(),
        last_loss: LossParts::default(),
    };
    let dir = tempfile::tempdir().unwrap();
    save_checkpoint(dir.path(), &trainable, &adam, &info).unwrap();
    let before = checkpoint_bits(dir.path());
    let sigma = 0.05;
    let done = nelf_train::trainer::reset_density_heads(dir.path(), sigma, 0.0).unwrap();
    assert_eq!(done.step, 2);
    assert_eq!(done.layers.len(), 2, "{:?}", done.layers);
    let after = checkpoint_bits(dir.path());
    assert_eq!(
        before.keys().collect::<Vec<_>>(),
        after.keys().collect::<Vec<_>>()
    );
    let reset: Vec<&String> = before.keys().filter(|k| before[*k] != after[*k]).collect();
    // Each head's output weight and bias with their two Adam moments: 2 × 2 × 3.
    assert_eq!(reset.len(), 12, "{reset:?}");
    assert!(
        reset
            .iter()
            .all(|k| done.layers.iter().any(|l| k.contains(l.as_str()))),
        "{reset:?}"
    );

    // Loaded, the reset heads give σ everywhere (weights × 0: the bias alone).
    let resumed = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam2 = resumed.optimizer(&config).unwrap();
    assert_eq!(load_checkpoint(dir.path(), &resumed, &mut adam2).unwrap().step, 2);
    let head = &heads[0];
    let model = resumed.snapshot().unwrap();
    let encoded = nelf_train::forward::encode(&model, &head.capture.views).unwrap();
    for stage in [nelf_field::Stage::Coarse, nelf_field::Stage::Fine] {
        let pass = nelf_train::forward::run_points(
            &model,
            &encoded,
            &head.geometry,
            &head.distill_points,
            &head.distill_dirs,
            stage,
        )
        .unwrap()
        .unwrap();
        let density = pass
            .trace
            .density
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert!(!density.is_empty());
        assert!(
            density.iter().all(|d| (f64::from(*d) - sigma).abs() < 1e-6),
            "{density:?}"
        );
    }
    // And the run continues.
    train_step(&resumed, &mut adam2, &heads, None, &config).unwrap();
    assert!(nelf_train::trainer::reset_density_heads(dir.path(), 0.0, 1.0).is_err());
}

#[test]
fn a_damaged_checkpoint_is_refused_with_its_name() {
    let config = tiny_config();
    let dir = tempfile::tempdir().unwrap();
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let mut adam = trainable.optimizer(&config).unwrap();
    let info = CheckpointInfo {
        step: 0,
        train_secs: 0.0,
        config: config.clone(),
        last_loss: LossParts::default(),
    };
    save_checkpoint(dir.path(), &trainable, &adam, &info).unwrap();
    let path = dir.path().join(nelf_train::trainer::CHECKPOINT_TENSORS);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let err = load_checkpoint(dir.path(), &trainable, &mut adam)
        .unwrap_err()
        .to_string();
    assert!(err.contains("checkpoint.safetensors"), "{err}");
}

/// The tiny configuration, the synthetic head, a seeded network and its weights
/// exported to a file (in the returned folder).
fn exported_tiny_network() -> (
    TrainConfig,
    PreparedHead,
    Trainable,
    tempfile::TempDir,
    std::path::PathBuf,
) {
    let config = tiny_config();
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("weights.safetensors");
    nelf_train::run::export_weights(&trainable, &config, &path).unwrap();
    (config, synthetic_head(), trainable, dir, path)
}

/// The training renderer (gradients, candle ops) and the inference renderer
/// (`nelf_field::render`, fused kernels) give the same pixels for the same weights
/// and depths: what is trained is what bakes.
#[test]
fn the_training_renderer_matches_the_inference_renderer() {
    check_training_matches_inference(None);
}

/// With the Lambertian shading prior (normals from the density, the transport
/// normalised to the head's source lighting), the training forward pass and the
/// inference one still agree.
#[test]
fn the_training_renderer_matches_the_inference_renderer_with_the_shading_prior() {
    check_training_matches_inference(Some(nelf_field::prior::ShadingPrior::default()));
}

fn check_training_matches_inference(prior: Option<nelf_field::prior::ShadingPrior>) {
    use nelf_field::render::{NetRay, RayUniforms, render_rays as infer};
    use nelf_field::{Model, NelfConfig, Stage};
    use nelf_train::forward::{encode, irradiance, render_rays};

    let (config, head, trainable, _dir, path) = exported_tiny_network();
    let nelf_config = NelfConfig {
        coarse_samples: config.coarse_samples,
        fine_samples: config.fine_samples,
        ..NelfConfig::default()
    };
    let model = Model::load(&path, nelf_config, &Device::Cpu).unwrap();
    // The exported weights say what image size they were trained at.
    assert_eq!(model.working_image_size(), Some(config.image_size));
    let config = TrainConfig {
        shading_prior_mm: prior.map_or(0.0, |p| p.step_mm),
        shading_prior_weight: prior.map_or(0.5, |p| p.weight),
        ..config
    };
    let model = config.model_for_head(&model, &head.source_light_net).unwrap();
    let trained = config
        .model_for_head(&trainable.model, &head.source_light_net)
        .unwrap();
    assert_eq!(model.shading_prior(), prior);
    assert_eq!(trained.shading_prior(), prior);
    let target = &head.targets[1];
    let centre = head.capture.head_centre_net();
    let rays: Vec<NetRay> = (0..40)
        .map(|i| {
            let (x, y) = (8.0 + (i % 8) as f64 * 2.1, 9.0 + (i / 8) as f64 * 2.7);
            NetRay::through_pixel(&target.camera, x, y, centre, 200.0)
        })
        .collect();
    let uniforms = RayUniforms::stratified(rays.len(), config.coarse_samples, config.fine_samples);
    let want = infer(
        &model,
        &model.encode(&head.capture.views).unwrap(),
        &rays,
        &uniforms,
        &target.light_net,
    )
    .unwrap();
    let encoded = encode(&trained, &head.capture.views).unwrap();
    let irr = irradiance(&target.light_net, &Device::Cpu).unwrap();
    let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let mut opaque = 0;
    for (stage, composite) in [(Stage::Coarse, &want.coarse), (Stage::Fine, &want.fine)] {
        let got = render_rays(
            &trained,
            &encoded,
            &head.geometry,
            &rays,
            &composite.depth_samples,
            stage,
            &irr,
        )
        .unwrap();
        let close = |a: &[f32], b: &[f32], what: &str| {
            let scale = b.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert!((x - y).abs() <= 1e-4 * scale, "{what}[{i}]: {x} vs {y}");
            }
        };
        close(&flat(&got.rgb), &composite.rgb, "rgb");
        close(&flat(&got.alpha), &composite.alpha, "alpha");
        close(&flat(&got.depth), &composite.depth, "depth");
        opaque += composite.alpha.iter().filter(|a| **a > 0.5).count();
    }
    assert!(opaque > 0, "no ray hit anything: the comparison says nothing");
}

/// Saves `tensors` as a weights file at `path` and returns the error loading it gives.
fn load_error(tensors: &std::collections::HashMap<String, Tensor>, path: &std::path::Path) -> String {
    candle_core::safetensors::save(tensors, path).unwrap();
    nelf_field::Model::load(path, nelf_field::NelfConfig::default(), &Device::Cpu)
        .unwrap_err()
        .to_string()
}

/// Weights trained through the shading prior say which one, and weights trained
/// without it say nothing; a file that gives half of it, or a prior out of range,
/// is refused, naming the file and the keys.
#[test]
fn weights_record_the_shading_prior_they_trained_through() {
    use nelf_field::prior::ShadingPrior;
    use nelf_field::{Model, NelfConfig};

    let dir = tempfile::tempdir().unwrap();
    let prior = ShadingPrior {
        step_mm: 6.0,
        weight: 0.25,
    };
    for trained in [None, Some(prior)] {
        let config = TrainConfig {
            shading_prior_mm: trained.map_or(0.0, |p| p.step_mm),
            shading_prior_weight: trained.map_or(0.5, |p| p.weight),
            ..tiny_config()
        };
        let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
        let path = dir.path().join("weights.safetensors");
        nelf_train::run::export_weights(&trainable, &config, &path).unwrap();
        let model = Model::load(&path, NelfConfig::default(), &Device::Cpu).unwrap();
        assert_eq!(model.trained_shading_prior(), trained);
    }
    let good = dir.path().join("weights.safetensors");
    let tensors = candle_core::safetensors::load(&good, &Device::Cpu).unwrap();
    let step_key = nelf_field::model::SHADING_PRIOR_MM_KEY;
    let weight_key = nelf_field::model::SHADING_PRIOR_WEIGHT_KEY;
    let damages: [&[(&str, f32)]; 3] = [&[(weight_key, 2.0)], &[(step_key, -1.0)], &[(step_key, f32::NAN)]];
    for damage in damages {
        let mut damaged = tensors.clone();
        for (key, value) in damage {
            damaged.insert((*key).to_string(), Tensor::new(&[*value], &Device::Cpu).unwrap());
        }
        let err = load_error(&damaged, &dir.path().join("damaged.safetensors"));
        assert!(
            err.contains(step_key) && err.contains("damaged.safetensors"),
            "{damage:?}: {err}"
        );
    }
    let mut half = tensors.clone();
    half.remove(weight_key);
    let err = load_error(&half, &dir.path().join("half.safetensors"));
    assert!(
        err.contains(weight_key) && err.contains("half.safetensors"),
        "{err}"
    );
}

/// Weights trained with source-relative lighting say so, and a field over them
/// divides its light transport by the capture's source power when told it; weights in
/// absolute units ignore the power; a power that is no positive number is refused.
#[test]
fn source_relative_weights_say_so_and_their_bake_takes_the_source_power() {
    use nelf_field::{Model, NelfConfig, NelfField};
    use nelf_scene::field::{FieldSource, ViewPolicy};

    let head = synthetic_head();
    let dir = tempfile::tempdir().unwrap();
    let mut fields = Vec::new();
    for relative in [false, true] {
        let config = TrainConfig {
            source_relative_light: relative,
            ..tiny_config()
        };
        let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
        let path = dir.path().join(format!("weights-{relative}.safetensors"));
        nelf_train::run::export_weights(&trainable, &config, &path).unwrap();
        let model = Model::load(&path, NelfConfig::default(), &Device::Cpu).unwrap();
        assert_eq!(model.source_relative_light(), relative);
        let field = NelfField::new(model, &head.capture).unwrap();
        fields.push(field);
    }
    // Damaged metadata is refused, naming the file and the key.
    let good = dir.path().join("weights-true.safetensors");
    let mut tensors = candle_core::safetensors::load(&good, &Device::Cpu).unwrap();
    for (key, value) in [
        (nelf_field::model::SOURCE_RELATIVE_LIGHT_KEY, 0.5f32),
        (nelf_field::model::WORKING_IMAGE_SIZE_KEY, 7.0),
    ] {
        let original = tensors.insert(key.to_string(), Tensor::new(&[value], &Device::Cpu).unwrap());
        let err = load_error(&tensors, &dir.path().join("damaged.safetensors"));
        assert!(err.contains(key) && err.contains("damaged.safetensors"), "{err}");
        tensors.insert(key.to_string(), original.unwrap());
    }
    let centre = head.capture.head_centre_m.as_vec3();
    let points: Vec<glam::Vec3> = (0..16)
        .map(|i| {
            centre
                + glam::Vec3::new(
                    0.004 * (i % 4) as f32 - 0.006,
                    0.004 * (i / 4) as f32 - 0.006,
                    0.03,
                )
        })
        .collect();
    let view = ViewPolicy::TowardPoint(head.capture.cameras[0].centre().as_vec3());
    let evaluate = |field: &NelfField| {
        let mut density = vec![0.0f32; points.len()];
        let mut lt = vec![0.0f32; points.len() * 384];
        field.evaluate(&points, &view, &mut density, &mut lt).unwrap();
        (density, lt)
    };
    for (relative, field) in [false, true].into_iter().zip(fields) {
        let (density, lt) = evaluate(&field);
        assert!(lt.iter().any(|v| *v > 0.0), "the points are inside the hull");
        assert_eq!(field.light_transport_scale(), 1.0);
        let powered = field.with_source_light_power(2.5).unwrap();
        let (density_p, lt_p) = evaluate(&powered);
        assert_eq!(density, density_p, "the power changes no density");
        let scale = if relative { 1.0 / 2.5 } else { 1.0 };
        assert_eq!(powered.light_transport_scale(), scale as f32);
        for (a, b) in lt.iter().zip(&lt_p) {
            assert!(
                (a * scale as f32 - b).abs() <= 1e-6 * a.abs().max(1e-6),
                "{a} × {scale} vs {b}"
            );
        }
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let model = powered.model().clone();
            let field = NelfField::new(model, &head.capture).unwrap();
            assert!(
                field.with_source_light_power(bad).is_err(),
                "power {bad} is refused"
            );
        }
    }
}

/// The view-count table scores a network with fewer source views: rows in the
/// order asked, finite scores, the flat-colour baseline the same in every row (it
/// does not see the source views), and impossible counts refused.
#[test]
fn the_view_count_table_scores_subsets_of_the_source_views() {
    use nelf_train::eval::{first_views, view_count_table};

    let config = tiny_config();
    let head = synthetic_head();
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let model = trainable.snapshot().unwrap();
    let all = head.capture.views.views();
    let two = first_views(&head, 2).unwrap();
    assert_eq!(two.capture.views.views(), 2);
    assert_eq!(
        two.capture.views.images.len() * all,
        head.capture.views.images.len() * 2
    );
    assert!(first_views(&head, 1).is_err());
    assert!(first_views(&head, all + 1).is_err());
    let rows = view_count_table(&model, &[head], &config, &[2, all], None, None, None).unwrap();
    assert_eq!(rows.iter().map(|r| r.views).collect::<Vec<_>>(), [2, all]);
    for r in &rows {
        assert!(
            r.psnr.is_finite() && r.foreground_psnr.is_finite() && r.ssim.is_finite(),
            "{r:?}"
        );
        assert_eq!(r.heads, 1);
        // The source-view calibrated scores: finite, with a gain in the searched range.
        assert!(
            r.calibrated_psnr.is_finite()
                && r.calibrated_foreground_psnr.is_finite()
                && r.calibrated_ssim.is_finite(),
            "{r:?}"
        );
        let (lo, hi) = nelf_field::calibrate::GAIN_RANGE;
        assert!((f64::from(lo)..=f64::from(hi)).contains(&r.median_gain), "{r:?}");
        // The source-normalised rendering is scored too, and differs from the raw one.
        assert!(
            r.normalised_psnr.is_finite()
                && r.normalised_foreground_psnr.is_finite()
                && r.normalised_ssim.is_finite()
                && r.normalised_psnr != r.psnr,
            "{r:?}"
        );
    }
    assert_eq!(rows[0].flat_psnr, rows[1].flat_psnr);
    assert_eq!(rows[0].flat_ssim, rows[1].flat_ssim);
}

#[test]
fn the_srgb_colour_loss_scores_as_8_bit_srgb_does_and_has_finite_gradients() {
    use candle_core::Var;
    use nelf_train::forward::{srgb_encode, srgb_l2};
    // The encoding: the linear toe, the power curve, clamping at both ends.
    let x = Tensor::new(&[0.0f32, 0.001, 0.003_130_8, 0.18, 1.0, 4.0, -1.0], &Device::Cpu).unwrap();
    let got = srgb_encode(&x).unwrap().to_vec1::<f32>().unwrap();
    let want = [0.0, 0.01292, 0.040_45, 0.461_356, 1.0, 1.0, 0.0];
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-4, "{got:?}");
    }
    // The same curve as the project's scalar encoder, over a sweep across the knee.
    let sweep: Vec<f32> = (0..=400).map(|i| -0.1 + 1.2 * i as f32 / 400.0).collect();
    let encoded = srgb_encode(&Tensor::new(sweep.as_slice(), &Device::Cpu).unwrap())
        .unwrap()
        .to_vec1::<f32>()
        .unwrap();
    for (x, e) in sweep.iter().zip(&encoded) {
        let scalar = nelf_scene::mesh_io::linear_to_srgb(*x);
        assert!((e - scalar).abs() < 1e-6, "{x}: {e} vs {scalar}");
    }
    // Gradients stay finite at black (where x^(1/2.4) has an infinite slope) and are
    // zero where both sides are clamped.
    let a = Var::new(&[0.0f32, 0.0, 0.5, 2.0], &Device::Cpu).unwrap();
    let b = Tensor::new(&[0.0f32, 0.2, 0.25, 3.0], &Device::Cpu).unwrap();
    let loss = srgb_l2(a.as_tensor(), &b).unwrap();
    let grad = loss
        .backward()
        .unwrap()
        .get(&a)
        .unwrap()
        .to_vec1::<f32>()
        .unwrap();
    assert!(grad.iter().all(|g| g.is_finite()), "{grad:?}");
    assert!(grad[1] < 0.0 && grad[2] > 0.0 && grad[3] == 0.0, "{grad:?}");
}

/// `--distill-radiance-loss srgb-l2` swaps the distillation's radiance term for the
/// squared error of clamped sRGB: a positive term, linear in `--distill-weight`, and
/// not the L1 one (the tiny network's radiance is not the synthetic head's).
#[test]
fn the_distillation_radiance_loss_can_be_srgb_l2() {
    let trainable = Trainable::init(&tiny_config(), &Device::Cpu).unwrap();
    let head = synthetic_head();
    let total = |distill_weight: f64, loss: ColourLoss| {
        let config = TrainConfig {
            distill_weight,
            distill_sigma_weight: Some(0.0),
            distill_radiance_loss: loss,
            ..tiny_config()
        };
        loss_value(&trainable, &head, &config, 5)
    };
    let images = total(0.0, ColourLoss::SrgbL2);
    let (half, one) = (
        total(0.5, ColourLoss::SrgbL2) - images,
        total(1.0, ColourLoss::SrgbL2) - images,
    );
    let l1 = total(1.0, ColourLoss::L1) - images;
    assert!(half > 1e-6, "the sRGB radiance term adds to the loss ({half})");
    assert!(
        (one - 2.0 * half).abs() <= 1e-3 * one,
        "linear in its weight: {half} then {one}"
    );
    assert!(
        (one - l1).abs() > 1e-4 * l1.max(one),
        "not the L1 term: {one} against {l1}"
    );
}

/// The transport-shape term has its own weight, adds to the loss and is linear in
/// its weight. Off, the loss (with the σ term on, so the distillation pass runs) is
/// that of the head without the term's lightings and radiances, bit for bit; on, such
/// a head is an error, not a term silently skipped.
#[test]
fn the_transport_shape_term_is_linear_in_its_own_weight() {
    let trainable = Trainable::init(&tiny_config(), &Device::Cpu).unwrap();
    let head = synthetic_head();
    let config = |shape: f64| TrainConfig {
        distill_weight: 0.0,
        distill_sigma_weight: Some(0.0),
        distill_shape_weight: shape,
        ..tiny_config()
    };
    let total = |shape: f64| loss_value(&trainable, &head, &config(shape), 5);
    let bare = PreparedHead {
        shape_lights: Vec::new(),
        shape_radiance: Vec::new(),
        ..synthetic_head()
    };
    let with_sigma = TrainConfig {
        distill_sigma_weight: Some(0.1),
        ..config(0.0)
    };
    assert_eq!(
        loss_value(&trainable, &head, &with_sigma, 5).to_bits(),
        loss_value(&trainable, &bare, &with_sigma, 5).to_bits()
    );
    let refused = step_loss(&trainable.model, &bare, &config(1.0), &mut step_rng(5, 0));
    assert!(
        refused
            .as_ref()
            .is_err_and(|e| e.to_string().contains("distill-shape-weight")),
        "a head without shape lightings: {:?}",
        refused.map(|(_, parts)| parts)
    );
    let images = total(0.0);
    let (half, one) = (total(0.5) - images, total(1.0) - images);
    assert!(half > 1e-6, "the shape term adds to the loss ({half})");
    assert!(
        (one - 2.0 * half).abs() <= 1e-3 * one,
        "linear in its weight: {half} then {one}"
    );
}

/// The shape term's relit colour is the truth's radiance when the transport is the
/// truth's, and the same for that transport scaled by any positive factor per point
/// and channel (its colour), up to the ratio's floor: it sees only the shape.
#[test]
fn relit_by_shape_gives_the_truth_for_its_shape_at_any_colour() {
    let (n, k) = (5usize, 4usize);
    let mut rng = step_rng(11, 3);
    let mut draw = |count: usize, lo: f32, hi: f32| -> Vec<f32> {
        (0..count).map(|_| rng.random_range(lo..hi)).collect()
    };
    let truth = draw(n * 384, 0.0, 0.2);
    let source_light = draw(384, 0.5, 2.0);
    let lights = draw(k * 384, 0.0, 3.0);
    let scales = draw(n * 3, 0.3, 4.0);
    let dot =
        |t: &[f32], l: &[f32], c: usize| -> f32 { (0..128).map(|i| t[c * 128 + i] * l[c * 128 + i]).sum() };
    let true_source: Vec<f32> = (0..n)
        .flat_map(|p| {
            (0..3)
                .map(|c| dot(&truth[p * 384..(p + 1) * 384], &source_light, c))
                .collect::<Vec<_>>()
        })
        .collect();
    let want: Vec<f32> = (0..n)
        .flat_map(|p| {
            let t = &truth[p * 384..(p + 1) * 384];
            (0..k)
                .flat_map(|j| {
                    (0..3)
                        .map(|c| dot(t, &lights[j * 384..(j + 1) * 384], c))
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let scaled: Vec<f32> = truth
        .iter()
        .enumerate()
        .map(|(i, v)| v * scales[(i / 384) * 3 + (i % 384) / 128])
        .collect();
    let device = Device::Cpu;
    let relit = |lt: &[f32]| -> Vec<f32> {
        relit_by_shape(
            &Tensor::from_slice(lt, (n, 3, 128), &device).unwrap(),
            &Tensor::from_slice(&source_light, (3, 128), &device).unwrap(),
            &Tensor::from_slice(&lights, (k, 3, 128), &device).unwrap(),
            &Tensor::from_slice(&true_source, (n, 1, 3), &device).unwrap(),
        )
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f32>()
        .unwrap()
    };
    // The floor ε = 0.01 against source radiances of ~6–25: a relative error ≤ 0.2 %.
    for (name, lt) in [("the truth", &truth), ("the truth recoloured", &scaled)] {
        let got = relit(lt);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= 2e-3 * w.abs() + 1e-5, "{name}: {g} against {w}");
        }
    }
    // A transport of another shape (the source lighting's pattern moved) is not.
    let mut other = truth.clone();
    other.rotate_left(17);
    let got = relit(&other);
    let worst = got
        .iter()
        .zip(&want)
        .map(|(g, w)| (g - w).abs() / w.abs().max(1e-3))
        .fold(0.0f32, f32::max);
    assert!(
        worst > 0.05,
        "another shape relights differently (worst relative error {worst})"
    );
}

/// Test-time fine-tuning: weights read back from their file give the network they
/// were written from, a few steps on the source views lower the colour loss there,
/// and leaving a view out removes exactly that view.
#[test]
fn fine_tuning_on_the_source_views_lowers_their_colour_loss() {
    use nelf_train::finetune::{FineTuneConfig, fine_tune, source_targets, without_view};
    use rand::SeedableRng;

    let (config, head, trainable, _dir, path) = exported_tiny_network();
    let bytes = std::fs::read(&path).unwrap();
    let loaded =
        Trainable::from_safetensors_bytes(&bytes, &path, *trainable.model.config(), &Device::Cpu).unwrap();
    let targets = source_targets(&head);
    assert_eq!(targets.len(), head.capture.views.views());
    assert_eq!(targets[1].light_net, head.source_light_net);
    let colour_loss = |model: &nelf_field::Model| -> f64 {
        targets
            .iter()
            .map(|t| {
                let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
                nelf_train::trainer::step_loss_on(model, &head, t, &config, &mut rng)
                    .unwrap()
                    .1
                    .rgb_fine
            })
            .sum()
    };
    let before = colour_loss(&trainable.model);
    assert_eq!(
        colour_loss(&loaded.model),
        before,
        "the weights changed on their way through the file"
    );
    let tune = FineTuneConfig {
        steps: 30,
        rays: 64,
        lr_mlp: 1e-3,
        lr_encoder: 1e-3,
        ..FineTuneConfig::default()
    };
    let mut seen = 0;
    let (tuned, report) = fine_tune(&loaded, &head, &tune, &config, |_, _| seen += 1).unwrap();
    assert_eq!((seen, report.steps), (30, 30));
    let after = colour_loss(&tuned);
    eprintln!(
        "fine-tuning: colour loss {before:.5} -> {after:.5} ({:.1} s)",
        report.secs
    );
    assert!(after < 0.8 * before, "colour loss {before} -> {after}");

    let two = without_view(&head, 1).unwrap();
    let pixels = head.capture.views.width * head.capture.views.height;
    assert_eq!(two.capture.views.views(), 2);
    assert_eq!(two.capture.views.cameras[1], head.capture.views.cameras[2]);
    assert_eq!(
        two.capture.views.masks[pixels..],
        head.capture.views.masks[2 * pixels..]
    );
    assert!(without_view(&head, 0).is_err(), "view 0 holds the light frame");
    assert!(without_view(&two, 1).is_err(), "the network needs 2 views");
}

// The domain-adaptation hook (`nelf_train::domain`), on a real photograph: the
// astronaut portrait of `data/metrics` (NASA, public domain), its background blacked
// out beyond an ellipse about the face, as a matted portrait set would come.

/// A folder holding the matted astronaut portrait (and `extra` more files).
fn real_portraits(extra: &[(&str, &[u8])]) -> tempfile::TempDir {
    let source = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/metrics/astronaut.png");
    let mut photo = image::open(source)
        .unwrap_or_else(|e| panic!("{source}: {e} (the test's real portrait is missing)"))
        .to_rgb8();
    let (w, h) = photo.dimensions();
    for (x, y, p) in photo.enumerate_pixels_mut() {
        let dx = (x as f32 - 0.45 * w as f32) / (0.3 * w as f32);
        let dy = (y as f32 - 0.35 * h as f32) / (0.38 * h as f32);
        if dx * dx + dy * dy > 1.0 {
            *p = image::Rgb([0, 0, 0]);
        }
    }
    let dir = tempfile::tempdir().unwrap();
    photo.save(dir.path().join("astronaut.png")).unwrap();
    for (name, bytes) in extra {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    dir
}

/// A checkpoint of `trainable` and `adam` as they stand, in a fresh folder.
fn checkpoint_of(
    trainable: &Trainable,
    adam: &nelf_train::adam::Adam,
    config: &TrainConfig,
    last_loss: LossParts,
) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let info = CheckpointInfo {
        step: adam.steps(),
        train_secs: 1.0,
        config: config.clone(),
        last_loss,
    };
    save_checkpoint(dir.path(), trainable, adam, &info).unwrap();
    dir
}

fn hook_config(dir: &std::path::Path) -> TrainConfig {
    TrainConfig {
        real_images: Some(dir.to_path_buf()),
        ..tiny_config()
    }
}

#[test]
fn the_domain_head_has_the_official_layout() {
    let dir = real_portraits(&[]);
    let trainable = Trainable::init(&hook_config(dir.path()), &Device::Cpu).unwrap();
    let c0 = hook_config(dir.path()).architecture().unwrap().encoder_channels[0];
    let head: Vec<(String, Vec<usize>)> = trainable
        .weights()
        .unwrap()
        .into_iter()
        .filter(|(n, _)| nelf_train::domain::is_head_variable(n))
        .map(|(n, t)| (n, t.dims().to_vec()))
        .collect();
    let p = "image_encoder.reproduces.";
    let want: Vec<(String, Vec<usize>)> = [
        ("0.act.weight", vec![2 * c0]),
        ("0.conv.bias", vec![c0]),
        ("0.conv.weight", vec![c0, 2 * c0, 3, 3]),
        ("0.norm.bias", vec![2 * c0]),
        ("0.norm.weight", vec![2 * c0]),
        ("1.act.weight", vec![c0]),
        ("1.conv.bias", vec![c0]),
        ("1.conv.weight", vec![c0, c0, 3, 3]),
        ("1.norm.bias", vec![c0]),
        ("1.norm.weight", vec![c0]),
        ("2.act.weight", vec![c0]),
        ("2.conv.bias", vec![3]),
        ("2.conv.weight", vec![3, c0, 1, 1]),
        ("2.norm.bias", vec![c0]),
        ("2.norm.weight", vec![c0]),
        ("3.norm.bias", vec![3]),
        ("3.norm.weight", vec![3]),
    ]
    .into_iter()
    .map(|(n, d)| (format!("{p}{n}"), d))
    .collect();
    assert_eq!(head, want);
    // Without the hook there is no head, and the network's own weights are the same.
    let plain = Trainable::init(&tiny_config(), &Device::Cpu).unwrap();
    let with_hook: Vec<_> = weights_bits(&trainable)
        .into_iter()
        .filter(|(n, _)| !nelf_train::domain::is_head_variable(n))
        .collect();
    assert!(
        with_hook == weights_bits(&plain),
        "the hook changed the network's initial weights"
    );
}

#[test]
fn real_portraits_load_and_bad_folders_are_refused() {
    use nelf_train::domain::RealImages;
    let dir = real_portraits(&[("notes.txt", b"not an image")]);
    let real = RealImages::load(dir.path(), 32).unwrap();
    assert_eq!((real.len(), real.size()), (1, 32));
    let (path, pixels) = real.get(0).unwrap();
    assert!(path.ends_with("astronaut.png"));
    assert_eq!(pixels.len(), 32 * 32 * 3);
    assert!(pixels.iter().all(|v| (0.0..=1.0).contains(v)));
    let lit = pixels
        .chunks_exact(3)
        .filter(|p| p.iter().any(|&v| v > 0.0))
        .count();
    assert!((250..800).contains(&lit), "{lit} foreground pixels of 1024");
    assert!(real.pick(0, 7) < real.len());

    // A soft alpha matte over a white background: transparent comes out black, the
    // opaque middle white, the soft rim between.
    let matted = tempfile::tempdir().unwrap();
    let matte = image::RgbaImage::from_fn(64, 48, |x, y| {
        let r = ((x as f32 - 32.0).powi(2) + (y as f32 - 24.0).powi(2)).sqrt();
        image::Rgba([255, 255, 255, (255.0 * (16.0 - r).clamp(0.0, 1.0)) as u8])
    });
    matte.save(matted.path().join("matte.png")).unwrap();
    let soft = RealImages::load(matted.path(), 32).unwrap();
    let (_, px) = soft.get(0).unwrap();
    let at = |x: usize, y: usize| px[3 * (y * 32 + x)];
    assert_eq!(at(0, 0), 0.0);
    assert_eq!(at(31, 31), 0.0);
    assert!(at(16, 16) > 0.99, "{}", at(16, 16));
    assert!(px.iter().any(|&v| v > 0.05 && v < 0.95), "no soft rim");

    let empty = tempfile::tempdir().unwrap();
    let err = RealImages::load(empty.path(), 32).unwrap_err().to_string();
    assert!(
        err.contains(&empty.path().display().to_string()) && err.contains("no real portraits"),
        "{err}"
    );
    let broken = real_portraits(&[("broken.png", b"\x89PNG\r\n\x1a\n truncated")]);
    let err = RealImages::load(broken.path(), 32).unwrap_err().to_string();
    assert!(err.contains("broken.png"), "{err}");
    let black = tempfile::tempdir().unwrap();
    image::RgbImage::new(40, 30)
        .save(black.path().join("night.png"))
        .unwrap();
    let err = RealImages::load(black.path(), 32).unwrap_err().to_string();
    assert!(err.contains("night.png") && err.contains("black"), "{err}");
    let missing = dir.path().join("absent");
    let err = RealImages::load(&missing, 32).unwrap_err().to_string();
    assert!(err.contains("absent"), "{err}");
}

#[test]
fn the_domain_term_trains_the_encoder_and_its_head() {
    use nelf_train::domain::{RealImages, reproduction_loss};
    let dir = real_portraits(&[]);
    let config = TrainConfig {
        lr_encoder: 3e-3,
        ..hook_config(dir.path())
    };
    let real = RealImages::load(dir.path(), 32).unwrap();
    let (_, pixels) = real.get(0).unwrap();
    let trainable = Trainable::init(&config, &Device::Cpu).unwrap();
    let head = trainable.reproduce.as_ref().unwrap();
    let mut adam = trainable.optimizer(&config).unwrap();
    let mut losses = Vec::new();
    for step in 0..8 {
        let loss = reproduction_loss(&trainable.model, head, pixels, 32).unwrap();
        losses.push(loss.to_scalar::<f32>().unwrap());
        let grads = loss.backward().unwrap();
        if step == 0 {
            // The gradient reaches the encoder's first stage, not only the head.
            let first = trainable
                .varmap
                .data()
                .lock()
                .unwrap()
                .get("image_encoder.resblocks.0.normactconv0.conv.weight")
                .unwrap()
                .clone();
            let g = grads.get(first.as_tensor()).unwrap();
            assert!(g.abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap() > 0.0);
        }
        adam.step(&grads).unwrap();
    }
    assert!(
        losses[7] < 0.8 * losses[0],
        "reproduction loss {losses:?} did not fall"
    );
}

#[test]
fn the_domain_term_adds_to_a_step_and_resumes_bit_for_bit() {
    use nelf_train::domain::RealImages;
    let dir = real_portraits(&[]);
    let heads = vec![synthetic_head()];
    let real = RealImages::load(dir.path(), 32).unwrap();
    let plain_config = tiny_config();
    let hook = TrainConfig {
        real_weight: 0.5,
        ..hook_config(dir.path())
    };

    // The step's own loss is the run's without the hook; the term adds λ_r × its value.
    let plain = Trainable::init(&plain_config, &Device::Cpu).unwrap();
    let mut plain_adam = plain.optimizer(&plain_config).unwrap();
    let without = train_step(&plain, &mut plain_adam, &heads, None, &plain_config).unwrap();
    let unbroken = Trainable::init(&hook, &Device::Cpu).unwrap();
    let mut adam = unbroken.optimizer(&hook).unwrap();
    let with = train_step(&unbroken, &mut adam, &heads, Some(&real), &hook).unwrap();
    assert!(with.real > 0.0);
    assert_eq!(with.rgb_fine.to_bits(), without.rgb_fine.to_bits());
    assert!((with.total - (without.total + 0.5 * with.real)).abs() < 1e-9);
    // A network made with the hook refuses a step without portraits, and the reverse.
    assert!(train_step(&unbroken, &mut adam, &heads, None, &hook).is_err());
    assert!(train_step(&plain, &mut plain_adam, &heads, Some(&real), &plain_config).is_err());
    assert_eq!((adam.steps(), plain_adam.steps()), (1, 1));
    let last = train_step(&unbroken, &mut adam, &heads, Some(&real), &hook).unwrap();

    // Saved after two steps and resumed for two more: the unbroken four, bit for bit.
    let ckpt = checkpoint_of(&unbroken, &adam, &hook, last);
    let resumed = Trainable::init(
        &TrainConfig {
            seed: 5,
            ..hook.clone()
        },
        &Device::Cpu,
    )
    .unwrap();
    let mut adam2 = resumed.optimizer(&hook).unwrap();
    load_checkpoint(ckpt.path(), &resumed, &mut adam2).unwrap();
    for _ in 0..2 {
        train_step(&unbroken, &mut adam, &heads, Some(&real), &hook).unwrap();
        train_step(&resumed, &mut adam2, &heads, Some(&real), &hook).unwrap();
    }
    assert!(
        weights_bits(&unbroken) == weights_bits(&resumed),
        "weights differ after resuming"
    );

    // A checkpoint saved without the hook continues with it: the head starts afresh.
    let plain_ckpt = checkpoint_of(&plain, &plain_adam, &plain_config, without);
    let turned_on = Trainable::init(&hook, &Device::Cpu).unwrap();
    let mut adam3 = turned_on.optimizer(&hook).unwrap();
    load_checkpoint(plain_ckpt.path(), &turned_on, &mut adam3).unwrap();
    train_step(&turned_on, &mut adam3, &heads, Some(&real), &hook).unwrap();

    // Weights exported with the head load as a network (the head is ignored there).
    let file = ckpt.path().join("weights.safetensors");
    let named: std::collections::HashMap<String, Tensor> = unbroken.weights().unwrap().into_iter().collect();
    candle_core::safetensors::save(&named, &file).unwrap();
    let bytes = std::fs::read(&file).unwrap();
    let model =
        nelf_field::Model::from_safetensors_bytes(&bytes, &file, *unbroken.model.config(), &Device::Cpu);
    assert!(model.is_ok(), "{:?}", model.err());
}
