//! Training steps (Sun et al. 2021, §4.3), split by job:
//!
//! * [`prepare`](self::prepare()): a dataset head at the training resolution in the
//!   network's units ([`PreparedHead`]: source views, target views, the lightings and
//!   the distillation's ground truth);
//! * sampling: the step's generator ([`step_rng`]), the pixels and rays of a target
//!   view and their samples along each ray, rendered through the coarse and fine
//!   networks ([`render_passes`]);
//! * the loss of a step ([`step_loss`], [`step_loss_on`]; the equation is there);
//! * [`Trainable`]: the network's variables, their seeded initial values, the optimiser
//!   over them;
//! * checkpoints: save, load and resume ([`save_checkpoint`], [`load_checkpoint`]),
//!   and the density heads' reset ([`reset_density_heads`]);
//! * [`train_step`]: one optimiser step, which the resumable loop of [`crate::run`]
//!   repeats.
//!
//! Every random choice of step `k` comes from a generator seeded by `(seed, k)`, so
//! the state of a run is its weights, its Adam moments and its step count: a
//! checkpoint holds exactly those, and a resumed run continues bit for bit.

mod checkpoint;
mod loss;
mod prepare;
mod sampling;
mod step;
mod trainable;

pub use checkpoint::{
    CHECKPOINT_INFO, CHECKPOINT_TENSORS, CheckpointInfo, DensityReset, RunPaths, load_checkpoint,
    read_checkpoint_info, reset_density_heads, save_checkpoint,
};
pub use loss::{FREE_SPACE_MARGIN_MM, LossParts, relit_by_shape, secs_since, step_loss, step_loss_on};
pub use prepare::{
    PreparedHead, PreparedTarget, SHAPE_PROBES, prepare, prepare_heads, select_views, shape_probe_lightings,
};
pub use sampling::{Jitter, render_passes, step_rng, target_rays};
pub use step::train_step;
pub use trainable::Trainable;
