//! Adam (Kingma & Ba 2015) over named variables with a step size per variable,
//! whose whole state (first and second moments, step count) can be saved and
//! restored exactly, so that a resumed run continues bit for bit:
//!
//! `m ← β₁m + (1−β₁)g`, `v ← β₂v + (1−β₂)g²`,
//! `θ ← θ − α·(m / (1−β₁ᵗ)) / (√(v / (1−β₂ᵗ)) + ε)`.
//!
//! Optionally it keeps an exponential moving average of the weights after each
//! update (`θ̄ ← β·θ̄ + (1−β)·θ`, Polyak & Juditsky 1992), saved and restored with
//! the moments.

use std::collections::BTreeMap;

use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};

use crate::error::TrainError;

/// β₁ (the paper's and PyTorch's default).
const BETA1: f64 = 0.9;
/// β₂.
const BETA2: f64 = 0.999;
/// ε.
const EPS: f64 = 1e-8;
/// Key prefix of the weight average's tensors in a checkpoint.
pub const EMA_PREFIX: &str = "ema.";

/// The tensor `key` of a checkpoint, which must have the shape `dims` of the
/// network it is loaded into.
pub(crate) fn checkpoint_tensor<'a>(
    tensors: &'a std::collections::HashMap<String, Tensor>,
    key: &str,
    dims: &[usize],
) -> Result<&'a Tensor, TrainError> {
    let t = tensors
        .get(key)
        .ok_or_else(|| TrainError::Settings(format!("the checkpoint has no `{key}`")))?;
    if t.dims() != dims {
        return Err(TrainError::Settings(format!(
            "`{key}` is {:?} in the checkpoint, {dims:?} in this network",
            t.dims()
        )));
    }
    Ok(t)
}

/// One optimised variable.
#[derive(Debug)]
struct Slot {
    var: Var,
    lr: f64,
    m: Tensor,
    v: Tensor,
    /// The moving average of the weights, when one is kept.
    ema: Option<Tensor>,
}

/// Adam over named variables (sorted by name, so the update order is fixed).
#[derive(Debug)]
pub struct Adam {
    slots: BTreeMap<String, Slot>,
    steps: u64,
    ema_decay: Option<f64>,
}

impl Adam {
    /// Adam over `vars`, each with its step size; with `ema_decay` it also keeps a
    /// moving average of the weights, started from their values now.
    pub fn new(vars: Vec<(String, Var, f64)>, ema_decay: Option<f64>) -> Result<Self, TrainError> {
        if let Some(beta) = ema_decay
            && !(0.0..1.0).contains(&beta)
        {
            return Err(TrainError::Settings(format!(
                "a weight average's decay must be in [0, 1), got {beta}"
            )));
        }
        let mut slots = BTreeMap::new();
        for (name, var, lr) in vars {
            let m = var.as_tensor().zeros_like()?;
            let v = var.as_tensor().zeros_like()?;
            let ema = match ema_decay {
                Some(_) => Some(var.as_tensor().detach().copy()?),
                None => None,
            };
            slots.insert(name, Slot { var, lr, m, v, ema });
        }
        Ok(Self {
            slots,
            steps: 0,
            ema_decay,
        })
    }

    /// Updates taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// One update from `grads` (variables without a gradient are skipped).
    pub fn step(&mut self, grads: &GradStore) -> Result<(), TrainError> {
        self.steps += 1;
        let t = self.steps as i32;
        let c1 = 1.0 - BETA1.powi(t);
        let c2 = 1.0 - BETA2.powi(t);
        for slot in self.slots.values_mut() {
            let Some(g) = grads.get(slot.var.as_tensor()) else {
                continue;
            };
            // candle leaves a variable's gradient attached to the graph that made it
            // (its backward pass skips variables when it detaches), so a moment built
            // from it would keep that step's whole forward graph alive, and the next
            // moment this one: ~70 MB a step. Detached, a step frees its graph.
            let g = g.detach();
            let g = &g;
            slot.m = ((&slot.m * BETA1)? + (g * (1.0 - BETA1))?)?;
            slot.v = ((&slot.v * BETA2)? + (g.sqr()? * (1.0 - BETA2))?)?;
            let m_hat = (&slot.m / c1)?;
            let v_hat = (&slot.v / c2)?;
            let delta = (m_hat / (v_hat.sqrt()? + EPS)?)?;
            let next = (slot.var.as_tensor() - (delta * slot.lr)?)?;
            // `next` is built from the variable and so carries its graph; the average
            // must not, or each step's average would keep the one before alive (the
            // run grew to 24 GB in 1,500 steps before this detach).
            if let (Some(beta), Some(ema)) = (self.ema_decay, &mut slot.ema) {
                *ema = ((&*ema * beta)? + (next.detach() * (1.0 - beta))?)?.detach();
            }
            slot.var.set(&next)?;
        }
        Ok(())
    }

    /// The moving average of the weights (sorted by name), when one is kept.
    pub fn averaged_weights(&self) -> Option<Vec<(String, Tensor)>> {
        self.ema_decay?;
        self.slots
            .iter()
            .map(|(name, s)| s.ema.clone().map(|t| (name.clone(), t)))
            .collect()
    }

    /// Waits for the device to finish the update (reads one value back).
    pub fn sync(&self) -> Result<(), TrainError> {
        if let Some(slot) = self.slots.values().next() {
            slot.var
                .as_tensor()
                .flatten_all()?
                .narrow(0, 0, 1)?
                .to_vec1::<f32>()?;
        }
        Ok(())
    }

    /// The moments as named tensors (`adam_m.NAME`, `adam_v.NAME`, and the weight
    /// average's `ema.NAME` when one is kept) for a checkpoint.
    pub fn state_tensors(&self) -> Vec<(String, Tensor)> {
        self.slots
            .iter()
            .flat_map(|(name, s)| {
                [
                    Some((format!("adam_m.{name}"), s.m.clone())),
                    Some((format!("adam_v.{name}"), s.v.clone())),
                    s.ema.clone().map(|t| (format!("{EMA_PREFIX}{name}"), t)),
                ]
            })
            .flatten()
            .collect()
    }

    /// Restores the moments, the weight average and the step count saved by
    /// [`Adam::state_tensors`] (call after the weights are restored).
    pub fn restore(
        &mut self,
        tensors: &std::collections::HashMap<String, Tensor>,
        steps: u64,
    ) -> Result<(), TrainError> {
        for (name, slot) in &mut self.slots {
            for (key, target) in [
                (format!("adam_m.{name}"), &mut slot.m),
                (format!("adam_v.{name}"), &mut slot.v),
            ] {
                // The domain-adaptation head of a run that turns the hook on from a
                // checkpoint saved without it starts with zero moments.
                if crate::domain::is_head_variable(name) && !tensors.contains_key(&key) {
                    continue;
                }
                let t = checkpoint_tensor(tensors, &key, target.dims())?;
                *target = t.to_device(target.device())?;
            }
            // An average saved with the checkpoint continues; a checkpoint without
            // one (saved with the average off) starts it from the restored weights.
            if let Some(ema) = &mut slot.ema {
                let key = format!("{EMA_PREFIX}{name}");
                *ema = match tensors.get(&key) {
                    Some(_) => checkpoint_tensor(tensors, &key, ema.dims())?.to_device(ema.device())?,
                    None => slot.var.as_tensor().detach().copy()?,
                };
            }
        }
        self.steps = steps;
        Ok(())
    }
}
