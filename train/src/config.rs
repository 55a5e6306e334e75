//! The one configuration of a training run (`nelf train run`), saved beside its
//! checkpoint and with its weights: the network's widths, the image and ray budget
//! per step, the optimiser and the losses of Sun et al. 2021 (§4.3: L1 rendering,
//! depth ÷ 200 mm, alpha, log-L1 lighting; novel-light mode 70 %, self-rotation 30 %;
//! Adam, 10⁻⁴ for the per-point MLPs and 2·10⁻⁴ for the encoder) plus an optional
//! 3D distillation loss on σ and T at points near the surface.

use std::path::PathBuf;

use nelf_field::{Architecture, Model, NelfConfig};
use serde::{Deserialize, Serialize};

use crate::error::TrainError;

/// How rendered colours are compared with the truth.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColourLoss {
    /// `|c − c*|` on linear HDR colours (the paper's). Under uncertainty it seeks the
    /// median, which lies below the mean for right-skewed radiance: a network that
    /// cannot yet tell the shading renders too dark.
    #[default]
    L1,
    /// `(srgb(c) − srgb(c*))²` with colours clamped to [0, 1]: the mean of what 8-bit
    /// sRGB PSNR scores.
    SrgbL2,
}

/// Settings of `nelf train run`.
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Dataset folder written by `nelf train data`.
    #[arg(long, default_value = "out/train-data")]
    pub data: PathBuf,
    /// Run folder: checkpoint, configuration, validation log and curve.
    #[arg(long, short = 'o', default_value = "out/train-run")]
    pub out: PathBuf,
    /// Network widths: `official` (checkpoint-compatible) or `small` / `tiny`
    /// (fewer channels; see [`TrainConfig::architecture`]).
    #[arg(long, default_value = "small")]
    pub arch: String,
    /// Side of the square images the network sees, pixels (a multiple of 16 that
    /// divides the dataset's size; captures are box-filtered down to it).
    #[arg(long, default_value_t = 64)]
    pub image_size: usize,
    /// Target rays per step (the defaults suit this machine's CPU; a GPU takes
    /// 1024 rays of 64 + 64 samples).
    #[arg(long, default_value_t = 128)]
    pub rays: usize,
    /// Coarse samples per ray.
    #[arg(long, default_value_t = 32)]
    pub coarse_samples: usize,
    /// Importance samples per ray for the fine network (0: coarse network only).
    #[arg(long, default_value_t = 16)]
    pub fine_samples: usize,
    /// Steps to train to (a resumed run continues up to this many).
    #[arg(long, default_value_t = 100_000)]
    pub steps: u64,
    /// Stop after this many seconds of training in this invocation (0: no limit).
    #[arg(long, default_value_t = 0.0)]
    pub max_secs: f64,
    /// Adam step size of the per-point networks.
    #[arg(long, default_value_t = 1e-4)]
    pub lr_mlp: f64,
    /// Adam step size of the image encoder.
    #[arg(long, default_value_t = 2e-4)]
    pub lr_encoder: f64,
    /// The colour loss: `l1` (the paper's, on linear HDR colours) or `srgb-l2` (squared
    /// error of the colours as they are scored, sRGB clamped to [0, 1]).
    #[arg(long, value_enum, default_value_t = ColourLoss::L1)]
    #[serde(default)]
    pub colour_loss: ColourLoss,
    /// Give the network every lighting in units of the head's source lighting: each
    /// map divided by the source map's mean radiance (`Σ Ω L / 4π`). The images cannot
    /// tell a bright head under a dim light from a dim head under a bright one, so the
    /// absolute power of the source lighting is unknowable from them; without this the
    /// network must guess it (on `nelf train data`'s heads its spread is ×1.85, one
    /// geometric standard deviation). Weights trained so record it
    /// (`nelf.source_relative_light`) and bakes divide their light transport by the
    /// capture's source power where the capture knows its lighting.
    #[arg(long)]
    #[serde(default)]
    pub source_relative_light: bool,
    /// Share of steps in novel-light mode (the rest: self-rotation).
    #[arg(long, default_value_t = 0.7)]
    pub novel_light_share: f64,
    /// Weight of the depth loss (|depth − true depth| / 200 mm, inside the true mask).
    #[arg(long, default_value_t = 0.1)]
    pub depth_weight: f64,
    /// Weight of the alpha loss (|alpha − true alpha|).
    #[arg(long, default_value_t = 0.1)]
    pub alpha_weight: f64,
    /// Weight of the log-L1 lighting loss on the source-light estimate.
    #[arg(long, default_value_t = 0.1)]
    pub light_weight: f64,
    /// Weight of the 3D distillation loss (σ and T at points near the surface; 0: off).
    #[arg(long, default_value_t = 0.0)]
    pub distill_weight: f64,
    /// How the distillation compares radiance (`Σ T·L` against `Σ T*·L` under each of
    /// the head's lightings): `l1` (linear HDR) or `srgb-l2` (clamped sRGB, squared).
    /// What each form did to validation: `docs/measurements/settings.md`.
    #[arg(long, value_enum, default_value_t = ColourLoss::L1)]
    #[serde(default)]
    pub distill_radiance_loss: ColourLoss,
    /// Weight of the distillation's σ term alone (default: `--distill-weight`). The σ
    /// term is `|log(1 + σ·1 mm) − log(1 + σ*·1 mm)|`, whose gradient `1/(1 + σ)` is
    /// weak where a network's density has saturated: `nelf-small-run` at step 7457
    /// had σ ≈ 13–21/mm at true-empty points inside the hull (its geometry the visual
    /// hull, 18 mm of mean depth error) with the σ term at 0.1.
    #[arg(long)]
    #[serde(default)]
    pub distill_sigma_weight: Option<f64>,
    /// Weight of the distillation's transport-shape term (0: off). At each
    /// distillation point it relights the truth's colour under the source lighting
    /// `L_S` by the network's transport, `(T*·L_S)·(T·L)/(T·L_S)`, and compares that
    /// with the truth's `T*·L` (the loss kind of `--distill-radiance-loss`) under the
    /// head's target lightings and [`crate::trainer::SHAPE_PROBES`] fixed procedural
    /// ones (sun, room and studio maps, scaled to the source's mean radiance). It
    /// trains only the shape of `T` across lightings, what a bake's source
    /// normalisation keeps from the network (why: `docs/measurements/settings.md`).
    #[arg(long, default_value_t = 0.0)]
    #[serde(default)]
    pub distill_shape_weight: f64,
    /// Weight of the free-space loss: `log(1 + σ·1 mm)` at the ray samples the truth
    /// knows are empty (every sample of a background ray, and those more than
    /// `FREE_SPACE_MARGIN_MM` in front of the true depth of a foreground one), both
    /// passes (0: off). Beyond the paper, like the distillation: it carves the visual
    /// hull where the rendering losses cannot, their gradients `δ·e^{−σδ}` gone once
    /// σ·δ ≫ 1.
    #[arg(long, default_value_t = 0.0)]
    #[serde(default)]
    pub free_space_weight: f64,
    /// Decay `β` of an exponential moving average of the weights, updated after every
    /// step (`θ̄ ← β·θ̄ + (1−β)·θ`; 0: off). With it on, validation, `weights.safetensors`
    /// and the exported network are the average, not the last step's weights: one
    /// head per step makes each step's weights swing between checkpoints
    /// (`docs/measurements/settings.md`), and the average over the last `1/(1−β)`
    /// steps smooths them out.
    /// The checkpoint keeps both (the average as `ema.NAME`); a checkpoint without an
    /// average starts it from its weights.
    #[arg(long, default_value_t = 0.0)]
    #[serde(default)]
    pub ema_decay: f64,
    /// Train through the Lambertian shading prior (`nelf_field::prior`) as bakes apply
    /// it: each head's per-view light transport normalised to its known source
    /// lighting and mixed with the clamped cosine about the normal of the density,
    /// whose gradient is taken over this many mm (0: the network's own transport, as
    /// the paper). The network then learns what the prior misses; validation scores
    /// the same mix.
    #[arg(long, default_value_t = 0.0)]
    #[serde(default)]
    pub shading_prior_mm: f32,
    /// Weight of the prior against the network's own transport.
    #[arg(long, default_value_t = nelf_field::prior::TRAINING_WEIGHT)]
    #[serde(default = "default_shading_prior_weight")]
    pub shading_prior_weight: f32,
    /// Folder of real portraits (PNG, JPEG or EXR; background black or transparent) for the
    /// domain-adaptation hook (`crate::domain`): each step also reproduces one of them
    /// through the image encoder and a decoder head, an L1 loss inside its
    /// foreground, so that the encoder's features stay faithful to photographs. The
    /// paper's real-portrait set cannot be fetched here; none of the shipped weights
    /// was trained with it. Off when not given.
    #[arg(long)]
    #[serde(default)]
    pub real_images: Option<PathBuf>,
    /// Weight of the domain-adaptation loss (the official implementation's 1).
    #[arg(long, default_value_t = 1.0)]
    #[serde(default = "default_real_weight")]
    pub real_weight: f64,
    /// Distillation points per step.
    #[arg(long, default_value_t = 256)]
    pub distill_points: usize,
    /// Seed of the initial weights and of every random choice.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Seconds between checkpoints.
    #[arg(long, default_value_t = 300.0)]
    pub checkpoint_secs: f64,
    /// Steps between validations on the held-out heads (0: never).
    #[arg(long, default_value_t = 500)]
    pub val_every: u64,
    /// Held-out heads per validation (their novel-light target views).
    #[arg(long, default_value_t = 4)]
    pub val_heads: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            data: PathBuf::from("out/train-data"),
            out: PathBuf::from("out/train-run"),
            arch: "small".into(),
            image_size: 64,
            rays: 128,
            coarse_samples: 32,
            fine_samples: 16,
            steps: 100_000,
            max_secs: 0.0,
            lr_mlp: 1e-4,
            lr_encoder: 2e-4,
            colour_loss: ColourLoss::L1,
            source_relative_light: false,
            novel_light_share: 0.7,
            depth_weight: 0.1,
            alpha_weight: 0.1,
            light_weight: 0.1,
            distill_weight: 0.0,
            distill_sigma_weight: None,
            distill_shape_weight: 0.0,
            distill_radiance_loss: ColourLoss::L1,
            free_space_weight: 0.0,
            ema_decay: 0.0,
            shading_prior_mm: 0.0,
            shading_prior_weight: nelf_field::prior::TRAINING_WEIGHT,
            real_images: None,
            real_weight: 1.0,
            distill_points: 256,
            seed: 0,
            checkpoint_secs: 300.0,
            val_every: 500,
            val_heads: 4,
        }
    }
}

fn default_real_weight() -> f64 {
    1.0
}

fn default_shading_prior_weight() -> f32 {
    nelf_field::prior::TRAINING_WEIGHT
}

impl TrainConfig {
    /// The shading prior this run trains through (`None` for `shading_prior_mm` 0).
    pub fn shading_prior(&self) -> Option<nelf_field::prior::ShadingPrior> {
        nelf_field::prior::ShadingPrior::from_step_mm(self.shading_prior_mm, self.shading_prior_weight)
    }

    /// `model` as this run applies it to `head`: with the shading prior, normalised to
    /// the head's source lighting and the prior mixed in; otherwise as it is.
    pub fn model_for_head(&self, model: &Model, head_source_light_net: &[f32]) -> Result<Model, TrainError> {
        Ok(match self.shading_prior() {
            Some(prior) => model
                .clone()
                .with_source_normalisation(Some(head_source_light_net))?
                .with_shading_prior(Some(prior))?,
            None => model.clone(),
        })
    }
    /// The weight of the distillation's σ term: `distill_sigma_weight`, else
    /// `distill_weight`.
    pub fn distill_sigma_weight(&self) -> f64 {
        self.distill_sigma_weight.unwrap_or(self.distill_weight)
    }

    /// The widths `arch` names: `official` (32/64/128/256, latent 32, geometry 64,
    /// light-transport hidden 128), `small` (16/32/64/64, 16, 32, 64) or `tiny`
    /// (8/16/16/32, 4, 8, 16: for tests).
    pub fn architecture(&self) -> Result<Architecture, TrainError> {
        let arch = match self.arch.as_str() {
            "official" => Architecture::OFFICIAL,
            "small" => Architecture {
                encoder_channels: [16, 32, 64, 64],
                latent_channels: 16,
                geometry_features: 32,
                lt_hidden: 64,
            },
            "tiny" => Architecture {
                encoder_channels: [8, 16, 16, 32],
                latent_channels: 4,
                geometry_features: 8,
                lt_hidden: 16,
            },
            other => {
                return Err(TrainError::Settings(format!(
                    "--arch {other}: choose official, small or tiny"
                )));
            }
        };
        Ok(arch)
    }

    /// Whether the domain-adaptation hook is on (a real-portrait folder is given).
    pub fn domain_adaptation(&self) -> bool {
        self.real_images.is_some()
    }

    /// The model configuration of this run.
    pub fn nelf_config(&self) -> Result<NelfConfig, TrainError> {
        Ok(NelfConfig {
            coarse_samples: self.coarse_samples,
            fine_samples: self.fine_samples,
            architecture: self.architecture()?,
            ..NelfConfig::default()
        })
    }

    /// Checks ranges before any work is done.
    pub fn validate(&self) -> Result<(), TrainError> {
        let bad = |m: String| Err(TrainError::Settings(m));
        self.architecture()?;
        if self.image_size == 0 || self.image_size % 16 != 0 {
            return bad(format!(
                "--image-size {} must be a positive multiple of 16",
                self.image_size
            ));
        }
        if self.rays == 0 || self.coarse_samples < 2 {
            return bad(format!(
                "--rays {} and --coarse-samples {} must be at least 1 and 2",
                self.rays, self.coarse_samples
            ));
        }
        let rates = [self.lr_mlp, self.lr_encoder];
        if !rates.iter().all(|r| r.is_finite() && *r > 0.0) {
            return bad(format!("step sizes {rates:?} must be positive"));
        }
        if !(0.0..=1.0).contains(&self.novel_light_share) {
            return bad(format!(
                "--novel-light-share {} must be in [0, 1]",
                self.novel_light_share
            ));
        }
        let weights = [
            self.depth_weight,
            self.alpha_weight,
            self.light_weight,
            self.distill_weight,
            self.distill_sigma_weight(),
            self.distill_shape_weight,
            self.free_space_weight,
            self.real_weight,
        ];
        if !weights.iter().all(|w| w.is_finite() && *w >= 0.0) {
            return bad(format!("loss weights {weights:?} must be non-negative"));
        }
        if !(self.shading_prior_mm.is_finite() && self.shading_prior_mm >= 0.0) {
            return bad(format!(
                "--shading-prior-mm {} must be ≥ 0 (0: off)",
                self.shading_prior_mm
            ));
        }
        if let Some(prior) = self.shading_prior() {
            prior.validate()?;
        }
        if !(0.0..1.0).contains(&self.ema_decay) {
            return bad(format!(
                "--ema-decay {} must be in [0, 1) (0: off)",
                self.ema_decay
            ));
        }
        if !(self.checkpoint_secs.is_finite() && self.checkpoint_secs > 0.0 && self.max_secs >= 0.0) {
            return bad(format!(
                "--checkpoint-secs {} must be positive and --max-secs {} non-negative",
                self.checkpoint_secs, self.max_secs
            ));
        }
        Ok(())
    }

    /// Whether a checkpoint trained with `other` can continue under `self`: the
    /// same widths, image size and seed (the network and its data). The budget per
    /// step, the step sizes and the loss weights may change between sessions (for
    /// example more rays on a GPU); a run continues bit for bit only when nothing
    /// changed.
    pub fn same_network(&self, other: &Self) -> bool {
        self.arch == other.arch && self.image_size == other.image_size && self.seed == other.seed
    }
}
