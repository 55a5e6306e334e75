//! One optimiser step ([`train_step`]): the step's generator draws a training head,
//! the loss of [`super::step_loss`] (plus, with the domain-adaptation hook, the
//! reproduction loss of one real portrait) is differentiated, and Adam updates the
//! weights. The resumable loop that repeats it is [`crate::run`].

use std::time::Instant;

use rand::Rng;

use super::loss::{LossParts, scalar, secs_since, step_loss};
use super::prepare::PreparedHead;
use super::sampling::step_rng;
use super::trainable::Trainable;
use crate::adam::Adam;
use crate::config::TrainConfig;
use crate::domain::{RealImages, reproduction_loss};
use crate::error::TrainError;

/// One optimiser step on the head the step's generator draws.
///
/// With the domain-adaptation hook (`trainable` made with a real-portrait folder,
/// `real` its portraits) the step adds the reproduction loss of one portrait
/// ([`crate::domain`]), drawn from a stream of its own.
pub fn train_step(
    trainable: &Trainable,
    adam: &mut Adam,
    heads: &[PreparedHead],
    real: Option<&RealImages>,
    config: &TrainConfig,
) -> Result<LossParts, TrainError> {
    match (&trainable.reproduce, real) {
        (Some(_), None) => {
            return Err(TrainError::Settings(
                "the network has a domain-adaptation head but no real portraits were given".into(),
            ));
        }
        (None, Some(_)) => {
            return Err(TrainError::Settings(
                "real portraits were given to a network made without --real-images".into(),
            ));
        }
        _ => {}
    }
    let mut rng = step_rng(config.seed, adam.steps());
    if heads.is_empty() {
        return Err(TrainError::Settings("no training heads".into()));
    }
    let head = &heads[rng.random_range(0..heads.len())];
    let model = config.model_for_head(&trainable.model, &head.source_light_net)?;
    let (mut loss, mut parts) = step_loss(&model, head, config, &mut rng)?;
    if let (Some(decoder), Some(real)) = (&trainable.reproduce, real)
        && config.real_weight > 0.0
    {
        let pick = real.pick(config.seed, adam.steps());
        let (_, pixels) = real
            .get(pick)
            .ok_or_else(|| TrainError::Settings("no real portraits".into()))?;
        let term = reproduction_loss(&model, decoder, pixels, real.size())?;
        parts.real = scalar(&term)?;
        parts.total += config.real_weight * parts.real;
        loss = (loss + (term * config.real_weight)?)?;
    }
    let clock = Instant::now();
    let grads = loss.backward()?;
    parts.phase_secs[3] = secs_since(clock);
    adam.step(&grads)?;
    // Values are read back (a device sync) so the time is the update's own.
    adam.sync()?;
    parts.phase_secs[4] = secs_since(clock) - parts.phase_secs[3];
    Ok(parts)
}
