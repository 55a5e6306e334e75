//! A network being trained ([`Trainable`]): its variables under their official
//! names, the model that reads them, their seeded initial values (PyTorch's
//! defaults), the optimiser over them, and copies of the weights for validation and
//! export.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use nelf_field::Model;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::adam::Adam;
use crate::config::TrainConfig;
use crate::domain::{ReproduceHead, is_head_variable};
use crate::error::TrainError;

/// A network being trained: its variables and the model that reads them.
pub struct Trainable {
    /// The variables, by their official names.
    pub varmap: VarMap,
    /// The model over [`Trainable::varmap`].
    pub model: Model,
    /// The domain-adaptation hook's decoder head, when the run has one (its
    /// variables are in [`Trainable::varmap`] under [`crate::domain::HEAD_PREFIX`]).
    pub reproduce: Option<ReproduceHead>,
}

impl std::fmt::Debug for Trainable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainable")
            .field("model", &self.model)
            .finish_non_exhaustive()
    }
}

impl Trainable {
    /// A network of `config`'s widths with seeded initial weights: PyTorch's default
    /// `U(±1/√fan_in)` for matrices and biases, unit `GroupNorm` scales, zero
    /// shifts, `PReLU` slopes 0.25.
    pub fn init(config: &TrainConfig, device: &Device) -> Result<Self, TrainError> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
        let model = Model::new(&vb, config.nelf_config()?)?;
        let mut rng = Pcg64::seed_from_u64(config.seed ^ 0x5EED_1417);
        init_variables(&sorted_vars(&varmap)?, &mut rng, device)?;
        // The hook's head is made after the network's variables are drawn, from a
        // stream of its own, so the network starts as it does without the hook.
        let reproduce = if config.domain_adaptation() {
            let head = ReproduceHead::new(&vb, &config.architecture()?)?;
            let vars: Vec<_> = sorted_vars(&varmap)?
                .into_iter()
                .filter(|(n, _)| is_head_variable(n))
                .collect();
            let mut rng = Pcg64::seed_from_u64(config.seed ^ 0x5245_5052_4F44);
            init_variables(&vars, &mut rng, device)?;
            Some(head)
        } else {
            None
        };
        Ok(Self {
            varmap,
            model,
            reproduce,
        })
    }

    /// A network to go on training from the weights in `bytes` (a safetensors file,
    /// official key names, as [`Model::from_safetensors_bytes`] reads it: its widths,
    /// working image size and light units come from the file; `origin` names it in
    /// errors).
    pub fn from_safetensors_bytes(
        bytes: &[u8],
        origin: &Path,
        config: nelf_field::NelfConfig,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let read = Model::from_safetensors_bytes(bytes, origin, config, device)?;
        let tensors = candle_core::safetensors::load_buffer(bytes, device)
            .map_err(|e| TrainError::file(origin, format!("not a safetensors file: {e}")))?;
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
        let model = Model::new(&vb, *read.config())?
            .with_working_image_size(read.working_image_size())
            .with_source_relative_light(read.source_relative_light());
        let trainable = Self {
            varmap,
            model,
            reproduce: None,
        };
        trainable.load_weights(&tensors, "")?;
        Ok(trainable)
    }

    /// The variables with the step size of their module (encoder or MLPs).
    pub fn optimizer(&self, config: &TrainConfig) -> Result<Adam, TrainError> {
        let vars = sorted_vars(&self.varmap)?
            .into_iter()
            .map(|(name, var)| {
                let lr = if name.starts_with("image_encoder.") {
                    config.lr_encoder
                } else {
                    config.lr_mlp
                };
                (name, var, lr)
            })
            .collect();
        Adam::new(vars, (config.ema_decay > 0.0).then_some(config.ema_decay))
    }

    /// The weights as named tensors (the official key names).
    pub fn weights(&self) -> Result<Vec<(String, Tensor)>, TrainError> {
        Ok(sorted_vars(&self.varmap)?
            .into_iter()
            .map(|(n, v)| (n, v.as_tensor().clone()))
            .collect())
    }

    /// The network with a copy of the current weights as plain tensors: it builds no
    /// gradient graph and takes the fused inference kernels (validation: a graph
    /// over a full image held ~24 GB here).
    pub fn snapshot(&self) -> Result<Model, TrainError> {
        self.snapshot_of(self.weights()?)
    }

    /// The network with a copy of `weights` (named as [`Trainable::weights`], for
    /// example [`Adam::averaged_weights`]) as plain tensors.
    pub fn snapshot_of(&self, weights: Vec<(String, Tensor)>) -> Result<Model, TrainError> {
        let tensors = weights
            .into_iter()
            .map(|(n, t)| Ok((n, t.detach().copy()?)))
            .collect::<Result<HashMap<_, _>, TrainError>>()?;
        let vb = VarBuilder::from_tensors(tensors, DType::F32, self.model.device());
        Ok(Model::new(&vb, *self.model.config())?
            .with_working_image_size(self.model.working_image_size())
            .with_source_relative_light(self.model.source_relative_light()))
    }

    /// Sets the weights from named tensors (every variable must be present, but for
    /// the domain-adaptation head, which keeps its values where a file saved without
    /// the hook lacks it).
    pub fn load_weights(&self, tensors: &HashMap<String, Tensor>, prefix: &str) -> Result<(), TrainError> {
        for (name, var) in sorted_vars(&self.varmap)? {
            let key = format!("{prefix}{name}");
            if is_head_variable(&name) && !tensors.contains_key(&key) {
                continue;
            }
            let t = crate::adam::checkpoint_tensor(tensors, &key, var.dims())?;
            var.set(&t.to_device(var.device())?)?;
        }
        Ok(())
    }
}

/// Draws the initial values of `vars` as [`Trainable::init`] describes.
fn init_variables(vars: &[(String, Var)], rng: &mut Pcg64, device: &Device) -> Result<(), TrainError> {
    // Fan-in of each bias: its sibling weight's.
    let fans: HashMap<String, usize> = vars
        .iter()
        .filter(|(n, v)| n.ends_with(".weight") && v.dims().len() >= 2)
        .map(|(n, v)| {
            (
                n.trim_end_matches(".weight").to_string(),
                v.dims()[1..].iter().product(),
            )
        })
        .collect();
    for (name, var) in vars {
        let dims = var.dims().to_vec();
        let count: usize = dims.iter().product();
        let (stem, leaf) = name.rsplit_once('.').unwrap_or(("", name.as_str()));
        let norm = stem.ends_with("norm");
        let values: Vec<f32> = if dims.len() >= 2 {
            let fan: usize = dims[1..].iter().product();
            let bound = 1.0 / (fan.max(1) as f32).sqrt();
            (0..count).map(|_| rng.random_range(-bound..bound)).collect()
        } else if norm && leaf == "weight" {
            vec![1.0; count]
        } else if norm && leaf == "bias" {
            vec![0.0; count]
        } else if leaf == "bias" {
            let bound = 1.0 / (fans.get(stem).copied().unwrap_or(1).max(1) as f32).sqrt();
            (0..count).map(|_| rng.random_range(-bound..bound)).collect()
        } else {
            vec![0.25; count]
        };
        var.set(&Tensor::from_vec(values, dims, device)?)?;
    }
    Ok(())
}

/// The variables of `varmap`, sorted by name.
fn sorted_vars(varmap: &VarMap) -> Result<Vec<(String, Var)>, TrainError> {
    let data = varmap
        .data()
        .lock()
        .map_err(|_| TrainError::Settings("the variable map's lock is poisoned".into()))?;
    let mut vars: Vec<(String, Var)> = data.iter().map(|(n, v)| (n.clone(), v.clone())).collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(vars)
}
