//! A run's checkpoint: save, load and resume. A checkpoint is the run's whole state
//! (weights, Adam moments and step count: every random choice of a step comes from
//! the step's own generator), so a resumed run continues bit for bit. Also the
//! density heads' reset of a saturated run ([`reset_density_heads`]) and the files
//! of a run folder ([`RunPaths`]). Files are written through [`crate::files`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::loss::LossParts;
use super::trainable::Trainable;
use nelf_format::io_error::IoResultExt;

use crate::adam::Adam;
use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::files::{write_bytes, write_tensors};

/// What a checkpoint records beside its tensors (`checkpoint.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckpointInfo {
    /// Steps taken.
    pub step: u64,
    /// Seconds of training so far, over all sessions.
    pub train_secs: f64,
    /// The run's configuration.
    pub config: TrainConfig,
    /// The last step's losses.
    pub last_loss: LossParts,
}

/// File names inside a run folder.
pub const CHECKPOINT_TENSORS: &str = "checkpoint.safetensors";
/// The checkpoint's metadata.
pub const CHECKPOINT_INFO: &str = "checkpoint.json";

/// Saves weights, Adam moments and the step to `dir` (tensors first, then the
/// metadata that names the step: a crash between the two leaves the older
/// metadata, which a resume then rejects as not matching, never a silent mix).
pub fn save_checkpoint(
    dir: &Path,
    trainable: &Trainable,
    adam: &Adam,
    info: &CheckpointInfo,
) -> Result<(), TrainError> {
    std::fs::create_dir_all(dir).with_path(dir)?;
    let mut tensors: HashMap<String, Tensor> = trainable
        .weights()?
        .into_iter()
        .map(|(n, t)| (format!("param.{n}"), t))
        .collect();
    tensors.extend(adam.state_tensors());
    tensors.insert("step".into(), Tensor::new(&[info.step as f64], &Device::Cpu)?);
    let path = dir.join(CHECKPOINT_TENSORS);
    write_tensors(&tensors, &path)?;
    let json = serde_json::to_vec_pretty(info).map_err(|e| TrainError::Settings(e.to_string()))?;
    write_bytes(&dir.join(CHECKPOINT_INFO), &json)
}

/// Reads a checkpoint's description (`checkpoint.json`) without its tensors.
pub fn read_checkpoint_info(dir: &Path) -> Result<CheckpointInfo, TrainError> {
    let info_path = dir.join(CHECKPOINT_INFO);
    let text = std::fs::read(&info_path).with_path(&info_path)?;
    serde_json::from_slice(&text).map_err(|e| TrainError::File {
        path: info_path,
        message: format!("not a checkpoint description: {e}"),
    })
}

/// Loads a checkpoint saved by [`save_checkpoint`] into `trainable` and `adam`.
pub fn load_checkpoint(
    dir: &Path,
    trainable: &Trainable,
    adam: &mut Adam,
) -> Result<CheckpointInfo, TrainError> {
    let info_path = dir.join(CHECKPOINT_INFO);
    let info = read_checkpoint_info(dir)?;
    let path = dir.join(CHECKPOINT_TENSORS);
    let tensors =
        candle_core::safetensors::load(&path, trainable.model.device()).map_err(|e| TrainError::File {
            path: path.clone(),
            message: format!("not a checkpoint: {e}"),
        })?;
    let saved_step = tensors
        .get("step")
        .and_then(|t| t.to_vec1::<f64>().ok())
        .and_then(|v| v.first().copied())
        .ok_or_else(|| TrainError::File {
            path: path.clone(),
            message: "no step".into(),
        })?;
    if saved_step != info.step as f64 {
        return Err(TrainError::File {
            path,
            message: format!(
                "holds step {saved_step}, {} says {}",
                info_path.display(),
                info.step
            ),
        });
    }
    trainable
        .load_weights(&tensors, "param.")
        .map_err(|e| TrainError::File {
            path: path.clone(),
            message: e.to_string(),
        })?;
    adam.restore(&tensors, info.step).map_err(|e| TrainError::File {
        path: path.clone(),
        message: e.to_string(),
    })?;
    Ok(info)
}

/// What [`reset_density_heads`] changed.
#[derive(Debug, Clone, PartialEq)]
pub struct DensityReset {
    /// The checkpoint's step (unchanged).
    pub step: u64,
    /// The output layers reset, one per density head (coarse, fine).
    pub layers: Vec<String>,
}

/// Re-initialises the output layer of each density head (`*density_mlp.layers.N`, the
/// last `N`) in the checkpoint in `dir`: its weights scaled by `weight_scale`, its bias
/// set so that `softplus(bias) = sigma_per_mm`, its Adam moments zeroed; every other
/// tensor and the step stay as they were.
///
/// For a run whose density saturated: with `σ·δ ≫ 1` over every ray step inside the
/// hull, alpha is 1 wherever the hull is and `∂α/∂σ = δ·e^{−σδ}` is 0, so neither the
/// colour nor the alpha loss can carve the hull again (`nelf-small-run` sat at
/// σ ≈ 17/mm with 12.5 mm steps from step ~300 to 3514).
pub fn reset_density_heads(
    dir: &Path,
    sigma_per_mm: f64,
    weight_scale: f64,
) -> Result<DensityReset, TrainError> {
    if !(sigma_per_mm > 0.0 && sigma_per_mm.is_finite() && weight_scale.is_finite()) {
        return Err(TrainError::Settings(format!(
            "density reset: σ must be positive and finite (got {sigma_per_mm}/mm), the weight scale finite (got {weight_scale})"
        )));
    }
    let info = read_checkpoint_info(dir)?;
    let path = dir.join(CHECKPOINT_TENSORS);
    let mut tensors = candle_core::safetensors::load(&path, &Device::Cpu).map_err(|e| TrainError::File {
        path: path.clone(),
        message: format!("not a checkpoint: {e}"),
    })?;
    // The last layer of each density head: the highest `N` among its biases.
    let mut last: HashMap<String, usize> = HashMap::new();
    for key in tensors.keys() {
        let Some(rest) = key.strip_prefix("param.") else {
            continue;
        };
        let Some((head, tail)) = rest.split_once("density_mlp.layers.") else {
            continue;
        };
        let Some(n) = tail.strip_suffix(".bias").and_then(|n| n.parse::<usize>().ok()) else {
            continue;
        };
        let entry = last.entry(format!("{head}density_mlp.layers")).or_insert(n);
        *entry = (*entry).max(n);
    }
    if last.is_empty() {
        return Err(TrainError::File {
            path,
            message: "no density head (`*density_mlp.layers.N.bias`) in this checkpoint".into(),
        });
    }
    // softplus⁻¹(σ) = ln(e^σ − 1).
    let bias_value = sigma_per_mm.exp_m1().ln() as f32;
    let mut layers: Vec<String> = last.iter().map(|(stem, n)| format!("{stem}.{n}")).collect();
    layers.sort();
    let missing = |key: &str| TrainError::File {
        path: path.clone(),
        message: format!("{key} is missing"),
    };
    for layer in &layers {
        for leaf in ["weight", "bias"] {
            // The parameter, then its two Adam moments (zeroed).
            for kind in ["param", "adam_m", "adam_v"] {
                let key = format!("{kind}.{layer}.{leaf}");
                let old = tensors.get(&key).ok_or_else(|| missing(&key))?;
                let new = match (kind, leaf) {
                    ("param", "weight") => (old * weight_scale)?,
                    ("param", _) => Tensor::full(bias_value, old.dims(), &Device::Cpu)?,
                    _ => old.zeros_like()?,
                };
                tensors.insert(key, new);
            }
        }
    }
    write_tensors(&tensors, &path)?;
    Ok(DensityReset {
        step: info.step,
        layers,
    })
}

/// Where a run keeps its files.
#[derive(Debug, Clone)]
pub struct RunPaths {
    /// The run folder.
    pub dir: PathBuf,
}

impl RunPaths {
    /// The validation log.
    pub fn log(&self) -> PathBuf {
        self.dir.join("validation.csv")
    }

    /// The exported weights (official key names).
    pub fn weights(&self) -> PathBuf {
        self.dir.join("weights.safetensors")
    }
}
